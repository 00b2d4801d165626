"""The whole-loop reference of a system file: its plant and controller in one compiled loop, no FMI
(``pmsm_ev.whole_loop``; ``pmsm-cosim bench``, case (h)).

``run_whole_loop(spec, out_dir)`` makes the plant and the control unit from the parameters the FMUs would be
given (each parameter's start value in the system file, else the FMU's default: the parameter group's), the
signals' values per step as the master evaluates them (``pmsm_cosim.engine.master.SignalClock``) and the
recorded columns from the system's ``[record]``, runs the loop and writes ``results.csv`` as the master writes it:
the same system gives the same file, byte for byte (``tests/test_whole_loop.py``). It covers a system of one
``PmsmEvPlant`` and one ``FocEkf5`` or ``FocSensorless`` wired as the shipped scenarios wire them, Gauss-Seidel,
single-rate, the scenario signals on the plant's ``delta`` and the controller's ``omega_ref``; another system is a
``NotCovered`` with the reason. A plant step the FMU's compiled step declines is its Python step, as in the FMU.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

from pmsm_ev import kernels as _k
from pmsm_ev.control_unit import ControlUnit, parameter_groups
from pmsm_ev.params import (
    DT_DEFAULT,
    MotorParams,
    PlantParams,
    VehicleParams,
)
from pmsm_ev.plant import ENERGY_SLOTS, THERMAL_SLOTS, Plant
from pmsm_ev.whole_loop import NotCovered, WholeLoop

from ..engine.checks import time_grid
from ..engine.master import SignalClock
from ..engine.recording import ResultWriter
from ..engine.system import COLUMN_CONVERSIONS, SystemSpec

#: the controller FMUs covered: model -> its unit's observer (its parameter groups: ``parameter_groups``)
CONTROLLERS = {"FocEkf5": "ekf5", "FocSensorless": "sensorless"}
PLANT = "PmsmEvPlant"
#: the wiring of the shipped scenarios, which the loop's transfers are
WIRING = {("plant", "i_alpha", "ctrl", "i_alpha"), ("plant", "i_beta", "ctrl", "i_beta"),
          ("plant", "theta_e", "ctrl", "theta_meas"), ("plant", "omega_m", "ctrl", "omega_meas"),
          ("ctrl", "v_alpha", "plant", "v_alpha"), ("ctrl", "v_beta", "plant", "v_beta"),
          ("ctrl", "T_brake", "plant", "T_brake"),
          # the battery's DC link: 0 with the ideal link, which the controller then ignores (a plant on the battery
          # is not covered, ``build``), so the loop does not transfer them
          ("plant", "v_bat", "ctrl", "v_dc_meas"), ("plant", "P_charge_max", "ctrl", "P_charge_max"),
          ("plant", "P_discharge_max", "ctrl", "P_discharge_max")}
#: the signal inputs it sets: (instance role, variable) -> (target kind, slot)
SIGNAL_INPUTS = {("plant", "delta"): (_k.TARGET_PLANT, _k.PIO_DELTA),
                 ("ctrl", "omega_ref"): (_k.TARGET_UNIT, _k.UIO_OMEGA_REF)}
#: the controller's outputs read from its unit's properties (the FMU reads them so)
UNIT_PROPERTIES = ("i_dref", "T_ref", "ref_region")


def _group(default, start: dict):
    """The dataclass ``default`` with the start values of its fields (as the FMU's typed variables hold
    them)."""
    changes = {}
    for f in dataclasses.fields(default):
        if f.name in start:
            value, was = start[f.name], getattr(default, f.name)
            changes[f.name] = (bool(value) if isinstance(was, bool) else int(value) if isinstance(was, int)
                               else float(value) if isinstance(was, float) else value)
    return dataclasses.replace(default, **changes)


def _roles(spec: SystemSpec) -> dict[str, str]:
    """{instance name: "plant" or "ctrl"}; ``NotCovered`` unless the system is one the loop covers."""
    if spec.algorithm != "gauss-seidel":
        raise NotCovered(f"{spec.name}: the whole loop steps Gauss-Seidel only (not {spec.algorithm})")
    roles = {}
    for comp in spec.components:
        model = Path(comp.fmu).stem
        role = "plant" if model == PLANT else "ctrl" if model in CONTROLLERS else None
        if role is None or role in roles.values():
            raise NotCovered(f"{spec.name}: the whole loop covers one {PLANT} and one of "
                             f"{', '.join(CONTROLLERS)} (not {comp.name}: {model})")
        if comp.step_multiple != 1:
            raise NotCovered(f"{spec.name}: {comp.name} is multi-rate")
        roles[comp.name] = role
    if [roles[c.name] for c in spec.components] != ["ctrl", "plant"]:
        raise NotCovered(f"{spec.name}: the whole loop steps the controller, then the plant")
    wiring = {(roles[c.src], c.src_var, roles[c.dst], c.dst_var) for c in spec.connections}
    if wiring != WIRING:
        raise NotCovered(f"{spec.name}: the whole loop has the shipped scenarios' connections only")
    return roles


def build(spec: SystemSpec) -> tuple[WholeLoop, dict[str, str]]:
    """The loop of ``spec``'s plant and controller, made from its start values; {instance: role}."""
    roles = _roles(spec)
    comps = {roles[c.name]: c for c in spec.components}
    plant_start, ctrl_start = comps["plant"].start, comps["ctrl"].start
    if plant_start.get("battery", "ideal") != "ideal":  # the battery's link to the controller is not in the loop
        raise NotCovered(f"{spec.name}: the whole loop covers the ideal DC link only (battery = "
                         f"{plant_start['battery']!r})")
    plant = Plant(_group(MotorParams(), plant_start), _group(VehicleParams(), plant_start),
                  _group(PlantParams(), plant_start))
    observer = CONTROLLERS[Path(comps["ctrl"].fmu).stem]
    groups = {}
    for default in parameter_groups(observer):  # as the slave declares them: a class, its defaults
        default = default() if isinstance(default, type) else default
        groups[type(default)] = _group(default, ctrl_start)
    dt = float(ctrl_start.get("dt", 0.0))
    unit = ControlUnit.from_groups(observer, str(ctrl_start.get("angle_source", "measured")), groups.__getitem__,
                                   dt or DT_DEFAULT)
    return WholeLoop(plant, unit, dt), roles


