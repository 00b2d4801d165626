"""The report's section "Sensorless from standstill": the sensorless unit (FocSensorless)
against the sensored drive on the same runs: both paper scenarios and ``hill-start-if`` from
standstill, with exact sensors, sigma = 1 A noise and +2 / -1 A offsets, and scenario 1's
start-up from eight initial rotor angles over [-pi, pi).

The configurations are :class:`pmsm_cosim.app.report.Config` of the shared report machinery
(one ``pmsm-cosim run`` each, reused while settings and FMU builds are unchanged); the
figures of merit are ``pmsm_cosim.app.metrics``' of each run (``sensorless_metrics``,
``figures_where`` of its windows, the angle error with the row-timing term removed with the
run's own step and pole pairs, ``run_timing``) and ``compare.summarize``'s; every sentence
is filled from them.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from pmsm_ev.kernels import MODE_EKF
from pmsm_ev.params import ScenarioParams, StartupParams
from pmsm_ev.results import row_timing_corrected_angle_error
from pmsm_ev.scenarios import SENSORLESS_START_DELAY

from ..drive import load_system
from ..metrics.rows import T_FROM
from ..metrics.sensorless import ROLL_BACK_LIMIT, STARTUP_BAND, STARTUP_FROM, handovers, sensorless_metrics
from ..metrics.windows import figures_where, run_timing
from .drawing import figure_links, pyplot, save_figure

#: the runs: (short name, shipped scenario, title)
SCENARIOS = (("s1", "scenario1-sensorless", "Scenario 1"), ("s2", "scenario2-sensorless", "Scenario 2"),
             ("hill", "hill-start-if", "Hill start"))
#: sensor conditions: (short name, --set assignments, description)
CONDITIONS = (("exact", (), "exact sensors"),
              ("noisy1A", ("plant.sensor_noise=1.0",), "σ = 1 A noise"),
              ("offset", ("plant.sensor_offset_a=2.0", "plant.sensor_offset_b=-1.0"), "offsets +2 / −1 A"))
#: initial rotor angles of the start-up runs [rad]: 8 points over [-pi, pi)
ANGLES = tuple(-math.pi + k * math.pi / 4 for k in range(8))
#: conditions of the start-up runs, and their stop time [s]: past the first 5 deg step (50 s)
ANGLE_CONDITIONS = ("exact", "noisy1A")
ANGLE_STOP = 60.0
#: the controllers compared: (setup key of pmsm_cosim.app.report.SETUPS)
SETUP_KEYS = ("sensorless", "sensored")

#: the hill start's margins [s]: the figure from this long before the stop to this long after the restart, the
#: roll-back at the restart until this long after it; the stand judged from this long after it begins (the car
#: settles), its zoomed figure this long either side of it
HILL_MARGIN, STAND_SETTLE, STAND_ZOOM = 5.0, 1.0, 1.5


def hill_route(scenario: str = "hill-start-if") -> dict:
    """The hill start's route from its system file: the grade [°] and when it comes (``grade_at`` [s]), and the
    speed reference's ``stop`` (its fall to 0), ``stand`` (at 0) and ``restart`` (its rise), each (start, end) [s]."""
    spec = load_system(scenario)
    d, w = spec.signals["delta"].profile, spec.signals["omega_ref"].profile
    t, v = w.times, w.values
    i = next(j for j in range(1, len(v) - 1) if v[j] > 0.0 and v[j + 1] == 0.0)  # the fall to the stop
    return {"grade": math.degrees(max(d.values)), "grade_at": next(a for a, x in zip(d.times, d.values) if x > 0.0),
            "stop": (t[i], t[i + 1]), "stand": (t[i + 1], t[i + 2]), "restart": (t[i + 2], t[i + 3])}


#: the issue's targets
SPEED_RATIO = 1.1  #: speed RMS error and step dips, against the sensored drive's
SETTLING_EXTRA = 0.5  #: settling time over the sensored drive's [s]
ANGLE_LIMIT = 0.05  #: angle error after the start-up [rad], row timing removed


