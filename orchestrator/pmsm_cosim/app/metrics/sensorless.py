"""The sensorless unit's figures (rows with ``pmsm_ev.results.SENSORLESS_COLUMNS``): its mode changes, the
handover to the closed loop, the start-up's speed error against its band, the roll-back, the time in I-f.
"""

from __future__ import annotations

import numpy as np

from .rows import T_FROM, roll_back

#: a start-up target: |omega_m - omega_ref| within this band [rad/s] ...
STARTUP_BAND = 10.0
#: ... from this time on [s] (the delayed routes reach 200 rad/s at 12.5 s)
STARTUP_FROM = 12.0
#: a car that rolls back more than this [m] was not held: the sensorless unit's start-up on level road and its
#: stop and restart on the hill (the report's targets), and the dead-time runs of the robustness report
ROLL_BACK_LIMIT = 0.05


def sensorless_metrics(r: dict[str, np.ndarray], t_from: float = T_FROM) -> dict:
    """Figures of a run with the sensorless columns (``SENSORLESS_COLUMNS``): the mode changes
    (time, from, to; 0 alignment, 1 I-f, 2 closed loop on the EKF; with injection 3 acquisition,
    4 polarity, 5 closed loop on the injection), the first handover to the closed loop (mode 2 or 5),
    the largest |omega_m - omega_ref| from ``STARTUP_FROM`` on, the roll-back [m] before ``t_from``
    (start-up) and after it (stops and restarts), and the time spent in I-f after ``t_from`` [s]."""
    t, mode = r["time"], r["mode"]
    changes = [(float(t[i + 1]), float(mode[i]), float(mode[i + 1])) for i in np.nonzero(np.diff(mode))[0]]
    closed = [c[0] for c in changes if c[2] in (2.0, 5.0)]
    late = t >= STARTUP_FROM
    early = t <= t_from
    dt_row = float(t[1] - t[0]) if len(t) > 1 else 0.0
    return {
        "mode_changes": changes,
        "t_closed_loop": closed[0] if closed else (0.0 if len(mode) and mode[0] in (2.0, 5.0) else None),
        "startup_speed_error_max": float(np.max(np.abs(r["omega_m"][late] - r["omega_ref"][late])))
        if np.any(late) else None,
        "roll_back_start": roll_back(r["x_vehicle"][early]),
        "roll_back_after": roll_back(r["x_vehicle"][~early]) if np.any(~early) else None,
        "t_if_after": float(np.count_nonzero(mode[~early] == 1.0) * dt_row),
    }


def handovers(mode_changes) -> dict[str, list[float]]:
    """The mode changes of ``sensorless_metrics`` by kind, their times [s]: ``closed`` (into the
    closed loop, mode 2, from any mode), ``down`` (from the closed loop back to I-f, 2 -> 1) and
    ``up`` (from I-f to the closed loop, 1 -> 2)."""
    return {"closed": [c[0] for c in mode_changes if c[2] == 2.0],
            "down": [c[0] for c in mode_changes if c[1] == 2.0 and c[2] == 1.0],
            "up": [c[0] for c in mode_changes if c[1] == 1.0 and c[2] == 2.0]}
