"""The whole speed range: following the driver (where the car fell behind, against its band), and the data
sheet's acceleration figures (0-50, 0-100 km/h, top speed, the braking and the energy it recovered).
"""

from __future__ import annotations

import math

import numpy as np

from .rows import KMH, direction, runs_of

#: behind the driver: the vehicle speed short of the reference's (in the reference's direction) by more
#: than this [km/h] ... [chosen: the regulatory drive-cycle band, +-2 km/h]
BEHIND_BAND_KMH = 2.0
#: ... for longer than this [s] [chosen: a speed loop tuned soft for the observers (omega_n = 2 rad/s)
#: lags a ramp by ~1 s; a shortfall that lasts longer is a car that cannot follow]
BEHIND_HOLD = 1.0
#: the launch of an acceleration run: the first row whose speed reference exceeds this [rad/s]
LAUNCH_REF = 1.0


def wheel_ratio(r: dict[str, np.ndarray]) -> float:
    """v_vehicle / omega_m of a run [m/rad] (eqs 1, 6: r_w / n_g), from its rows with the car moving;
    nan if it never moved."""
    w, v = r["omega_m"], r["v_vehicle"]
    moving = np.abs(w) > 1.0
    if not np.any(moving):
        return math.nan
    return float(np.median(v[moving] / w[moving]))


def behind_figures(r: dict[str, np.ndarray], band_kmh: float = BEHIND_BAND_KMH,
                   hold: float = BEHIND_HOLD) -> dict | None:
    """Where and by how much the car fell behind the driver (a route faster than its top speed, a hill
    steeper than its torque: not an error, a figure): the stretches where the vehicle speed stays short of
    the reference's (omega_ref through ``wheel_ratio``, in the reference's direction) by more than
    ``band_kmh`` for longer than ``hold``. None if there is none (or the car never moved); else
    ``episodes``, ``t_behind`` [s] (their total), ``largest_kmh`` (the largest shortfall) and ``t_largest``
    [s], ``first`` [t_start, t_end] [s]."""
    t = r["time"]
    ratio = wheel_ratio(r)
    if len(t) < 2 or not math.isfinite(ratio):
        return None
    dt_row = float(t[1] - t[0])
    d = direction(r["omega_ref"])
    short = KMH * d * (r["omega_ref"] * ratio - r["v_vehicle"])  # [km/h], > 0: behind
    stretches = [(a, b) for a, b in runs_of(short > band_kmh) if (b - a) * dt_row > hold]
    if not stretches:
        return None
    worst = max(stretches, key=lambda ab: float(np.max(short[ab[0]:ab[1]])))
    i = worst[0] + int(np.argmax(short[worst[0]:worst[1]]))
    a, b = stretches[0]
    return {"episodes": len(stretches), "t_behind": float(sum(b - a for a, b in stretches) * dt_row),
            "largest_kmh": float(short[i]), "t_largest": float(t[i]),
            "first": [float(t[a]), float(t[b - 1])]}


def _first_at_or_above(t: np.ndarray, x: np.ndarray, level: float, t_from: float) -> float | None:
    """The first time >= ``t_from`` at which ``x`` reaches ``level``, interpolated between rows; None if never."""
    idx = np.nonzero((x >= level) & (t >= t_from))[0]
    if not len(idx):
        return None
    i = int(idx[0])
    if i == 0 or t[i - 1] < t_from or x[i] == x[i - 1]:
        return float(t[i])
    return float(t[i - 1] + (level - x[i - 1]) / (x[i] - x[i - 1]) * (t[i] - t[i - 1]))


def acceleration_figures(r: dict[str, np.ndarray]) -> dict | None:
    """The data sheet's figures of an acceleration run (the car reaches 50 km/h; None otherwise): from the
    launch (the first row whose omega_ref exceeds its first row's by ``LAUNCH_REF``; ``v_launch_kmh``, the
    speed there: 0 from standstill, a flying start's else), ``t_0_50`` and ``t_0_100`` [s] to 50 and
    100 km/h (None if not reached), ``top_speed_kmh`` and when (``t_top``); the braking from the top speed:
    ``t_brake`` [s], the first row after the top speed whose reference is below its maximum (None if it
    never falls), ``braking_time`` to below 1 km/h, and with the plant's energy columns ``E_kinetic`` and
    ``E_regen`` recorded (J): ``kinetic_Wh`` at the braking's start, ``recovered_Wh`` (the DC-link energy
    regenerated from then on) and ``recovered_share`` of the kinetic energy."""
    t, v, w_ref = r["time"], r["v_vehicle"] * KMH, r["omega_ref"]
    if not len(t) or float(np.max(v)) < 50.0:
        return None
    launch = np.nonzero(w_ref > w_ref[0] + LAUNCH_REF)[0]  # (a flying start: the reference's first rise)
    i0 = int(launch[0]) if len(launch) else 0
    t0 = float(t[i0])
    t50 = _first_at_or_above(t, v, 50.0, t0)
    t100 = _first_at_or_above(t, v, 100.0, t0)
    i_top = int(np.argmax(v))
    out = {"t_launch": t0, "v_launch_kmh": float(v[i0]), "t_0_50": None if t50 is None else t50 - t0,
           "t_0_100": None if t100 is None else t100 - t0,
           "top_speed_kmh": float(v[i_top]), "t_top": float(t[i_top]),
           "t_brake": None, "braking_time": None}
    falling = np.nonzero((np.arange(len(t)) > i_top) & (w_ref < float(np.max(w_ref[:i_top + 1])) - LAUNCH_REF))[0]
    if not len(falling):
        return out
    ib = int(falling[0])
    out["t_brake"] = float(t[ib])
    stopped = np.nonzero((np.arange(len(t)) >= ib) & (np.abs(v) < 1.0))[0]
    out["braking_time"] = float(t[stopped[0]] - t[ib]) if len(stopped) else None
    if "E_kinetic" in r and "E_regen" in r:
        kinetic = float(r["E_kinetic"][ib])
        recovered = float(r["E_regen"][-1] - r["E_regen"][ib])
        out.update(kinetic_Wh=kinetic / 3600.0, recovered_Wh=recovered / 3600.0,
                   recovered_share=recovered / kinetic if kinetic > 0 else None)
    return out
