"""Helpers on the recorded rows that the figures of merit share: the RMS of an array, the runs of True in a
mask, the longest of them, the driver's direction, a position's roll-back, km/h per m/s, and where the "after"
figures start (``T_FROM``).
"""

from __future__ import annotations

import numpy as np

KMH = 3.6  #: km/h per m/s
#: the start of the window of the "after" figures [s] (``windows.after_figures``, ``windows.tracking_figures``,
#: ``sensorless.sensorless_metrics``): past the paper scenarios' 10 s start-up ramp and its settling, the sensorless
#: unit's route delayed by its alignment (at speed by 12.5 s) and the robustness maps' road step at 15 s;
#: ``pmsm-cosim compare --from``, the report and the robustness report all start their "after" figures here
T_FROM = 20.0


def rms(x) -> float:
    """The root mean square of ``x`` (nan if empty)."""
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else float("nan")


def runs_of(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, end) index pairs of the runs of True in ``mask`` (end exclusive)."""
    padded = np.concatenate(([0], mask.astype(np.int8), [0]))
    edges = np.diff(padded)
    return list(zip(np.nonzero(edges == 1)[0].tolist(), np.nonzero(edges == -1)[0].tolist()))


def longest_run(mask: np.ndarray, dt_row: float) -> float:
    """Longest run of True [s]."""
    if not np.any(mask):
        return 0.0
    padded = np.concatenate(([0], mask.astype(np.int8), [0]))
    starts, ends = np.nonzero(np.diff(padded) == 1)[0], np.nonzero(np.diff(padded) == -1)[0]
    return float(np.max(ends - starts) * dt_row)


def direction(omega_ref: np.ndarray) -> np.ndarray:
    """+1 where the driver asks for forward (or to hold, at the start), -1 for reverse; a zero
    reference keeps the direction of the last non-zero one (a car stopped from reverse)."""
    d = np.sign(omega_ref)
    nz = np.nonzero(d)[0]
    if len(nz) == 0:
        return np.ones_like(omega_ref)
    idx = np.maximum.accumulate(np.where(d != 0, np.arange(len(d)), -1))
    out = np.where(idx >= 0, d[np.maximum(idx, 0)], 1.0)
    return out


def roll_back(x: np.ndarray) -> float:
    """Largest backward travel [m] of a position trace: its drop below its running maximum."""
    return float(np.max(np.maximum.accumulate(x) - x)) if len(x) else 0.0