def config_specs():
    """(id, scenario, setup key, --set assignments, own stop time, description) of every run."""
    specs = []
    for short, scen, _ in SCENARIOS:
        for cond, sets, desc in CONDITIONS:
            for key in SETUP_KEYS:
                specs.append((f"sl-{short}-{cond}-{key}", scen, key, sets, None, desc))
    for cond in ANGLE_CONDITIONS:
        sets, desc = next((s, d) for c, s, d in CONDITIONS if c == cond)
        for k, theta in enumerate(ANGLES):
            specs.append((f"sl-start{k}-{cond}-sensorless", "scenario1-sensorless", "sensorless",
                          sets + (f"plant.theta_e0={theta!r}",), ANGLE_STOP, f"θ(0) = {theta:+.3f} rad, {desc}"))
    return specs


def _finish(fig, axes, path: Path, mode_axis=None) -> Path:
    """Grid, mode ticks; save and close."""
    if mode_axis is not None:
        mode_axis.set_ylabel("mode")
        mode_axis.set_yticks([0, 1, 2], ["align", "I-f", "EKF"])
    for ax in axes:
        ax.grid(True, lw=0.3)
    axes[-1].set_xlabel("time [s]")
    return save_figure(fig, path)


def figures(data, fig_dir: Path) -> list[Path]:
    """The first 15 s of the start-up from the 8 angles, and the hill stop and restart."""
    plt = pyplot()

    made = []
    runs = [(k, data.runs.get(f"sl-start{k}-exact-sensorless")) for k in range(len(ANGLES))]
    runs = [(k, r) for k, r in runs if r is not None]
    if runs:
        fig, axes = plt.subplots(3, 1, figsize=(7.5, 7.0), sharex=True)
        for k, run in runs:
            r = run.r
            sel = r["time"] <= 15.0
            t = r["time"][sel]
            label = f"θ(0) = {ANGLES[k]:+.2f}"
            axes[0].plot(t, r["omega_m"][sel], lw=0.9, label=label)
            axes[1].plot(t, _corrected_error(run)[sel], lw=0.9)
            axes[2].plot(t, r["mode"][sel], lw=0.9)
        r0 = runs[0][1].r
        sel = r0["time"] <= 15.0
        axes[0].plot(r0["time"][sel], r0["omega_ref"][sel], "k--", lw=0.8, label="ω_ref")
        axes[0].set_ylabel("ω_m [rad/s]")
        axes[0].legend(fontsize=6, ncol=3)
        axes[1].set_ylabel("θ̂ − θ [rad]\n(row timing removed)")
        axes[0].set_title("Sensorless start-up from standstill, scenario 1, exact sensors: the first 15 s")
        made.append(_finish(fig, axes, fig_dir / "sensorless_startup.png", axes[2]))
    # sensored (dashed) first, the sensorless unit on top
    hill = [(data.runs.get(f"sl-hill-{c}-{k}"), f"{k}, {d}", "--" if k == "sensored" else "-")
            for k in ("sensored", "sensorless") for c, _, d in CONDITIONS[:2]]
    hr = hill_route()
    window = (hr["stop"][0] - HILL_MARGIN, hr["restart"][1] + HILL_MARGIN)
    # the runs that reach the window (a report with a short stop time has none there)
    hill = [(r, lab, ls) for r, lab, ls in hill if r is not None and r.r["time"][-1] >= window[0]]
    if hill:
        fig, axes = plt.subplots(4, 1, figsize=(7.5, 8.5), sharex=True)
        for i, (run, label, ls) in enumerate(hill):
            r = run.r
            sel = (r["time"] >= window[0]) & (r["time"] <= window[1])
            t = r["time"][sel]
            style = {"lw": 0.9, "color": f"C{i}", "ls": ls}
            axes[0].plot(t, r["omega_m"][sel], label=label, **style)
            axes[1].plot(t, r["x_vehicle"][sel] - r["x_vehicle"][sel][0], **style)
            axes[2].plot(t, r["T_e"][sel], **style)
            axes[3].plot(t, r["mode"][sel], **style)
        r = hill[0][0].r
        sel = (r["time"] >= window[0]) & (r["time"] <= window[1])
        axes[0].plot(r["time"][sel], r["omega_ref"][sel], "k--", lw=0.8, label="ω_ref")
        axes[2].plot(r["time"][sel], r["T_L_mech"][sel], "k--", lw=0.8, label="T_L,mech")
        axes[0].set_ylabel("ω_m [rad/s]")
        axes[0].legend(fontsize=7)
        axes[1].set_ylabel(f"x − x({window[0]:g} s) [m]")
        axes[2].set_ylabel("T_e [N m]")
        axes[2].legend(fontsize=7)
        axes[0].set_title(f"hill-start-if on {hr['grade']:g}°: "
                          + ", ".join(f"{k} ({hr[k][0]:g}-{hr[k][1]:g} s)" for k in ("stop", "stand", "restart")))
        made.append(_finish(fig, axes, fig_dir / "sensorless_hill.png", axes[3]))
        # the position over the stand, zoomed: the roll-back in millimetres
        mid = sum(hr["stand"]) / 2
        fig, ax = plt.subplots(figsize=(7.5, 3.0))
        for i, (run, label, ls) in enumerate(hill):
            r = run.r
            sel = (r["time"] >= hr["stand"][0] - STAND_ZOOM) & (r["time"] <= hr["stand"][1] + STAND_ZOOM)
            x45 = float(np.interp(mid, r["time"], r["x_vehicle"]))
            ax.plot(r["time"][sel], 1000.0 * (r["x_vehicle"][sel] - x45), lw=0.9, label=label, color=f"C{i}", ls=ls)
        ax.set_ylabel(f"x − x({mid:g} s) [mm]")
        ax.set_ylim(-100.0, 40.0)
        ax.set_title("hill-start-if: vehicle position around the stand (below 0: rolled back)")
        ax.legend(fontsize=7)
        made.append(_finish(fig, [ax], fig_dir / "sensorless_hill_position.png"))
    return made