def _columns(spec: SystemSpec, roles: dict[str, str], signals: list[str]) -> list[tuple[int, int]]:
    """The loop's (``COL_*``, slot) of each recorded column."""
    cols = []
    for col in spec.columns:
        if col.kind == "time":
            cols.append((_k.COL_TIME, 0))
        elif col.kind == "signal":
            cols.append((_k.COL_SIGNAL, signals.index(col.variable)))
        elif roles[col.instance] == "plant":
            var = col.variable
            if var in ENERGY_SLOTS or var == "P_dc":
                cols.append((_k.COL_ENERGY, _k.E_P_DC if var == "P_dc" else ENERGY_SLOTS[var]))
            elif var in THERMAL_SLOTS:
                cols.append((_k.COL_ENERGY, THERMAL_SLOTS[var]))
            elif var in ("R_s_now", "psi_now"):
                cols.append((_k.COL_PARAM, _k.P_R_S if var == "R_s_now" else _k.P_PSI))
            elif var in ("W_magnetic", "E_kinetic"):
                cols.append((_k.COL_W_MAGNETIC if var == "W_magnetic" else _k.COL_E_KINETIC, 0))
            elif hasattr(_k, "PIO_" + var.upper()):
                cols.append((_k.COL_PLANT, getattr(_k, "PIO_" + var.upper())))
            else:
                raise NotCovered(f"{spec.name}: the whole loop does not record plant.{var}")
        elif col.variable in UNIT_PROPERTIES:
            cols.append((_k.COL_LATER, 0))
        elif hasattr(_k, "UIO_" + col.variable.upper()):
            cols.append((_k.COL_UNIT, getattr(_k, "UIO_" + col.variable.upper())))
        elif col.variable in _k.UNIT_STATUS_OUTPUTS:  # written by the compiled step (unit_status_outputs)
            cols.append((_k.COL_UNIT, _k.UIO_STATUS + _k.UNIT_STATUS_OUTPUTS.index(col.variable)))
        else:
            raise NotCovered(f"{spec.name}: the whole loop does not record ctrl.{col.variable}")
    return cols


def run_whole_loop(spec: SystemSpec, out_dir=None) -> dict:
    """Run ``spec`` in the whole loop; with ``out_dir``, write its ``results.csv`` there. Returns {"rows": the
    recorded rows (lists of floats, as the master writes them), "columns", "macro_steps", "wall_time_s",
    "cpu_time_s", "us_per_step", "setup_s"}: the wall and CPU time of the steps and of making the rows (the
    master's loop time covers its recording too), not of the set-up (compiling, the signals' events)."""
    t_setup = time.perf_counter()
    n_steps, every = time_grid(spec)
    h = spec.step_size
    loop, roles = build(spec)
    loop.compile()
    clock = SignalClock(spec)
    names = [sig.name for sig in clock.signals]
    targets = []
    for sig in spec.signals.values():
        if len(sig.drives) != 1 or (roles.get(sig.drives[0][0]), sig.drives[0][1]) not in SIGNAL_INPUTS:
            raise NotCovered(f"{spec.name}: the whole loop sets the signals of plant.delta and ctrl.omega_ref only "
                             f"(not {sig.name} -> {sig.drives})")
        targets.append(SIGNAL_INPUTS[(roles[sig.drives[0][0]], sig.drives[0][1])])
    events = list(clock.events(n_steps).values())
    cols = _columns(spec, roles, names)
    later = [j for j, (kind, _) in enumerate(cols) if kind == _k.COL_LATER]
    setup = time.perf_counter() - t_setup
    t0, cpu0 = time.perf_counter(), time.process_time()
    rows, states = loop.run(n_steps, h, every, events, targets, cols, states=bool(later))
    out_rows = _rows(spec, loop, rows, states, later)
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    columns = [c.name for c in spec.columns]
    if out_dir is not None:
        with ResultWriter(Path(out_dir), columns) as w:
            for row in out_rows:
                w.write(row)
    return {"rows": out_rows, "columns": columns, "macro_steps": n_steps, "wall_time_s": wall, "cpu_time_s": cpu,
            "us_per_step": 1e6 * wall / n_steps, "setup_s": setup}


def _rows(spec: SystemSpec, loop: WholeLoop, rows, states, later: list[int]) -> list[list[float]]:
    """The loop's rows as the master writes them: the unit conversions of the record, and the controller's
    outputs that its unit's properties give, read from the unit in each row's state."""
    convs = [(j, COLUMN_CONVERSIONS[c.unit][1]) for j, c in enumerate(spec.columns) if c.unit]
    out = rows.tolist()
    unit = loop.unit
    saved = unit._s.copy()
    try:
        for r, row in enumerate(out):
            for j, conv in convs:
                row[j] = float(conv(row[j]))
            if later:
                unit._s[:] = states[r]
                for j in later:
                    row[j] = float(getattr(unit, spec.columns[j].variable))
    finally:
        unit._s[:] = saved
    for row in out:
        for v in row:
            if not math.isfinite(v):
                raise NotCovered(f"{spec.name}: a recorded value is not finite ({v}) at t = {row[0]:.9g} s")
    return out
