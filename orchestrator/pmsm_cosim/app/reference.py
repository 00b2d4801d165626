"""Monolithic reference run: plant and control unit in one loop, no FMUs; and the converged reference.

The discrete ordering is the co-simulation's (Gauss-Seidel): at t_k the row is recorded,
the control unit reads the plant's outputs at t_k and computes its voltage and its friction
brake's demand (``T_brake``, connected as the shipped systems connect it), then the plant
advances to t_k + dt with them. Usage::

    python -m pmsm_cosim.app.reference --scenario 1 --out runs/ref1

The converged reference (``run_converged``, ``--converged SYSTEM``) is any shipped scenario or system file, or a
slice of it (``stop_time``), with the plant's equations integrated to convergence: the same models, the same
voltage held over each communication step in the stationary frame as the co-simulation holds it, the same
controller, integrated by the rotor-frame RK4 with ``CONVERGED_SUBSTEPS`` sub-steps a step or more, each turning
at most ``CONVERGED_SUBSTEP_ANGLE`` (``converged_settings``). ``converged_errors`` measures a run against it: the
vehicle's speed, the rotor's electrical angle, the DC energy per km and the energy balance's residual
(docs/performance.md, "The plant's integrator")::

    python -m pmsm_cosim.app.reference --converged us06-sensorless --stop-time 60 --out runs/us06-converged
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.params import ANGLE_SOURCES, OBSERVERS, SENSORLESS_EKF, DriveParams, ParameterError
from pmsm_ev.plant import Plant
from pmsm_ev.results import ALL_COLUMNS, SENSORLESS_COLUMNS
from pmsm_ev.scenarios import SCENARIO_STOP_TIME, Profile, elevation_profile, speed_reference

from ..engine.errors import CosimError
from ..engine.recording import ResultWriter, read_results, write_metrics
from .api import simulate
from .metrics.cycle_energy import balance_check
from .metrics.energy import energy_metrics
from .metrics.run import compute_metrics

#: the converged reference's sub-steps per communication step at least [-]: RK4's error falls as the sub-step's
#: fourth power, so 16 sub-steps put it 16^4 = 65536 times below the one-sub-step step's at standstill
CONVERGED_SUBSTEPS = 16
#: the largest electrical angle of one of the converged reference's sub-steps [rad]: 0.01 rad is 10 times below the
#: rotor-frame default (``PlantParams.substep_angle``), 1e5 times its RK4 error on the rotation; at top speed the
#: plant's cap ``pmsm_ev.kernels.MAX_SUBSTEPS`` (64 sub-steps, 0.0097 rad each at 131 km/h and 1e-4 s) binds first
CONVERGED_SUBSTEP_ANGLE = 0.01
#: km/h per m/s
KMH_PER_MS = 3.6


def converged_settings() -> dict[str, object]:
    """The plant's start values of the converged reference (``--set`` of a run): its rotor-frame RK4 with
    ``CONVERGED_SUBSTEPS`` sub-steps a step at least, each turning at most ``CONVERGED_SUBSTEP_ANGLE``."""
    return {"plant.integrator": "rk4_rotor", "plant.rk4_substeps": CONVERGED_SUBSTEPS,
            "plant.substep_angle": CONVERGED_SUBSTEP_ANGLE}


def run_system(system, out_dir, *, stop_time: float | None = None, set: dict | None = None,
               converged: bool = False) -> dict:
    """Run the shipped scenario or system file ``system`` (the first ``stop_time`` s of it if given, ``set`` its
    start values as ``--set``) as ``pmsm-cosim run`` does without figures (``pmsm_cosim.app.api.simulate``), into
    ``out_dir``; with ``converged`` the converged reference of it (``converged_settings`` over ``set``). Returns its
    metrics."""
    values = dict(set or {})
    if converged:
        values.update(converged_settings())
    _, m = simulate(system, stop_time=stop_time, set=values or None, output_dir=out_dir)
    if m["status"] != "completed":
        raise CosimError(f"{system}: the run did not complete: {m['status']}")
    return m


def run_converged(system, out_dir, *, stop_time: float | None = None, set: dict | None = None) -> dict:
    """The converged reference of ``system`` (``run_system`` with ``converged``)."""
    return run_system(system, out_dir, stop_time=stop_time, set=set, converged=True)


def _wrap(x):
    """Angles wrapped to [-pi, pi) (an array)."""
    return (x + math.pi) % (2.0 * math.pi) - math.pi


def converged_errors(run_dir, reference_dir) -> dict:
    """The errors of the run in ``run_dir`` against the converged reference in ``reference_dir`` (the same system
    and rows): the largest difference of the vehicle's speed [km/h] and of the rotor's electrical angle [rad] over
    the rows, the relative difference of the DC energy per km [-], and the run's energy balance residual relative to
    its DC throughput (``balance_check``) beside the reference's."""
    r, c = read_results(Path(run_dir)), read_results(Path(reference_dir))
    if len(r["time"]) != len(c["time"]) or abs(float(r["time"][-1]) - float(c["time"][-1])) > 1e-9:
        raise CosimError(f"{run_dir} and {reference_dir} do not hold the same rows")
    e_r, e_c = energy_metrics(r), energy_metrics(c)
    out = {"speed_kmh": float(abs(r["v_vehicle"] - c["v_vehicle"]).max()) * KMH_PER_MS,
           "angle_rad": float(abs(_wrap(r["theta_e"] - c["theta_e"])).max())}
    if "dc_Wh_per_km" in e_r and e_c.get("dc_Wh_per_km"):
        out["dc_Wh_per_km"] = e_r["dc_Wh_per_km"]
        out["dc_per_km_rel"] = e_r["dc_Wh_per_km"] / e_c["dc_Wh_per_km"] - 1.0
        out["balance_rel"] = balance_check(r)["relative"]
        out["balance_rel_reference"] = balance_check(c)["relative"]
    return out


