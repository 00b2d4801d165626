"""The robustness report's figures: each run's (``pmsm_ev.results``), the stability rule that
classifies it, the maps' grids, the Monte-Carlo failure rates, the dead-time runs, and the
findings the page states (every number and every verdict of its text is computed here from the
runs).

**The stability rule** (defined here once; the figures and the page quote it). After ``T_FROM``
(past the sensorless unit's start-up and the road step):

* a run **diverged** if it did not complete, or its angle estimate slipped an electrical turn
  after T_FROM while the control used it (a slipping frame is a lost motor whatever the speed
  does), or its speed RMS error is above ``DIVERGED_LIMIT`` (25 % of 200 rad/s: the speed no longer
  follows the reference);
* it is **stable** if it did not diverge and its speed RMS error is below ``SPEED_LIMIT`` (2.5 % of
  200 rad/s): a biased speed estimate makes a steady speed error without losing the motor, so
  between the two limits a run is *biased*, neither stable nor diverged.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pmsm_ev.params import MotorParams

from ....engine.recording import read_results
from ....sweeps import read_summary
from ...metrics.rows import T_FROM
from ...metrics.sensorless import ROLL_BACK_LIMIT
from ...metrics.windows import figures_where, run_timing, tracking_figures
from . import cycle as cycle_mc
from .interval import wilson
from .runs import ANGLE_USED, CONTROLLERS, CYCLE_MONTE_CARLO, DEAD_TIME, MAPS, MONTE_CARLOS, Map, sweep_spec

#: stable below this speed RMS error after T_FROM [rad/s] (2.5 % of 200 rad/s)
SPEED_LIMIT = 5.0
#: diverged above this speed RMS error after T_FROM [rad/s] (25 % of 200 rad/s)
DIVERGED_LIMIT = 50.0
#: the dead-time runs' windows [s]: the stop, stand and restart; the roll-back after; the climb at
#: full speed on the slope; the speed estimate's lead on the way down to the stop
DEAD_WINDOW = (30.0, 70.0)
DEAD_ROLL_FROM = 20.0
DEAD_CLIMB = (25.0, 30.0)
DEAD_LEAD_AT = 38.0
#: one effect "dominates" another when it is this many times larger
DOMINANT = 3.0
_M = MotorParams()


def classify(figures: dict, completed: bool = True, angle_used: bool = True) -> dict:
    """``diverged`` and ``stable`` of a run's figures (``tracking_figures``) by the stability rule."""
    speed = figures.get("speed_rms_after", math.nan)
    slips = figures.get("slips_after") or 0
    diverged = bool(not completed or not math.isfinite(speed) or speed > DIVERGED_LIMIT
                    or (angle_used and slips > 0))
    return {"diverged": diverged, "stable": bool(not diverged and speed < SPEED_LIMIT)}


def run_metrics(r: dict, dt: float, pole_pairs: float, t_from: float = T_FROM, angle_used: bool = True) -> dict:
    """A run's figures (``pmsm_cosim.app.metrics.windows.tracking_figures`` with the run's control period ``dt`` and
    pole pairs), its mean i_q and reference after ``t_from`` (the load and the speed the page's
    physics is quoted at), and its class (:func:`classify`; slips count only where the control
    uses the estimated angle, ``angle_used``)."""
    m = tracking_figures(r, t_from, dt, pole_pairs)
    after = r["time"] >= t_from
    m["i_q_after"] = float(np.mean(r["i_q"][after])) if after.any() else math.nan
    m["omega_ref_after"] = float(np.mean(r["omega_ref"][after])) if after.any() else math.nan
    m.update(classify(m, True, angle_used))
    return m


_NOT_RUN = {"speed_rms_after": math.nan, "speed_bias_after": math.nan, "angle_rms_after": math.nan,
            "i_q_after": math.nan, "omega_ref_after": math.nan, "slips": None, "slips_after": None}


def _run_dir(out: Path, row: dict) -> Path:
    return out / "runs" / row["run"]


def _metrics_json(run_dir: Path) -> dict:
    return json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))


