"""Monolithic reference run: plant and control unit in one loop, no FMUs.

The discrete ordering is the co-simulation's (Gauss-Seidel): at t_k the row is recorded,
the control unit reads the plant's outputs at t_k and computes its voltage and its friction
brake's demand (``T_brake``, connected as the shipped systems connect it), then the plant
advances to t_k + dt with them. Usage::

    python -m pmsm_cosim.app.reference --scenario 1 --out runs/ref1
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

from ..engine.recording import ResultWriter, read_results, write_metrics
from .metrics.run import compute_metrics


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
    a = ap.parse_args(argv)
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


if __name__ == "__main__":
    sys.exit(main())
