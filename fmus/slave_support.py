"""Machinery shared by the project's pythonfmu slaves; no physics here.

``DriveSlave`` is a ``pythonfmu.Fmi2Slave`` that adds what the project's FMUs need on
top of pythonfmu 0.7.0:

* variables declared with unit and description; parameters declared from the
  ``pmsm_ev.params`` dataclasses, one FMU parameter per field (Real, Integer, Boolean or
  String after the field's type), fixed after initialisation;
* a complete modelDescription (``to_xml``): UnitDefinitions and ``unit`` attributes,
  start values that round-trip exactly (``repr``), ModelStructure with the output
  dependencies (none: every output is computed inside ``do_step``) and the
  InitialUnknowns with their dependencies;
* lean Real access: ``get_real`` reads the attributes named by a list indexed by value
  reference, ``set_real`` writes inputs straight into the instance dict (parameters and
  wrong references go through checked setters), instead of pythonfmu's dict look-up and
  type test per variable;
* the physics is built from the parameters (and validated by the dataclasses) at
  ``exit_initialization_mode``; a ``ParameterError`` is raised with the reason;
* parameter defaults of a packaged copy: ``resources/start_values.json`` (name -> value,
  written by ``pmsm_ev_fmus.write_fmu_with_starts``) replaces the coded default of those
  parameters, so that a host that cannot set String parameters runs a chosen value;
* ``fmi2SetupExperiment`` with a stop time before the start time is refused;
* FMI 2.0's state machine and arguments (``DriveSlave.refusal``): a call in the wrong state, a
  non-finite Real input, a communication point that does not continue the last step (without an FMU
  state restored) are refused, a step longer than the slave integrates to its accuracy (``max_step``)
  discarded; the lean binding returns fmi2Error (fmi2Discard) with the line logged, pythonfmu's own
  path fmi2Fatal (fmus/README.md, "Misuse");
* the FMU state (``fmi2GetFMUstate``/``fmi2SetFMUstate``, JSON-serialisable) holds every
  variable plus the full state of the wrapped physics (subclass hooks), all as named fields:
  a state whose fields are not this FMU's (another FMU's, another version's) is refused with
  the field named (``FmuStateError``).

Errors: pythonfmu 0.7.0's C wrapper turns every Python exception into ``fmi2Fatal``
(there is no way to return ``fmi2Error`` from Python) and logs it, with status
``fmi2Fatal``, as ``Fatal py exception encountered: [<call>] ...`` followed by the repr of
the exception: the exception's text is the reason (the wrapper forwards log messages
only when the master enables logging). A failing call logs nothing of its own: the
wrapper flushes the log queue while the exception is still set, and Python 3.13 refuses
a host's Python logger callback (fmpy's) in that state (``SystemError``, the reason
lost).

Lifetime in the wrapper (pythonfmu 0.6.5 to 0.7.0, read in its C++ source; older versions
are refused at import, see ``WRAPPER_CHECKED``):

* it releases the Python instance, its class and its log queue when an exception occurs
  and once more in ``fmi2FreeInstance``; ``_fail`` takes one extra reference to each, so a
  master that frees a failed instance does not crash the process (one that leaves it, as
  FMI 2.0 asks after fmi2Fatal, leaks that one instance);
* its library keeps a ``std::shared_ptr`` to an interpreter guard that a C++ static
  destructor releases at ``exit()`` and that the library's ELF destructor resets once more
  afterwards: a write into freed heap memory whenever the library is still loaded when the
  process exits (dlclose does not unload it once another library has bound to its unique
  symbols), which aborts the process in a later free() ("corrupted double-linked list")
  in 4 of 10 short runs with numba's compiled kernels. ``release_at_exit`` resets that
  pointer through the library's own ``finalizePythonInterpreter`` from a Python ``atexit``
  handler, which runs before the C++ destructors (docs/errors.md, "Crash at exit").
"""

from __future__ import annotations

import atexit
import ctypes
import dataclasses
import functools
import json
import math
import operator
import os
import re
import sys
from pathlib import Path
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import (
    Boolean,
    DefaultExperiment,
    Fmi2Causality,
    Fmi2Initial,
    Fmi2Slave,
    Fmi2Variability,
    Integer,
    Real,
    String,
)
from pythonfmu import __version__ as PYTHONFMU_VERSION
from pythonfmu.enums import Fmi2Status

from pmsm_ev_fmus.metadata import DISPLAY_UNITS, PARAMETERS, UNITS

AUTHOR = "pmsm-ev-cosim contributors"
LICENSE = "MIT"
#: DefaultExperiment of every FMU: the paper's 350 s scenarios at the 10 kHz control rate
START_TIME, STOP_TIME, STEP_SIZE = 0.0, 350.0, 1.0e-4

