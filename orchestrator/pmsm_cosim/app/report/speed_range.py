"""The report's section "The whole speed range": the data sheet's acceleration run, full torque from
standstill (or a flying start) on a level road to the top speed, 131 km/h, then regenerative braking,
with three controllers: the sensored drive (``acceleration``), the stationary-frame EKF5 from a flying
start (``acceleration-flying``) and the sensorless unit from standstill (``acceleration-if``).
The figures of merit are ``pmsm_cosim.app.metrics.speed_range.acceleration_figures`` and ``energy_metrics`` of each run
(metrics.json), the angle error with the row-timing term removed (``row_timing_corrected_angle_error``);
the envelope is the scenario's controller's (``pmsm_ev.references``, docs/speed-range.md)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from pmsm_ev import references
from pmsm_ev.params import VehicleParams
from pmsm_ev.results import row_timing_corrected_angle_error

from .. import envelope
from ..drive import load_system
from ..metrics.cycle_energy import plant_params
from ..metrics.rows import KMH
from ..metrics.speed_range import wheel_ratio
from ..metrics.windows import figures_where, run_timing
from .configs import SPEED_RANGE_RUNS as RUNS
from .drawing import figure_links, pyplot, save_figure
from .drawing import num as _num

#: the scenario's controller settings, for its envelope (acceleration.toml's ctrl start values)
SCENARIO_SETS = ("reference=fw", "v_dc=360", "P_regen_max=50000", "inverter_losses=true", "gear_model=power_flow")
#: the angle is judged once the rotor turns faster than this [rad/s] (at standstill no back-EMF shows it)
ANGLE_FROM_SPEED = 100.0


def limits():
    """The drive's limits with the scenario's controller settings (``SCENARIO_SETS``; ``pmsm_ev.references``)."""
    p = envelope.parameters(SCENARIO_SETS)
    return references.limits(p["controller"], p["motor"])


def route(spec, vehicle: VehicleParams) -> dict:
    """The acceleration route of a system (``spec``: its speed reference's table, the standing start, the
    step to the top, the braking ramp and the driver's easing off) at the wheels of ``vehicle`` (eqs 1, 6:
    v = omega r_w / n_g): ``top_kmh``, ``t_brake`` [s], ``decel`` [m/s²] and ``ease_kmh``."""
    table = spec.signals["omega_ref"].profile
    t, w = table.times, table.values
    top = max(w)
    i = max(j for j, x in enumerate(w) if x == top)  # the braking starts at the plateau's last point
    k = vehicle.r_w / vehicle.n_g
    return {"top_kmh": top * k * KMH, "t_brake": t[i], "decel": (w[i] - w[i + 1]) / (t[i + 1] - t[i]) * k,
            "ease_kmh": w[i + 1] * k * KMH}


def route_text(rt: dict) -> str:
    """The route's sentence (``route``)."""
    return (f"on a level road the speed reference steps to the top speed, {rt['top_kmh']:.0f} km/h at the wheels, so "
            f"the speed PI asks for the most torque the drive has; from {rt['t_brake']:g} s it ramps down at "
            f"{rt['decel']:.0f} m/s² (the driver easing off below {rt['ease_kmh']:.1f} km/h)")


def figures_of(data, cid: str) -> dict | None:
    """One run's figures: metrics.json's acceleration and energy blocks, the synchronism, and the angle
    error above ``ANGLE_FROM_SPEED`` (row timing removed)."""
    run = data.runs.get(cid)
    if run is None:
        return None
    m = run.metrics
    out = {"acceleration": m.get("acceleration") or {}, "energy": m.get("energy") or {},
           "synchronism": m.get("synchronism") or {}, "status": m.get("status")}
    dt, pole_pairs = run_timing(m)
    r = run.r
    fast = np.abs(r["omega_m"]) > ANGLE_FROM_SPEED
    if cid != "accel-sensored":
        out["angle"] = figures_where(r, fast, dt, pole_pairs)
    out["top_speed_w"] = float(np.max(r["omega_m"]))
    return out


