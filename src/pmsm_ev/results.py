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
#: what runs of the sensorless unit add: the vehicle position [m] (roll-back), the mode
#: (0 alignment, 1 I-f, 2 closed loop on the observer; ``pmsm_ev.control_unit.MODES``), the fault
#: (``pmsm_ev.kernels`` FAULT_*) and the control frame's angle [rad] and speed [rad/s] (synchronism)
SENSORLESS_COLUMNS = ("x_vehicle", "mode", "fault", "theta_ctrl", "omega_ctrl")
#: the plant's energy outputs [J] (``pmsm_ev.plant.Plant.energies``, the plant FMU's outputs of the same
#: names) and the position [m]: a run that records them all gets the energy block of its metrics
#: (``energy_metrics``); the acceleration and drive-cycle scenarios record them (``pmsm_ev.cycle_energy``: per phase)
ENERGY_COLUMNS = ("E_dc", "E_regen", "E_copper", "E_inverter", "E_iron", "E_friction", "E_gear", "E_aero", "E_rolling",
                  "E_grade", "E_brake", "E_kinetic", "W_magnetic", "x_vehicle")
#: the battery's outputs (``pmsm_ev.plant.BATTERY_SLOTS``; plant start value battery = "ecm"): a run that records them
#: with ``ENERGY_COLUMNS`` gets the battery's figures in its energy block (``battery_metrics``)
BATTERY_COLUMNS = ("soc", "v_bat", "i_bat", "Q_bat", "E_chemical", "E_battery", "W_battery")
#: the least distance [m] for a figure per kilometre: 10 m, a car's length or two (below it, a run
#: that stands, aligns or creeps would divide by almost nothing)
ENERGY_MIN_DISTANCE = 10.0

#: speed band for settling times [rad/s]
SETTLING_BAND = 1.0
#: averaging window at the end of each plateau [s]
PLATEAU_WINDOW = 2.0


def _wrap(x):
    return (x + math.pi) % (2 * math.pi) - math.pi