_KINDS = {"float": Real, "int": Integer, "bool": Boolean, "str": String}
#: the most value-reference sets whose get_real reader a slave keeps (memory stays bounded whatever
#: a master asks for)
_READS_KEPT = 64
#: parameter defaults of a packaged copy of an FMU (resources/), see ``packaged_starts``
START_VALUES_FILE = "start_values.json"


#: the pythonfmu versions whose C++ wrapper the lifetime code below and the lean binding
#: (``fmus/lean_binding.c``) were checked against, the first and the last; ``_fail`` and
#: ``release_at_exit`` rely on its behaviour (see the module doc); the build refuses another
#: version (``build.check_pythonfmu``), pyproject.toml pins this range
WRAPPER_CHECKED = ("0.6.5", "0.7.0")


def version_tuple(text: str) -> tuple[int, ...]:
    """(major, minor, micro) of a version string: "0.7.0" -> (0, 7, 0)."""
    return tuple(int(part) for part in re.findall(r"\d+", text)[:3])


if version_tuple(PYTHONFMU_VERSION) < version_tuple(WRAPPER_CHECKED[0]):
    raise ImportError(f"pythonfmu {PYTHONFMU_VERSION}: the project's FMUs need pythonfmu >= {WRAPPER_CHECKED[0]}")

#: the wrapper libraries (paths) of this process whose interpreter guard is reset at exit
_WRAPPER_LIBRARIES: set[str] = set()


#: the folders of an FMU's ``binaries/`` that may hold the project's Linux libraries: FMI 2.0's platform folder, and
#: FMI 3.0's, where the FMI 3.0 units keep the same FMI 2.0 stack behind their FMI 3.0 layer (fmus/README.md, "FMI 3.0")
LINUX_BINARIES = ("linux64", "x86_64-linux")


def _linux_libraries(resources) -> list[Path]:
    """The shared libraries of the FMU unpacked around ``resources``, in its Linux platform folders."""
    binaries = Path(resources).parent / "binaries"
    return [library for folder in LINUX_BINARIES for library in sorted((binaries / folder).glob("*.so"))]


def release_at_exit(resources) -> None:
    """Have the wrapper library of the FMU unpacked around ``resources`` reset its
    interpreter guard when this Python exits (module doc: the wrapper's exit-time write
    into freed memory). Only in a Python program on Linux: where the wrapper started the
    interpreter itself (``sys.orig_argv`` empty) the guard's reset finalizes it, so it is
    left to the wrapper."""
    if not resources or not sys.platform.startswith("linux") or not getattr(sys, "orig_argv", None):
        return
    for library in _linux_libraries(resources):
        if not _WRAPPER_LIBRARIES:
            atexit.register(_release_wrapper_libraries)
        _WRAPPER_LIBRARIES.add(str(library))


