"""The changes a run makes to a system before it is run or exported: one function,
:func:`apply_overrides`, for the command line (``pmsm-cosim run`` and ``export-ssp``) and the
Python API (:func:`pmsm_cosim.simulate`), so that both take the same values and say the same
about a wrong one.

=====================  =============================  ==========================================
override               command line                   Python (``simulate``)
=====================  =============================  ==========================================
plant's FMU            ``--plant FMU``                ``plant=FMU``
controller's FMU       ``--controller FMU``           ``controller=FMU``
any instance's FMU     ``--fmu INSTANCE=FMU``         ``fmus={"INSTANCE": FMU}``
stop time [s]          ``--stop-time S``              ``stop_time=S``
base step [s]          ``--step S``                   ``step_size=S``
recording interval     ``--output-interval S``        ``output_interval=S``
coupling               ``--algorithm A``              ``algorithm=A``
start values           ``--set INSTANCE.VAR=VALUE``   ``set={"INSTANCE.VAR": VALUE}`` (or fmpy's
                                                      ``start_values=``)
a signal from a CSV    ``--profile SIGNAL=CSV``       ``profiles={"SIGNAL": CSV}``
a drive cycle          ``--cycle NAME|CSV``           ``cycle=NAME|CSV`` (omega_ref from the cycle,
                                                      module ``cycles``; stop time: its duration)
recorded columns       ``--record NAME ...``          ``record=[NAME, ...]`` (or fmpy's ``output=``)
=====================  =============================  ==========================================

An FMU is an ``.fmu`` file (``{fmus}/X.fmu`` is the project's FMU folder), a shipped FMU by
name (``FocEkf4``) or an observer's name (``ekf4``, ``ekf5``, ``ekf5ab``, ``sensored``,
``sensorless``: its controller FMU). A start value, a ``--fmu`` and a ``--profile`` are
written ``KEY=VALUE`` on the command line; in Python a dict or a list of those strings.
The system given is never changed: the overrides apply to a copy.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Iterable, Mapping
from pathlib import Path

from pmsm_ev_fmus.build import FMUS, OBSERVER_FMUS

from ..engine.errors import CosimError, close_matches
from ..engine.system import ALGORITHMS, ColumnSpec, SystemSpec, check_references, resolve_fmu_path, split_reference
from . import cycles
from .drive import load_system, project_fmu_dir

#: the instances ``plant`` and ``controller`` replace the FMU of (``--plant``, ``--controller``)
PLANT_INSTANCE = "plant"
CONTROLLER_INSTANCE = "ctrl"
#: the command line's name of each override (the Python API's is the key)
CLI_FLAGS = {"plant": "--plant", "controller": "--controller", "fmus": "--fmu", "stop_time": "--stop-time",
             "step_size": "--step", "output_interval": "--output-interval", "algorithm": "--algorithm",
             "set": "--set", "profiles": "--profile", "record": "--record", "cycle": "--cycle"}


def _named(option: str, value, cli: bool) -> str:
    """How a message names an option and its value: ``--controller ekf9`` / ``controller='ekf9'``."""
    return f"{CLI_FLAGS[option]} {value}" if cli else f"{option}={value!r}"


def _named_item(option: str, key: str, value, cli: bool) -> str:
    """How a message names one ``KEY=VALUE`` of an option: ``--set ctrl.x=1`` / ``set['ctrl.x']=1``."""
    return f"{CLI_FLAGS[option]} {key}={value}" if cli else f"{option}[{key!r}]={value!r}"


def fmu_choices() -> tuple[str, ...]:
    """The names an FMU may be given by: the observers', then the shipped FMUs'."""
    return (*OBSERVER_FMUS, *FMUS)


def resolve_fmu(value, what: str) -> Path:
    """The FMU file of ``value``: an observer's name (``ekf4``), a shipped FMU's (``FocEkf4``),
    both in the project's FMU folder, or the path of an ``.fmu`` file (``{fmus}/X.fmu``,
    ``~`` and relative to the working directory)."""
    text = str(value).strip()
    name = OBSERVER_FMUS.get(text, text)
    if name in FMUS:
        return project_fmu_dir() / f"{name}.fmu"
    if not text.lower().endswith(".fmu"):
        raise CosimError(f"{what}: not an .fmu file, an observer or a shipped FMU{close_matches(text, fmu_choices())}; "
                         f"choose one of {', '.join(fmu_choices())} or give an .fmu file")
    return resolve_fmu_path(text, Path.cwd(), what, fmu_dir=project_fmu_dir())


def _pairs(values, option: str, form: str, cli: bool) -> list[tuple[str, object]]:
    """``{"k": v}`` or ``["k=v", ...]`` -> [(k, v)]: the values of a ``KEY=VALUE`` option."""
    if isinstance(values, Mapping):
        return [(str(k).strip(), v) for k, v in values.items()]
    if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
        raise CosimError(f"{_named(option, values, cli)}: give a dict {{{form.split('=')[0]!r}: value}} "
                         f"or a list of '{form}'")
    pairs = []
    for text in values:
        key, sep, value = str(text).partition("=")
        if not sep or not key.strip():
            raise CosimError(f"{_named(option, text, cli)}: expected {form}")
        pairs.append((key.strip(), value.strip()))
    return pairs


def _seconds(value, option: str, cli: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < math.inf:
        raise CosimError(f"{_named(option, value, cli)}: must be a finite number > 0 s")
    return float(value)


def _columns(spec: SystemSpec, record, cli: bool) -> list[ColumnSpec]:
    """The recorded columns of ``record``: time (the system's time column, or ``time``)
    first, then each name as a column of the system (``omega_m``) or a source
    (``plant.omega_m``, ``signals.delta``, the column named as written); a dict names its
    columns: ``{"w": "plant.omega_m"}``."""
    if isinstance(record, (str, bytes)) or not isinstance(record, (Iterable, Mapping)):
        raise CosimError(f"{_named('record', record, cli)}: give a list of column names or INSTANCE.VAR")
    entries = list(record.items()) if isinstance(record, Mapping) else [(str(n).strip(), str(n).strip())
                                                                         for n in record]
    known = {c.name: c for c in spec.columns}
    time = next((c for c in spec.columns if c.kind == "time"), ColumnSpec("time", "time"))
    columns = [time]
    for name, source in entries:
        source = str(source).strip()
        if source in ("time", time.name):
            continue
        if source in known and name == source:
            column = known[source]
        elif "." in source:
            inst, var = split_reference(source, _named("record", source, cli))
            if inst == "signals":
                if var not in spec.signals:
                    raise CosimError(f"{_named('record', source, cli)}: unknown signal {var!r}"
                                     f"{close_matches(var, spec.signals)}; signals: {', '.join(spec.signals)}")
                column = ColumnSpec(str(name), "signal", variable=var)
            else:
                spec.component(inst, _named("record", source, cli))
                column = ColumnSpec(str(name), "variable", inst, var)
        else:
            raise CosimError(f"{_named('record', source, cli)}: not a column of {spec.name}"
                             f"{close_matches(source, known)}; give INSTANCE.VAR or one of {', '.join(known)}")
        if any(c.name == column.name for c in columns):
            raise CosimError(f"{_named('record', source, cli)}: column {column.name!r} given twice")
        columns.append(column)
    return columns


def apply_overrides(system, *, plant=None, controller=None, fmus=None, stop_time=None, step_size=None,
                    output_interval=None, algorithm=None, set=None, profiles=None, record=None,
                    cycle=None, cli: bool = False) -> SystemSpec:
    """The system ``system`` (a :class:`SystemSpec`, copied, never changed, or what
    :func:`~pmsm_cosim.app.drive.load_system` takes) with the overrides (module doc); ``cli``
    names them in messages as the command line does (``--controller X``), else as Python does
    (``controller='X'``). Checked as far as it can be without opening the FMUs (their
    variables and the values' types are checked by the master)."""
    spec = copy.deepcopy(system) if isinstance(system, SystemSpec) else load_system(system)
    # a replaced FMU: the start values the system file wrote for the one it had are set where the new FMU has the
    # variable (``ComponentSpec.optional_start``: e.g. the sensorless unit's ``low_speed`` when ``--controller
    # sensored`` swaps it out), else left out with a warning by the master; ``--set`` values are the user's own
    for option, instance, value in (("plant", PLANT_INSTANCE, plant), ("controller", CONTROLLER_INSTANCE, controller)):
        if value is not None:
            what = _named(option, value, cli)
            spec.component(instance, what).replace_fmu(resolve_fmu(value, what), str(value))
    for instance, value in _pairs(fmus or {}, "fmus", "INSTANCE=FMU", cli):
        what = _named_item("fmus", instance, value, cli)
        spec.component(instance, what).replace_fmu(resolve_fmu(value, what), str(value))
    if cycle is not None:  # omega_ref from the cycle (module cycles); the stop time its duration unless given
        what = _named("cycle", cycle, cli)
        loaded = cycles.load_cycle(str(cycle), what)
        target = cycles.split_reference(cycles.CYCLE_DRIVES, what)
        old = spec.signals.get(cycles.CYCLE_SIGNAL)
        drives = old.drives if old is not None and old.drives else [target]
        cycles.drive_with_cycle(spec, loaded, drives, what)
        if stop_time is None:
            spec.stop_time = loaded.duration
    for option, value in (("stop_time", stop_time), ("step_size", step_size), ("output_interval", output_interval)):
        if value is not None:
            setattr(spec, option, _seconds(value, option, cli))
    if algorithm is not None:
        if algorithm not in ALGORITHMS:
            raise CosimError(f"{_named('algorithm', algorithm, cli)}: choose {' or '.join(ALGORITHMS)}")
        spec.algorithm = algorithm
    for target, value in _pairs(set or {}, "set", "INSTANCE.VAR=VALUE", cli):
        what = _named_item("set", target, value, cli)
        instance, variable = split_reference(target, what)
        comp = spec.component(instance, what)
        comp.start[variable] = value
        comp.optional_start = comp.optional_start - {variable}  # the user's own: set, or refused
    for signal, csv in _pairs(profiles or {}, "profiles", "SIGNAL=CSV", cli):
        if signal not in spec.signals:
            raise CosimError(f"{_named_item('profiles', signal, csv, cli)}: unknown signal {signal!r}"
                             f"{close_matches(signal, spec.signals)}; signals: {', '.join(spec.signals) or '(none)'}")
        spec.set_signal_csv(f"{signal}={csv}")
    if set:
        cycles.resample(spec, "--set" if cli else "set")  # a cycle's reference through the new r_w, n_g
    if record is not None:
        spec.columns = _columns(spec, record, cli)
    check_references(spec)
    return spec