def angle_error_unwrapped(r: dict[str, np.ndarray]) -> np.ndarray:
    """theta_hat - theta_e [rad], continuous across rows: wrapped to [-pi, pi) at the first
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
        m["synchronism"] = synchronism_metrics(r)
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


_WH = 1.0 / 3600.0  #: J -> Wh


def energy_metrics(r: dict[str, np.ndarray]) -> dict:
    """The energy figures of a run that recorded ``ENERGY_COLUMNS`` [Wh], from its first to its
    last row (the plant's energies are integrals since its start, the stored ones its state's):
    ``dc`` (the DC link's net energy), ``drawn`` (what it delivered, dc + regen) and ``regen`` (what
    went back), the ``losses`` by kind (copper, inverter, iron, friction, gear; ``total``), the ``road``
    work by force (aero, rolling, grade: the grade's is the potential energy gained), ``brake`` (the
    friction brake's), the changes of the ``kinetic`` and ``magnetic`` energies, ``residual`` (dc
    minus all the others, the balance: each term is integrated on its own), ``distance_m`` (the
    path travelled, the sum of |dx| over the rows) and, where it is at least ``ENERGY_MIN_DISTANCE``,
    ``dc_per_km`` and ``drawn_per_km`` [Wh/km] (None otherwise)."""
    if len(r["time"]) == 0:
        return {"rows": 0}

    def wh(name: str) -> float:
        return float(r[name][-1] - r[name][0]) * _WH

    losses = {"copper": wh("E_copper"), "inverter": wh("E_inverter"), "iron": wh("E_iron"),
              "friction": wh("E_friction"), "gear": wh("E_gear")}
    losses["total"] = sum(losses.values())
    road = {"aero": wh("E_aero"), "rolling": wh("E_rolling"), "grade": wh("E_grade")}
    dc, regen, brake = wh("E_dc"), wh("E_regen"), wh("E_brake")
    kinetic, magnetic = wh("E_kinetic"), wh("W_magnetic")
    distance = float(np.sum(np.abs(np.diff(r["x_vehicle"])))) if len(r["x_vehicle"]) > 1 else 0.0
    per_km = distance >= ENERGY_MIN_DISTANCE
    return {
        "dc_Wh": dc, "drawn_Wh": dc + regen, "regen_Wh": regen,
        "losses_Wh": losses, "road_Wh": road, "brake_Wh": brake,
        "kinetic_change_Wh": kinetic, "magnetic_change_Wh": magnetic,
        "residual_Wh": dc - losses["total"] - sum(road.values()) - brake - kinetic - magnetic,
        "distance_m": distance,
        "dc_Wh_per_km": dc / (distance / 1000.0) if per_km else None,
        "drawn_Wh_per_km": (dc + regen) / (distance / 1000.0) if per_km else None,
    }


def battery_metrics(r: dict[str, np.ndarray], energy: dict) -> dict:
    """The battery's figures of a run that recorded ``BATTERY_COLUMNS`` and ``ENERGY_COLUMNS``, from its first to its
    last row: the state of charge at both ends, the charge drawn ``charge_Ah`` (negative: charged), the terminal
    energy (the DC link's, ``energy['dc_Wh']``), the chemical energy (the open-circuit voltage times the current),
    the battery's losses, the change of the RC pair's stored energy and ``residual_Wh`` (chemical less the three:
    the battery's balance), the terminal voltage's least and largest over the rows, and Wh/km at the terminals and
    from the chemistry where ``energy`` has a distance for it. The energy the friction brake took
    (``energy['brake_Wh']``) is the braking the battery refused (its charge acceptance) or the motor could not give."""
    def wh(name: str) -> float:
        return float(r[name][-1] - r[name][0]) * _WH

    chemical, losses, stored = wh("E_chemical"), wh("E_battery"), wh("W_battery")
    km = energy["distance_m"] / 1000.0 if energy.get("dc_Wh_per_km") is not None else None
    return {"soc_start": float(r["soc"][0]), "soc_end": float(r["soc"][-1]),
            "charge_Ah": float(r["Q_bat"][-1] - r["Q_bat"][0]) / 3600.0,
            "terminal_Wh": energy["dc_Wh"], "chemical_Wh": chemical, "losses_Wh": losses, "rc_change_Wh": stored,
            "residual_Wh": chemical - energy["dc_Wh"] - losses - stored,
            "v_bat_min": float(np.min(r["v_bat"])), "v_bat_max": float(np.max(r["v_bat"])),
            "terminal_Wh_per_km": energy["dc_Wh_per_km"],
            "chemical_Wh_per_km": chemical / km if km else None}


#: a start-up target: |omega_m - omega_ref| within this band [rad/s] ...
STARTUP_BAND = 10.0
#: ... from this time on [s] (the delayed routes reach 200 rad/s at 12.5 s)
STARTUP_FROM = 12.0


def row_timing_corrected_angle_error(r: dict[str, np.ndarray], dt: float, pole_pairs: float) -> np.ndarray:
    """theta_hat - theta_e [rad] with the row-timing term removed, wrapped to [-pi, pi): a row at
    t_k holds the estimate computed at t_{k-1}, one control period ``dt`` [s] before the rotor's
    angle in the same row, so the raw error includes -N omega_m dt (-0.08 rad at 200 rad/s and
    1e-4 s with N = 4, for every observer, sensored too); N = ``pole_pairs``. Take both from the
    run (:func:`run_timing`)."""
    return _wrap(r["theta_hat"] - r["theta_e"] + pole_pairs * r["omega_m"] * dt)


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


def roll_back(x: np.ndarray) -> float:
    """Largest backward travel [m] of a position trace: its drop below its running maximum."""
    return float(np.max(np.maximum.accumulate(x) - x)) if len(x) else 0.0


def sensorless_metrics(r: dict[str, np.ndarray], t_from: float = 20.0) -> dict:
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


# -- figures of a window of rows (the tables of compare and the reports) ----------------------------
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
    out.update(speed_rms_error=_rms(e), speed_bias=float(np.mean(r["omega_m"][mask] - r["omega_ref"][mask])),
               speed_error_max=float(np.max(np.abs(e))), speed_max=float(np.max(np.abs(r["omega_m"][mask]))))
    if dt is not None and pole_pairs is not None:
        err = row_timing_corrected_angle_error(r, dt, pole_pairs)[mask]
        out.update(angle_rms=float(np.sqrt(np.mean(err ** 2))), angle_max=float(np.max(np.abs(err))))
    if "x_vehicle" in r:
        x = r["x_vehicle"][mask]
        out.update(roll_back=roll_back(x), travel=float(np.ptp(x)))
    return out


def handovers(mode_changes) -> dict[str, list[float]]:
    """The mode changes of ``sensorless_metrics`` by kind, their times [s]: ``closed`` (into the
    closed loop, mode 2, from any mode), ``down`` (from the closed loop back to I-f, 2 -> 1) and
    ``up`` (from I-f to the closed loop, 1 -> 2)."""
    return {"closed": [c[0] for c in mode_changes if c[2] == 2.0],
            "down": [c[0] for c in mode_changes if c[1] == 2.0 and c[2] == 1.0],
            "up": [c[0] for c in mode_changes if c[1] == 1.0 and c[2] == 2.0]}


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
    angle = float(np.sqrt(np.mean(np.square(_wrap(err[after]))))) if after.any() else math.nan
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
    err = (r["theta_hat"] - r["theta_e"] + math.pi) % (2 * math.pi) - math.pi
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


#: the scalar figures of merit of a run (:func:`summary_metrics`), in this order
SUMMARY_METRICS = (
    "speed_rms_error", "omega_hat_rms_error", "theta_error_rms", "theta_error_max",
    "max_speed_deviation", "max_settling_time", "T_L_hat_error_max",
    "inside_share", "slipped_turns", "fault_latched", "dc_Wh_per_km",
)

#: their units
SUMMARY_UNITS = {
    "speed_rms_error": "rad/s", "omega_hat_rms_error": "rad/s", "theta_error_rms": "rad", "theta_error_max": "rad",
    "max_speed_deviation": "rad/s", "max_settling_time": "s", "T_L_hat_error_max": "N m",
    "inside_share": "-", "slipped_turns": "-", "fault_latched": "-", "dc_Wh_per_km": "Wh/km",
}


def summary_metrics(m: dict) -> dict[str, float]:
    """One number per figure of merit of a run's metrics (e.g. a metrics.json), for tables
    of many runs: the RMS errors as they are, and over the elevation steps and plateaus:

    * ``max_speed_deviation`` [rad/s]: the largest speed dip after any step;
    * ``max_settling_time`` [s]: the longest settling into the band (inf if a step never
      settled within its segment);
    * ``T_L_hat_error_max`` [N m]: the largest |mean T_L_hat - mean T_L_mech| over the
      plateaus' end windows (how well the observer's load estimate tracks eq 31);
    * of a drive cycle (``docs/cycles.md``): ``inside_share`` [-], the share of the cycle inside the
      tolerance band (``trace``); ``slipped_turns`` [-] and ``fault_latched`` [-] (1 if the safe state
      latched, else 0) of the sensorless unit (``synchronism``); ``dc_Wh_per_km`` [Wh/km], the DC link's
      energy per distance (``energy``).

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
    trace, sync, energy = (m.get(k) if isinstance(m.get(k), dict) else {} for k in ("trace", "synchronism", "energy"))
    out["inside_share"] = num(trace.get("inside_share"))
    out["slipped_turns"] = num(sync.get("slipped_turns"))
    latched = sync.get("fault_latched")
    out["fault_latched"] = float(latched) if isinstance(latched, bool) else nan
    out["dc_Wh_per_km"] = num(energy.get("dc_Wh_per_km"))
    return out


# -- synchronism: did the drive keep the car? (the sensorless unit's test matrix) ----------------------
#: the control frame and the rotor disagree (out of synchronism) when their speeds differ by more than
#: this [rad/s] plus ``SYNC_REL`` times the rotor's speed [chosen: a locked I-f vector swings within
#: +-3 rad/s of the rotor, one out of step differs by its whole speed]
SYNC_BAND = 10.0
SYNC_REL = 0.1
#: the rotor stands below this speed [rad/s]; the frame turns above ``FRAME_TURNING`` [rad/s]
ROTOR_STANDING = 1.0
FRAME_TURNING = 5.0
#: recovered: |omega_m - omega_ref| within this band [rad/s] from some time on to the end
RECOVERY_BAND = 30.0


def _direction(omega_ref: np.ndarray) -> np.ndarray:
    """+1 where the driver asks for forward (or to hold, at the start), -1 for reverse; a zero
    reference keeps the direction of the last non-zero one (a car stopped from reverse)."""
    d = np.sign(omega_ref)
    nz = np.nonzero(d)[0]
    if len(nz) == 0:
        return np.ones_like(omega_ref)
    idx = np.maximum.accumulate(np.where(d != 0, np.arange(len(d)), -1))
    out = np.where(idx >= 0, d[np.maximum(idx, 0)], 1.0)
    return out


def wrong_way_travel(x: np.ndarray, omega_ref: np.ndarray) -> float:
    """Largest travel against the driver's direction [m]: within each stretch of one direction
    (``_direction``), the largest drop of direction x position below its running maximum."""
    d = _direction(omega_ref)
    edges = np.nonzero(np.diff(d))[0] + 1
    worst = 0.0
    for seg in np.split(np.arange(len(x)), edges):
        if len(seg):
            worst = max(worst, roll_back(d[seg[0]] * x[seg]))
    return worst


def slipped_turns(r: dict[str, np.ndarray], pole_pairs: int) -> int:
    """Largest number of electrical turns the control frame got ahead of (or behind) the rotor
    after the angle was found (not in the alignment, mode 0, nor in the injection's acquisition and
    polarity test, modes 3 and 4, where the frame jumps onto the rotor's axis and turns by pi when the
    polarity says so): the lead theta_ctrl - theta_e unwrapped row by row with the rotation the
    recorded speeds predict (N (omega_ctrl - omega_m) per second), so that a frame spinning
    past a standing rotor is counted even when it turns more than pi between rows."""
    t, lead = r["time"], r["theta_ctrl"] - r["theta_e"]
    keep = (r["mode"] != 0.0) & (r["mode"] != 3.0) & (r["mode"] != 4.0)
    if np.count_nonzero(keep) < 2:
        return 0
    t, lead = t[keep], lead[keep]
    rate = pole_pairs * (r["omega_ctrl"][keep] - r["omega_m"][keep])
    dt = np.diff(t)
    predicted = 0.5 * (rate[1:] + rate[:-1]) * dt
    steps = _wrap(np.diff(lead) - predicted) + predicted
    unwrapped = lead[0] + np.concatenate(([0.0], np.cumsum(steps)))
    turns = np.round((unwrapped - _wrap(unwrapped)) / (2.0 * np.pi))
    return int(np.max(np.abs(turns - turns[0])))


def _longest(mask: np.ndarray, dt_row: float) -> float:
    """Longest run of True [s]."""
    if not np.any(mask):
        return 0.0
    padded = np.concatenate(([0], mask.astype(np.int8), [0]))
    starts, ends = np.nonzero(np.diff(padded) == 1)[0], np.nonzero(np.diff(padded) == -1)[0]
    return float(np.max(ends - starts) * dt_row)


def synchronism_metrics(r: dict[str, np.ndarray], t_disturbance: float = 0.0,
                        pole_pairs: float = MotorParams().N) -> dict:
    """Did the drive keep the car (rows with ``SENSORLESS_COLUMNS``)? ``pole_pairs``: the plant's (the
    project's motor unless given; ``compute_metrics`` has no other). After the alignment:

    * ``roll_back_m``: the largest travel against the driver's direction (``wrong_way_travel``);
    * ``wrong_way_speed``: the largest speed against it [rad/s] (>= 0);
    * ``t_out_of_sync``: the time the control frame's speed and the rotor's disagree by more than
      ``SYNC_BAND`` + ``SYNC_REL`` |omega_m| [s]; ``slipped_turns`` (``slipped_turns``);
    * ``t_spin_standing``: the longest time the frame turned (|omega_ctrl| > ``FRAME_TURNING``) while the
      rotor stood (|omega_m| < ``ROTOR_STANDING``) [s];
    * ``t_recovered``: from when on |omega_m - omega_ref| <= ``RECOVERY_BAND`` to the end [s] (None: not
      by the end), ``recovery_time``: that after ``t_disturbance`` [s], ``speed_rms_after``: the RMS speed
      error from then on (and from ``t_disturbance``) [rad/s];
    * the unit's own fault output: ``episodes`` (loss-of-synchronism episodes it detected), ``t_first_episode``,
      ``fault_latched`` and ``t_fault`` (when the safe state latched).
    """
    t = r["time"]
    dt_row = float(t[1] - t[0]) if len(t) > 1 else 0.0
    after = r["mode"] != 0.0
    d = _direction(r["omega_ref"])
    w_m, w_ref, w_ctrl = r["omega_m"], r["omega_ref"], r["omega_ctrl"]
    out_of_sync = after & (np.abs(w_ctrl - w_m) > SYNC_BAND + SYNC_REL * np.abs(w_m))
    spin = after & (np.abs(w_ctrl) > FRAME_TURNING) & (np.abs(w_m) < ROTOR_STANDING)
    bad = np.nonzero(np.abs(w_m - w_ref) > RECOVERY_BAND)[0]
    if len(bad) == 0:
        t_rec = float(t[0])
    elif bad[-1] == len(t) - 1:
        t_rec = None
    else:
        t_rec = float(t[bad[-1] + 1])
    fault = r["fault"]
    rises = np.nonzero((fault[1:] >= 1.0) & (fault[:-1] < 1.0))[0] + 1
    if len(fault) and fault[0] >= 1.0:
        rises = np.concatenate(([0], rises))
    latched = np.nonzero(fault >= 2.0)[0]
    from_rec = t >= (max(t_rec, t_disturbance) if t_rec is not None else np.inf)
    return {
        "roll_back_m": wrong_way_travel(r["x_vehicle"], w_ref),
        "wrong_way_speed": float(max(0.0, -np.min(d * w_m))) if len(t) else 0.0,
        "t_out_of_sync": float(np.count_nonzero(out_of_sync) * dt_row),
        "slipped_turns": slipped_turns(r, pole_pairs),
        "t_spin_standing": _longest(spin, dt_row),
        "t_recovered": t_rec,
        "recovery_time": None if t_rec is None else max(0.0, t_rec - t_disturbance),
        "speed_rms_after": _rms(w_m[from_rec] - w_ref[from_rec]) if np.any(from_rec) else None,
        "episodes": int(len(rises)),
        "t_first_episode": float(t[rises[0]]) if len(rises) else None,
        "fault_latched": bool(len(latched)),
        "t_fault": float(t[latched[0]]) if len(latched) else None,
    }


# -- the whole speed range: following the driver, and the data sheet's acceleration figures -------------
#: behind the driver: the vehicle speed short of the reference's (in the reference's direction) by more
#: than this [km/h] ... [chosen: the regulatory drive-cycle band, +-2 km/h]
BEHIND_BAND_KMH = 2.0
#: ... for longer than this [s] [chosen: a speed loop tuned soft for the observers (omega_n = 2 rad/s)
#: lags a ramp by ~1 s; a shortfall that lasts longer is a car that cannot follow]
BEHIND_HOLD = 1.0
#: the launch of an acceleration run: the first row whose speed reference exceeds this [rad/s]
LAUNCH_REF = 1.0
KMH = 3.6  #: km/h per m/s


def wheel_ratio(r: dict[str, np.ndarray]) -> float:
    """v_vehicle / omega_m of a run [m/rad] (eqs 1, 6: r_w / n_g), from its rows with the car moving;
    nan if it never moved."""
    w, v = r["omega_m"], r["v_vehicle"]
    moving = np.abs(w) > 1.0
    if not np.any(moving):
        return math.nan
    return float(np.median(v[moving] / w[moving]))


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, end) index pairs of the runs of True in ``mask`` (end exclusive)."""
    padded = np.concatenate(([0], mask.astype(np.int8), [0]))
    edges = np.diff(padded)
    return list(zip(np.nonzero(edges == 1)[0].tolist(), np.nonzero(edges == -1)[0].tolist()))


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
    d = _direction(r["omega_ref"])
    short = KMH * d * (r["omega_ref"] * ratio - r["v_vehicle"])  # [km/h], > 0: behind
    stretches = [(a, b) for a, b in _runs(short > band_kmh) if (b - a) * dt_row > hold]
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


# -- following a drive cycle: the regulatory tolerance band (issue 24; docs/cycles.md, "Following the trace") --
#: the speed tolerance of a chassis-dynamometer test [km/h] and the time window it is taken over [s]: the
#: upper limit is the trace's highest point within +-1 s of the time plus 2 km/h, the lower its lowest within
#: +-1 s minus 2 km/h (WLTP: UN GTR No. 15, Annex 6, paragraph 2.6.8.3; EU 2017/1151, Annex XXI, Sub-Annex 6,
#: 2.6.8.3). The EPA's schedules define the same band with 2 mph = 3.2 km/h (40 CFR 86.115-78(b)(1);
#: 40 CFR 600.109-08(b)(2) for the HWFET): ``EPA_BAND_KMH``. Issue 24 holds every cycle to the 2 km/h.
TRACE_BAND_KMH = 2.0
TRACE_WINDOW_S = 1.0
#: 2 mph [km/h] (1 mile = 1609.344 m): the EPA cycles' own band (40 CFR 86.115-78(b)(1))
EPA_BAND_KMH = 2.0 * 1.609344
#: a speed this close to a limit [m/s] counts as on it (rounding of the limits' arithmetic only)
_BAND_TOL = 1e-9


def _trace_extreme(t_trace: np.ndarray, v_trace: np.ndarray, at: np.ndarray, window_s: float, op) -> np.ndarray:
    """The highest (``op`` = np.maximum) or lowest (np.minimum) value of the piecewise-linear trace over
    [at - window_s, at + window_s] at each time of ``at``: the extreme of a piecewise-linear function over an
    interval is at the interval's ends or at a point of the trace inside it. Before the first point and after
    the last the end value holds."""
    ext = op(np.interp(at - window_s, t_trace, v_trace), np.interp(at + window_s, t_trace, v_trace))
    lo = np.searchsorted(t_trace, at - window_s, side="right")
    hi = np.searchsorted(t_trace, at + window_s, side="left")
    count = hi - lo
    for k in range(int(count.max(initial=0))):
        idx = lo + k
        valid = idx < hi
        ext = np.where(valid, op(ext, v_trace[np.minimum(idx, v_trace.size - 1)]), ext)
    return ext


def trace_band(t_trace, v_trace, band_kmh: float = TRACE_BAND_KMH, window_s: float = TRACE_WINDOW_S,
               time=None) -> tuple[np.ndarray, np.ndarray]:
    """The tolerance band of a speed trace (``TRACE_BAND_KMH``: GTR No. 15 Annex 6 2.6.8.3, 40 CFR 86.115-78):
    (lower, upper) [m/s] at the times ``time`` [s] (default: the trace's own), the trace's lowest value
    within +-``window_s`` of each time minus ``band_kmh`` and its highest plus ``band_kmh``. The trace
    (``t_trace`` [s] increasing, ``v_trace`` [m/s]) is read as linear between its points, as the
    regulations' "smooth trace drawn through the points" at 1 Hz."""
    t_trace, v_trace = np.asarray(t_trace, dtype=float), np.asarray(v_trace, dtype=float)
    if t_trace.ndim != 1 or t_trace.shape != v_trace.shape or t_trace.size < 2 or np.any(np.diff(t_trace) <= 0):
        raise ValueError("trace_band: t_trace and v_trace must be 1-D, of one length >= 2, t_trace increasing")
    if not (band_kmh >= 0 and window_s >= 0 and math.isfinite(band_kmh) and math.isfinite(window_s)):
        raise ValueError(f"trace_band: band_kmh and window_s must be finite and >= 0 (got {band_kmh}, {window_s})")
    at = t_trace if time is None else np.asarray(time, dtype=float)
    band = band_kmh / KMH
    return (_trace_extreme(t_trace, v_trace, at, window_s, np.minimum) - band,
            _trace_extreme(t_trace, v_trace, at, window_s, np.maximum) + band)


def trace_figures(time, v_actual, cycle, band_kmh: float = TRACE_BAND_KMH,
                  window_s: float = TRACE_WINDOW_S) -> dict:
    """How a run followed a drive cycle (``cycle``: a ``pmsm_ev.cycles.Cycle``, or anything with ``time`` [s]
    and ``speed`` [m/s] arrays), from its rows ``time`` [s] (evenly spaced, as results.csv) and the vehicle
    speed ``v_actual`` [m/s], over the rows from 0 to the end of the cycle or of the run, whichever is first:

    * ``inside_share``: the share of that time the speed is inside the band (``trace_band``), each row
      standing for one row interval;
    * ``excursions``: the number of stretches of consecutive rows outside it, ``excursion_lengths_s`` their
      lengths [s] (rows x row interval), ``longest_excursion_s`` and ``t_longest_excursion`` [s] (its first
      row; both None without an excursion);
    * ``rmse_kmh``: the RMS of the speed's deviation from the trace (linear between its points) [km/h];
      ``max_deviation_kmh`` the deviation of largest magnitude (signed, + faster than the trace) and
      ``t_max_deviation`` [s] where;
    * ``t_end`` [s], ``band_kmh``, ``window_s``: what was measured."""
    t, v = np.asarray(time, dtype=float), np.asarray(v_actual, dtype=float)
    t_trace, v_trace = np.asarray(cycle.time, dtype=float), np.asarray(cycle.speed, dtype=float)
    if t.ndim != 1 or t.shape != v.shape or t.size < 2:
        raise ValueError("trace_figures: time and v_actual must be 1-D, of one length >= 2")
    t_end = float(min(t[-1], t_trace[-1]))
    keep = (t >= t_trace[0]) & (t <= t_end + 1e-9)
    t, v = t[keep], v[keep]
    dt_row = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    lower, upper = trace_band(t_trace, v_trace, band_kmh, window_s, t)
    outside = (v < lower - _BAND_TOL) | (v > upper + _BAND_TOL)
    runs = _runs(outside)
    lengths = [float((b - a) * dt_row) for a, b in runs]
    dev = (v - np.interp(t, t_trace, v_trace)) * KMH
    i_dev = int(np.argmax(np.abs(dev)))
    longest = int(np.argmax(lengths)) if lengths else None
    return {"t_end": t_end, "band_kmh": float(band_kmh), "window_s": float(window_s),
            "inside_share": float(1.0 - np.count_nonzero(outside) / outside.size),
            "excursions": len(runs), "excursion_lengths_s": lengths,
            "longest_excursion_s": None if longest is None else lengths[longest],
            "t_longest_excursion": None if longest is None else float(t[runs[longest][0]]),
            "rmse_kmh": float(np.sqrt(np.mean(dev * dev))),
            "max_deviation_kmh": float(dev[i_dev]), "t_max_deviation": float(t[i_dev])}