def _release_wrapper_libraries() -> None:
    for path in sorted(_WRAPPER_LIBRARIES):
        try:  # only a library still loaded: one unloaded by dlclose ran its destructors in order
            library = ctypes.CDLL(path, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
        except OSError:
            continue
        reset = getattr(library, "finalizePythonInterpreter", None)
        if reset is not None:
            reset.restype = None
            reset()
    _WRAPPER_LIBRARIES.clear()


#: the lean binding's entry point (``fmus/lean_binding.c``): where a slave offers itself
LEAN_OFFER = "pmsm_fmu_offer"
#: the slots of ``DriveSlave.compiled_slots``: buffer b's element i is ``COMPILED_BUFFER * b + i``
COMPILED_BUFFER = 1 << 20
#: the slot of a ``DriveSlave.compiled_live`` output in the lean binding's table (``fmus/lean_binding.c``)
LIVE_SLOT = -2


def compiled_offer(step: int, *buffers) -> tuple:
    """What ``DriveSlave.compiled_step`` returns to the lean binding: the C function's address, then the addresses of
    its three buffers (C-contiguous float64 arrays), then their lengths, by which the binding checks every slot
    (``compiled_slots``) before it reads or writes one."""
    if len(buffers) != 3 or any(getattr(b, "dtype", None) != "float64" or not b.flags.c_contiguous for b in buffers):
        raise ValueError("compiled_offer takes three C-contiguous float64 arrays")
    return (step, *(b.ctypes.data for b in buffers), *(b.size for b in buffers))


#: the lean binding's offer function of each FMU's binaries folder in this process (None: pythonfmu's own binary)
_LEAN_OFFERS: dict[str, object] = {}


def lean_offer(resources):
    """The ``pmsm_fmu_offer`` function of the lean binding that holds the FMU unpacked around
    ``resources`` (``binaries/linux64/pmsm-binding.so``, or ``binaries/x86_64-linux/`` in an FMI 3.0 unit, already
    loaded by the host), or None when its binary is pythonfmu's own (another platform, a build without a C compiler,
    another host's copy)."""
    if not resources or not sys.platform.startswith("linux"):
        return None
    folder = str(Path(resources).parent / "binaries")
    if folder not in _LEAN_OFFERS:
        _LEAN_OFFERS[folder] = None
        for library in _linux_libraries(resources):
            try:  # the library the host loaded (by this path), with the GIL held across the call
                handle = ctypes.PyDLL(str(library), mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
            except OSError:
                continue
            offer = getattr(handle, LEAN_OFFER, None)
            if offer is not None:
                offer.argtypes, offer.restype = [ctypes.py_object], ctypes.c_int
                _LEAN_OFFERS[folder] = offer
                break
    return _LEAN_OFFERS[folder]


class FmuUsageError(RuntimeError):
    """An FMI call that the FMU cannot honour (illegal value or call sequence)."""


class FmiCallError(FmuUsageError):
    """A call FMI 2.0 does not allow (wrong state, non-finite input, a communication point that does not continue
    the last one): ``DriveSlave.refusal`` says which; the lean binding returns its status (fmi2Error)."""


#: the FMI 2.0 co-simulation states of a slave (``DriveSlave.refusal``)
INSTANTIATED, INITIALIZATION, STEP_MODE, TERMINATED = "instantiated", "initialization mode", "step mode", "terminated"
#: the statuses a refusal returns
FMI2_DISCARD, FMI2_ERROR = 2, 3
#: the typed get and set calls, by the variable type each reads or writes (``DriveSlave.refusal``: a value reference
#: that names no variable, or one of another type, is refused with fmi2Error and a log line, where pythonfmu would
#: raise and answer fmi2Fatal)
_TYPED_ACCESS = {f"fmi2{op}{name}": kind for op in ("Get", "Set")
                 for name, kind in (("Real", Real), ("Integer", Integer), ("Boolean", Boolean), ("String", String))}
#: a communication point continues the last step when within this share of the last step size of where it ended
#: (plus a few ulps of the time): a master's own rounding of t + h, never a step back or forward
CONTINUITY_TOLERANCE = 1e-3
#: ... in ulps of the time
TIME_ULPS = 16
_TIME_ULPS = TIME_ULPS * sys.float_info.epsilon
#: the constants the lean binding (``fmus/lean_binding.c``) shares with the slaves, their one home: the build
#: compiles the binding with each as a ``-D`` definition (``pmsm_ev_fmus.build``), the C source defines none
BINDING_CONSTANTS = {"COMPILED_BUFFER": f"{COMPILED_BUFFER}L", "LIVE_SLOT": f"({LIVE_SLOT}L)",
                     "CONTINUITY_TOLERANCE": repr(CONTINUITY_TOLERANCE), "TIME_ULPS": str(TIME_ULPS)}


class FmuStateError(ValueError):
    """A state given to ``fmi2SetFMUstate`` that is not one of this FMU's (its fields differ)."""


def check_fields(what: str, state, names) -> dict:
    """``state`` if it is a dict with exactly the fields ``names``; else ``FmuStateError`` naming the
    missing and unknown ones."""
    if not isinstance(state, dict):
        raise FmuStateError(f"{what}: a dict of named fields expected (got {type(state).__name__})")
    missing, unknown = sorted(set(names) - set(state)), sorted(set(state) - set(names))
    if missing or unknown:
        raise FmuStateError(f"{what}: the fields differ from this FMU's (a state of another FMU or version?): "
                            f"missing {missing}, unknown {unknown}")
    return state


class SimulationError(RuntimeError):
    """The physics cannot continue (e.g. its state is no longer finite)."""


def packaged_starts(resources) -> dict:
    """The parameter defaults of a packaged copy (``resources/start_values.json``: a JSON
    object, name -> value), {} when the FMU has none."""
    path = Path(resources) / START_VALUES_FILE if resources else None
    if path is None or not path.is_file():
        return {}
    values = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(values, dict):
        raise FmuUsageError(f"{START_VALUES_FILE}: not a JSON object")
    return values


def _packaged_value(name: str, value, kind):
    """``value`` from ``start_values.json`` as a value of the parameter's FMI type."""
    ok = {Real: isinstance(value, (int, float)) and not isinstance(value, bool),
          Integer: isinstance(value, int) and not isinstance(value, bool),
          Boolean: isinstance(value, bool), String: isinstance(value, str)}[kind]
    if not ok:
        raise FmuUsageError(f"{START_VALUES_FILE}: {name} = {value!r} is not a {kind.__name__}")
    return float(value) if kind is Real else value


def _wrong_access(name: str, what: str, *_args):
    raise FmuUsageError(f"variable {name!r} {what}")


def _checked_step(method):
    """``do_step`` of a subclass behind the FMI 2.0 checks (``DriveSlave.refusal``): a call in the wrong state or
    at a communication point that does not continue the last step raises ``FmiCallError`` (pythonfmu: fmi2Fatal);
    a step longer than the slave integrates to its accuracy is logged and returns False (fmi2Discard). The lean
    binding calls the unchecked method (``__wrapped__``) after the same checks of its own."""
    @functools.wraps(method)
    def do_step(self, current_time, step_size):
        refused = self.refusal("fmi2DoStep", current_time, step_size)
        if refused is not None:
            status, message = refused
            if status == FMI2_DISCARD:
                self.log(message, Fmi2Status.discard)
                return False
            self._fail("fmi2DoStep", FmiCallError(message))
            raise FmiCallError(message)
        done = method(self, current_time, step_size)
        if done:
            self._next_time, self._last_step = current_time + step_size, step_size
        return done

    return do_step


class DriveSlave(Fmi2Slave):
    """Base of the project's slaves (abstract: subclasses give the physics hooks).

    Subclasses declare their variables in ``__init__`` and implement ``build`` (make the
    physics object from the parameters, copy its outputs), ``do_step``,
    ``physics_state`` and ``restore_physics``.

    FMI 2.0's state machine and arguments are checked here, for every slave (``refusal``): a call in the wrong
    state, a non-finite Real input, a communication point that does not continue the last step (without an FMU
    state restored) are refused, a step longer than ``max_step`` discarded.
    """

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        step = cls.__dict__.get("do_step")
        if step is not None and not hasattr(step, "__wrapped__"):
            cls.do_step = _checked_step(step)
        init = cls.__init__

        @functools.wraps(init)
        def __init__(self, *args, **kw):
            init(self, *args, **kw)
            if type(self) is cls:  # the most derived class is done: every variable declared
                self._offer()

        cls.__init__ = __init__

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.author = AUTHOR
        self.license = LICENSE
        self.default_experiment = DefaultExperiment(start_time=START_TIME, stop_time=STOP_TIME,
                                                    step_size=STEP_SIZE)
        self._units: dict[str, str | None] = {}
        self._display_units: dict[str, str] = {}
        self._start_dependencies: dict[str, tuple[str, ...]] = {}
        self._parameter_names: list[str] = []
        self.parameter_notes: dict[str, str] = {}  # name -> text appended to the description
        self._real_getters: list = []
        self._real_setters: list = []
        #: by value reference: the attribute of a Real variable (get_real), None otherwise
        self._real_names: list = []
        #: by value reference: the attribute of a Real input (set_real writes it), None otherwise
        self._real_inputs: list = []
        #: get_real's readers by the tuple of value references asked for (a master asks for the same few
        #: sets every step): (operator.attrgetter of their attributes, whether it is one)
        self._real_reads: dict = {}
        self._initialized = False
        self._stale = True  # parameters changed since the physics was built
        self._built_with = None  # parameter values the physics was built with
        self._packaged_starts = packaged_starts(self.resources)
        release_at_exit(self.resources)
        self._fmi_state = INSTANTIATED
        self._in_step_mode = False  # read by the lean binding
        self._next_time = None  # where the last step ended (None: any communication point)
        self._last_step = 0.0
        self._max_step = math.inf  # the longest step the slave integrates to its accuracy (``max_step``)

    # -- declaring variables ---------------------------------------------------------
    def _declare(self, var, value, unit=None, display_unit=None):
        name = var.name
        if name in self._units:
            raise ValueError(f"variable {name!r} declared twice")
        setattr(self, name, value)
        if var.getter is None:
            var.getter = functools.partial(getattr, self, name)
        self._units[name] = unit
        if display_unit:
            self._display_units[name] = display_unit
        vr = len(self.vars)
        self.register_variable(var, nested=False)
        assert var.value_reference == vr == len(self._real_getters)
        is_input = isinstance(var, Real) and var.causality == Fmi2Causality.input
        self._real_names.append(name if isinstance(var, Real) else None)
        self._real_inputs.append(name if is_input else None)
        if isinstance(var, Real):
            self._real_getters.append(var.getter)
            if var.causality == Fmi2Causality.output:
                self._real_setters.append(functools.partial(_wrong_access, name, "is an output and cannot be set"))
            else:
                self._real_setters.append(var.setter)
        else:
            self._real_getters.append(functools.partial(_wrong_access, name, f"is not a Real ({type(var).__name__})"))
            self._real_setters.append(functools.partial(_wrong_access, name, f"is not a Real ({type(var).__name__})"))

    def add_input(self, name: str, unit: str | None, description: str, start: float = 0.0,
                  display_unit: str | None = None) -> None:
        """A Real input, continuous; its value is held over each communication step."""
        var = Real(name, causality=Fmi2Causality.input, variability=Fmi2Variability.continuous,
                   description=description, setter=functools.partial(setattr, self, name))
        self._declare(var, float(start), unit, display_unit)

    def add_output(self, name: str, unit: str | None, description: str, *, discrete: bool = False,
                   start: float | None = 0.0, start_dependencies=(), display_unit: str | None = None) -> None:
        """A Real output. ``start=None``: its initial value is calculated from the parameters
        named in ``start_dependencies`` (initial="calculated", listed in InitialUnknowns);
        otherwise it is ``start`` until the first step, whatever the parameters
        (initial="exact")."""
        variability = Fmi2Variability.discrete if discrete else Fmi2Variability.continuous
        initial = Fmi2Initial.calculated if start is None else Fmi2Initial.exact
        var = Real(name, causality=Fmi2Causality.output, variability=variability, initial=initial,
                   description=description)
        if start is None:
            self._start_dependencies[name] = tuple(start_dependencies)
        self._declare(var, 0.0 if start is None else float(start), unit, display_unit)

    def add_parameter(self, name: str, value, kind=None, description: str | None = None,
                      unit: str | None = None) -> None:
        """A parameter (fixed, initial="exact"); unit and description default to ``metadata``."""
        known_unit, known_text = PARAMETERS.get(name, (None, None))
        unit = unit if unit is not None else known_unit
        description = description or known_text or f"{name} (see pmsm_ev.params)"
        if name in self.parameter_notes:
            description += "; " + self.parameter_notes[name]
        kind = kind or (Boolean if isinstance(value, bool) else Integer if isinstance(value, int)
                        else Real if isinstance(value, float) else String)
        if kind is Real:
            value = float(value)
        if name in self._packaged_starts:  # the default of this packaged copy
            value = _packaged_value(name, self._packaged_starts[name], kind)
        var = kind(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                   initial=Fmi2Initial.exact, description=description,
                   setter=functools.partial(self._set_parameter, name))
        self._declare(var, value, unit)
        self._parameter_names.append(name)

    def add_parameters(self, *groups) -> None:
        """One parameter per field of each dataclass in ``groups`` (a class: default = field
        default; an instance: default = its value)."""
        for group in groups:
            cls, defaults = (group, group()) if isinstance(group, type) else (type(group), group)
            for f in dataclasses.fields(cls):
                type_name = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")
                self.add_parameter(f.name, getattr(defaults, f.name), _KINDS.get(type_name))

    def _set_parameter(self, name, value) -> None:
        if value == getattr(self, name):
            return
        if self._initialized:
            raise FmuUsageError(f"parameter {name!r} is fixed: it cannot change after initialisation")
        setattr(self, name, value)
        self._stale = True

    def parameters(self, cls):
        """The dataclass ``cls`` filled from the current parameter values (not validated)."""
        return cls(**{f.name: getattr(self, f.name) for f in dataclasses.fields(cls)})

    def parameter_values(self) -> tuple:
        return tuple(getattr(self, name) for name in self._parameter_names)

    def mark_built(self) -> None:
        """Called by ``build``: the physics now matches the parameters."""
        self._built_with = self.parameter_values()
        self._stale = False

    # -- hooks ---------------------------------------------------------------------
    def build(self) -> None:  # pragma: no cover - abstract
        """Make the physics from the parameters (raises ParameterError), copy its outputs."""
        raise NotImplementedError

    def physics_state(self):  # pragma: no cover - abstract
        """The physics state as a JSON-serialisable snapshot."""
        raise NotImplementedError

    def restore_physics(self, snapshot) -> None:  # pragma: no cover - abstract
        """Rebuild the physics if the parameters differ, set its state, copy its outputs."""
        raise NotImplementedError

    def forget_physics(self) -> None:  # pragma: no cover - abstract
        """Drop the physics (a state from before initialisation was restored)."""
        raise NotImplementedError

    def needs_rebuild(self) -> bool:
        return self._built_with != self.parameter_values()

    def max_step(self) -> tuple[float, str]:
        """The longest communication step this slave integrates to its stated accuracy, with the parameters it
        was initialised with, and why (a step longer is discarded): none by default (inf)."""
        return math.inf, ""

    # -- FMI 2.0's state machine and arguments ----------------------------------------
    #: inputs the slave never reads (declared by it, e.g. the sensorless unit's theta_meas, omega_meas): any
    #: value is accepted there, NaN included, since none can reach its physics
    unread_inputs: frozenset = frozenset()

    def refusal(self, call: str, *args) -> tuple[int, str] | None:
        """None when FMI 2.0 allows ``call`` (an FMI function's name) with ``args`` now, else (status, the log
        line): fmi2Error for a call in the wrong state, a non-finite Real input, a communication point that does
        not continue the last step; fmi2Discard for a step longer than ``max_step``. The lean binding asks this
        before it forwards a checked call, and where its own checks of the direct path fail."""
        state = self._fmi_state
        if call == "fmi2SetupExperiment" and state != INSTANTIATED:
            return FMI2_ERROR, f"fmi2SetupExperiment in {state}: allowed only before fmi2EnterInitializationMode"
        if call == "fmi2EnterInitializationMode" and state != INSTANTIATED:
            return FMI2_ERROR, (f"fmi2EnterInitializationMode in {state}: allowed once, after fmi2Instantiate or "
                                f"fmi2Reset")
        if call == "fmi2ExitInitializationMode" and state != INITIALIZATION:
            return FMI2_ERROR, f"fmi2ExitInitializationMode in {state}: allowed only after fmi2EnterInitializationMode"
        if call == "fmi2DoStep":
            t, h = args
            if state != STEP_MODE:
                when = "after fmi2Terminate" if state == TERMINATED else "before fmi2ExitInitializationMode"
                return FMI2_ERROR, f"fmi2DoStep {when} (the FMU is in {state})"
            if not math.isfinite(t):
                return FMI2_ERROR, f"fmi2DoStep: the communication point {t!r} is not finite"
            last = self._next_time
            if last is not None and abs(t - last) > CONTINUITY_TOLERANCE * self._last_step + _TIME_ULPS * abs(t):
                return FMI2_ERROR, (f"fmi2DoStep at t = {t!r} s does not continue the last step, which ended at "
                                    f"{last!r} s (restore an FMU state to step from another time)")
            if h > self._max_step:
                return FMI2_DISCARD, f"fmi2DoStep of {h!r} s discarded: {self.max_step()[1]}"
        if call in _TYPED_ACCESS:
            wrong = self._wrong_reference(call, args[0])
            if wrong is not None:
                return FMI2_ERROR, wrong
        if call == "fmi2SetReal":
            vrs, values = args
            inputs = self._real_inputs
            for vr, value in zip(vrs, values):
                if (0 <= vr < len(inputs) and inputs[vr] is not None and inputs[vr] not in self.unread_inputs
                        and not math.isfinite(value)):
                    return FMI2_ERROR, f"fmi2SetReal: input {inputs[vr]!r} = {value!r} is not finite; not set"
        return None

    def _wrong_reference(self, call: str, vrs) -> str | None:
        """The log line for the first of ``vrs`` that names no variable, or one not of the type ``call`` reads or
        writes (``_TYPED_ACCESS``); None when all are right."""
        kind = _TYPED_ACCESS[call]
        done = "read" if call.startswith("fmi2Get") else "set"
        for vr in vrs:
            var = self.vars.get(vr)
            if var is None:
                return f"{call}: no variable has the value reference {vr}; nothing {done}"
            if not isinstance(var, kind):
                return (f"{call}: value reference {vr} is {var.name!r}, a {type(var).__name__}, not a {kind.__name__}; "
                        f"nothing {done}")
        return None

    def _refuse(self, call: str, *args) -> None:
        """Raise ``FmiCallError`` if ``refusal`` refuses ``call`` (pythonfmu's path: fmi2Fatal, the line logged)."""
        refused = self.refusal(call, *args)
        if refused is not None:
            exc = FmiCallError(refused[1])
            self._fail(call, exc)
            raise exc

    # -- FMI calls -------------------------------------------------------------------
    def _fail(self, where: str, exc: Exception) -> None:
        """An FMI call fails with ``exc`` (re-raised by the caller; the wrapper logs its repr):
        keep the objects the C wrapper releases twice alive (pythonfmu 0.6.5 to 0.7.0, see
        ``WRAPPER_CHECKED``). Nothing is logged here (see the module doc: the wrapper would
        pass it to the host with the exception still set)."""
        for obj in (self, self.log_queue, type(self)):
            ctypes.pythonapi.Py_IncRef(ctypes.py_object(obj))

    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self._refuse("fmi2SetupExperiment")
        try:
            if stop_time is not None and not stop_time >= start_time:
                raise FmuUsageError(f"stop time {stop_time!r} s is before the start time {start_time!r} s")
        except Exception as exc:
            self._fail("fmi2SetupExperiment", exc)
            raise

    def _offer(self) -> None:
        """Offer this slave to the lean binding, if the FMU's library is it (``fmus/lean_binding.c``), when it is
        made (in fmi2Instantiate or fmi2Reset): once initialised, the binding reads the Real variables, writes
        the Real inputs and calls ``do_step`` (unchecked) itself after its own checks; it asks ``refusal``
        before it forwards a checked call; everything else, and anything that would fail, goes through
        pythonfmu."""
        offer = lean_offer(self.resources)
        if offer is not None:
            step = self.do_step
            raw = getattr(type(self).do_step, "__wrapped__", None)
            names = {name: vr for vr, name in enumerate(self._real_names) if name is not None}
            slots = [-1] * len(self._real_names)
            for name, slot in self.compiled_slots().items():
                slots[names[name]] = slot
            for name in self.compiled_live():
                slots[names[name]] = LIVE_SLOT
            offer((self, self.__dict__, raw.__get__(self) if raw is not None else step, self._defer_step,
                   self.log_queue, tuple(self._real_names), tuple(name is not None for name in self._real_inputs),
                   self.refusal, self.compiled_step if self._compiled_is_the_step() else None, self.compiled_pull,
                   tuple(slots)))

    def _compiled_is_the_step(self) -> bool:
        """Whether ``compiled_step`` is this slave's ``do_step``: the class that defines the ``do_step`` it runs
        defines ``compiled_step`` too (a subclass with a step of its own, e.g. a benchmark's pass-through unit, has
        no compiled step unless it gives its own)."""
        for klass in type(self).__mro__:
            if "do_step" in klass.__dict__:
                return "compiled_step" in klass.__dict__
        return False

    # -- the compiled step (fmus/README.md, "The compiled step"; ``pmsm_ev.kernels.fmu``) -----------------------
    def compiled_slots(self) -> dict[str, int]:
        """The Real variables the lean binding reads and writes in the compiled step's buffers, by name: their
        slot, ``COMPILED_BUFFER * b + i`` for element i of buffer b (0 the slave's buffer, 1 and 2 the vectors
        ``compiled_step`` names); the others are read through Python. None by default."""
        return {}

    def compiled_live(self) -> tuple[str, ...]:
        """Real outputs outside the compiled step's buffers whose getters read the physics object's buffers (not the
        slave's attributes, which are behind while the buffers hold its values): the lean binding reads them
        through Python without ``compiled_pull`` first, so that the buffers stay the slave's. None by default."""
        return ()

    def compiled_step(self):
        """Called by the lean binding (the GIL held) before it steps in compiled code: None where this slave has
        no compiled step now (the binding runs its Python ``do_step``), else (the C function's address, the
        addresses of its three buffers, their lengths: ``compiled_offer``), the buffers filled from the slave's
        attributes: from then on they hold the slave's inputs, outputs and state until ``compiled_pull``. None by
        default."""
        return None

    def compiled_pull(self) -> None:
        """Called by the lean binding (the GIL held) before any Python runs on this slave after a compiled step:
        the slave's attributes (and its physics object's) from the buffers of ``compiled_step``."""

    def enter_initialization_mode(self):
        self._refuse("fmi2EnterInitializationMode")
        self._fmi_state = INITIALIZATION
        self._next_time, self._last_step = None, 0.0

    def _defer_step(self, exc: BaseException) -> None:
        """The lean binding's ``do_step`` raised ``exc``: raise it again from pythonfmu's fmi2DoStep,
        which the binding calls next, so that pythonfmu reports it as it reports any exception."""
        def raise_again(*_args):
            raise exc

        self.do_step = raise_again

    def exit_initialization_mode(self):
        self._refuse("fmi2ExitInitializationMode")
        try:
            self.build()  # validates the parameters
            self._initialized = True
            self._max_step = self.max_step()[0]
        except Exception as exc:
            self._fail("fmi2ExitInitializationMode", exc)
            raise
        self._fmi_state, self._in_step_mode = STEP_MODE, True

    def terminate(self):
        self._fmi_state, self._in_step_mode = TERMINATED, False

    def get_real(self, vrs):
        try:
            if self._stale:  # only before initialisation: outputs calculated from parameters
                self.build()
            key = tuple(vrs)
            read = self._real_reads.get(key)
            if read is None:
                names = self._real_names
                values = [getattr(self, names[vr]) for vr in vrs]  # raises for a vr that is not a Real
                if 0 < len(key) and len(self._real_reads) < _READS_KEPT:
                    self._real_reads[key] = (operator.attrgetter(*[names[vr] for vr in vrs]), len(key) == 1)
                return values
            get, single = read
            return [get(self)] if single else [*get(self)]
        except Exception as exc:
            exc = self._checked_access(self._real_getters, vrs, exc)
            self._fail("fmi2GetReal", exc)
            raise exc from None

    def set_real(self, vrs, values):
        try:
            inputs, attributes = self._real_inputs, self.__dict__
            for vr, value in zip(vrs, values):
                name = inputs[vr]
                if name is None:  # a parameter (fixed after initialisation) or an error
                    self._real_setters[vr](value)
                elif not math.isfinite(value) and name not in self.unread_inputs:
                    raise FmiCallError(self.refusal("fmi2SetReal", [vr], [value])[1])
                else:
                    attributes[name] = value
        except Exception as exc:
            self._fail("fmi2SetReal", exc)
            raise

    @staticmethod
    def _checked_access(accessors, vrs, exc: Exception) -> Exception:
        """The error of the first value reference that is unknown or of the wrong type
        (its accessor raises FmuUsageError), else ``exc``."""
        for vr in vrs:
            if not 0 <= vr < len(accessors):
                return FmuUsageError(f"no variable has the value reference {vr}")
            if isinstance(accessors[vr], functools.partial) and accessors[vr].func is _wrong_access:
                try:
                    accessors[vr]()
                except FmuUsageError as usage:
                    return usage
        return exc

    def get_integer(self, vrs):
        return self._guarded("fmi2GetInteger", super().get_integer, vrs)

    def get_boolean(self, vrs):
        return self._guarded("fmi2GetBoolean", super().get_boolean, vrs)

    def get_string(self, vrs):
        return self._guarded("fmi2GetString", super().get_string, vrs)

    def set_integer(self, vrs, values):
        return self._guarded("fmi2SetInteger", super().set_integer, vrs, values)

    def set_boolean(self, vrs, values):
        return self._guarded("fmi2SetBoolean", super().set_boolean, vrs, values)

    def set_string(self, vrs, values):
        return self._guarded("fmi2SetString", super().set_string, vrs, values)

    def _guarded(self, where, call, *args):
        try:
            return call(*args)
        except Exception as exc:
            self._fail(where, exc)
            raise

    def _get_fmu_state(self):
        """Every variable, plus the physics state once initialised (JSON-serialisable)."""
        try:
            return {
                "variables": {var.name: getattr(self, var.name) for var in self.vars.values()},
                "initialized": self._initialized,
                "physics": self.physics_state() if self._initialized else None,
            }
        except Exception as exc:
            self._fail("fmi2GetFMUstate", exc)
            raise

    def _set_fmu_state(self, state):
        try:
            check_fields(f"{type(self).__name__} FMU state", state, ("variables", "initialized", "physics"))
            check_fields(f"{type(self).__name__} FMU state, variables", state["variables"],
                         [var.name for var in self.vars.values()])
            for name, value in state["variables"].items():
                setattr(self, name, value)
            self._initialized = bool(state["initialized"])
            if self._initialized:
                self.restore_physics(state["physics"])
                self._max_step = self.max_step()[0]
                self._fmi_state = STEP_MODE
            else:
                self.forget_physics()
                self._built_with = None
                self._stale = True
                if self._fmi_state not in (INSTANTIATED, INITIALIZATION):
                    self._fmi_state = INSTANTIATED
            self._in_step_mode = self._fmi_state == STEP_MODE
            self._next_time, self._last_step = None, 0.0  # a restored state steps from any time
        except Exception as exc:
            self._fail("fmi2SetFMUstate", exc)
            raise

    # -- modelDescription ------------------------------------------------------------
    def to_xml(self, model_options=None):
        root = super().to_xml(model_options or {})
        variables = list(self.vars.values())
        index = {var.name: i + 1 for i, var in enumerate(variables)}

        # UnitDefinitions go right after CoSimulation (FMI 2.0 schema order)
        used = sorted({u for u in self._units.values() if u})
        definitions = Element("UnitDefinitions")
        for unit in used:
            element = SubElement(definitions, "Unit", name=unit)
            SubElement(element, "BaseUnit", {k: str(v) for k, v in UNITS[unit].items()})
            for display, factor in DISPLAY_UNITS.get(unit, ()):
                SubElement(element, "DisplayUnit", name=display, factor=repr(factor))
        if used:
            root.insert(list(root).index(root.find("CoSimulation")) + 1, definitions)

        for element in root.find("ModelVariables"):
            name = element.get("name")
            typed = element[0]
            unit = self._units.get(name)
            if unit:
                typed.set("unit", unit)
            if name in self._display_units:
                typed.set("displayUnit", self._display_units[name])
            if typed.tag == "Real" and "start" in typed.attrib:
                typed.set("start", repr(float(getattr(self, name))))  # exact round trip

        structure = root.find("ModelStructure")
        for child in list(structure):
            structure.remove(child)
        outputs = [var for var in variables if var.causality == Fmi2Causality.output]
        if outputs:
            node = SubElement(structure, "Outputs")
            for var in outputs:  # computed inside do_step only: no direct feedthrough
                SubElement(node, "Unknown", index=str(index[var.name]), dependencies="")
        calculated = [var for var in outputs if var.initial == Fmi2Initial.calculated]
        if calculated:
            node = SubElement(structure, "InitialUnknowns")
            for var in calculated:
                deps = sorted(index[n] for n in self._start_dependencies[var.name])
                SubElement(node, "Unknown", index=str(index[var.name]),
                           dependencies=" ".join(str(d) for d in deps))
        return root


class PassThrough:
    """The benchmark's pass-through units (``PassThroughPlant``, ``PassThroughFoc``; ``pmsm-cosim bench``): put
    before a drive slave's class, it keeps that slave's interface, parameters and FMI plumbing but ``do_step``
    computes nothing (the outputs keep their initial values), and its compiled step is the real slave's buffers
    with the C step that computes nothing (``pmsm_ev.kernels.fmu``, "pass"): the floor of the FMI calls, in
    compiled code where the kernels are compiled."""

    @_checked_step  # behind the FMI 2.0 checks as every slave's (``DriveSlave.__init_subclass__`` wraps only a
    def do_step(self, current_time, step_size):  # do_step of the class itself)
        return True

    def compiled_step(self):
        offer = super().compiled_step()
        if offer is None:
            return None
        step = self.__dict__.get("_pass_address")
        if step is None:
            from pmsm_ev import accel  # noqa: PLC0415 - compiled kernels exist: the offer above says so

            step = self._pass_address = accel.kernels().fmu_step_address("pass")
        return (step, *offer[1:])
