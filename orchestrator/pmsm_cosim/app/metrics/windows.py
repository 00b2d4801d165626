"""Figures of a window of rows (the tables of compare and the reports): the elevation steps' figures, the
figures after a time or of the rows a mask selects, the robustness maps' tracking figures, the plateaus'
drift and ripple, the angle's recovery; and a run's timing (from its metrics.json) for the angle error with
the row timing removed.
"""

from __future__ import annotations

import math

import numpy as np

from pmsm_ev.params import MotorParams
from pmsm_ev.results import (
    angle_error,
    angle_error_unwrapped,
    eq31_load_torque,
    row_timing_corrected_angle_error,
    wrap_angle,
)

from .rows import rms, roll_back
from .run import compute_metrics


def run_timing(metrics: dict) -> tuple[float, float]:
    """(dt, N) of a run for :func:`row_timing_corrected_angle_error`, from its metrics.json: the
    control period dt [s] is the communication step ``step_size`` (times the controller's
    ``step_multiple``, component ``ctrl``, when the run's settings give one); N the plant's pole
    pairs: the start value ``N`` of the component ``plant`` when the run set one, else the value
    the project's plant is built with (``MotorParams().N``, the FMU's and the monolithic loop's
    default). ValueError (one line) when metrics.json has no step size."""
    step = metrics.get("step_size") if isinstance(metrics, dict) else None
    if not isinstance(step, (int, float)) or isinstance(step, bool) or not step > 0:
        raise ValueError(f"the run's metrics have no step size (step_size = {step!r}): cannot remove the "
                         "row-timing term of the angle error")
    comps = {c.get("name"): c for c in (metrics.get("settings") or {}).get("components") or ()
             if isinstance(c, dict)}
    ctrl, plant = comps.get("ctrl") or {}, comps.get("plant") or {}
    multiple = ctrl.get("step_multiple") or 1
    pole_pairs = (plant.get("start") or {}).get("N", MotorParams().N)
    return float(step) * float(multiple), float(pole_pairs)


def step_figures(m: dict) -> dict:
    """Over the elevation steps and plateaus of a run's metrics (``compute_metrics``, e.g. its
    metrics.json): ``step_dev_min``, ``step_dev_max`` [rad/s] (the smallest and largest speed dip
    after a step), ``settling_max`` [s] (the longest settling; inf if a step never settled within
    its segment) and ``T_L_err_max`` [N m] (the largest |mean T_L_hat - mean T_L_mech| over the
    plateaus' end windows; None for an observer without a load estimate). None where the run has
    no such figure."""
    steps = m.get("steps") or []
    devs = [s["max_speed_deviation"] for s in steps]
    settle = [s["settling_time"] for s in steps]
    plateaus = m.get("plateaus") or []
    if plateaus and any(p["T_L_hat_mean"] != 0.0 for p in plateaus):
        tl_err = max(abs(p["T_L_hat_mean"] - p["T_L_mech_mean"]) for p in plateaus)
    else:  # no plateau long enough, or an observer without a load-torque estimate
        tl_err = None
    return {
        "step_dev_min": min(devs) if devs else None,
        "step_dev_max": max(devs) if devs else None,
        # a step that never settled within its segment counts as infinitely long
        "settling_max": (math.inf if any(s is None for s in settle) else max(settle)) if settle else None,
        "T_L_err_max": tl_err,
    }


#: the keys of :func:`after_figures`
AFTER_KEYS = ("speed_rms_after", "omega_hat_rms_after", "theta_rms_after", "theta_max_after", "theta_drift",
              "T_L_eq31_rms_after")


def after_figures(r: dict[str, np.ndarray], t_from: float) -> dict:
    """Figures of the rows with ``time >= t_from`` (None for each if fewer than 2): the speed,
    speed-estimate and angle errors of ``compute_metrics`` on them (``speed_rms_after``,
    ``omega_hat_rms_after``, ``theta_rms_after``, ``theta_max_after``), the change of the
    unwrapped angle error from t_from to the end (``theta_drift`` [rad], 2 pi = one electrical
    turn) and the RMS difference of T_L_hat from eq 31 (``T_L_eq31_rms_after`` [N m], None
    without a load estimate). The angle figures are those of the rows as recorded (row timing
    in them, like metrics.json's)."""
    t = r["time"]
    w = t >= t_from
    if np.count_nonzero(w) < 2:
        return dict.fromkeys(AFTER_KEYS)
    mw = compute_metrics({k: v[w] for k, v in r.items()})
    err = angle_error_unwrapped(r)[w]
    return {
        "speed_rms_after": mw["speed_rms_error"],
        "omega_hat_rms_after": mw["omega_hat_rms_error"],
        "theta_rms_after": mw["theta_error_rms"],
        "theta_max_after": mw["theta_error_max"],
        "theta_drift": float(err[-1] - err[0]),
        # eq 31: what a load estimate built on J_m alone should show (None without one)
        "T_L_eq31_rms_after": (float(np.sqrt(np.mean((r["T_L_hat"] - eq31_load_torque(r))[w] ** 2)))
                               if np.any(r["T_L_hat"]) else None),
    }


