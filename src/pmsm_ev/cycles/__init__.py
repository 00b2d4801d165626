"""Drive cycles and road profiles as data (issue 24; docs/cycles.md, "The cycles as data").

* ``load(name_or_path) -> Cycle``: a shipped cycle by name (``names()``: wltc3b, udds, hwfet,
  us06; the CSV files of FASTSim 2.1.5, Apache-2.0, unchanged: data/README.md) or a user's CSV
  (a time column and a speed column whose unit its header gives; module ``table``).
* ``load_road(name_or_path) -> RoadProfile``: the grade by position, from a CSV of distance
  against grade or elevation (the shipped example: ``hilly``).

Bad input raises ``CycleError`` (a ``ValueError``): one line naming the file, the row (1-based,
the header is row 1) and the problem. Loading reads only; nothing is written.
"""

from __future__ import annotations

from .road import SHIPPED_ROADS, RoadProfile, load_road
from .table import ALIASES, GRADE_MAX, UNITS, CycleError
from .trace import SHIPPED, STANDSTILL_KMH, WLTC3B_PHASES, Cycle, Phase, load, names

__all__ = ["ALIASES", "GRADE_MAX", "SHIPPED", "SHIPPED_ROADS", "STANDSTILL_KMH", "UNITS", "WLTC3B_PHASES",
           "Cycle", "CycleError", "Phase", "RoadProfile", "load", "load_road", "names"]