def sweep_results(out: Path, t_from: float = T_FROM, angle_used: bool = True) -> list[dict]:
    """summary.csv of a sweep directory, each row with its ``run_metrics`` (``stable`` False and
    NaN figures for a run that did not complete)."""
    rows = []
    for row in read_summary(out / "summary.csv"):
        row = dict(row)
        if row["status"] == "completed":
            d = _run_dir(out, row)
            row.update(run_metrics(read_results(d), *run_timing(_metrics_json(d)), t_from, angle_used))
        else:
            row.update(_NOT_RUN)
            row.update(stable=False, diverged=row["status"] == "failed")
        rows.append(row)
    return rows


def _axis(values, nominal):
    """Axis values: the mismatch in % of the nominal value, or the values as they are."""
    return [100.0 * (v / nominal - 1.0) for v in values] if nominal else list(values)


def grid_of(rows: list[dict], m: Map) -> dict:
    """The map's cells: x and y values (sorted), and per metric an array [y, x]."""
    xs = sorted({float(r[m.x]) for r in rows})
    ys = sorted({float(r[m.y]) for r in rows})
    shape = (len(ys), len(xs))
    g = {"x": _axis(xs, m.x_nominal), "y": _axis(ys, m.y_nominal),
         "speed": np.full(shape, np.nan), "bias": np.full(shape, np.nan), "angle": np.full(shape, np.nan),
         "i_q": np.full(shape, np.nan), "omega_ref": np.full(shape, np.nan),
         "slips": np.zeros(shape, int), "stable": np.zeros(shape, bool), "diverged": np.zeros(shape, bool),
         "status": np.full(shape, "not run", dtype=object)}
    for r in rows:
        i, j = ys.index(float(r[m.y])), xs.index(float(r[m.x]))
        g["speed"][i, j] = r["speed_rms_after"]
        g["bias"][i, j] = r["speed_bias_after"]
        g["angle"][i, j] = r["angle_rms_after"]
        g["i_q"][i, j] = r["i_q_after"]
        g["omega_ref"][i, j] = r["omega_ref_after"]
        g["slips"][i, j] = r["slips"] or 0
        g["stable"][i, j] = r["stable"]
        g["diverged"][i, j] = r["diverged"]
        g["status"][i, j] = r["status"]
    return g


def route_of(r: dict) -> dict:
    """What a run's route was, read from its rows: its length ``t_end`` [s], the reference's final
    value ``omega_ref`` [rad/s] and its ramp (``ramp_from``, ``ramp_to`` [s]: the first row above 0
    and the first at the final value; None for a reference constant from the start), the first road
    step (``step_at`` [s], ``step_deg`` [°]; None without one)."""
    t, w, d = r["time"], r["omega_ref"], r["delta_deg"]
    final = float(w[-1]) if len(w) else math.nan
    moving = np.nonzero(w > 0.0)[0]
    at_final = np.nonzero(w >= final)[0]
    ramp = len(moving) and moving[0] > 0
    change = np.nonzero(np.diff(d))[0]
    return {"t_end": float(t[-1]) if len(t) else 0.0, "omega_ref": final,
            "ramp_from": float(t[moving[0] - 1]) if ramp else None, "ramp_to": float(t[at_final[0]]) if ramp else None,
            "step_at": float(t[change[0] + 1]) if len(change) else None,
            "step_deg": float(d[change[0] + 1]) if len(change) else None}


def _first_completed(out: Path):
    for row in read_summary(out / "summary.csv"):
        if row["status"] == "completed":
            return read_results(_run_dir(out, row))
    return None


# --- the dead-time runs ----------------------------------------------------------------------------

@dataclass
class DeadRun:
    """One run of the dead-time sweep: its summary row, columns and figures."""

    row: dict
    r: dict = field(repr=False)
    dt: float
    pole_pairs: float
    v_dc: float
    figures: dict = field(default_factory=dict)

    @property
    def dead_time(self) -> float:
        return float(self.row["plant.dead_time"])

    @property
    def compensation(self) -> float:
        return float(self.row["ctrl.dead_time_comp"])