def _num(x, fmt=".2f") -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if x == math.inf:
        return "never"
    return format(x, fmt)


def _corrected_error(run) -> np.ndarray:
    """The run's angle error with the row-timing term removed, with the run's own step and pole pairs."""
    return row_timing_corrected_angle_error(run.r, *run_timing(run.metrics))


def _figures_of(data, cid: str) -> dict | None:
    """The figures of one run (``pmsm_ev.results``): summarize's row plus the sensorless metrics and
    the angle error (row timing removed, with the run's step and pole pairs) in the closed loop."""
    run, row = data.runs.get(cid), data.rows.get(cid)
    if run is None or row is None:
        return None
    r = run.r
    t = r["time"]
    dt, pole_pairs = run_timing(run.metrics)
    out = dict(row)
    out.update(sensorless_metrics(r, T_FROM))
    # the angle error in closed loop (standing in I-f, at no back-EMF, it is not observable)
    closed = figures_where(r, (t >= T_FROM) & (r["mode"] == MODE_EKF), dt, pole_pairs)
    out["angle_max_after"], out["angle_rms_after"] = closed["angle_max"], closed["angle_rms"]
    drift = row.get("theta_drift")
    out["turns"] = None if drift is None else abs(drift) / (2 * math.pi)
    ups = handovers(out["mode_changes"])["closed"]
    out["t_up"] = ups[0] if ups else None
    out["angle_max_after_handover"] = (None if out["t_up"] is None else
                                       figures_where(r, t >= out["t_up"] + 0.5, dt, pole_pairs)["angle_max"])
    return out


def _hill_figures(data, cid: str) -> dict | None:
    """The hill start's figures; None without the run or for a run that ends before its stand and restart (a
    report with a short stop time)."""
    f = _figures_of(data, cid)
    if f is None:
        return None
    t = data.runs[cid].r["time"]
    r = data.runs[cid].r
    hr = hill_route()
    stand = figures_where(r, (t >= hr["stand"][0] + STAND_SETTLE) & (t <= hr["stand"][1]))
    f["roll_back_stop"] = figures_where(r, (t >= hr["stop"][0]) & (t <= hr["stand"][1]))["roll_back"]
    restart = (t >= hr["restart"][0]) & (t <= hr["restart"][1] + HILL_MARGIN)
    f["roll_back_restart"] = figures_where(r, restart)["roll_back"]
    f["stand_travel"], f["stand_speed_max"] = stand["travel"], stand["speed_max"]
    h = handovers(f["mode_changes"])
    f["t_down"] = h["down"][0] if h["down"] else None
    f["t_restart_up"] = next((u for u in h["up"] if u > sum(hr["stand"]) / 2), None)
    return None if None in (f["roll_back_stop"], f["roll_back_restart"], f["stand_travel"]) else f