def figures(data, fig_dir: Path) -> list[Path]:
    """Speed, torque and power along the runs; their operating points on the envelope; the angle error."""
    plt = pyplot()

    runs = [(cid, setup.label, data.runs[cid]) for cid, _, setup in RUNS if cid in data.runs]
    if not runs:
        return []
    made = []
    fig, axes = plt.subplots(3, 1, figsize=(7.5, 8.0), sharex=True)
    for i, (cid, label, run) in enumerate(runs):
        r = run.r
        t = r["time"]
        axes[0].plot(t, r["v_vehicle"] * KMH, lw=0.9, color=f"C{i}", label=label)
        axes[1].plot(t, r["T_e"], lw=0.9, color=f"C{i}")
        if "T_brake" in r:
            axes[1].plot(t, -r["T_brake"] / VehicleParams().n_g, lw=0.7, color=f"C{i}", ls=":")
        if "P_dc" in r:
            axes[2].plot(t, r["P_dc"] / 1e3, lw=0.9, color=f"C{i}")
    r0 = runs[0][2].r
    axes[0].plot(r0["time"], r0["omega_ref"] * wheel_ratio(r0) * KMH, "k--", lw=0.7, label="reference")
    axes[0].set_ylabel("v [km/h]")
    axes[0].legend(fontsize=7)
    run = data.runs.get(RUNS[0][0])
    top = route(load_system(RUNS[0][1]), plant_params(run.metrics)[1] if run else VehicleParams())["top_kmh"]
    axes[0].set_title(f"Acceleration to {top:.0f} km/h and regenerative braking, level road")
    axes[1].set_ylabel("T_e [N m]\n(dotted: friction brake / n_g)")
    axes[2].set_ylabel("P_dc [kW]")
    axes[2].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(True, lw=0.3)
    made.append(save_figure(fig, fig_dir / "accel_speed.png"))

    lim = limits()
    speeds = references.region_speeds(lim)
    w = np.linspace(0.0, 1.15 * max(float(np.max(run.r["omega_m"])) for _, _, run in runs), 300)
    motoring, braking, region = references.torque_envelope(w, lim)
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    points = [(Path(label), {"omega_m": run.r["omega_m"], "T_e": run.r["T_e"]}) for _, label, run in runs]
    envelope.plot_envelope(ax, lim, speeds, w, motoring, braking, region, points)
    made.append(save_figure(fig, fig_dir / "accel_envelope.png"))

    est = [(cid, label, run) for cid, label, run in runs if cid != "accel-sensored"]
    if est:
        fig, axes = plt.subplots(2, 1, figsize=(7.5, 5.5), sharex=True)
        for i, (cid, label, run) in enumerate(est, start=1):
            r = run.r
            e = row_timing_corrected_angle_error(r, *run_timing(run.metrics))
            fast = np.abs(r["omega_m"]) > ANGLE_FROM_SPEED
            axes[0].plot(r["time"][fast], e[fast], ".", ms=1.0, color=f"C{i}", label=label)
            if "mode" in r and cid == "accel-sensorless":
                axes[1].plot(r["time"], r["mode"], lw=0.9, color=f"C{i}", label=f"{label}: mode")
            if "ref_region" in r:
                axes[1].plot(r["time"], r["ref_region"] + 0.1 * i, ".", ms=1.0, color=f"C{i}",
                             label=f"{label}: generator's region")
        axes[0].set_ylabel(f"θ̂ − θ [rad]\n(row timing removed,\n|ω_m| > {ANGLE_FROM_SPEED:g} rad/s)")
        axes[0].legend(fontsize=7)
        axes[1].set_ylabel("mode (0 align, 1 I-f, 2 EKF)\nregion (0 MTPA, 1 FW, 3 limits, 4 T_max)")
        axes[1].legend(fontsize=6)
        axes[1].set_xlabel("time [s]")
        for ax in axes:
            ax.grid(True, lw=0.3)
        made.append(save_figure(fig, fig_dir / "accel_angle.png"))
    return made


