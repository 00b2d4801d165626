"""The result contract shared by the monolithic reference and the co-simulation.

``DIR/results.csv``: one header row, SI units (angles in rad except ``delta_deg``),
rows at the output interval, streamed (flushed row by row). A row at time t_k holds
every signal at communication point t_k: the plant's outputs at t_k and the control
unit's outputs as last computed (at t_{k-1}), i.e. before step k is taken.

``DIR/metrics.json``: the figures of ``compute_metrics`` plus run bookkeeping.
"""

from __future__ import annotations

import math

import numpy as np

from .params import MotorParams, VehicleParams

#: columns every results.csv has, in this order (more may follow)
CONTRACT_COLUMNS = (
    "time", "delta_deg", "omega_ref", "omega_m", "omega_hat", "theta_e", "theta_hat",
    "i_d", "i_q", "i_d_hat", "i_q_hat", "T_e", "T_L_mech", "T_L_hat", "v_d", "v_q",
)
#: extra columns the project's runs add
EXTRA_COLUMNS = ("i_alpha", "i_beta", "v_alpha", "v_beta", "i_qref", "v_vehicle")
ALL_COLUMNS = CONTRACT_COLUMNS + EXTRA_COLUMNS
#: what runs of the sensorless unit add: the vehicle position [m] (roll-back) and the mode
#: (0 alignment, 1 I-f, 2 closed loop on the observer; ``pmsm_ev.control_unit.MODES``)
SENSORLESS_COLUMNS = ("x_vehicle", "mode")

#: speed band for settling times [rad/s]
SETTLING_BAND = 1.0
#: averaging window at the end of each plateau [s]
PLATEAU_WINDOW = 2.0


def _wrap(x):
    return (x + math.pi) % (2 * math.pi) - math.pi


def angle_error_unwrapped(r: dict[str, np.ndarray]) -> np.ndarray:
    """theta_hat - theta_e [rad], continuous across rows: wrapped to (-pi, pi] at the first
    row, then unwrapped, so that an estimate slipping by whole electrical turns shows as
    a steadily growing error (k 2 pi after k slips) instead of a saw-tooth. Valid while
    the error changes by less than pi between two recorded rows."""
    err = _wrap(r["theta_hat"] - r["theta_e"])
    return np.unwrap(err) if len(err) else err


def eq31_load_torque(r: dict[str, np.ndarray], motor=None, vehicle=None) -> np.ndarray:
    """What the EKF5's T_L state converges to (eqs 30-31): its mechanical model carries
    J_m only, so T_L_hat absorbs friction and the reflected vehicle inertia:
    T_L_mech + B_m omega + T_m0 + (J_eq - J_m) d(omega)/dt [N m], d(omega)/dt by central
    differences of the recorded speed. Default parameters unless given."""
    motor, vehicle = motor or MotorParams(), vehicle or VehicleParams()
    w, t = r["omega_m"], r["time"]
    dw = np.gradient(w, t) if len(t) >= 2 else np.zeros_like(w)
    return r["T_L_mech"] + motor.B_m * w + motor.T_m0 + vehicle.reflected_inertia * dw


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else float("nan")