def figures_where(r: dict[str, np.ndarray], mask, dt: float | None = None,
                  pole_pairs: float | None = None) -> dict:
    """Figures of the rows selected by the boolean ``mask`` (each None when it selects none):

    * ``speed_rms_error`` (RMS of omega_ref - omega_m), ``speed_bias`` (mean omega_m - omega_ref),
      ``speed_error_max`` (max |omega_ref - omega_m|), ``speed_max`` (max |omega_m|) [rad/s];
    * with ``dt`` and ``pole_pairs`` (:func:`run_timing`), the angle error with the row-timing
      term removed (:func:`row_timing_corrected_angle_error`): ``angle_rms``, ``angle_max`` [rad];
    * with the column ``x_vehicle``: ``roll_back`` (:func:`roll_back`) and ``travel`` (its range) [m].
    """
    mask = np.asarray(mask, dtype=bool)
    out = dict.fromkeys(("speed_rms_error", "speed_bias", "speed_error_max", "speed_max", "angle_rms",
                         "angle_max", "roll_back", "travel"))
    if not np.any(mask):
        return out
    e = r["omega_ref"][mask] - r["omega_m"][mask]
    out.update(speed_rms_error=rms(e), speed_bias=float(np.mean(r["omega_m"][mask] - r["omega_ref"][mask])),
               speed_error_max=float(np.max(np.abs(e))), speed_max=float(np.max(np.abs(r["omega_m"][mask]))))
    if dt is not None and pole_pairs is not None:
        err = row_timing_corrected_angle_error(r, dt, pole_pairs)[mask]
        out.update(angle_rms=float(np.sqrt(np.mean(err ** 2))), angle_max=float(np.max(np.abs(err))))
    if "x_vehicle" in r:
        x = r["x_vehicle"][mask]
        out.update(roll_back=roll_back(x), travel=float(np.ptp(x)))
    return out


def whole_turns(x: np.ndarray) -> int:
    """Whole electrical turns spanned by an unwrapped angle error: floor(range / 2 pi) (0 if empty)."""
    return int(math.floor((float(np.max(x)) - float(np.min(x))) / (2 * math.pi))) if len(x) else 0


def tracking_figures(r: dict[str, np.ndarray], t_from: float, dt: float, pole_pairs: float) -> dict:
    """How well a run tracks after ``t_from`` (the robustness maps' figures): ``speed_rms_after``
    and ``speed_bias_after`` (mean omega_m - omega_ref) [rad/s], ``angle_rms_after`` [rad] (row
    timing removed), the electrical turns the estimate slipped (:func:`whole_turns` of the
    unwrapped corrected angle error) from the first closed-loop row on (``slips``; mode 2 where
    the run has a ``mode`` column, else from the start) and after t_from (``slips_after``), and
    the run's last time ``t_end`` [s]. NaN figures when no row is after t_from."""
    t = r["time"]
    err = np.unwrap(row_timing_corrected_angle_error(r, dt, pole_pairs))
    after = t >= t_from
    closed = np.nonzero(r["mode"] == 2.0)[0] if "mode" in r else np.array([0])
    start = int(closed[0]) if len(closed) else len(t)
    speed = float(np.sqrt(np.mean((r["omega_ref"][after] - r["omega_m"][after]) ** 2))) if after.any() else math.nan
    angle = float(np.sqrt(np.mean(np.square(wrap_angle(err[after]))))) if after.any() else math.nan
    bias = float(np.mean(r["omega_m"][after] - r["omega_ref"][after])) if after.any() else math.nan
    return {"speed_rms_after": speed, "speed_bias_after": bias, "angle_rms_after": angle,
            "slips": whole_turns(err[start:]), "slips_after": whole_turns(err[after]),
            "t_end": float(t[-1]) if len(t) else 0.0}


def plateau_split(r: dict[str, np.ndarray], t_from: float, settle: float) -> dict:
    """Angle drift and speed ripple on level (0 deg) and on inclined plateaus: the change of the
    unwrapped angle error over the segments of constant elevation (after ``t_from``), summed per
    kind (``level_drift``, ``inclined_drift`` [rad]), and the largest peak-to-peak omega_m within a
    segment from ``settle`` s after its step (``level_ptp``, ``inclined_ptp`` [rad/s]); None where
    the run has no such segment."""
    t, d, w = r["time"], r["delta_deg"], r["omega_m"]
    err = angle_error_unwrapped(r)
    bounds = [0] + [i for i in range(1, len(d)) if d[i] != d[i - 1]] + [len(d)]
    out = {"level_drift": 0.0, "inclined_drift": 0.0, "level_ptp": None, "inclined_ptp": None}
    seen = {"level": False, "inclined": False}
    for a, b in zip(bounds[:-1], bounds[1:]):
        kind = "level" if d[a] == 0 else "inclined"
        m = (t >= max(t[a], t_from)) & (t <= t[b - 1])
        if np.count_nonzero(m) >= 2:
            seen[kind] = True
            out[f"{kind}_drift"] += float(err[m][-1] - err[m][0])
        m2 = (t >= max(t[a] + (settle if a > 0 else 0.0), t_from)) & (t <= t[b - 1])
        if np.count_nonzero(m2) >= 2:
            ptp = float(np.ptp(w[m2]))
            key = f"{kind}_ptp"
            out[key] = ptp if out[key] is None else max(out[key], ptp)
    for kind, ok in seen.items():
        if not ok:
            out[f"{kind}_drift"] = None
    return out


def angle_recovery(r: dict[str, np.ndarray], band: float, hold: float) -> dict:
    """The wrapped angle error theta_hat - theta_e (as recorded) at the start, at 1 s and at the end
    [rad], and the first time it is below ``band`` [rad] and stays there for ``hold`` [s]
    (``t_recovered``; None: never)."""
    t = r["time"]
    err = angle_error(r)
    ok = np.abs(err) < band
    t_rec = None
    for i in np.nonzero(ok)[0]:
        window = (t >= t[i]) & (t <= t[i] + hold)
        if t[i] + hold <= t[-1] and np.all(ok[window]):
            t_rec = float(t[i])
            break
    at1 = np.nonzero(t >= 1.0)[0]
    return {"start": float(err[0]), "at_1s": float(err[at1[0]]) if len(at1) else None,
            "end": float(err[-1]), "t_recovered": t_rec}