def grid(stop_time: float, dt: float, output_interval: float) -> tuple[int, int]:
    """(number of steps, steps per recorded row); both must be whole numbers."""
    if not (dt > 0 and math.isfinite(dt)):
        raise ParameterError(f"step must be > 0 s (got {dt})")
    if not (stop_time > 0 and math.isfinite(stop_time)):
        raise ParameterError(f"stop time must be > 0 s (got {stop_time})")
    n = round(stop_time / dt)
    if abs(n * dt - stop_time) > 1e-9 * max(1.0, stop_time):
        raise ParameterError(f"stop time {stop_time} s is not a whole number of {dt} s steps")
    every = round(output_interval / dt)
    if every < 1 or abs(every * dt - output_interval) > 1e-9 * max(1.0, output_interval):
        raise ParameterError(f"output interval {output_interval} s is not a multiple of the {dt} s step")
    return n, every


def run_reference(out_dir, scenario: int | str = 1, stop_time: float = SCENARIO_STOP_TIME,
                  observer: str = "ekf5", angle_source: str = "measured",
                  params: DriveParams | None = None, output_interval: float = 0.01,
                  elevation: Profile | None = None, omega_ref: Profile | None = None,
                  startup_columns: bool | None = None) -> dict:
    """Run, write results.csv and metrics.json into ``out_dir``, return the metrics.

    ``elevation`` [rad] and ``omega_ref`` [rad/s] replace the scenario's profiles. Without
    ``params``, the sensorless unit's EKF is ``SENSORLESS_EKF`` (its model on J_eq).
    ``startup_columns`` records ``SENSORLESS_COLUMNS`` too (default: for the sensorless unit)."""
    sensorless = observer == "sensorless"
    p = (params or (DriveParams(ekf=SENSORLESS_EKF) if sensorless else DriveParams())).validate()
    dt = p.dt
    n_steps, every = grid(stop_time, dt, output_interval)
    delta_of = elevation or elevation_profile(scenario)
    omega_ref_of = omega_ref or speed_reference(p.scenario)
    plant = Plant(p.motor, p.vehicle, p.plant)
    ctrl = ControlUnit(observer, angle_source, p.motor, p.controller, p.ekf, dt, p.startup, p.injection)
    startup_columns = sensorless if startup_columns is None else startup_columns
    columns = ALL_COLUMNS + SENSORLESS_COLUMNS if startup_columns else ALL_COLUMNS
    theta_meas = plant.theta_e  # the angle the unit was last given (the row's theta_ctrl when it uses it)
    out = Path(out_dir)
    status = "completed"
    t0, cpu0 = time.perf_counter(), time.process_time()
    k = 0
    with ResultWriter(out, columns) as w:
        try:
            for k in range(n_steps + 1):
                t = k * dt
                delta = delta_of(t)
                w_ref = omega_ref_of(t)
                if k % every == 0 or k == n_steps:
                    o = ctrl.observer
                    row = (t, math.degrees(delta), w_ref, plant.omega_m, o.omega_hat, plant.theta_e,
                           o.theta_hat, plant.i_d, plant.i_q, o.i_d_hat, o.i_q_hat, plant.T_e,
                           plant.T_L_mech, o.T_L_hat, ctrl.v_d, ctrl.v_q, plant.i_alpha, plant.i_beta,
                           *ctrl.v_out, ctrl.i_qref, plant.v_vehicle)
                    if startup_columns:
                        theta_ctrl = ctrl.theta_ctrl if ctrl.angle_source == "estimated" else theta_meas
                        row += (plant.x_vehicle, ctrl.mode, ctrl.fault, theta_ctrl, ctrl.omega_ctrl)
                    w.write(row)
                if k == n_steps:
                    break
                theta_meas = plant.theta_e
                v_alpha, v_beta = ctrl.step(plant.i_alpha, plant.i_beta, w_ref, theta_meas, plant.omega_m)[:2]
                plant.step(v_alpha, v_beta, delta, dt, ctrl.T_brake)  # ctrl.T_brake -> plant.T_brake, as connected
                if not math.isfinite(plant.omega_m + plant.i_d + plant.i_q):
                    raise FloatingPointError(f"plant state is not finite at t = {(k + 1) * dt:.6g} s")
        except KeyboardInterrupt:
            status = "interrupted"
        except FloatingPointError as exc:
            status = f"failed: {exc}"
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    metrics = compute_metrics(read_results(out))
    metrics.update({"status": status, "wall_time_s": wall, "macro_steps": k,
                    "us_per_step": 1e6 * wall / max(k, 1), "cpu_time_s": cpu, "observer": observer,
                    "angle_source": ctrl.angle_source, "step_size": dt, "stop_time": stop_time})
    write_metrics(out, metrics)
    return metrics


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pmsm_cosim.app.reference", description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", choices=("1", "2"), default="1")
    ap.add_argument("--stop-time", type=float, default=SCENARIO_STOP_TIME, help="[s], default 350")
    ap.add_argument("--observer", choices=OBSERVERS, default="ekf5")
    ap.add_argument("--angle-source", choices=ANGLE_SOURCES, default="measured")
    ap.add_argument("--step", type=float, default=DriveParams().dt, help="control period [s]")
    ap.add_argument("--output-interval", type=float, default=0.01, help="[s]")
    ap.add_argument("--out", required=True, help="output directory")
    ap.add_argument("--converged", metavar="SYSTEM", help="run the converged reference of a shipped scenario or "
                    "system file instead (the first --stop-time s if given; --scenario, --observer, "
                    "--angle-source, --step, --output-interval do not apply)")
    ap.add_argument("--against", metavar="RUN_DIR", help="with --converged: print the errors of the run in "
                    "RUN_DIR (the same system and stop time) against it")
    a = ap.parse_args(argv)
    if a.converged:
        return _main_converged(a, argv)
    try:
        params = DriveParams(dt=a.step, ekf=SENSORLESS_EKF) if a.observer == "sensorless" else DriveParams(dt=a.step)
        m = run_reference(a.out, a.scenario, a.stop_time, a.observer, a.angle_source, params, a.output_interval)
    except (ParameterError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{m['status']}: {m['macro_steps']} steps in {m['wall_time_s']:.1f} s "
          f"({m['us_per_step']:.1f} us/step); speed RMS error {m['speed_rms_error']:.3f} rad/s; "
          f"results in {a.out}")
    return 0 if m["status"] == "completed" else 1


def _main_converged(a, argv) -> int:
    """``--converged SYSTEM``: run its converged reference into ``--out``, and with ``--against`` the errors."""
    stop_time = a.stop_time if "--stop-time" in (argv if argv is not None else sys.argv[1:]) else None
    try:
        m = run_converged(a.converged, a.out, stop_time=stop_time)
    except (ParameterError, ValueError, CosimError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"converged reference of {a.converged}: {m['macro_steps']} steps in {m['wall_time_s']:.1f} s; "
          f"results in {a.out}")
    if a.against:
        e = converged_errors(a.against, a.out)
        print("errors of " + a.against + ": " + ", ".join(f"{k} {v:.3g}" for k, v in e.items() if v is not None))
    return 0


if __name__ == "__main__":
    sys.exit(main())