def compute_metrics(r: dict[str, np.ndarray]) -> dict:
    """Figures of merit from recorded columns (see module doc for the contract)."""
    t = r["time"]
    speed_err = r["omega_ref"] - r["omega_m"]
    theta_err = _wrap(r["theta_hat"] - r["theta_e"])
    m = {
        "speed_rms_error": _rms(speed_err),
        "omega_hat_rms_error": _rms(r["omega_hat"] - r["omega_m"]),
        "theta_error_rms": _rms(theta_err),
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
    return m


#: a start-up target: |omega_m - omega_ref| within this band [rad/s] ...
STARTUP_BAND = 10.0
#: ... from this time on [s] (the delayed routes reach 200 rad/s at 12.5 s)
STARTUP_FROM = 12.0


def row_timing_corrected_angle_error(r: dict[str, np.ndarray], dt: float, pole_pairs: int) -> np.ndarray:
    """theta_hat - theta_e [rad] with the row-timing term removed: a row at t_k holds the
    estimate computed at t_{k-1}, which trails the rotor by omega_e dt (0.08 rad at 200
    rad/s for every observer, sensored too); wrapped to (-pi, pi]."""
    return _wrap(r["theta_hat"] - r["theta_e"] + pole_pairs * r["omega_m"] * dt)


def roll_back(x: np.ndarray) -> float:
    """Largest backward travel [m] of a position trace: its drop below its running maximum."""
    return float(np.max(np.maximum.accumulate(x) - x)) if len(x) else 0.0


def sensorless_metrics(r: dict[str, np.ndarray], t_from: float = 20.0) -> dict:
    """Figures of a run with the sensorless columns (``SENSORLESS_COLUMNS``): the mode changes
    (time, from, to; 0 alignment, 1 I-f, 2 closed loop), the first handover to the closed
    loop, the largest |omega_m - omega_ref| from ``STARTUP_FROM`` on, the roll-back [m] before
    ``t_from`` (start-up) and after it (stops and restarts), and the time spent in I-f after
    ``t_from`` [s]."""
    t, mode = r["time"], r["mode"]
    changes = [(float(t[i + 1]), float(mode[i]), float(mode[i + 1])) for i in np.nonzero(np.diff(mode))[0]]
    closed = [c[0] for c in changes if c[2] == 2.0]
    late = t >= STARTUP_FROM
    early = t <= t_from
    dt_row = float(t[1] - t[0]) if len(t) > 1 else 0.0
    return {
        "mode_changes": changes,
        "t_closed_loop": closed[0] if closed else (0.0 if len(mode) and mode[0] == 2.0 else None),
        "startup_speed_error_max": float(np.max(np.abs(r["omega_m"][late] - r["omega_ref"][late])))
        if np.any(late) else None,
        "roll_back_start": roll_back(r["x_vehicle"][early]),
        "roll_back_after": roll_back(r["x_vehicle"][~early]) if np.any(~early) else None,
        "t_if_after": float(np.count_nonzero(mode[~early] == 1.0) * dt_row),
    }


#: the scalar figures of merit of a run (:func:`summary_metrics`), in this order
SUMMARY_METRICS = (
    "speed_rms_error", "omega_hat_rms_error", "theta_error_rms", "theta_error_max",
    "max_speed_deviation", "max_settling_time", "T_L_hat_error_max",
)

#: their units
SUMMARY_UNITS = {
    "speed_rms_error": "rad/s", "omega_hat_rms_error": "rad/s", "theta_error_rms": "rad", "theta_error_max": "rad",
    "max_speed_deviation": "rad/s", "max_settling_time": "s", "T_L_hat_error_max": "N m",
}


def summary_metrics(m: dict) -> dict[str, float]:
    """One number per figure of merit of a run's metrics (e.g. a metrics.json), for tables
    of many runs: the RMS errors as they are, and over the elevation steps and plateaus:

    * ``max_speed_deviation`` [rad/s]: the largest speed dip after any step;
    * ``max_settling_time`` [s]: the longest settling into the band (inf if a step never
      settled within its segment);
    * ``T_L_hat_error_max`` [N m]: the largest |mean T_L_hat - mean T_L_mech| over the
      plateaus' end windows (how well the observer's load estimate tracks eq 31).

    NaN where the run has no such figure (no steps, no plateau long enough, no metrics).
    """
    nan = float("nan")

    def num(x) -> float:
        return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else nan

    out = {k: num(m.get(k)) for k in SUMMARY_METRICS[:4]}
    steps = [s for s in m.get("steps") or () if isinstance(s, dict)]
    plateaus = [p for p in m.get("plateaus") or () if isinstance(p, dict)]
    out["max_speed_deviation"] = max((num(s.get("max_speed_deviation")) for s in steps), default=nan)
    out["max_settling_time"] = max((math.inf if s.get("settling_time") is None else num(s["settling_time"])
                                    for s in steps), default=nan)
    out["T_L_hat_error_max"] = max((abs(num(p.get("T_L_hat_mean")) - num(p.get("T_L_mech_mean")))
                                    for p in plateaus), default=nan)
    return out