def dead_run(row: dict, run_dir: Path) -> DeadRun:
    """A dead-time run with its figures: the whole run's speed RMS error, the largest speed error in
    ``DEAD_WINDOW``, the roll-back after ``DEAD_ROLL_FROM``, the angle RMS error in the window, the
    turns slipped, the voltage error of the dead time (v_dc t_d / T_s, T_s the control period), the
    speed bias and mean voltage magnitude on the climb ``DEAD_CLIMB``, the speed estimate's lead at
    ``DEAD_LEAD_AT``."""
    r, m = read_results(run_dir), _metrics_json(run_dir)
    dt, n = run_timing(m)
    plant = {c.get("name"): c for c in m.get("settings", {}).get("components", ())}.get("plant", {})
    v_dc = float((plant.get("start") or {}).get("v_dc", 0.0))
    run = DeadRun(row, r, dt, n, v_dc)
    t = r["time"]
    win = figures_where(r, (t >= DEAD_WINDOW[0]) & (t <= DEAD_WINDOW[1]), dt, n)
    climb = (t >= DEAD_CLIMB[0]) & (t <= DEAD_CLIMB[1])
    k = int(np.searchsorted(t, DEAD_LEAD_AT))
    run.figures = {
        "speed_rms": figures_where(r, np.ones(len(t), bool))["speed_rms_error"],
        "speed_error_max": win["speed_error_max"], "angle_rms": win["angle_rms"],
        "roll_back": figures_where(r, t > DEAD_ROLL_FROM)["roll_back"],
        "slips": tracking_figures(r, T_FROM, dt, n)["slips"],
        "v_error": v_dc * run.dead_time / dt,
        "climb_bias": figures_where(r, climb)["speed_bias"],
        "climb_voltage": float(np.mean(np.hypot(r["v_d"][climb], r["v_q"][climb]))) if climb.any() else None,
        "lead": float(r["omega_hat"][k] - r["omega_m"][k]) if k < len(t) else None,
    }
    return run


# --- everything the page reads --------------------------------------------------------------------

@dataclass
class Collected:
    """The runs of a robustness report, summarised: ``grids`` {map key: {controller: grid}},
    ``mc`` {label: rows}, ``dead`` [DeadRun], ``routes`` {sweep name: ``route_of`` its first run},
    ``mc_design`` {label: the Monte-Carlo sweep's spec}; ``t_from``: the start of the figures' window [s];
    ``cycle`` the drive cycle Monte-Carlo's rows (``cycle.cycle_rows``) and ``cycle_design`` its spec."""

    grids: dict
    mc: dict
    dead: list
    routes: dict
    mc_design: dict
    t_from: float = T_FROM
    cycle: list = field(default_factory=list)
    cycle_design: object = None


def collect(runs_dir: Path, t_from: float = T_FROM) -> Collected:
    """The figures of the sweep directories present in ``runs_dir``."""
    runs_dir = Path(runs_dir)
    grids: dict = {}
    routes: dict = {}
    for m in MAPS:
        for key, _ in CONTROLLERS:
            out = runs_dir / f"robust_{m.key}_{key}"
            if (out / "summary.csv").is_file():
                grids.setdefault(m.key, {})[key] = grid_of(sweep_results(out, t_from, ANGLE_USED[key]), m)
                r = _first_completed(out)
                if r is not None:
                    routes[out.name] = route_of(r)
    mc, design = {}, {}
    for name, label in MONTE_CARLOS:
        if (runs_dir / name / "summary.csv").is_file():
            mc[label] = sweep_results(runs_dir / name, t_from)
            design[label] = sweep_spec(name)
            r = _first_completed(runs_dir / name)
            if r is not None:
                routes[name] = route_of(r)
    dead = []
    dead_dir = runs_dir / DEAD_TIME
    if (dead_dir / "summary.csv").is_file():
        for row in read_summary(dead_dir / "summary.csv"):
            if row["status"] == "completed":
                dead.append(dead_run(row, _run_dir(dead_dir, row)))
    cycle, cycle_design = [], None
    if (runs_dir / CYCLE_MONTE_CARLO / "summary.csv").is_file():
        cycle, cycle_design = cycle_mc.cycle_rows(runs_dir / CYCLE_MONTE_CARLO), sweep_spec(CYCLE_MONTE_CARLO)
    return Collected(grids, mc, dead, routes, design, t_from, cycle, cycle_design)