def render(data, fig_names) -> list[str]:
    """The section's lines, every figure computed from the runs."""
    run = data.runs.get(RUNS[0][0])
    rt = route(load_system(RUNS[0][1]), plant_params(run.metrics)[1] if run else VehicleParams())
    L = [f"## The whole speed range: acceleration to {rt['top_kmh']:.0f} km/h and regenerative braking\n"]
    rows = {cid: figures_of(data, cid) for cid, _, _ in RUNS}
    if not any(rows.values()):
        return L + ["(no runs)\n"]
    p = envelope.parameters(SCENARIO_SETS)
    lim = limits()
    speeds = references.region_speeds(lim)
    v_dc = p["controller"].v_dc
    L.append(
        "The EV data sheet's test (shipped scenarios `acceleration`, `acceleration-flying`, "
        f"`acceleration-if`; docs/speed-range.md): {route_text(rt)}. The reference generator works in field "
        f"weakening on the {v_dc:g} V DC link (I_max {lim.i_max:g} A, T_max {lim.T_max:.1f} N m on MTPA, the voltage "
        f"{lim.u_fw:.0f} V = {p['controller'].fw_margin:g} × {v_dc:g} V/√3; base speed {speeds['base_speed']:.0f} "
        "rad/s, "
        f"no torque left beyond {speeds['max_speed']:.0f} rad/s), regenerates up to "
        f"{lim.P_regen_max / 1e3:g} kW and leaves the rest of the braking to the friction brake; the current "
        "control is the high-speed one, the observers' current model Tustin's, the gear's efficiency acts in "
        "the direction the power flows, the inverter loses its conduction and switching losses. Times are from "
        "the launch (the reference's rise); *recovered* is the DC-link energy regenerated from the braking's "
        "start, as a share of the kinetic energy there.\n")
    head = ("| controller | launch at | to 50 km/h | to 100 km/h | top speed | braking time | kinetic at braking | "
            f"recovered | friction brake | DC drawn | DC regenerated | losses | net Wh/km | θ̂ − θ above "
            f"{ANGLE_FROM_SPEED:g} rad/s (rms, max) | slipped turns |")
    L.append(head)
    L.append("|" + "---|" * (head.count("|") - 1))
    for cid, _, setup in RUNS:
        f = rows[cid]
        if f is None:
            L.append(f"| {setup.label} | (no run) |" + " |" * (head.count("|") - 3))
            continue
        a, e, s = f["acceleration"], f["energy"], f["synchronism"]
        ang = f.get("angle")
        angle = "-" if not ang else f"{_num(ang.get('angle_rms'), '.4f')}, {_num(ang.get('angle_max'), '.4f')} rad"
        share = a.get("recovered_share")
        L.append(
            f"| {setup.label} | {_num(a.get('v_launch_kmh'), '.1f')} km/h | {_num(a.get('t_0_50'))} s | "
            f"{_num(a.get('t_0_100'))} s | {_num(a.get('top_speed_kmh'), '.1f')} km/h | "
            f"{_num(a.get('braking_time'))} s | {_num(a.get('kinetic_Wh'), '.1f')} Wh | "
            f"{_num(a.get('recovered_Wh'), '.1f')} Wh ({_num(None if share is None else 100 * share, '.0f')} %) | "
            f"{_num(e.get('brake_Wh'), '.1f')} Wh | {_num(e.get('drawn_Wh'), '.1f')} Wh | "
            f"{_num(e.get('regen_Wh'), '.1f')} Wh | {_num((e.get('losses_Wh') or {}).get('total'), '.1f')} Wh | "
            f"{_num(e.get('dc_Wh_per_km'), '.0f')} | {angle} | {s.get('slipped_turns', '-')} |")
    L.append("")
    sens = rows.get("accel-sensored")
    if sens and sens["energy"]:
        e = sens["energy"]
        lo = e.get("losses_Wh") or {}
        L.append(
            f"Where the sensored run's energy went (Wh, metrics.json's `energy`): DC link {e['drawn_Wh']:.1f} drawn, "
            f"{e['regen_Wh']:.1f} regenerated; copper {lo.get('copper', 0):.2f}, inverter {lo.get('inverter', 0):.2f}, "
            f"friction {lo.get('friction', 0):.2f}, gear {lo.get('gear', 0):.2f}; aerodynamic drag "
            f"{e['road_Wh']['aero']:.1f}, rolling {e['road_Wh']['rolling']:.1f}; friction brake {e['brake_Wh']:.2f}; "
            f"the balance's residual {e['residual_Wh']:.2e} Wh (each term integrated on its own).\n")
    sl = rows.get("accel-sensorless")
    if sl:
        s = sl["synchronism"]
        L.append(
            f"The sensorless unit from standstill: {s.get('slipped_turns', '-')} electrical turns slipped, "
            f"{s.get('episodes', '-')} loss-of-synchronism episodes, roll-back {_num(s.get('roll_back_m'), '.3f')} m; "
            f"top speed {_num(sl['acceleration'].get('top_speed_kmh'), '.1f')} km/h "
            f"({_num(sl['top_speed_w'], '.0f')} rad/s, {_num(sl['top_speed_w'] * lim.N / (2 * math.pi), '.0f')} Hz "
            f"electrical).\n")
    L += figure_links(("accel_speed", "accel_envelope", "accel_angle"), fig_names)
    return L
