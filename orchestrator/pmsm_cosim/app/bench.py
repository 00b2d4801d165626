"""Step-cost benchmark of the co-simulation: ``pmsm-cosim bench`` (``benchmarks/step_cost.py``).

On the same slice of scenario 1 (t = 0 .. ``slice`` s at its 1e-4 s step) it measures the
wall time per macro step of

(a) the orchestrator's master with the project's FMUs (``PmsmEvPlant`` + ``FocEkf5``);
(b) the same master and system with pass-through FMUs of the same interface whose
    ``fmi2DoStep`` computes nothing (``PassThroughPlant`` + ``PassThroughFoc``): the floor
    of FMI calls, pythonfmu and the master;
(c) the monolithic reference run ``pmsm_cosim.app.reference`` (same physics, no FMUs);
(d) libcosim (``libcosimpy``, if installed) stepping the same FMUs with the same
    connections; the scenario signals are set through its override manipulator when their
    value changes, as the master does (its loop is a Python ``for`` over ``execution.step()``;
    nothing is recorded);

and, on the first ``cycle_slice`` s of WLTC 3b (``--cycle wltc3b``; by default 60 s: standing to
11 s, the alignment and the I-f start, then the drive away, 44.5 km/h at 35 s, 14.7 km/h at 60 s),

(e) the sensorless cycle drive: the master with ``PmsmEvPlant`` + ``FocSensorless`` as the shipped
    scenario ``wltc3b-if`` runs them (the reference generator in field weakening on
    360 V, the high-speed current control, Tustin's current model, the speed loop's feedforward,
    the regenerative limit and the friction brake, the plant's inverter losses, power-flow gear
    and 1 A of current noise; a row every 50 ms), the cycle's omega_ref a linear table that
    changes every step;
(f) the same system, signals and cycle with the pass-through FMUs: the FMI floor of (e);
(g) the cycle drive with injection at and near zero speed: the shipped scenario ``wltc3b-sensorless`` (as
    (e), the unit with ``low_speed = "injection"``, the plant's algebraic flux model);
(h) the whole compiled loop (no FMI) of the system of (e): its plant and controller in one numba-compiled loop
    of the FMUs' own compiled steps (``pmsm_ev.kernels.whole_loop``, ``pmsm_cosim.app.whole_loop``), the
    signals and rows as the master's, its results.csv the same as (e)'s, byte for byte: the limit that the
    co-simulation is measured against (its time includes making the rows; not the set-up);
(i) the same for the system of (a);
(j) a plain fmpy master stepping the FMUs of (a): fmpy's ``FMU2Slave`` and its own methods (``getReal``,
    ``setReal``, ``doStep``), a Python loop in the order of the system file (Gauss-Seidel, as the master), the
    connections of each destination read from each source in one ``getReal`` and set in one ``setReal``, the
    signals set when their value changes; nothing recorded (``fmpy_loop``: what a user writes with fmpy alone);
(k) the master and system of (a) on the FMI 3.0 units of the same FMUs (``pmsm-cosim build --fmi 3``: the FMI 3.0
    layer in front of the same FMI 2.0 stack, fmus/README.md, "FMI 3.0"), the controller's sample clock ticked in
    event mode at its interval (here every step: fmi3EnterEventMode, fmi3SetClock, fmi3UpdateDiscreteStates,
    fmi3EnterStepMode, then fmi3DoStep);
(l) the same without event mode (``--no-event-mode``: the controller samples in fmi3DoStep, as its FMI 2.0 unit);
    (k) and (l) are run once each after the other cases (their rows); then their ratios to (a): (a), (k) and (l)
    stepped in lock step, one thread each, ``FMI3_ROUNDS`` rounds (``--fmi3-rounds``): each one's turns of 10 rows
    (1000 steps) taken in turn, a's, k's, l's, a's, ... (``LockStep``: the next round l's, k's, a's, ...),
    each timed alone, wall and its thread's CPU time. The j-th turns of the three cover the same steps, a few
    milliseconds apart, so that a drift of the machine's speed (up to 3.5x over a day here; runs taken seconds apart
    saw k/a from 0.3 to 2.3) cancels in their ratio; a round's k/a and l/a are the median of those ratios over its
    turns (a turn that waited for the processor moves a few of them), the printed ones the median of the rounds',
    each round's printed beside;

(m) the cost a step at 0, 50, 100 and 131 km/h held (``SPEEDS_KMH``) for the shipped sensored drive (``wltc3b``:
    ``FocSensored``, the linear flux model) and the shipped sensorless drive (``wltc3b-sensorless``: injection at
    standstill, the algebraic flux model; at speed its stationary-frame EKF5, ``FocEkf5AB`` from a flying start,
    as the unit starts from standstill only): the master on ``speed_slice`` s of the system with its plant started
    at that speed and ``omega_ref`` held there (``held_speed_spec``), each case's errors against the converged
    reference of the same slice (``pmsm_cosim.app.reference.converged_errors``: the largest differences of the
    vehicle's speed and of the electrical angle over the rows) and the ratio of the cost at 131 km/h to the cost at
    standstill;

and prints one table with the ratios a/b, d/a, j/a, e/f, e/h, a/i, k/a and l/a (the FMI 3.0 units' cost a step
against the FMI 2.0 units': in lock step, above), in wall time (what a user waits) and in
CPU time of the process (less sensitive to other load on the machine; for libcosim it
includes its worker threads). (a)-(c) include the recording of a row every 10 ms, (e), (f) every
50 ms, as in a normal run of their scenario. With ``memory`` it also runs ``pmsm-cosim run scenario1``
(figures included) for 100 s and for the full 350 s, each in a fresh process, and prints
their wall time and peak resident memory (its own high-water mark, ``run_child``): memory must not grow
with the duration. With ``cycle_memory`` it runs the whole WLTC 3b with the shipped sensorless drive,
``pmsm-cosim run wltc3b-sensorless`` (injection; figures included), for half the
cycle (900 s) and the whole (1800 s, 18 million steps), likewise.

Timings on a shared machine vary with its load: the 1, 5 and 15 min load averages are
printed with the table.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from pmsm_ev import accel
from pmsm_ev import cycles as pcycles
from pmsm_ev.params import VehicleParams
from pmsm_ev_fmus.build import BENCH_FMUS, ENV_BINDING, BuildError, build_all, build_fmu, read_build_info

from ..engine.errors import CosimError
from ..engine.fmu import convert_start
from ..engine.master import Master
from ..engine.signals import Table
from ..engine.system import SignalSpec
from .drive import load_system, project_fmu_dir
from .overrides import apply_overrides
from .reference import KMH_PER_MS, converged_errors, converged_settings, run_reference
from .whole_loop import run_whole_loop

SCENARIO = "scenario1"
DEFAULT_SLICE = 20.0  #: [s] of simulated time per case
MEMORY_STOP_TIMES = (100.0, 350.0)
CYCLE_SYSTEM = "wltc3b-if"  #: cases (e), (f): the shipped sensorless cycle scenario
INJECTION_SYSTEM = "wltc3b-sensorless"  #: case (g): the same with injection
CYCLE = "wltc3b"
DEFAULT_CYCLE_SLICE = 60.0  #: [s] of the cycle in cases (e), (f)
CYCLE_MEMORY_STOP_TIMES = (900.0, 1800.0)  #: half the WLTC, the whole
#: the whole WLTC's wall time and memory: the shipped sensorless drive (injection), the scenario users run
CYCLE_MEMORY_SYSTEM = INJECTION_SYSTEM
#: case (m): the drives whose cost a step it measures at held speeds, sensored and sensorless, each with the controller
#: it runs at speed (None: the system's own): the sensorless unit starts from standstill only (its alignment and
#: polarity check), at speed it runs its stationary-frame EKF5, which FocEkf5AB runs from a flying start
SPEED_SYSTEMS = (("wltc3b", None), ("wltc3b-sensorless", "ekf5ab"))
SPEEDS_KMH = (0.0, 50.0, 100.0, 131.0)  #: case (m): the held speeds [km/h] (131: WLTC 3b's top speed, 131.3)
DEFAULT_SPEED_SLICE = 2.0  #: [s] of each held speed in case (m)
#: the master's stepping loop of each case run (metrics.json's "loop"; $PMSM_COSIM_LOOP chooses it)
LOOPS_SEEN: list[str] = []


def load_average() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def jit_mode() -> str:
    """How the physics kernels run in this process (``pmsm_ev.accel``)."""
    return accel.describe()


# -- the cases -----------------------------------------------------------------------------
def _spec(stop_time: float, plant: Path | None = None, ctrl: Path | None = None):
    spec = load_system(SCENARIO)
    spec.stop_time = stop_time
    if plant is not None:
        spec.set_fmu("plant", plant)
    if ctrl is not None:
        spec.set_fmu("ctrl", ctrl)
    return spec


def cycle_spec(stop_time: float, plant: Path | None = None, ctrl: Path | None = None, system: str = CYCLE_SYSTEM):
    """The system of (e) and (f): ``wltc3b-if --cycle wltc3b --stop-time stop_time`` (of (g):
    ``system`` = ``INJECTION_SYSTEM``)."""
    spec = apply_overrides(system, cycle=CYCLE, stop_time=stop_time)
    if plant is not None:
        spec.set_fmu("plant", plant)
    if ctrl is not None:
        spec.set_fmu("ctrl", ctrl)
    return spec


def median(values) -> float:
    ordered = sorted(values)
    mid = len(ordered) // 2
    return ordered[mid] if len(ordered) % 2 else 0.5 * (ordered[mid - 1] + ordered[mid])


def cosim_us_per_step(stop_time: float, work: Path, plant: Path | None = None,
                      ctrl: Path | None = None, spec=None, event_mode: bool = True,
                      clock=None) -> tuple[float, float]:
    """(a), (b), (k), (l) (``event_mode``: the master's, for FMI 3.0 units), or (e), (f) with the ``spec`` of
    ``cycle_spec``: the master's loop (wall, CPU) time per macro step [us]; ``clock``: its progress hook (a
    ``LockStep``'s)."""
    out = Path(tempfile.mkdtemp(prefix="cosim-", dir=work))
    master = Master(spec if spec is not None else _spec(stop_time, plant, ctrl), event_mode=event_mode)
    m = master.run(out, catch_sigint=False, progress=clock)
    if m["status"] != "completed":
        raise CosimError(f"benchmark run did not complete: {m['status']}")
    LOOPS_SEEN.append(m["loop"])
    return m["us_per_step"], 1e6 * master.loop_cpu_time / m["macro_steps"]


def reference_us_per_step(stop_time: float, work: Path) -> tuple[float, float]:
    """(c): the monolithic reference's loop (wall, CPU) time per step [us]."""
    out = Path(tempfile.mkdtemp(prefix="ref-", dir=work))
    m = run_reference(out, 1, stop_time=stop_time)
    if m["status"] != "completed":
        raise CosimError(f"reference run did not complete: {m['status']}")
    return m["us_per_step"], 1e6 * m["cpu_time_s"] / m["macro_steps"]


def held_speed_spec(system: str, kmh: float, stop_time: float, converged: bool = False, at_speed: str | None = None):
    """Case (m): ``system`` for ``stop_time`` s with the plant started at ``kmh`` [km/h] (``omega_m0``) and the speed
    reference held there (the cycle's ``omega_ref`` replaced by a constant); above 0 km/h with the controller
    ``at_speed`` if given, from a flying start (``x0_omega``); with ``converged`` its converged reference
    (``converged_settings``)."""
    table_ii = VehicleParams()
    spec = apply_overrides(system, stop_time=stop_time)
    plant = spec.component("plant", "case (m)")
    omega = kmh / KMH_PER_MS / float(plant.start.get("r_w", table_ii.r_w)) * float(plant.start.get("n_g", table_ii.n_g))
    values = {"plant.omega_m0": omega}
    controller = at_speed if kmh > 0.0 else None
    if controller is not None:
        values["ctrl.x0_omega"] = omega
    if converged:
        values.update(converged_settings())
    spec = apply_overrides(system, stop_time=stop_time, set=values, controller=controller)
    old = spec.signals["omega_ref"]
    spec.signals["omega_ref"] = SignalSpec("omega_ref", Table((0.0,), (omega,), "previous", "omega_ref", "rad/s"),
                                           "rad/s", list(old.drives), "rad/s")
    return spec


def speed_cases(say, work: Path, stop_time: float) -> dict:
    """Case (m), printed: {(system, km/h): (us/step wall, us/step CPU, errors)}."""
    out = {}
    # the drives' FMUs (the held speeds' systems name FocSensored and FocEkf5AB beside (a)'s and (e)'s)
    build_all(out_dir=project_fmu_dir(), names=["PmsmEvPlant", "FocSensored", "FocSensorless", "FocEkf5AB"])
    say(f"{'(m) drive at a held speed':<34}{'km/h':>6}{'us/step wall':>14}{'us/step CPU':>13}"
        f"{'speed err km/h':>16}{'angle err rad':>15}")
    for system, at_speed in SPEED_SYSTEMS:
        for kmh in SPEEDS_KMH:
            run_dir = Path(tempfile.mkdtemp(prefix="speed-", dir=work))
            ref_dir = Path(tempfile.mkdtemp(prefix="speed-ref-", dir=work))
            master = Master(held_speed_spec(system, kmh, stop_time, at_speed=at_speed))
            m = master.run(run_dir, catch_sigint=False)
            Master(held_speed_spec(system, kmh, stop_time, converged=True, at_speed=at_speed)).run(
                ref_dir, catch_sigint=False)
            err = converged_errors(run_dir, ref_dir)
            cpu = 1e6 * master.loop_cpu_time / m["macro_steps"]
            out[(system, kmh)] = (m["us_per_step"], cpu, err)
            label = system if at_speed is None or kmh == 0.0 else f"{system} ({at_speed})"
            say(f"{label:<34}{kmh:>6g}{m['us_per_step']:>14.2f}{cpu:>13.2f}{err['speed_kmh']:>16.2e}"
                f"{err['angle_rad']:>15.2e}")
            shutil.rmtree(run_dir, ignore_errors=True)
            shutil.rmtree(ref_dir, ignore_errors=True)
        top, still = out[(system, SPEEDS_KMH[-1])], out[(system, SPEEDS_KMH[0])]
        say(f"{system + ': cost at ' + f'{SPEEDS_KMH[-1]:g}' + ' / at 0 km/h':<40}{top[0] / still[0]:>14.2f}"
            f"{top[1] / still[1]:>13.2f}")
    return out


def whole_loop_us_per_step(spec) -> tuple[float, float]:
    """(h): the whole compiled loop of ``spec``'s system (``run_whole_loop``), (wall, CPU) time per step [us]."""
    m = run_whole_loop(spec)
    return m["us_per_step"], 1e6 * m["cpu_time_s"] / m["macro_steps"]


def libcosim_us_per_step(stop_time: float, plant: Path, ctrl: Path) -> tuple[float, float] | None:
    """(d): libcosim's fixed-step execution of the same system, (wall, CPU of all the
    process's threads) per step [us]; None without libcosimpy."""
    try:
        from libcosimpy.CosimExecution import CosimExecution  # noqa: PLC0415 - libcosimpy: optional (case d)
        from libcosimpy.CosimLogging import CosimLogLevel, log_output_level  # noqa: PLC0415 - libcosimpy: optional (case d)
        from libcosimpy.CosimManipulator import CosimManipulator  # noqa: PLC0415 - libcosimpy: optional (case d)
        from libcosimpy.CosimSlave import CosimLocalSlave  # noqa: PLC0415 - libcosimpy: optional (case d)
    except ImportError:
        return None
    spec = _spec(stop_time, plant, ctrl)
    log_output_level(CosimLogLevel.WARNING)
    h = spec.step_size
    ex = CosimExecution.from_step_size(step_size=round(h * 1e9))
    index, refs = {}, {}
    for comp in spec.components:
        index[comp.name] = ex.add_local_slave(CosimLocalSlave(fmu_path=str(comp.fmu), instance_name=comp.name))
        refs[comp.name] = {v.name.decode(): v.reference for v in ex.slave_variables(index[comp.name])}
    for comp in spec.components:
        for var, value in comp.start.items():
            if isinstance(value, str):
                ex.string_initial_value(index[comp.name], refs[comp.name][var], value)
            else:
                ex.real_initial_value(index[comp.name], refs[comp.name][var], float(value))
    for c in spec.connections:
        if ex.connect_real_variables(index[c.src], refs[c.src][c.src_var], index[c.dst], refs[c.dst][c.dst_var]):
            raise CosimError(f"libcosim refused the connection {c}")
    manipulator = CosimManipulator.create_override()
    ex.add_manipulator(manipulator)
    targets = [(sig.profile, index[inst], refs[inst][var]) for sig in spec.signals.values()
               for inst, var in sig.drives]
    last = [profile(0.0) for profile, _, _ in targets]
    for (_profile, slave, ref), value in zip(targets, last):
        ex.real_initial_value(slave, ref, value)
    n_steps = round(stop_time / h)
    step, override = ex.step, manipulator.slave_real_values
    t0, cpu0 = time.perf_counter(), time.process_time()
    for n in range(n_steps):
        t = n * h
        for k, (profile, slave, ref) in enumerate(targets):
            v = profile(t)
            if v != last[k]:
                last[k] = v
                override(slave, [ref], [v])
        if not step():
            raise CosimError(f"libcosim step {n} failed")
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    return 1e6 * wall / n_steps, 1e6 * cpu / n_steps


def fmpy_loop(spec, n_steps: int, clock=None) -> dict[str, dict[str, float]]:
    """Step ``spec``'s system ``n_steps`` steps with a plain fmpy master (case (j)): each FMU an ``FMU2Slave``,
    its start values and the signals' values at t = 0 set before initialization, then per step, component by
    component in the system file's order, its connected inputs read from their sources (one ``getReal`` per
    source) and set (one ``setReal``), the signals that drive it set when their value changed, ``doStep``.
    ``clock`` ``(start, stop)``: called around the stepping loop alone. Returns every component's Real outputs
    after the last step ({instance: {name: value}}): the same as the master's, which steps the same way."""
    from fmpy import extract, read_model_description  # noqa: PLC0415 - fmpy: the master's own dependency
    from fmpy.fmi2 import FMU2Slave  # noqa: PLC0415

    h = spec.step_size
    slaves, variables, folders = {}, {}, []
    try:
        for comp in spec.components:
            md = read_model_description(str(comp.fmu))
            folders.append(extract(str(comp.fmu)))
            slave = FMU2Slave(guid=md.guid, unzipDirectory=folders[-1], instanceName=comp.name,
                              modelIdentifier=md.coSimulation.modelIdentifier)
            slave.instantiate()
            slave.setupExperiment(startTime=0.0, stopTime=n_steps * h)
            variables[comp.name] = {v.name: v for v in md.modelVariables}
            for var, value in comp.start.items():
                sv = variables[comp.name][var]
                value = convert_start(sv, value, f"start value {comp.name}.{var}")  # the master's conversion
                setter = {"Real": slave.setReal, "Boolean": slave.setBoolean, "String": slave.setString}
                setter.get(sv.type, slave.setInteger)([sv.valueReference], [value])
            slaves[comp.name] = slave
        vr = {name: {var: sv.valueReference for var, sv in vs.items()} for name, vs in variables.items()}
        signals = [(sig.profile, inst, vr[inst][var]) for sig in spec.signals.values() for inst, var in sig.drives]
        last = [profile(0.0) for profile, _inst, _ref in signals]
        for (_profile, inst, ref), value in zip(signals, last):
            slaves[inst].setReal([ref], [value])
        for slave in slaves.values():
            slave.enterInitializationMode()
            slave.exitInitializationMode()
        plan = []  # per component in order: its slave, [(source slave, source refs, its refs)], its signals
        for comp in spec.components:
            sources: dict[str, tuple[list, list]] = {}
            for c in spec.connections:
                if c.dst == comp.name:
                    if variables[c.src][c.src_var].type != "Real":
                        raise CosimError(f"the plain fmpy master of case (j) connects Reals only, not {c}")
                    src_refs, dst_refs = sources.setdefault(c.src, ([], []))
                    src_refs.append(vr[c.src][c.src_var])
                    dst_refs.append(vr[comp.name][c.dst_var])
            plan.append((slaves[comp.name], [(slaves[src], a, b) for src, (a, b) in sources.items()],
                         [k for k, (_p, inst, _r) in enumerate(signals) if inst == comp.name]))
        if clock is not None:
            clock[0]()
        for n in range(n_steps):
            t = n * h
            for slave, transfers, mine in plan:
                for source, src_refs, dst_refs in transfers:
                    slave.setReal(dst_refs, source.getReal(src_refs))
                for k in mine:
                    profile, _inst, ref = signals[k]
                    v = profile(t)
                    if v != last[k]:
                        last[k] = v
                        slave.setReal([ref], [v])
                slave.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        if clock is not None:
            clock[1]()
        return {name: {var: slaves[name].getReal([sv.valueReference])[0] for var, sv in variables[name].items()
                       if sv.causality == "output" and sv.type == "Real"} for name in slaves}
    finally:
        for slave in slaves.values():
            slave.terminate()
            slave.freeInstance()
        for folder in folders:
            shutil.rmtree(folder, ignore_errors=True)


def fmpy_us_per_step(stop_time: float, plant: Path, ctrl: Path) -> tuple[float, float]:
    """(j): the plain fmpy master (``fmpy_loop``) on the system of (a), (wall, CPU) time per step [us]."""
    n_steps = round(stop_time / 1e-4)
    marks = []
    fmpy_loop(_spec(stop_time, plant, ctrl), n_steps,
              clock=(lambda: marks.append((time.perf_counter(), time.process_time())),) * 2)
    (w0, c0), (w1, c1) = marks
    return 1e6 * (w1 - w0) / n_steps, 1e6 * (c1 - c0) / n_steps


def passthrough_fmus(out_dir: Path) -> dict[str, Path]:
    return {name: build_fmu(name, out_dir)[0] for name in BENCH_FMUS}


def project_fmus() -> dict[str, Path]:
    return build_all(out_dir=project_fmu_dir(), names=["PmsmEvPlant", "FocEkf5", "FocSensorless"])


def fmi3_units() -> tuple[dict[str, Path] | None, str]:
    """(k), (l): the FMI 3.0 units of the FMUs of (a) (``build_all(fmi=3)``, beside the FMI 2.0 ones), or (None, why
    not: they need the lean build, Linux x86-64 and a C compiler)."""
    try:
        return build_all(out_dir=project_fmu_dir(), names=["PmsmEvPlant", "FocEkf5"], fmi=3), ""
    except BuildError as exc:
        return None, str(exc)


#: the cases of the table, in its order (the module's doc)
CASES = {
    "a": "(a) orchestrator + PmsmEvPlant/FocEkf5 FMUs",
    "b": "(b) orchestrator + pass-through FMUs",
    "c": "(c) monolithic reference (no FMUs)",
    "d": "(d) libcosim + PmsmEvPlant/FocEkf5 FMUs",
    "e": "(e) sensorless cycle drive: FocSensorless FMUs",
    "f": "(f) the same with pass-through FMUs",
    "g": "(g) (e) with injection (wltc3b-sensorless)",
    "h": "(h) whole compiled loop (no FMI), system of (e)",
    "i": "(i) whole compiled loop (no FMI), system of (a)",
    "j": "(j) a plain fmpy master + the FMUs of (a)",
    "k": "(k) (a) on the FMI 3.0 units, clock ticked",
    "l": "(l) (a) on the FMI 3.0 units, no event mode",
}
#: the rounds of (a), (k), (l) in lock step whose ratios k/a, l/a are taken (the module's doc); odd: the median is a
#: round's
FMI3_ROUNDS = 5
#: the ratios printed below the table: (numerator, denominator)
RATIOS = (("a", "b"), ("d", "a"), ("j", "a"), ("e", "f"), ("e", "h"), ("a", "i"), ("k", "a"), ("l", "a"))


class LockStep:
    """Masters stepped in lock step, one thread each: the progress hook of master i (``hook(i)``, given to its
    ``Master.run(progress=...)``, which calls it at each row) lets its loop go on only in its turn, for ``stride``
    rows, and the turns go round in the order of the masters (0, 1, ..., 0, ...; a master done is passed over). A turn
    is timed from the moment it began to its last row (wall, and its thread's CPU time): ``costs[i]``, master i's
    (wall, CPU) [us] a step, turn by turn. Nothing steps before every master is set up (``run``). The turns are long
    enough (``stride`` rows; 10: 1000 steps of (a), about a millisecond) that a master's caches, which the others' turns
    have used, weigh little in them, and short enough that the machine's speed does not change between them."""

    def __init__(self, count: int, h: float, stride: int = 10):
        self.h = h
        self.stride = stride
        self.count = count
        self.turn = -1
        self.done = [False] * count
        self.aborted = False
        self.ready = [threading.Event() for _ in range(count)]
        self.costs: list[list[tuple[float, float]]] = [[] for _ in range(count)]
        self.cond = threading.Condition()

    def hook(self, i: int) -> "_Turn":
        return _Turn(self, i)

    def _pass(self, i: int) -> None:
        """The turn to the next master after i not done (``cond`` held)."""
        for k in range(1, self.count + 1):
            j = (i + k) % self.count
            if not self.done[j]:
                self.turn = j
                break
        self.cond.notify_all()

    def _wait(self, i: int) -> None:
        while self.turn != i and not self.aborted:
            self.cond.wait()
        if self.aborted:
            raise KeyboardInterrupt  # the master's loop ends the run "interrupted"

    def run(self, steppers) -> list:
        """``steppers[i](hook)``: master i's run (with ``hook`` as its progress hook), each in a thread of its own,
        set up one after the other, then stepped in turn; their results, in order (an exception of one raised)."""
        out, errors = [None] * self.count, [None] * self.count

        def work(i):
            hook = self.hook(i)
            try:
                out[i] = steppers[i](hook)
            except BaseException as exc:  # noqa: BLE001 - raised again by the calling thread
                errors[i] = exc
            finally:
                hook.close()

        threads = [threading.Thread(target=work, args=(i,), daemon=True) for i in range(self.count)]
        try:
            for i, thread in enumerate(threads):  # one set-up at a time: each thread waits at its first row
                thread.start()
                while not self.ready[i].wait(0.2):
                    pass
            with self.cond:
                self._pass(self.count - 1)
            for thread in threads:
                while thread.is_alive():
                    thread.join(0.2)
        except BaseException:
            with self.cond:
                self.aborted = True
                self.cond.notify_all()
            raise
        for exc in errors:
            if exc is not None:
                raise exc
        return out


class _Turn:
    """Master i's progress hook in a ``LockStep``."""

    def __init__(self, lock: LockStep, i: int):
        self.lock, self.i = lock, i
        self.start: tuple[float, float, float] | None = None
        self.rows = 0
        self.closed = False

    def update(self, t: float) -> None:
        wall, cpu = time.perf_counter(), time.thread_time()
        lock = self.lock
        if self.start is not None:
            self.rows += 1
            if self.rows < lock.stride:
                return
            self.rows = 0
            n = round((t - self.start[2]) / lock.h)
            if n > 0:
                lock.costs[self.i].append((1e6 * (wall - self.start[0]) / n, 1e6 * (cpu - self.start[1]) / n))
        with lock.cond:
            if self.start is None:
                lock.ready[self.i].set()
            else:
                lock._pass(self.i)
            lock._wait(self.i)
        self.start = (time.perf_counter(), time.thread_time(), t)

    def close(self) -> None:
        lock = self.lock
        with lock.cond:
            if self.closed:
                return
            self.closed = True
            lock.done[self.i] = True
            lock.ready[self.i].set()  # a master that failed before its first row
            if lock.turn == self.i:
                lock._pass(self.i)
            lock.cond.notify_all()


def fmi3_rounds(rounds: int, lock_step) -> dict:
    """k/a and l/a of ``rounds`` rounds of (a), (k), (l) in lock step: ``lock_step(order)`` -> {case: [(wall, CPU) us a
    step, turn by turn]} of the three stepped in turn in ``order`` (a k l, then l k a, ...). Returns
    {"k/a": pairs, "l/a": pairs}, a pair a round's (wall, CPU): the median over its turns of their ratio
    (module doc)."""
    pairs: dict = {"k/a": [], "l/a": []}
    order = ["a", "k", "l"]
    for _ in range(rounds):
        costs = lock_step(list(order))
        order.reverse()
        for case in ("k", "l"):
            ratios = list(zip(costs[case], costs["a"]))
            pairs[f"{case}/a"].append((median(x[0] / y[0] for x, y in ratios), median(x[1] / y[1] for x, y in ratios)))
    return pairs


def bindings() -> str:
    """The FMI binding of the FMUs measured (build_info.json's "binding": fmus/README.md, "The lean binding")."""
    found = {(read_build_info(path) or {}).get("binding", "pythonfmu") for path in project_fmus().values()}
    return ", ".join(sorted(found))


# -- memory: a fresh process per run ---------------------------------------------------------
#: what a memory run's process runs: ``pmsm-cosim run ...`` (its arguments), then, where Linux tells it, its own peak
#: resident memory on a last line: VmHWM of /proc/self/status, the high-water mark of the process's own memory
#: since its exec. The ``wait4`` figure of a child is not that: Linux keeps the largest resident memory of the
#: process before the exec as well, so a child of the bench starts from the bench's own (255.0 MB printed for
#: whole WLTC runs whose own peak was 233-241 MB, once the bench had loaded the FMUs of its cases)
MEMORY_CHILD = """
import sys
from pmsm_cosim.app.cli import main
code = main(sys.argv[1:])
try:
    with open("/proc/self/status") as fh:
        hwm = next(line.split()[1] for line in fh if line.startswith("VmHWM:"))
    print(f"VmHWM {hwm} kB")
except (OSError, StopIteration):
    pass
sys.exit(code)
"""


def run_child(stop_time: float, out_dir: Path, system: str = SCENARIO, options=(), lines: int = 1
              ) -> tuple[float, float, str]:
    """``pmsm-cosim run SYSTEM [options] --stop-time T`` in a new process (``MEMORY_CHILD``): (wall s, peak RSS
    MB, its last ``lines`` lines of output). The peak is the process's own (VmHWM, kB / 1024) where Linux gives it,
    else what ``wait4`` says (which includes this process's memory at the spawn)."""
    cmd = [sys.executable, "-c", MEMORY_CHILD, "run", system, *options, "--stop-time", repr(stop_time),
           "--out", str(out_dir), "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    output = proc.stdout.read()
    _pid, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    proc.stdout.close()
    out_lines = output.strip().splitlines()
    peak = usage.ru_maxrss / 1024.0  # ru_maxrss is in KiB on Linux
    if out_lines and out_lines[-1].startswith("VmHWM "):
        peak = int(out_lines.pop().split()[1]) / 1024.0
    tail = out_lines[-lines:] if out_lines else [""]
    if proc.returncode != 0:
        raise CosimError(f"{' '.join(cmd[3:])} exited with {proc.returncode}: {tail[-1]}")
    return wall, peak, "\n".join(tail)


def memory_runs(say, stop_times, work: Path, system: str = SCENARIO, options=(), lines: int = 1) -> dict:
    """``run_child`` for each stop time, printed: {T: (wall s, peak RSS MB)}; the growth of the peak
    against the first."""
    mem = {}
    for stop in stop_times:
        wall, rss, tail = run_child(stop, work / f"run-{system}-{stop:g}", system, options, lines)
        mem[stop] = (wall, rss)
        extra = ""
        if stop != stop_times[0]:
            base = mem[stop_times[0]][1]
            extra = f" ({100.0 * (rss - base) / base:+.1f} % vs T = {stop_times[0]:g} s)"
        say(f"  T = {stop:>5g} s: {wall:7.1f} s wall, peak RSS {rss:7.1f} MB{extra}; "
            f"load average {load_average()}")
        for line in tail.splitlines():
            say(f"      {line}")
    return mem


# -- the report ------------------------------------------------------------------------------
def run_bench(slice_s: float = DEFAULT_SLICE, memory: bool = True, libcosim: bool = True,
              out=sys.stdout, cycle_slice: float = DEFAULT_CYCLE_SLICE, cycle_memory: bool = False,
              fmpy_case: bool = True, fmi3_case: bool = True, speed_slice: float = DEFAULT_SPEED_SLICE,
              fmi3_rounds_n: int = FMI3_ROUNDS) -> dict:
    def say(text: str = "") -> None:
        print(text, file=out, flush=True)

    work = Path(tempfile.mkdtemp(prefix="pmsm-bench-"))
    results: dict = {}
    try:
        real = project_fmus()
        dummy = passthrough_fmus(work / "fmus")
        plant, ctrl = real["PmsmEvPlant"], real["FocEkf5"]
        n = round(slice_s / 1e-4)
        say(f"step cost: {SCENARIO}, t = 0 .. {slice_s:g} s, dt = 1e-4 s ({n} macro steps per case (a)-(d), (i)); "
            f"{CYCLE_SYSTEM} --cycle {CYCLE}, t = 0 .. {cycle_slice:g} s ({round(cycle_slice / 1e-4)} per case "
            f"(e), (f), (g), (h)); physics kernels: {jit_mode()}")
        say(f"load average at start: {load_average()}")
        results["a"] = cosim_us_per_step(slice_s, work, plant, ctrl)
        results["b"] = cosim_us_per_step(slice_s, work, dummy["PassThroughPlant"], dummy["PassThroughFoc"])
        results["c"] = reference_us_per_step(slice_s, work)
        results["d"] = libcosim_us_per_step(slice_s, plant, ctrl) if libcosim else None
        results["e"] = cosim_us_per_step(cycle_slice, work,
                                         spec=cycle_spec(cycle_slice, plant, real["FocSensorless"]))
        results["f"] = cosim_us_per_step(cycle_slice, work, spec=cycle_spec(
            cycle_slice, dummy["PassThroughPlant"], dummy["PassThroughFoc"]))
        results["g"] = cosim_us_per_step(cycle_slice, work, spec=cycle_spec(
            cycle_slice, plant, real["FocSensorless"], INJECTION_SYSTEM))
        results["h"] = whole_loop_us_per_step(cycle_spec(cycle_slice, plant, real["FocSensorless"]))
        results["i"] = whole_loop_us_per_step(_spec(slice_s, plant, ctrl))
        results["j"] = fmpy_us_per_step(slice_s, plant, ctrl) if fmpy_case else None
        fmi3, no_fmi3 = fmi3_units() if fmi3_case else (None, "")
        results["k"] = results["l"] = None
        paired: dict = {}
        if fmi3 is not None:
            runs = {"a": (real, True), "k": (fmi3, True), "l": (fmi3, False)}

            def run(case, clock=None):
                units, event_mode = runs[case]
                return cosim_us_per_step(slice_s, work, units["PmsmEvPlant"], units["FocEkf5"], event_mode=event_mode,
                                         clock=clock)

            results["k"], results["l"] = run("k"), run("l")

            def lock_step(order):
                lock = LockStep(len(order), 1e-4)
                lock.run([lambda hook, case=case: run(case, hook) for case in order])
                return dict(zip(order, lock.costs))

            paired = fmi3_rounds(fmi3_rounds_n, lock_step)
            for ratio, pairs in paired.items():
                results[ratio] = (median(w for w, _c in pairs), median(c for _w, c in pairs))
        say(f"{'case':<50}{'us/step wall':>14}{'us/step CPU':>13}")
        for case, label in CASES.items():
            value = results[case]
            if value is None:
                why = "skipped"
                if case == "d" and libcosim:
                    why = "libcosimpy not installed"
                elif case in ("k", "l") and no_fmi3:
                    why = f"no FMI 3.0 units: {no_fmi3}"
                say(f"{label:<50}{'n/a':>14}  ({why})")
            else:
                say(f"{label:<50}{value[0]:>14.2f}{value[1]:>13.2f}")
        for x, y in RATIOS:
            ratio = f"{x}/{y}"
            if ratio in paired:
                say(f"{ratio + ' (in lock step, ' + str(len(paired[ratio])) + ' rounds)':<50}{results[ratio][0]:>14.3f}"
                    f"{results[ratio][1]:>13.3f}")
            elif results[x] is not None and results[y] is not None:
                say(f"{ratio:<50}{results[x][0] / results[y][0]:>14.2f}{results[x][1] / results[y][1]:>13.2f}")
        whole = round(pcycles.load(CYCLE).duration / 1e-4)
        for case in ("e", "g"):
            say(f"{f'({case}) x the whole ' + CYCLE + f' ({whole} steps) [s]':<50}"
                f"{results[case][0] * whole * 1e-6:>14.1f}{results[case][1] * whole * 1e-6:>13.1f}")
        if fmi3 is not None:
            say(f"k/a, l/a: (a), (k), (l) stepped in lock step, 10 rows (1000 steps) a turn, in turn (a k l, then "
                f"l k a, ...); a round's ratio the median over its turns, the ratio the median of "
                f"{fmi3_rounds_n} rounds'")
            for ratio, pairs in paired.items():
                say(f"  the rounds' {ratio}, wall: {' '.join(f'{w:.3f}' for w, _c in pairs)}")
                say(f"  the rounds' {ratio}, CPU:  {' '.join(f'{c:.3f}' for _w, c in pairs)}")
        if speed_slice:
            say()
            results["m"] = speed_cases(say, work, speed_slice)
        say(f"master's stepping loop: {', '.join(sorted(set(LOOPS_SEEN)))} (PMSM_COSIM_LOOP chooses)")
        say(f"the FMUs' binding: {bindings()} ({ENV_BINDING} chooses)")
        say(f"load average at end: {load_average()}")
        if memory:
            say()
            say(f"memory: 'pmsm-cosim run {SCENARIO} --stop-time T' (figures included), a fresh process each")
            results["memory"] = memory_runs(say, MEMORY_STOP_TIMES, work)
        if cycle_memory:
            say()
            say(f"memory: 'pmsm-cosim run {CYCLE_MEMORY_SYSTEM} --cycle {CYCLE} --stop-time T' (figures included), "
                f"a fresh process each")
            results["cycle_memory"] = memory_runs(say, CYCLE_MEMORY_STOP_TIMES, work, CYCLE_MEMORY_SYSTEM,
                                                  ("--cycle", CYCLE), lines=2)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return results


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--slice", type=float, default=DEFAULT_SLICE, metavar="S",
                    help=f"simulated seconds per case, from t = 0 (default {DEFAULT_SLICE:g}; at least 10)")
    ap.add_argument("--no-memory", action="store_true",
                    help="skip the 100 s and 350 s runs that measure peak memory (about 2 min)")
    ap.add_argument("--no-libcosim", action="store_true", help="skip case (d)")
    ap.add_argument("--no-fmpy", action="store_true", help="skip case (j), the plain fmpy master")
    ap.add_argument("--no-fmi3", action="store_true", help="skip cases (k), (l), the FMI 3.0 units")
    ap.add_argument("--fmi3-rounds", type=int, default=FMI3_ROUNDS, metavar="N",
                    help=f"rounds of (a), (k), (l) in lock step whose ratios k/a, l/a are taken (default "
                         f"{FMI3_ROUNDS}; at least 1)")
    ap.add_argument("--cycle-slice", type=float, default=DEFAULT_CYCLE_SLICE, metavar="S",
                    help=f"simulated seconds of {CYCLE} in cases (e), (f), from t = 0 (default "
                         f"{DEFAULT_CYCLE_SLICE:g}; at least 10)")
    ap.add_argument("--speed-slice", type=float, default=DEFAULT_SPEED_SLICE, metavar="S",
                    help=f"simulated seconds of each held speed in case (m) (default {DEFAULT_SPEED_SLICE:g}; "
                         f"0 skips it)")
    ap.add_argument("--cycle-memory", action="store_true",
                    help=f"also run the whole {CYCLE} sensorless ('pmsm-cosim run {CYCLE_MEMORY_SYSTEM} --cycle "
                         f"{CYCLE}', 18 million steps) and half of it, wall time and peak memory (about 1-2 min)")


def _check_slice(value: float, option: str) -> None:
    if not (value >= 10.0 and math.isfinite(value)) or abs(round(value / 1e-4) * 1e-4 - value) > 1e-9:
        raise CosimError(f"{option} must be a whole number of 1e-4 s steps and at least 10 s (got {value:g})")


def run_from_args(a) -> int:
    _check_slice(a.slice, "--slice")
    _check_slice(a.cycle_slice, "--cycle-slice")
    if a.fmi3_rounds < 1:
        raise CosimError(f"--fmi3-rounds must be at least 1 (got {a.fmi3_rounds})")
    if a.cycle_slice > pcycles.load(CYCLE).duration:
        raise CosimError(f"--cycle-slice must be at most {CYCLE}'s {pcycles.load(CYCLE).duration:g} s "
                         f"(got {a.cycle_slice:g})")
    run_bench(a.slice, memory=not a.no_memory, libcosim=not a.no_libcosim, fmpy_case=not a.no_fmpy,
              fmi3_case=not a.no_fmi3, cycle_slice=a.cycle_slice, speed_slice=a.speed_slice,
              cycle_memory=a.cycle_memory, fmi3_rounds_n=a.fmi3_rounds)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="benchmarks/step_cost.py", description=__doc__.split("\n\n")[0])
    add_arguments(ap)
    a = ap.parse_args(argv)
    try:
        return run_from_args(a)
    except CosimError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