def failure_rates(rows: list[dict]) -> dict:
    """A Monte-Carlo run's counts: samples, not stable, diverged, not completed, with the Wilson
    intervals of the first two."""
    n = len(rows)
    fails = sum(1 for r in rows if not r["stable"])
    div = sum(1 for r in rows if r["diverged"])
    return {"n": n, "fails": fails, "diverged": div, "fail_interval": wilson(fails, n),
            "diverged_interval": wilson(div, n), "incomplete": sum(1 for r in rows if r["status"] != "completed")}


# --- findings: what the text says, computed ---------------------------------------------------------

def near(values, target) -> int | None:
    """Index of ``target`` among ``values`` (to 1e-6), or None."""
    k = int(np.argmin([abs(v - target) for v in values])) if len(values) else None
    return k if k is not None and abs(values[k] - target) < 1e-6 else None


def rs_psi_findings(gs: dict) -> dict:
    """The R_s x psi maps: per controller (with the nominal cell in its grid) the steady speed error
    at the nominal R_s per psi mismatch, the largest one over psi and over R_s, whether the error has
    the sign of -delta psi in every cell, the cells diverged; over all, whether psi dominates R_s
    (``DOMINANT``), the back-EMF and resistive drop at the nominal cell and what the largest R_s
    mismatch is as a share of the voltage; the hot magnet (psi -10 %) cell of the sensorless unit;
    the adaptation's stable cells."""
    per, psi_effects, rs_effects = {}, [], []
    facts = {"per": per}
    for key, _ in CONTROLLERS:
        g = gs.get(key)
        if g is None:
            continue
        j0, i0 = near(g["x"], 0.0), near(g["y"], 0.0)
        if j0 is None or i0 is None:
            continue
        others = [i for i in range(len(g["y"])) if i != i0]
        psi_bias = [(g["y"][i], float(g["bias"][i, j0])) for i in others]
        psi_max = max((abs(b) for _, b in psi_bias if math.isfinite(b)), default=math.nan)
        rs_max = float(np.nanmax(np.abs(g["bias"][i0, :]))) if np.isfinite(g["bias"][i0, :]).any() else math.nan
        signs = all(math.isfinite(b) and b != 0 and math.copysign(1, b) == -math.copysign(1, y) for y, b in psi_bias)
        per[key] = {"psi_bias": psi_bias, "psi_max": psi_max, "rs_max": rs_max, "sign_minus_dpsi": signs,
                    "angle_max_nominal_psi": float(np.nanmax(g["angle"][i0, :])),
                    "diverged": int(g["diverged"].sum()), "cells": int(g["diverged"].size),
                    "diverged_nominal_rs": int(g["diverged"][:, j0].sum())}
        if ANGLE_USED[key]:
            psi_effects.append(psi_max)
            rs_effects.append(rs_max)
        if key == "sensorless":
            facts["omega"] = float(g["omega_ref"][i0, j0])
            facts["i_q"] = float(g["i_q"][i0, j0])
            facts["rs_mismatch_max"] = max(g["x"])
            ih = near(g["y"], -10.0)
            facts["hot_magnet"] = None if ih is None else {
                "stable": bool(g["stable"][ih, j0]), "speed": float(g["speed"][ih, j0]),
                "bias": float(g["bias"][ih, j0])}
    if not per:
        return {}
    facts["psi_dominates"] = bool(psi_effects) and all(
        math.isfinite(p) and math.isfinite(q) and p > DOMINANT * q for p, q in zip(psi_effects, rs_effects))
    if "omega" in facts:
        facts["back_emf"] = _M.N * facts["omega"] * _M.psi
        facts["rs_drop"] = _M.R_s * abs(facts["i_q"])
        facts["rs_share"] = 100.0 * facts["rs_mismatch_max"] / 100.0 * facts["rs_drop"] / facts["back_emf"]
        facts["tolerance_pct"] = 100.0 * SPEED_LIMIT / facts["omega"]
    if "sensorless" in gs and "sensorless_adapt" in gs:
        a, b = gs["sensorless"], gs["sensorless_adapt"]
        held = ~np.asarray(a["diverged"], bool) & ~np.asarray(b["diverged"], bool)  # a diverged cell has no bias
        facts["adapt"] = {"without": int(a["stable"].sum()), "with": int(b["stable"].sum()),
                          "cells": int(b["stable"].size),
                          "bias_without": float(np.nanmax(np.abs(a["bias"][held]))) if held.any() else math.nan,
                          "bias_with": float(np.nanmax(np.abs(b["bias"][held]))) if held.any() else math.nan,
                          "diverged_without": int(np.sum(a["diverged"])), "diverged_with": int(np.sum(b["diverged"]))}
    return facts


