"""The figures of merit of a run (its metrics.json, ``Master.run(metrics_of=...)`` through
``pmsm_cosim.app.drive.drive_metrics``), from the recorded columns of ``pmsm_ev.results``: the speed and
angle errors, the plateaus' torques, the elevation steps' dips and settling into ``SETTLING_BAND``, and the
blocks of the subjects a run's columns allow (``sensorless``, ``synchronism``, ``behind``, ``acceleration``,
``energy``)."""

from __future__ import annotations

import numpy as np

from pmsm_ev.results import BATTERY_COLUMNS, ENERGY_COLUMNS, SENSORLESS_COLUMNS, angle_error

from .energy import battery_metrics, energy_metrics
from .identification import identification_metrics
from .rows import rms
from .sensorless import sensorless_metrics
from .speed_range import acceleration_figures, behind_figures
from .synchronism import synchronism_metrics

#: speed band for settling times [rad/s]
SETTLING_BAND = 1.0
#: averaging window at the end of each plateau [s]
PLATEAU_WINDOW = 2.0


def compute_metrics(r: dict[str, np.ndarray]) -> dict:
    """Figures of merit from recorded columns (``pmsm_ev.results``: the result contract)."""
    t = r["time"]
    speed_err = r["omega_ref"] - r["omega_m"]
    theta_err = angle_error(r)
    m = {
        "speed_rms_error": rms(speed_err),
        "omega_hat_rms_error": rms(r["omega_hat"] - r["omega_m"]),
        "theta_error_rms": rms(theta_err),
        "theta_error_max": float(np.max(np.abs(theta_err))) if len(t) else float("nan"),
    }
    # piecewise-constant segments of the recorded elevation
    delta = r["delta_deg"]
    change_idx = [i for i in range(1, len(delta)) if delta[i] != delta[i - 1]]
    bounds = [0] + change_idx + [len(delta)]
    plateaus, steps = [], []
    for a, b in zip(bounds[:-1], bounds[1:]):
        t_start = float(t[a])
        t_end = float(t[b]) if b < len(t) else float(t[-1])
        if t_end - t_start < PLATEAU_WINDOW:
            continue
        w = (t >= t_end - PLATEAU_WINDOW) & (t <= t_end)
        if b < len(t):
            w &= t < t_end
        plateaus.append({
            "t_start": t_start, "t_end": t_end, "delta_deg": float(delta[a]),
            **{f"{k}_mean": float(np.mean(r[k][w])) for k in ("T_L_mech", "T_L_hat", "T_e", "omega_m", "omega_hat")},
        })
    for i, a in enumerate(change_idx):
        b = change_idx[i + 1] if i + 1 < len(change_idx) else len(t)
        dev = np.abs(speed_err[a:b])
        outside = np.nonzero(dev > SETTLING_BAND)[0]
        if len(outside) == 0:
            settling = 0.0
        elif outside[-1] == len(dev) - 1:
            settling = None  # never settled within the segment
        else:
            settling = float(t[a + outside[-1] + 1] - t[a])
        steps.append({
            "t": float(t[a]), "delta_from_deg": float(delta[a - 1]), "delta_to_deg": float(delta[a]),
            "max_speed_deviation": float(dev.max()) if len(dev) else 0.0,
            "settling_time": settling,
        })
    m["plateaus"] = plateaus
    m["steps"] = steps
    if all(c in r for c in SENSORLESS_COLUMNS):
        m["sensorless"] = sensorless_metrics(r)
        m["synchronism"] = synchronism_metrics(r)
    ident = identification_metrics(r)
    if ident is not None:
        m["identification"] = ident
    if "v_vehicle" in r:  # the whole speed range: where the car fell behind, the data sheet's figures
        behind = behind_figures(r)
        if behind is not None:
            m["behind"] = behind
        accel = acceleration_figures(r)
        if accel is not None:
            m["acceleration"] = accel
    if all(c in r for c in ENERGY_COLUMNS):
        m["energy"] = energy_metrics(r)
        if all(c in r for c in BATTERY_COLUMNS) and m["energy"].get("rows") != 0:
            m["energy"]["battery"] = battery_metrics(r, m["energy"])
    return m