def _table(data) -> list[str]:
    head = ("| scenario | sensors | controller | status | closed loop from [s] | speed RMS err after 20 s [rad/s] "
            "| × sensored | largest step dip [rad/s] | × sensored | settling max [s] | − sensored [s] "
            "| θ̂ err max after 20 s, closed loop [rad] | electrical turns slipped | roll-back, start [cm] "
            "| roll-back after 20 s [cm] |")
    lines = [head, "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for short, _, title in SCENARIOS:
        for cond, _, desc in CONDITIONS:
            ref = _figures_of(data, f"sl-{short}-{cond}-sensored")
            for key in SETUP_KEYS:
                f = _figures_of(data, f"sl-{short}-{cond}-{key}")
                if f is None:
                    continue
                ratio = dip_ratio = extra = None
                if short == "hill":  # its stop and restart ramps are no settling after a step
                    f["settling_max"] = None
                if key == "sensorless" and ref:
                    if f.get("speed_rms_after") and ref.get("speed_rms_after"):
                        ratio = f["speed_rms_after"] / ref["speed_rms_after"]
                    if f.get("step_dev_max") and ref.get("step_dev_max"):
                        dip_ratio = f["step_dev_max"] / ref["step_dev_max"]
                    if f.get("settling_max") is not None and ref.get("settling_max") is not None:
                        extra = f["settling_max"] - ref["settling_max"]
                lines.append(
                    f"| {title} | {desc} | {key} | {f['status']} | {_num(f['t_up'])} | "
                    f"{_num(f.get('speed_rms_after'), '.3f')} | {_num(ratio)} | {_num(f.get('step_dev_max'))} | "
                    f"{_num(dip_ratio)} | {_num(f.get('settling_max'))} | {_num(extra)} | "
                    f"{_num(f['angle_max_after'], '.4f')} | {_num(f['turns'], '.1f')} | "
                    f"{_num(100 * f['roll_back_start'])} | "
                    f"{_num(None if f['roll_back_after'] is None else 100 * f['roll_back_after'])} |")
    return lines


def _start_table(data) -> list[str]:
    lines = ["| θ(0) [rad] | sensors | closed loop from [s] | max abs(ω_m − ω_ref) from "
             f"{STARTUP_FROM:g} s [rad/s] | roll-back [cm] | θ̂ err max from 0.5 s after the handover [rad] | "
             "abs(ω_m − ω_ref) at the end [rad/s] |",
             "|---:|---|---:|---:|---:|---:|---:|"]
    for cond in ANGLE_CONDITIONS:
        desc = next(d for c, _, d in CONDITIONS if c == cond)
        for k, theta in enumerate(ANGLES):
            f = _figures_of(data, f"sl-start{k}-{cond}-sensorless")
            if f is None:
                continue
            r = data.runs[f"sl-start{k}-{cond}-sensorless"].r
            end = figures_where(r, np.arange(len(r["time"])) == len(r["time"]) - 1)["speed_error_max"]
            lines.append(f"| {theta:+.3f} | {desc} | {_num(f['t_up'])} | {_num(f['startup_speed_error_max'])} | "
                         f"{_num(100 * f['roll_back_start'])} | {_num(f['angle_max_after_handover'], '.4f')} | "
                         f"{end:.2f} |")
    return lines


def _verdict(ok: bool | None) -> str:
    return "-" if ok is None else ("met" if ok else "**not met**")


def _targets(data) -> tuple[list[str], list[str]]:
    """The target table and the sentences for the targets not met."""
    rows, misses = [], []

    def add(target, measured, ok, why=""):
        rows.append(f"| {target} | {measured} | {_verdict(ok)} |")
        if ok is False:
            misses.append(f"- {target}: {measured}. {why}".rstrip())

    for short, _, title in SCENARIOS[:2]:
        for cond in ("exact", "noisy1A"):
            desc = next(d for c, _, d in CONDITIONS if c == cond)
            f = _figures_of(data, f"sl-{short}-{cond}-sensorless")
            ref = _figures_of(data, f"sl-{short}-{cond}-sensored")
            if not f or not ref:
                continue
            where = f"{title}, {desc}"
            if f.get("speed_rms_after") is not None and ref.get("speed_rms_after"):
                ratio = f["speed_rms_after"] / ref["speed_rms_after"]
                add(f"{where}: speed RMS error after {T_FROM:g} s ≤ {SPEED_RATIO:g} × sensored",
                    f"{f['speed_rms_after']:.3f} vs {ref['speed_rms_after']:.3f} rad/s ({ratio:.3f} ×)",
                    ratio <= SPEED_RATIO, f"Over by {100 * (ratio / SPEED_RATIO - 1):.1f} %.")
            if f.get("step_dev_max") and ref.get("step_dev_max"):
                ratio = f["step_dev_max"] / ref["step_dev_max"]
                add(f"{where}: step dips ≤ {SPEED_RATIO:g} × sensored",
                    f"{f['step_dev_max']:.2f} vs {ref['step_dev_max']:.2f} rad/s ({ratio:.3f} ×)",
                    ratio <= SPEED_RATIO, f"Over by {100 * (ratio / SPEED_RATIO - 1):.1f} %.")
            if f.get("settling_max") is not None and ref.get("settling_max") is not None:
                extra = f["settling_max"] - ref["settling_max"]
                add(f"{where}: settling ≤ sensored + {SETTLING_EXTRA:g} s",
                    f"{_num(f['settling_max'])} vs {_num(ref['settling_max'])} s", extra <= SETTLING_EXTRA,
                    f"Over by {_num(extra - SETTLING_EXTRA)} s.")
            if f.get("angle_max_after") is not None:
                add(f"{where}: angle error after {T_FROM:g} s ≤ {ANGLE_LIMIT:g} rad (row timing removed)",
                    f"max {f['angle_max_after']:.4f}, RMS {f['angle_rms_after']:.4f} rad",
                    f["angle_max_after"] <= ANGLE_LIMIT,
                    f"Over by {f['angle_max_after'] - ANGLE_LIMIT:.4f} rad.")
            if f.get("turns") is not None:
                add(f"{where}: no electrical turn slipped", f"{f['turns']:.2f} turns (θ̂ drift)", f["turns"] < 0.5)
    worst_speed, worst_roll = None, None
    for cond in ANGLE_CONDITIONS:
        for k in range(len(ANGLES)):
            f = _figures_of(data, f"sl-start{k}-{cond}-sensorless")
            if not f:
                continue
            e, rb = f["startup_speed_error_max"], f["roll_back_start"]
            if e is not None:  # None: the run ended before STARTUP_FROM
                worst_speed = e if worst_speed is None else max(worst_speed, e)
                worst_roll = rb if worst_roll is None else max(worst_roll, rb)
    if worst_speed is not None:
        conds = " / ".join(next(d for c, _, d in CONDITIONS if c == cond) for cond in ANGLE_CONDITIONS)
        add(f"Start-up, every initial angle: abs(ω_m − ω_ref) ≤ {STARTUP_BAND:g} rad/s from {STARTUP_FROM:g} s on",
            f"largest {worst_speed:.2f} rad/s ({len(ANGLES)} angles × {conds})", worst_speed <= STARTUP_BAND)
        add(f"Start-up, every initial angle: backward roll ≤ {100 * ROLL_BACK_LIMIT:g} cm on level road",
            f"largest {100 * worst_roll:.2f} cm", worst_roll <= ROLL_BACK_LIMIT)
    stand = hill_route()["stand"]
    for cond in ("exact", "noisy1A", "offset"):
        desc = next(d for c, _, d in CONDITIONS if c == cond)
        h = _hill_figures(data, f"sl-hill-{cond}-sensorless")
        if not h:
            continue
        add(f"hill-start-if, {desc}: roll-back ≤ {100 * ROLL_BACK_LIMIT:g} cm at the stop and the restart",
            f"{100 * h['roll_back_stop']:.2f} / {100 * h['roll_back_restart']:.2f} cm",
            max(h["roll_back_stop"], h["roll_back_restart"]) <= ROLL_BACK_LIMIT)
        add(f"hill-start-if, {desc}: holds for the {stand[1] - stand[0]:g} s",
            f"moves {1000 * h['stand_travel']:.1f} mm, abs(ω_m) ≤ {h['stand_speed_max']:.3f} rad/s over "
            f"{stand[0] + STAND_SETTLE:g}-{stand[1]:g} s",
            h["stand_travel"] < 0.01)
    return ["| target | measured | |", "|---|---|---|"] + rows, misses


def render(data, fig_names) -> list[str]:
    """The section's lines."""
    s = StartupParams()
    # the row-timing term of the angle error, N omega dt at the scenarios' speed, with the step and pole pairs of
    # the runs
    w = ScenarioParams().omega_ref
    timings = {run_timing(run.metrics) for cid, run in data.runs.items() if cid.startswith("sl-")}
    lag = (" (every observer's rows trail the rotor by one period: "
           + " / ".join(f"{n * w * dt:.2g}" for dt, n in sorted(timings)) + f" rad at {w:g} rad/s)") if timings else ""
    L = ["## Sensorless from standstill\n"]
    L.append(
        f"The sensorless unit (`FocSensorless.fmu`, observer `sensorless`; docs/sensorless.md) never reads the "
        f"rotor angle or speed. At standstill it aligns the rotor in two steps: {s.i_align:g} A ramped up on the "
        f"+90° axis over {s.t_ramp:g} s, held {s.t_hold:g} s, swept to 0° over {s.t_sweep:g} s, held "
        f"{s.t_settle:g} s ({s.align_time:g} s in all); the stationary-frame EKF5 (its mechanical model on "
        f"J_eq) restarts at the aligned angle; an I-f drive ({s.i_if:g} A) follows the speed reference; "
        f"the FOC takes over on the EKF's angle and speed once ω̂ agrees with the I-f speed within "
        f"{100 * s.agree_tol:g} % for {s.agree_time:g} s above {s.omega_up:g} rad/s, and hands back to I-f "
        f"below {s.omega_down:g} rad/s with the vector left where the current is and its magnitude raised to "
        f"{s.if_margin:g} × the present current (at least {s.if_margin:g} × the EKF's load). The routes "
        f"`scenario1-sensorless`, `scenario2-sensorless` and `hill-start-if` hold ω_ref = 0 for "
        f"{SENSORLESS_START_DELAY:g} s (the alignment) and then ramp as the paper's scenarios do. Each row is "
        f"against the sensored drive (`FocSensored.fmu`) on the same run. Angle errors here have the "
        f"row-timing term −N ω dt removed{lag}.\n")
    L += _table(data)
    L.append("")
    delta = load_system(SCENARIOS[0][1]).signals["delta"].profile
    t_step, step = next((t, math.degrees(x)) for t, x in zip(delta.times, delta.values) if x != 0.0)
    L.append(f"Start-up from eight initial rotor angles (scenario 1, {ANGLE_STOP:g} s: the start, then the "
             f"{step:g}° step at {t_step:g} s):\n")
    L += _start_table(data)
    L.append("")
    h = {c: _hill_figures(data, f"sl-hill-{c}-sensorless") for c, _, _ in CONDITIONS}
    hr = hill_route()
    if h["exact"]:
        e = h["exact"]
        L.append(
            f"Hill start ({hr['grade']:g}° from {hr['grade_at']:g} s): with exact sensors the unit hands back to I-f "
            f"at {_num(e['t_down'])} s while slowing down, stands from {hr['stand'][0]:g} to {hr['stand'][1]:g} s "
            "moving "
            f"{1000 * e['stand_travel']:.1f} mm (largest |ω_m| {e['stand_speed_max']:.3f} rad/s), and hands over "
            f"to the EKF again at {_num(e['t_restart_up'])} s on the way up; roll-back {100 * e['roll_back_stop']:.2f} "
            f"cm at the stop and {100 * e['roll_back_restart']:.2f} cm at the restart"
            + "".join(f"; {d}: {100 * h[c]['roll_back_stop']:.2f} / {100 * h[c]['roll_back_restart']:.2f} cm, "
                      f"handovers at {_num(h[c]['t_down'])} / {_num(h[c]['t_restart_up'])} s"
                      for c, _, d in CONDITIONS[1:] if h[c])
            + ". While the car stands there is no back-EMF, so the EKF's angle is not observable: with exact "
              "sensors it stays put, with noise it drifts slowly; the I-f vector holds the car regardless (its "
              "current never falls while in I-f) and the EKF finds the angle again once the rotor turns.\n")
    table, misses = _targets(data)
    L.append("Targets:\n")
    L += table
    L.append("")
    if misses:
        L.append("Targets not reached, by how much:\n")
        L += misses
        L.append("")
    L += figure_links(("sensorless_startup", "sensorless_hill", "sensorless_hill_position"), fig_names)
    return L
