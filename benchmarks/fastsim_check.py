"""FASTSim as an independent check of the energy figures (issue 39): the same vehicle (Table II,
``pmsm_ev.params.VehicleParams``) through UDDS, HWFET and WLTC 3b in FASTSim 3.1 (NREL) and in this
project, compared at the wheels and at the DC link. docs/speed-range.md, "FASTSim as an independent check".

    pip install -e .[fastsim]          # FASTSim is optional: the project does not need it
    python benchmarks/fastsim_check.py [--cycles udds hwfet wltc3b] [--runs DIR] [--reuse]

The project's side is ``pmsm-cosim run CYCLE --set plant.v_a=0 --no-figures`` (the shipped sensored scenario
with the sourced losses, head wind off: FASTSim has none), in a subprocess, one cycle after the other; its
metrics.json gives the DC link's energy and the losses by term, its results.csv the wheel work
(``pmsm_cosim.app.metrics.cycle_energy.wheel_check``). FASTSim's side is built from ``VehicleParams``
(``fastsim_vehicle``) and the project's own cycle tables (the same 1 Hz samples), twice per cycle:

* generic: the wheel side (the chassis alone decides it: positive wheel energy, FASTSim's ``pwr_tractive``), and
  at the DC link FASTSim's own motor + power-electronics efficiency map (the 2022 Renault Zoe ZE50's, a 1-D curve
  against the fraction of the rated power) on an ideal battery;
* matched: that curve replaced by the project's own motor + inverter efficiency of the run, binned on the
  same axis (``efficiency_curve``), on an ideal battery (efficiency 1, no auxiliary load).

FASTSim's drag uses an effective air density of ``RHO_FASTSIM`` whatever its air density reads (measured:
its drag energy against the project's on the same trace); this script keeps Table II's rho_a and gives
FASTSim c_d rho_a / RHO_FASTSIM, so that rho c_d is Table II's on both sides; likewise its rolling resistance
uses g = ``G_FASTSIM`` and gets c_r g / G_FASTSIM. Both sides' gross flows (the positive wheel energy, the energy
regenerated) depend on the interval they are summed over: FASTSim's is 1 s, the project's rows 0.05 s; the
project's are also given summed over 1 s (``project_figures``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pmsm_cosim.app.metrics.cycle_energy import plant_params, wheel_check
from pmsm_ev import cycles
from pmsm_ev.params import VehicleParams

#: FASTSim 3.1's effective air density in its drag [kg/m^3], whatever its state's air density reads (1.2, with
#: SimParams' f2_const_air_density on, its default); measured: its drag energy against the project's
RHO_FASTSIM = 1.172848
#: FASTSim 3.1's gravity in its rolling resistance [m/s^2] (measured the same way: its rolling energy over
#: c_r m distance)
G_FASTSIM = 9.8
#: the FASTSim vehicle file the powertrain's layout is taken from (a BEV; every Table II field is overwritten)
BASE_VEHICLE = "2022_Renault_Zoe_ZE50_R135.yaml"
#: the motor's rated power given to FASTSim [W]: the axis of its efficiency curve and its traction limit
#: (the project's drive peaks at about 55 kW; FASTSim must not miss the trace on its limit)
P_EM_MAX = 80_000.0
#: the fractions of P_EM_MAX at which the matched efficiency curve is given
GRID = np.round(np.concatenate([np.arange(0, 20) * 0.01, 0.2 + np.arange(0, 17) * 0.05]), 6)
#: the least efficiency the matched curve takes (FASTSim needs a positive one)
EFF_MIN = 0.05
CYCLES = ("udds", "hwfet", "wltc3b")
_WH = 1.0 / 3600.0
#: the project's motor + inverter loss terms (the gear's is FASTSim's transmission)
MI_LOSSES = ("copper", "inverter", "iron", "friction")


def fastsim_chassis(vehicle: VehicleParams, rho_fastsim: float = RHO_FASTSIM, g_fastsim: float = G_FASTSIM) -> dict:
    """FASTSim's chassis and vehicle fields for ``vehicle`` (Table II), as a dict of field: value. The drag
    coefficient carries the air density, c_d rho_a / rho_fastsim, and the rolling-resistance coefficient the
    gravity, c_r g / g_fastsim, so that FASTSim's forces are Table II's. No wheel inertia (the project's rotating mass
    is the motor's J_m, at the shaft), no auxiliary load, the mass is m_v."""
    return {"drag_coef": vehicle.c_d * vehicle.rho_a / rho_fastsim,
            "frontal_area_square_meters": vehicle.A_f,
            "wheel_rr_coef": vehicle.c_r * vehicle.g / g_fastsim,
            "wheel_inertia_kilogram_square_meters": 0.0,
            "wheel_radius_meters": vehicle.r_w,
            "mass_kilograms": vehicle.m_v,
            "transmission_eff": vehicle.eta,
            "pwr_aux_base_watts": 0.0}


def efficiency_curve(time, e_dc, e_losses, p_max: float = P_EM_MAX, grid=GRID) -> tuple[np.ndarray, np.ndarray]:
    """The project's motor + inverter efficiency against the shaft power's fraction of ``p_max``, as FASTSim's
    two-sided curve: (fractions, efficiencies) on -grid[::-1] and grid (regeneration below 0, motoring above).
    From the recorded cumulative DC energy ``e_dc`` [J] and the sum of the motor + inverter losses ``e_losses``
    [J] at ``time`` [s]: over each row interval the shaft power P_sh = (dE_dc - dE_loss) / dt, put in the bin of
    the nearest grid point on its side; per bin, energy-weighted, motoring shaft / (shaft + loss) (= shaft /
    DC), regenerating (|shaft| - loss) / |shaft| (= DC / shaft), at least ``EFF_MIN`` (where the losses eat
    all the braking power the project still draws from the link; FASTSim cannot). At 0 the motoring side's
    first bin. Bins no interval falls in take the nearest filled bin's value on their side. Where the
    efficiency rises faster than the power near 0, the inner point is raised just enough for |fraction| /
    efficiency to grow outward (FASTSim refuses the curve otherwise)."""
    dt = np.diff(np.asarray(time, float))
    ok = dt > 0
    d_dc, d_loss = np.diff(np.asarray(e_dc, float))[ok], np.maximum(np.diff(np.asarray(e_losses, float))[ok], 0.0)
    d_sh = d_dc - d_loss
    frac = np.abs(d_sh) / dt[ok] / p_max
    edges = np.concatenate([[-np.inf], 0.5 * (grid[1:] + grid[:-1]), [np.inf]])
    idx = np.digitize(frac, edges) - 1
    sides = []
    for mask, motoring in ((d_sh >= 0, True), (d_sh < 0, False)):
        sh = np.bincount(idx[mask], weights=np.abs(d_sh[mask]), minlength=len(grid))
        loss = np.bincount(idx[mask], weights=d_loss[mask], minlength=len(grid))
        filled = sh > 0
        if not filled.any():
            sides.append(np.full(len(grid), np.nan))
            continue
        safe = np.where(filled, sh, 1.0)
        eff = sh / (safe + loss) if motoring else 1.0 - loss / safe
        eff = np.where(filled, np.maximum(eff, EFF_MIN), np.nan)
        pts = np.flatnonzero(filled)
        for i in np.flatnonzero(~filled):
            eff[i] = eff[pts[np.argmin(np.abs(pts - i))]]
        sides.append(eff)
    mot, reg = sides
    if np.isnan(mot).all():
        raise ValueError("no motoring in the run: no efficiency curve")
    if np.isnan(reg).all():
        reg = mot
    for eff in (mot, reg):  # FASTSim inverts the curve on the input power, |fraction| / efficiency: it must grow
        for i in range(len(grid) - 2, 0, -1):
            eff[i] = max(eff[i], eff[i + 1] * grid[i] / grid[i + 1] * (1.0 + 1e-6))
    return (np.concatenate([-grid[::-1], grid[1:]]), np.concatenate([reg[::-1][:-1], [mot[0]], mot[1:]]))


def fastsim_vehicle(fsim, vehicle: VehicleParams, eff: tuple[np.ndarray, np.ndarray] | None):
    """A FASTSim Vehicle of ``vehicle`` on BASE_VEHICLE's powertrain: an ideal battery (efficiency 1, no
    auxiliary load), a transmission of efficiency eta, a motor of P_EM_MAX with FASTSim's own curve
    (``eff`` None) or ``eff``, (fractions, efficiencies) from ``efficiency_curve``."""
    d = fsim.Vehicle.from_resource(BASE_VEHICLE).to_dict()
    f = fastsim_chassis(vehicle)
    ch = d["chassis"]
    for k in ("drag_coef", "frontal_area_square_meters", "wheel_rr_coef", "wheel_inertia_kilogram_square_meters",
              "wheel_radius_meters"):
        ch[k] = f[k]
    ch["glider_mass_kilograms"] = ch["cargo_mass_kilograms"] = ch["mass_kilograms"] = None
    d["mass_kilograms"] = f["mass_kilograms"]
    d["pwr_aux_base_watts"] = f["pwr_aux_base_watts"]
    bev = d["pt_type"]["BEV"]
    bev["res"]["eff_interp"] = {"Constant": 1.0}
    bev["transmission"]["eff_interp"] = f["transmission_eff"]
    em = bev["em"]
    em["pwr_out_max_watts"] = P_EM_MAX
    if eff is not None:
        em["eff_interp_achieved"]["data"] = {"grid": [[float(x) for x in eff[0]]], "values": [float(x) for x in eff[1]]}
        em.pop("eff_interp_at_max_input", None)
    return fsim.Vehicle.from_dict(d)


@dataclass
class FastsimRun:
    wheel_pos_Wh: float
    dc_Wh: float
    regen_Wh: float
    aero_Wh: float
    rolling_Wh: float
    brake_Wh: float
    gear_Wh: float
    em_loss_Wh: float
    distance_km: float
    trace_met: bool

    @property
    def dc_Wh_per_km(self) -> float:
        return self.dc_Wh / self.distance_km


def run_fastsim(fsim, cycle, veh) -> FastsimRun:
    """One FASTSim drive of ``cycle`` (a pmsm_ev Cycle: its samples as they are) with ``veh``."""
    n = len(cycle.time)
    grade = cycle.grade if cycle.grade is not None else np.zeros(n)
    cyc = fsim.Cycle.from_dict({"time_seconds": [float(x) for x in cycle.time],
                                "speed_meters_per_second": [float(x) for x in cycle.speed],
                                "grade": [float(x) for x in grade]})
    sd = fsim.SimDrive(veh, cyc)
    sd.run()
    out = sd.to_dict()
    v = out["veh"]
    hist, state = v["history"], v["state"]
    bev = v["pt_type"]["BEV"]
    em_hist = bev["em"]["history"]
    dt = np.diff(np.asarray(hist["time_seconds"], float))
    p_wheel = np.asarray(hist["pwr_tractive_watts"], float)[1:]
    p_el = np.asarray(em_hist["pwr_elec_prop_in_watts"], float)[1:]
    return FastsimRun(wheel_pos_Wh=float(np.sum(np.maximum(p_wheel, 0.0) * dt)) * _WH,
                      dc_Wh=float(np.sum(p_el * dt)) * _WH,
                      regen_Wh=float(-np.sum(np.minimum(p_el, 0.0) * dt)) * _WH,
                      aero_Wh=state["energy_drag_joules"] * _WH, rolling_Wh=state["energy_rr_joules"] * _WH,
                      brake_Wh=abs(state["energy_brake_joules"]) * _WH,
                      gear_Wh=bev["transmission"]["state"]["energy_loss_joules"] * _WH,
                      em_loss_Wh=bev["em"]["state"]["energy_loss_joules"] * _WH,
                      distance_km=float(hist["dist_meters"][-1]) / 1000.0,
                      trace_met=bool(state["cyc_met_overall"]))


def run_project(name: str, out: Path, reuse: bool) -> Path:
    """``pmsm-cosim run NAME --set plant.v_a=0`` into ``out`` (kept if ``reuse`` and it has metrics.json)."""
    if not (reuse and (out / "metrics.json").is_file()):
        cmd = [sys.executable, "-m", "pmsm_cosim.app.cli", "run", name, "--set", "plant.v_a=0", "--no-figures",
               "--quiet", "--out", str(out)]
        subprocess.run(cmd, check=True)
    return out


def project_figures(run_dir: Path) -> dict:
    """The project's energy block, its positive wheel energy and its motor + inverter efficiency curve."""
    from pmsm_cosim.engine.recording import read_results  # noqa: PLC0415 (the application's reader, here only)
    metrics = json.loads((run_dir / "metrics.json").read_text())
    _, vehicle = plant_params(metrics)
    cols = ["time", "delta_deg", "v_vehicle", "x_vehicle", "E_dc", "E_regen", "E_copper", "E_inverter", "E_iron",
            "E_friction", "E_gear", "E_aero", "E_rolling", "E_grade", "E_brake", "E_kinetic", "W_magnetic"]
    r = read_results(run_dir / "results.csv", columns=cols)
    wc = wheel_check(r, vehicle)
    t = np.asarray(r["time"], float)
    whole = np.abs(t - np.round(t)) < 1e-6  # the rows at whole seconds: FASTSim's intervals
    r1 = {k: np.asarray(v)[whole] for k, v in r.items()}
    d_dc1 = np.diff(np.asarray(r1["E_dc"], float))
    e_loss = sum(np.asarray(r["E_" + k], float) for k in MI_LOSSES)
    return {"energy": metrics["energy"], "wheel_pos_Wh": wc["wheel"]["traction_Wh"], "vehicle": vehicle,
            "wheel_pos_1s_Wh": wheel_check(r1, vehicle)["wheel"]["traction_Wh"],
            "regen_1s_Wh": float(-np.sum(np.minimum(d_dc1, 0.0))) * _WH,
            "eff": efficiency_curve(r["time"], r["E_dc"], e_loss)}


def pct(a: float, b: float) -> str:
    return f"{100.0 * (a - b) / b:+.2f} %"


def report(name: str, p: dict, fs_gen: FastsimRun, fs_mat: FastsimRun) -> str:
    """The table of one cycle: the wheel side from the generic-map drive (the same chassis in both), the DC link
    of both drives, the terms of the matched one."""
    fs_wheel = fs_gen
    e = p["energy"]
    km = e["distance_m"] / 1000.0
    lo = e["losses_Wh"]
    mi = sum(lo[k] for k in MI_LOSSES)
    rows = [f"== {name}: {km:.2f} km (FASTSim {fs_wheel.distance_km:.2f} km; trace met: "
            f"{fs_gen.trace_met and fs_mat.trace_met})",
            f"{'':34}{'project':>11}{'FASTSim':>11}{'difference':>12}",
            f"{'positive wheel energy [Wh]':34}{p['wheel_pos_Wh']:11.1f}{fs_wheel.wheel_pos_Wh:11.1f}"
            f"{pct(fs_wheel.wheel_pos_Wh, p['wheel_pos_Wh']):>12}",
            f"{'  project summed over 1 s [Wh]':34}{p['wheel_pos_1s_Wh']:11.1f}{fs_wheel.wheel_pos_Wh:11.1f}"
            f"{pct(fs_wheel.wheel_pos_Wh, p['wheel_pos_1s_Wh']):>12}",
            f"{'  aero [Wh]':34}{e['road_Wh']['aero']:11.1f}{fs_wheel.aero_Wh:11.1f}"
            f"{pct(fs_wheel.aero_Wh, e['road_Wh']['aero']):>12}",
            f"{'  rolling [Wh]':34}{e['road_Wh']['rolling']:11.1f}{fs_wheel.rolling_Wh:11.1f}"
            f"{pct(fs_wheel.rolling_Wh, e['road_Wh']['rolling']):>12}",
            f"{'DC link, generic map [Wh/km]':34}{e['dc_Wh_per_km']:11.1f}{fs_gen.dc_Wh_per_km:11.1f}"
            f"{pct(fs_gen.dc_Wh_per_km, e['dc_Wh_per_km']):>12}",
            f"{'DC link, matched map [Wh/km]':34}{e['dc_Wh_per_km']:11.1f}{fs_mat.dc_Wh_per_km:11.1f}"
            f"{pct(fs_mat.dc_Wh_per_km, e['dc_Wh_per_km']):>12}",
            f"{'  DC link, net [Wh]':34}{e['dc_Wh']:11.1f}{fs_mat.dc_Wh:11.1f}{fs_mat.dc_Wh - e['dc_Wh']:+12.1f}",
            f"{'  regenerated [Wh]':34}{e['regen_Wh']:11.1f}{fs_mat.regen_Wh:11.1f}"
            f"{fs_mat.regen_Wh - e['regen_Wh']:+12.1f}",
            f"{'  regenerated, over 1 s [Wh]':34}{p['regen_1s_Wh']:11.1f}{fs_mat.regen_Wh:11.1f}"
            f"{fs_mat.regen_Wh - p['regen_1s_Wh']:+12.1f}",
            f"{'  motor + inverter losses [Wh]':34}{mi:11.1f}{fs_mat.em_loss_Wh:11.1f}{fs_mat.em_loss_Wh - mi:+12.1f}",
            f"{'  gear / transmission [Wh]':34}{lo['gear']:11.1f}{fs_mat.gear_Wh:11.1f}"
            f"{fs_mat.gear_Wh - lo['gear']:+12.1f}",
            f"{'  friction brake [Wh]':34}{e['brake_Wh']:11.1f}{fs_mat.brake_Wh:11.1f}"
            f"{fs_mat.brake_Wh - e['brake_Wh']:+12.1f}",
            "project's losses [Wh]: " + ", ".join(f"{k} {lo[k]:.1f}" for k in (*MI_LOSSES, "gear"))
            + f"; FASTSim generic map: motor {fs_gen.em_loss_Wh:.1f}"]
    return "\n".join(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cycles", nargs="+", default=list(CYCLES), choices=CYCLES)
    ap.add_argument("--runs", type=Path, default=None, help="where the project's runs go (default: a temporary dir)")
    ap.add_argument("--reuse", action="store_true", help="reuse the project's runs found in --runs")
    args = ap.parse_args(argv)
    try:
        import fastsim as fsim  # noqa: PLC0415 (optional: pip install -e .[fastsim])
    except ImportError:
        print("fastsim_check: FASTSim is not installed (pip install -e .[fastsim], or pip install fastsim==3.1.0)",
              file=sys.stderr)
        return 2
    print(f"FASTSim {fsim.__version__}; base vehicle {BASE_VEHICLE}, rho {RHO_FASTSIM} kg/m^3 in its drag; "
          f"motor {P_EM_MAX / 1000:.0f} kW; ideal battery, no auxiliary load")
    with tempfile.TemporaryDirectory() as tmp:
        root = args.runs or Path(tmp)
        for name in args.cycles:
            p = project_figures(run_project(name, root / name, args.reuse))
            cyc = cycles.load(name)
            fs_gen = run_fastsim(fsim, cyc, fastsim_vehicle(fsim, p["vehicle"], None))
            fs_mat = run_fastsim(fsim, cyc, fastsim_vehicle(fsim, p["vehicle"], p["eff"]))
            print(report(name, p, fs_gen, fs_mat), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