def lq_load_findings(gl: dict) -> dict:
    """The L_q x load maps: for the sensorless unit the angle RMS error at the largest L_q mismatch
    unloaded and at the largest load (does it grow with the load, ``DOMINANT`` times?), the load
    current at the largest load and nominal L_q, the angle error eq 10 predicts there,
    delta L_q i_q / psi, and whether the measured one is within a factor 2 of it; per controller
    whether every unloaded cell is stable and the cells diverged."""
    out: dict = {"per": {}}
    for key, _ in CONTROLLERS:
        g = gl.get(key)
        if g is None:
            continue
        i0 = near(g["y"], 0.0)
        out["per"][key] = {"unloaded_stable": None if i0 is None else bool(g["stable"][i0, :].all()),
                           "diverged": int(g["diverged"].sum())}
    g = gl.get("sensorless")
    if g is not None:
        i0, j_nom = near(g["y"], 0.0), near(g["x"], 0.0)
        i_max, j_min = len(g["y"]) - 1, int(np.argmin(g["x"]))
        if i0 is not None and j_nom is not None and i_max != i0:
            a0, a1 = float(g["angle"][i0, j_min]), float(g["angle"][i_max, j_min])
            i_q = abs(float(g["i_q"][i_max, j_nom]))
            predicted = abs(g["x"][j_min]) / 100.0 * _M.L_q * i_q / _M.psi
            out.update(lq_mismatch=g["x"][j_min], load=g["y"][i_max], angle_unloaded=a0, angle_loaded=a1,
                       grows=bool(math.isfinite(a0) and math.isfinite(a1) and a1 > DOMINANT * a0), i_q=i_q,
                       predicted=predicted, explained=bool(predicted / 2 <= a1 <= 2 * predicted))
    return out if out["per"] else {}


def dead_time_findings(dead: list) -> dict:
    """The dead-time runs by inverter: ``raw`` (dead time, no compensation), ``ideal``, ``compensated``
    and ``over`` (compensation of an ideal inverter), and what the page concludes from them: the
    fundamental of the voltage error (4/pi v_err) and its share of the voltage on the climb, the
    speed at which the back-EMF falls to the error, whether the uncompensated car was held
    (``ROLL_BACK_LIMIT``; None for a run too short to tell), whether the compensated run matches
    the ideal one (speed RMS error within 5 %, roll-back within 1 cm) and whether
    over-compensation breaks the run (each left out where the runs are too short to tell)."""
    by = {(d.dead_time > 0, d.compensation > 0): d for d in dead}
    raw, ideal, comp, over = by.get((True, False)), by.get((False, False)), by.get((True, True)), by.get((False, True))
    out: dict = {"raw": raw, "ideal": ideal, "compensated": comp, "over": over}
    if raw is not None:
        f = raw.figures
        v = f["v_error"]
        out["fundamental"] = 4.0 / math.pi * v
        out["share_pct"] = 100.0 * out["fundamental"] / f["climb_voltage"] if f["climb_voltage"] else None
        out["omega_at_error"] = v / (raw.pole_pairs * _M.psi)
        out["raw_held"] = None if f["roll_back"] is None else f["roll_back"] <= ROLL_BACK_LIMIT
    if ideal is not None and comp is not None and None not in (comp.figures["roll_back"], ideal.figures["roll_back"]):
        a, b = comp.figures, ideal.figures
        out["comp_matches"] = bool(abs(a["speed_rms"] - b["speed_rms"]) <= 0.05 * b["speed_rms"]
                                   and abs(a["roll_back"] - b["roll_back"]) <= 0.01)
    if ideal is not None and over is not None and None not in (over.figures["roll_back"], over.figures[
            "speed_error_max"], ideal.figures["speed_error_max"]):
        a, b = over.figures, ideal.figures
        out["over_breaks"] = bool(a["roll_back"] > ROLL_BACK_LIMIT or a["slips"] > 0
                                  or a["speed_error_max"] > DOMINANT * b["speed_error_max"])
    return out
