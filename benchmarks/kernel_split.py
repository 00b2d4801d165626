"""Where a step of the sensorless cycle drive goes: the control unit's and the plant's step, each called
from Python as the FMUs call them, without the FMI plumbing and the master (which ``pmsm-cosim bench``'s
(f) measures).

    python benchmarks/kernel_split.py [--steps 100000]

The drive is the shipped ``wltc3b-if``'s: the start values of its components ``ctrl`` and
``plant`` are read from the system file and given to ``ControlUnit`` (sensorless) and ``Plant`` by the
names of their parameter dataclasses' fields, as the FMUs take them. It prints, in us per call:

* the two together on a closed loop: the unit from standstill (alignment, I-f, the EKF) following a
  speed reference of 0 for 3 s, then a ramp to 100 rad/s over 10 s, the plant driven by its voltage;
* each alone at the end state of that loop: ``ControlUnit.kernel_step`` at 100 rad/s, and
  ``Plant.step`` held at a speed of 0 ... 1500 rad/s (the RK4 sub-steps the plant takes grow with the
  speed, ``pmsm_ev.kernels.plant_step``: one up to 250 rad/s with the scenario's 0.1 rad a sub-step, six at
  1500 rad/s, seven at the top speed's 1554 rad/s).

Each figure is the fastest of ``--repeat`` runs (the others meet the machine's other work).
"""

from __future__ import annotations

import argparse
import dataclasses
import time

from pmsm_cosim.app.overrides import apply_overrides
from pmsm_ev import accel
from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.params import SENSORLESS_EKF, ControllerParams, MotorParams, PlantParams, StartupParams, VehicleParams
from pmsm_ev.plant import Plant

SYSTEM = "wltc3b-if"
DT = 1e-4  #: [s] the scenario's step and the unit's sample period
PLANT_SPEEDS = (0.0, 100.0, 300.0, 600.0, 1000.0, 1500.0)  #: [rad/s] the plant's speed held


def _with(group, start: dict):
    """``group`` (a parameter dataclass instance) with the start values that name its fields."""
    names = {f.name for f in dataclasses.fields(group)}
    return dataclasses.replace(group, **{k: v for k, v in start.items() if k in names})


def drive_params() -> dict:
    """The parameter groups of the scenario's controller and plant."""
    start = {c.name: dict(c.start) for c in apply_overrides(SYSTEM).components}
    ctrl, plant = start["ctrl"], start["plant"]
    return {"ctrl_motor": _with(MotorParams(), ctrl), "controller": _with(ControllerParams(), ctrl),
            "ekf": _with(SENSORLESS_EKF, ctrl), "startup": _with(StartupParams(), ctrl),
            "plant_motor": _with(MotorParams(), plant), "vehicle": _with(VehicleParams(), plant),
            "plant": _with(PlantParams(), plant)}


def make(p: dict, omega_m0: float = 0.0) -> tuple[ControlUnit, Plant]:
    unit = ControlUnit("sensorless", "estimated", p["ctrl_motor"], p["controller"], p["ekf"], DT, p["startup"])
    plant = Plant(p["plant_motor"], p["vehicle"], dataclasses.replace(p["plant"], omega_m0=omega_m0))
    return unit, plant


def closed_loop(p: dict, steps: int) -> tuple[float, float, ControlUnit, Plant]:
    """(unit us, plant us) per call over ``steps`` of the closed loop, and the unit and plant at its end."""
    unit, plant = make(p)
    step_unit = unit.kernel_step
    clock = time.perf_counter
    t_unit = t_plant = 0.0
    for k in range(steps):
        t = k * DT
        omega_ref = 0.0 if t < 3.0 else 100.0 * min((t - 3.0) / 10.0, 1.0)
        a = clock()
        out = step_unit(plant.i_alpha, plant.i_beta, omega_ref)
        b = clock()
        plant.step(out[0], out[1], 0.0, DT, unit.T_brake)
        t_unit += b - a
        t_plant += clock() - b
    return t_unit / steps * 1e6, t_plant / steps * 1e6, unit, plant


def unit_alone(unit: ControlUnit, plant: Plant, steps: int) -> float:
    step_unit, i_alpha, i_beta = unit.kernel_step, plant.i_alpha, plant.i_beta
    start = time.perf_counter()
    for _ in range(steps):
        step_unit(i_alpha, i_beta, 100.0)
    return (time.perf_counter() - start) / steps * 1e6


def plant_alone(p: dict, omega_m: float, steps: int) -> float:
    """``Plant.step`` with no voltage, the speed put back to ``omega_m`` before each step."""
    _, plant = make(p, omega_m)
    start = time.perf_counter()
    for _ in range(steps):
        plant.omega_m = omega_m
        plant.step(0.0, 0.0, 0.0, DT, 0.0)
    return (time.perf_counter() - start) / steps * 1e6


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=100_000, help="calls per figure (default 100000; the closed "
                                                               "loop runs 3 x as many, 30 s of drive)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per figure, the fastest kept (default 3)")
    a = ap.parse_args(argv)
    if a.steps < 1000 or a.repeat < 1:
        ap.error("--steps must be >= 1000 and --repeat >= 1")
    p = drive_params()
    print(f"kernel split: {SYSTEM}'s controller and plant, physics kernels: {accel.describe()}")
    best = None
    for _ in range(a.repeat):
        u, pl, unit, plant = closed_loop(p, 3 * a.steps)
        best = (u, pl) if best is None or u + pl < sum(best) else best
    mode = ("alignment", "I-f", "EKF")[int(unit.mode)]
    print(f"closed loop, {3 * a.steps * DT:g} s from standstill to 100 rad/s: ControlUnit.kernel_step "
          f"{best[0]:.2f} us, Plant.step {best[1]:.2f} us (at the end: {mode}, omega_m {plant.omega_m:.1f} rad/s)")
    alone = min(unit_alone(unit, plant, a.steps) for _ in range(a.repeat))
    print(f"ControlUnit.kernel_step alone at that state: {alone:.2f} us")
    for w in PLANT_SPEEDS:
        cost = min(plant_alone(p, w, a.steps) for _ in range(a.repeat))
        print(f"Plant.step alone at {w:6.0f} rad/s: {cost:.2f} us")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
