"""The figures of a run with the motor's thermal network (docs/speed-range.md, "A motor that warms";
``pmsm_ev.params.PlantParams.thermal_model``): the winding's and the magnet's temperatures over the drive, psi's
fall and R_s's rise, the current the same torque needs as the motor warms, and what limits first: the winding's
insulation limit or the magnet's maximum temperature, with the time it is reached, or neither within the drive.

The verdict reads the recorded columns (``T_wdg``, ``T_pm``, ``psi_now``, ``R_s_now``, ``over_temperature``, the
currents and the torque) and the limits the run's plant was given (``T_winding_max``, ``T_magnet_max``); the reaction
it states is the plant's output ``over_temperature`` (1 the winding, 2 the magnet), on which a controller derates.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pmsm_ev.params import PlantParams
from pmsm_ev.thermal import steady_temperatures

from ..engine.recording import read_results
from ..engine.system import SystemSpec
from .cycles import cycle_of

#: the columns the thermal block needs
THERMAL_COLUMNS = ("time", "T_wdg", "T_pm", "psi_now", "R_s_now", "over_temperature")
#: the samples whose |T_e| is at least this share of the run's peak torque enter the current per torque [-]: the
#: loaded points, where the current is the torque's (at light load the field-weakening current and the noise's 1 A
#: would dominate the ratio)
LOADED_SHARE = 0.2
#: the plant instance whose start values give the thermal model
PLANT = "plant"
#: the losses' columns of the sustained figures (the energies since the start, J)
LOSS_COLUMNS = ("E_copper", "E_iron", "E_friction")


def _plant_params(spec: SystemSpec) -> PlantParams:
    """The run's ``PlantParams``: its plant's start values of that group, the others the defaults."""
    plant = next((c for c in spec.components if c.name == PLANT), None)
    starts = plant.start if plant is not None else {}
    defaults = PlantParams()
    values = {}
    for f in dataclasses.fields(PlantParams):
        if f.name in starts:  # a system file's number, or the command line's text (--set plant.T_ambient=90)
            kind, value = type(getattr(defaults, f.name)), starts[f.name]
            if kind is bool:
                values[f.name] = value if isinstance(value, bool) else str(value).strip().lower() in ("true", "1")
            else:
                values[f.name] = kind(float(value)) if kind in (int, float) else kind(value)
    return PlantParams(**values)


def _first_at_or_above(time: np.ndarray, values: np.ndarray, limit: float) -> float | None:
    hit = np.flatnonzero(values >= limit)
    return float(time[hit[0]]) if hit.size else None


def current_per_torque(i_d: np.ndarray, i_q: np.ndarray, t_e: np.ndarray, floor: float) -> float | None:
    """The stator current per torque [A/(N m)] of the samples with |T_e| >= ``floor``: the least-squares slope through
    the origin of |i_s| = hypot(i_d, i_q) on |T_e|, sum |i_s| |T_e| / sum T_e^2; None without such samples."""
    loaded = np.abs(t_e) >= floor
    if not loaded.any():
        return None
    t = np.abs(t_e[loaded])
    return float(np.sum(np.hypot(i_d[loaded], i_q[loaded]) * t) / np.sum(t * t))


def thermal_figures(r: dict, t_winding_max: float, t_magnet_max: float, repeats: int = 1,
                    params: PlantParams | None = None) -> dict:
    """The thermal block of metrics.json from the recorded columns ``r`` (``THERMAL_COLUMNS``; with ``i_d``, ``i_q``,
    ``T_e`` the current per torque): the temperatures at the start, their peaks (and when) and at the end, psi and R_s
    at the start and the end, the first time each limit is reached and ``limits_first`` ('winding', 'magnet' or
    'neither'). With ``repeats`` > 1 (a cycle driven back to back) the current per torque of each repetition (the same
    speed trace, so the same torques: what the warmer magnet costs in current). With the run's ``params`` and the
    losses' columns (``LOSS_COLUMNS``) ``sustained``: the last repetition's mean losses held, the temperatures the
    network settles at (``pmsm_ev.thermal.steady_temperatures``), their margins, the node with the smaller margin
    (what limits first in a longer drive of this kind) and the coolant temperature that would bring each to its
    limit."""
    time = r["time"]
    t_w, t_m = r["T_wdg"], r["T_pm"]
    out = {"T_winding_max": t_winding_max, "T_magnet_max": t_magnet_max}
    for key, values in (("winding", t_w), ("magnet", t_m)):
        k = int(np.argmax(values))
        out[key] = {"T_start": float(values[0]), "T_peak": float(values[k]), "t_peak": float(time[k]),
                    "T_end": float(values[-1])}
    psi, r_s = r["psi_now"], r["R_s_now"]
    out["psi_start"], out["psi_end"], out["psi_min"] = float(psi[0]), float(psi[-1]), float(np.min(psi))
    out["psi_fall"] = 1.0 - out["psi_min"] / out["psi_start"]
    out["R_s_start"], out["R_s_end"], out["R_s_max"] = float(r_s[0]), float(r_s[-1]), float(np.max(r_s))
    out["R_s_rise"] = out["R_s_max"] / out["R_s_start"] - 1.0
    # the torque a current gives falls with psi: at i_d = 0 the same torque needs psi_start / psi times the current
    out["current_rise_same_torque"] = out["psi_start"] / out["psi_min"] - 1.0
    t_wl = _first_at_or_above(time, t_w, t_winding_max)
    t_ml = _first_at_or_above(time, t_m, t_magnet_max)
    out["t_winding_limit"], out["t_magnet_limit"] = t_wl, t_ml
    flags = r["over_temperature"]
    flagged = np.flatnonzero(flags != 0.0)
    out["t_over_temperature"] = float(time[flagged[0]]) if flagged.size else None
    if t_wl is None and t_ml is None:
        out["limits_first"] = "neither"
    elif t_ml is None or (t_wl is not None and t_wl <= t_ml):
        out["limits_first"] = "winding"
    else:
        out["limits_first"] = "magnet"
    out["margin_winding_K"] = t_winding_max - out["winding"]["T_peak"]
    out["margin_magnet_K"] = t_magnet_max - out["magnet"]["T_peak"]
    if params is not None and all(c in r for c in LOSS_COLUMNS) and time.size >= 2:
        # sustained: the drive's last repetition (the whole run without one) driven on and on, its mean losses held:
        # the network's steady state, and the coolant temperature at which each node would sit at its limit
        start = int(np.searchsorted(time, time[-1] - (float(time[-1]) - float(time[0])) / repeats))
        span = float(time[-1] - time[start])
        if span > 0.0:
            p_cu = (r["E_copper"][-1] - r["E_copper"][start]) / span
            p_res = (r["E_iron"][-1] - r["E_iron"][start] + r["E_friction"][-1] - r["E_friction"][start]) / span
            steady = steady_temperatures(params, p_cu, p_res)
            t_w_inf, t_m_inf = float(steady[2]), float(steady[3])
            sus = {"from_s": float(time[start]), "P_copper_W": float(p_cu), "P_residual_W": float(p_res),
                   "T_winding": t_w_inf, "T_magnet": t_m_inf,
                   "margin_winding_K": t_winding_max - t_w_inf, "margin_magnet_K": t_magnet_max - t_m_inf,
                   "T_coolant_winding_limit": t_winding_max - (t_w_inf - params.T_ambient),
                   "T_coolant_magnet_limit": t_magnet_max - (t_m_inf - params.T_ambient)}
            sus["limits_first"] = ("magnet" if sus["margin_magnet_K"] < sus["margin_winding_K"] else "winding")
            out["sustained"] = sus
    if all(c in r for c in ("i_d", "i_q", "T_e")) and time.size >= 2:
        floor = LOADED_SHARE * float(np.max(np.abs(r["T_e"])))
        out["current_per_torque_floor_Nm"] = floor
        out["current_per_torque"] = current_per_torque(r["i_d"], r["i_q"], r["T_e"], floor)
        if repeats > 1:
            span = (float(time[-1]) - float(time[0])) / repeats
            per = []
            for j in range(repeats):
                lo, hi = time[0] + j * span, time[0] + (j + 1) * span
                part = (time >= lo) & ((time < hi) if j < repeats - 1 else (time <= hi))
                per.append(current_per_torque(r["i_d"][part], r["i_q"][part], r["T_e"][part], floor))
            out["current_per_torque_by_repeat"] = per
            if per[0] and per[-1]:
                out["current_per_torque_rise"] = per[-1] / per[0] - 1.0
    return out


def with_thermal_figures(metrics_of, spec: SystemSpec):
    """``metrics_of`` for a run of ``spec``: as it is unless the run records the thermal network's columns
    (``THERMAL_COLUMNS``; every other run's metrics.json unchanged); with them, plus ``thermal``
    (:func:`thermal_figures`)."""
    names = {c.name for c in spec.columns}
    if not set(THERMAL_COLUMNS) <= names:
        plant = next((c for c in spec.components if c.name == PLANT), None)
        if plant is None or str(plant.start.get("thermal_model", "off")) == "off":
            return metrics_of
        # the network on (e.g. --set plant.thermal_model=lptn) where its columns are not recorded: said, not silent
        missing = ", ".join(c for c in THERMAL_COLUMNS if c not in names)
        note = (f"no thermal figures: the thermal network is on, but {missing} are not recorded (a system file "
                f"records them as wltc3b-thermal.toml does)")

        def noted(out_dir, columns, rows: int) -> dict:
            m = metrics_of(out_dir, columns, rows)
            m["metrics_note"] = f"{m['metrics_note']}; {note}" if "metrics_note" in m else note
            return m

        return noted
    params = _plant_params(spec)
    t_winding_max, t_magnet_max = params.T_winding_max, params.T_magnet_max
    cycle = cycle_of(spec)
    repeats = cycle.repeats if cycle is not None else 1

    def measured(out_dir, columns, rows: int) -> dict:
        m = metrics_of(out_dir, columns, rows)
        if rows >= 2:
            wanted = THERMAL_COLUMNS + tuple(c for c in ("i_d", "i_q", "T_e") + LOSS_COLUMNS if c in names)
            r = read_results(out_dir, columns=wanted)
            m["thermal"] = thermal_figures(r, t_winding_max, t_magnet_max, repeats, params)
        return m

    return measured


def summary_line(thermal: dict) -> str:
    """The thermal block in one line, as ``pmsm-cosim run`` prints it."""
    w, mg = thermal["winding"], thermal["magnet"]
    first = thermal["limits_first"]
    if first == "neither":
        verdict = (f"neither limit reached (margins {thermal['margin_winding_K']:.1f} K to the winding's "
                   f"{thermal['T_winding_max']:g} degC, {thermal['margin_magnet_K']:.1f} K to the magnet's "
                   f"{thermal['T_magnet_max']:g} degC)")
    else:
        t = thermal["t_winding_limit"] if first == "winding" else thermal["t_magnet_limit"]
        lim = thermal["T_winding_max"] if first == "winding" else thermal["T_magnet_max"]
        verdict = f"the {first} limits first: {lim:g} degC reached at {t:.1f} s (output over_temperature set)"
    cpt = ""
    if thermal.get("current_per_torque_rise") is not None:
        per = thermal["current_per_torque_by_repeat"]
        cpt = (f"; current per torque {per[0]:.4f} -> {per[-1]:.4f} A/(N m) from the first repetition to the last "
               f"({100 * thermal['current_per_torque_rise']:+.2f} %)")
    sus = thermal.get("sustained")
    if isinstance(sus, dict):
        part = "repetition" if thermal.get("current_per_torque_by_repeat") else "cycle"
        first = sus["limits_first"]
        verdict += (f"; sustained (the last {part}'s {sus['P_copper_W']:.0f} W copper, {sus['P_residual_W']:.0f} W "
                    f"iron and friction held) the winding would settle at {sus['T_winding']:.1f}, the magnet at "
                    f"{sus['T_magnet']:.1f} degC: the {first} nearer its limit (reached from a coolant of "
                    f"{sus['T_coolant_' + first + '_limit']:.1f} degC)")
    return (f"thermal: winding {w['T_start']:.1f} -> peak {w['T_peak']:.1f} degC at {w['t_peak']:.0f} s -> "
            f"{w['T_end']:.1f} degC, magnet {mg['T_start']:.1f} -> peak {mg['T_peak']:.1f} degC at "
            f"{mg['t_peak']:.0f} s; psi {thermal['psi_start']:.5f} -> {thermal['psi_min']:.5f} Wb "
            f"(-{100 * thermal['psi_fall']:.2f} %: the same torque needs "
            f"{100 * thermal['current_rise_same_torque']:+.2f} % current at i_d = 0), R_s "
            f"{100 * thermal['R_s_rise']:+.1f} %{cpt}; {verdict}")


__all__ = ["LOADED_SHARE", "LOSS_COLUMNS", "THERMAL_COLUMNS", "current_per_torque", "summary_line", "thermal_figures",
           "with_thermal_figures"]
