"""Drive cycles and road profiles as data (issue 24; docs/cycles.md, "The cycles as data").

* ``load(name_or_path) -> Cycle``: a shipped cycle by name (``names()``: wltc3b, udds, hwfet,
  us06; the CSV files of FASTSim 2.1.5, Apache-2.0, unchanged: data/README.md) or a user's CSV
  (a time column and a speed column whose unit its header gives; module ``table``).
* ``load_road(name_or_path) -> RoadProfile``: the grade by position, from a CSV of distance
  against grade or elevation (the shipped example: ``hilly``).
* ``repeated(cycle, n) -> Cycle``: the cycle n times back to back (a heat run).
* ``speed_reference(cycle, r_w, n_g) -> SpeedReference``: the cycle as the motor's speed reference
  omega_ref = v n_g / r_w and its derivative, smoothed as a driver would (module ``reference``:
  PCHIP through the 1 Hz points), on a 0.1 s grid.

Bad input raises ``CycleError`` (a ``ValueError``): one line naming the file, the row (1-based,
the header is row 1) and the problem. Loading reads only; nothing is written.
"""

from __future__ import annotations

from .reference import ACCEL_MARGIN, REFERENCE_DT, SpeedReference, pchip, speed_reference
from .road import SHIPPED_ROADS, RoadProfile, load_road
from .table import ALIASES, GRADE_MAX, UNITS, CycleError
from .trace import SHIPPED, STANDSTILL_KMH, WLTC3B_PHASES, Cycle, Phase, load, names, repeated

__all__ = ["ACCEL_MARGIN", "ALIASES", "GRADE_MAX", "REFERENCE_DT", "SHIPPED", "SHIPPED_ROADS", "STANDSTILL_KMH",
           "UNITS", "WLTC3B_PHASES", "Cycle", "CycleError", "Phase", "RoadProfile", "SpeedReference", "load",
           "load_road", "names", "pchip", "repeated", "speed_reference"]
