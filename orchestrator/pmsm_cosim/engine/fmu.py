"""One FMU instance on fmpy's FMI 2.0 or FMI 3.0 co-simulation API.

:class:`FmuInstance` reads the model description (cheap, no library loaded) so that a
system can be checked before anything is instantiated; :meth:`FmuInstance.instantiate`
then extracts the FMU, loads its library and runs instantiate, setupExperiment, the
start values, enterInitializationMode; :meth:`exit_initialization` completes the
initialization. For the stepping loop it exposes the raw ctypes entry points
(``get_real``, ``set_real``, ``do_step``, ...) and the instance handle ``handle``: they
are called with preallocated value-reference and value arrays, no per-call wrapping;
and leaner copies of fmi2DoStep and of fmi2Get/fmi2Set of every type (``lean``, see
:class:`LeanCalls`) for the hot loop.
The FMU's log messages are collected so a refusal can be reported in one line.

An FMI 3.0 co-simulation unit (fmpy's ``FMU3Slave``) is the same to the master: its variables of the types the
master connects and records take the names of their FMI 2.0 families (``Float64`` is ``Real``, ``Int32``
``Integer``; ``Boolean`` and ``String`` keep theirs: :data:`FMI3_KINDS`), its calls are fmi3Get/SetFloat64,
Int32, Boolean, String and fmi3DoStep (:class:`LeanCalls`, the same arguments plus the FMI 3.0 ones), its
instantiation has no fmi2SetupExperiment (the start and stop times go to fmi3EnterInitializationMode), and an
fmi3DoStep that asks to end the simulation (terminateSimulation) is the master's fmi2Discard with fmi2Terminated.
Variables of the other FMI 3.0 types (Float32, the other integers, Binary, Clock, an Int64 Enumeration) keep their
FMI 3.0 type name and cannot be connected, recorded or given start values.

Clocks (FMI 3.0 co-simulation with event mode): a unit with ``hasEventMode="true"`` whose every input clock is
periodic with a constant interval (``intervalVariability="constant"``, ``intervalDecimal``: :meth:`FmuInstance.clocks`)
is instantiated with eventModeUsed when the master ticks it (``event_mode``), and ticked at each multiple of its
interval: fmi3EnterEventMode, fmi3SetClock of its clocks that tick then, fmi3UpdateDiscreteStates,
fmi3EnterStepMode, before its fmi3DoStep from that instant (:meth:`LeanCalls.tick`). Any other clock is refused with
one line.
"""

from __future__ import annotations

import _ctypes
import ast
import atexit
import ctypes
import functools
import math
import os
import re
import shutil
import sys
import zipfile
from pathlib import Path
from xml.etree import ElementTree

from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    calloc,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    fmi2LastSuccessfulTime,
    fmi2Terminated,
    free,
)
from fmpy.fmi3 import FMU3Slave
from fmpy.model_description import ValidationError

from .errors import CosimError, close_matches, one_line

STATUS = ("OK", "warning", "discard", "error", "fatal", "pending")
FMI2_DISCARD, FMI2_ERROR, FMI2_FATAL = 2, 3, 4
#: instances left alone after fmi2Fatal (FMI 2.0: no further call to any function of
#: the instance, fmi2FreeInstance included); kept referenced so their callbacks stay alive
_ABANDONED: list = []
#: the FMI 2.0 value types by their get/set calls (an Enumeration is an Integer to them)
VALUE_KINDS = ("Real", "Integer", "Boolean", "String")
#: the FMI 3.0 types the master handles, by the FMI 2.0 family whose calls it makes (module doc)
FMI3_KINDS = {"Float64": "Real", "Int32": "Integer", "Boolean": "Boolean", "String": "String"}
#: an FMI 3.0 Enumeration is an Int64: a type this master does not handle (FMI 2.0's is an Integer)
FMI3_ENUMERATION = "Int64 Enumeration"
#: the FMI versions of the co-simulation units the master runs
FMI_VERSIONS = ("2.0", "3.0")
#: the FMI 3.0 calls of each FMI 2.0 family (Enumeration: FMI 2.0's, an Integer)
FMI3_CALLS = {"Real": "Float64", "Integer": "Int32", "Enumeration": "Int32", "Boolean": "Boolean", "String": "String"}
#: the FMI 3.0 calls of a clock's tick, in order (``LeanCalls.tick``)
TICK_CALLS = ("fmi3EnterEventMode", "fmi3SetClock", "fmi3UpdateDiscreteStates", "fmi3EnterStepMode")
#: causalities whose value may be set before initialization
SETTABLE_CAUSALITIES = ("parameter", "input")
_EXC_REPR = re.compile(r"^([A-Za-z_][A-Za-z0-9_.]*(?:Error|Exception))\((.*)\)$", re.S)
_EXC_TEXT = re.compile(r"(?:^|: )([A-Za-z_][A-Za-z0-9_]*(?:Error|Exception)): (.*)$")
#: generationTool prefix of Python FMUs, whose every call holds the GIL anyway
PYTHONFMU_TOOL = "PythonFMU"
#: exception classes whose text alone says it all
PLAIN_EXCEPTIONS = ("ValueError", "ParameterError", "ProfileError")
#: the function by which a pythonfmu-built library resets its interpreter guard (docs/errors.md, "Crash at exit")
PYTHONFMU_GUARD_RESET = "finalizePythonInterpreter"
#: the libraries (paths) of the pythonfmu-built FMUs this process loaded, whose guard is reset at its exit
_GUARDED_LIBRARIES: set[str] = set()
_GUARD_RESET_PLANNED = False


def reset_guard_at_exit(library) -> None:
    """Have a loaded FMU library (a ctypes library) that pythonfmu built reset its interpreter guard when this
    Python exits: pythonfmu 0.6.5-0.7.0 writes into freed memory at exit otherwise, whenever its library is still
    loaded, and the process may abort after its work is done (exit code 134, "corrupted double-linked list";
    docs/errors.md, "Crash at exit"). The project's FMUs do this themselves (``slave_support.release_at_exit``, so
    any Python host has it); an FMU of another origin, a user's or the tests' toys, does not, so the master does
    it for every FMU it loads. Only a library that exports the reset, only on Linux (pythonfmu resets it from
    DllMain elsewhere, in order) and only in a Python program (``sys.orig_argv`` set): where pythonfmu started
    the interpreter itself, the reset would finalize it, which is pythonfmu's to do."""
    global _GUARD_RESET_PLANNED
    if not sys.platform.startswith("linux") or not getattr(sys, "orig_argv", None):
        return
    try:
        getattr(library, PYTHONFMU_GUARD_RESET)
    except AttributeError:  # not pythonfmu's library (or one with another lifetime)
        return
    _GUARDED_LIBRARIES.add(library._name)
    if not _GUARD_RESET_PLANNED:
        atexit.register(reset_guards)  # Python's atexit runs before exit()'s C++ static destructors
        _GUARD_RESET_PLANNED = True


def reset_guards() -> None:
    """Reset the interpreter guard of every library ``reset_guard_at_exit`` registered that is still loaded (one
    that dlclose unloaded ran its destructors in order); registered with ``atexit``. Resetting twice (the
    project's FMUs reset theirs too) does nothing the second time: the guard is null."""
    for path in sorted(_GUARDED_LIBRARIES):
        try:
            library = ctypes.CDLL(path, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
        except OSError:
            continue
        reset = getattr(library, PYTHONFMU_GUARD_RESET)
        reset.restype = None
        reset()


def _exception_text(cls: str, text: str) -> str:
    short = cls.rsplit(".", 1)[-1]
    if short in PLAIN_EXCEPTIONS and text:
        return text
    return f"{short}: {text}" if text else short


def fmu_reason(message: str) -> str:
    """The useful part of an FMU log message.

    An exception raised inside a Python FMU shows up either as its repr on the last line
    (``...\\nValueError('text')``, PythonFMU's own report) or as ``...: ParameterError:
    text`` (the project's FMUs). This returns ``text``, prefixed by the exception class
    unless it is a plain value error.
    """
    lines = [ln.strip() for ln in str(message).splitlines() if ln.strip()]
    if not lines:
        return ""
    last = lines[-1]
    m = _EXC_REPR.match(last)
    if m:
        cls, args = m.group(1), m.group(2)
        try:
            value = ast.literal_eval(args) if args else ""
        except (ValueError, SyntaxError):
            value = args
        return _exception_text(cls, value if isinstance(value, str) else str(value))
    m = _EXC_TEXT.search(last)
    if m:
        return _exception_text(m.group(1), m.group(2).strip())
    return one_line(message)


def variable_unit(sv) -> str:
    """The unit a variable declares (directly or through its declared type), or ""."""
    if getattr(sv, "unit", None):
        return sv.unit
    dt = getattr(sv, "declaredType", None)
    return (getattr(dt, "unit", None) or "") if dt is not None else ""


def _fmi_version(path: Path, who: str) -> str:
    """The fmiVersion of an FMU file, after checking that it is a zip with a modelDescription.xml."""
    if not zipfile.is_zipfile(path):
        raise CosimError(f"{who}{path}: not an FMU (not a zip archive)")
    try:
        with zipfile.ZipFile(path) as z:
            if "modelDescription.xml" not in z.namelist():
                raise CosimError(f"{who}{path}: not an FMU (the archive has no modelDescription.xml)")
            with z.open("modelDescription.xml") as fh:
                for _event, element in ElementTree.iterparse(fh, events=("start",)):
                    return str(element.get("fmiVersion") or "")  # the root element
    except CosimError:
        raise
    except ElementTree.ParseError as exc:
        raise CosimError(f"{who}{path}: modelDescription.xml is not well-formed XML ({one_line(exc)})") from None
    except (zipfile.BadZipFile, OSError, ValueError, RuntimeError, EOFError) as exc:
        raise CosimError(f"{who}{path}: not an FMU ({one_line(exc)})") from None
    return ""


def read_description(path: Path, label: str = ""):
    """fmpy's model description of an FMU file, or a one-line CosimError saying what is wrong:
    missing, not a zip, no modelDescription.xml, not FMI 2.0, no co-simulation interface."""
    who = f"{label}: " if label else ""
    if path.is_dir():
        raise CosimError(f"{who}{path}: is a directory, not an .fmu file")
    if not path.is_file():
        raise CosimError(f"{who}FMU not found: {path}")
    version = _fmi_version(path, who)
    if version not in FMI_VERSIONS:
        what = f"an FMI {version} FMU" if version else "an FMU without fmiVersion"
        raise CosimError(f"{who}{path}: {what}; only FMI 2.0 and FMI 3.0 co-simulation FMUs are supported")
    try:
        md = read_model_description(str(path), validate=True)
    except ValidationError as exc:
        raise CosimError(f"{who}{path}: invalid modelDescription.xml ({one_line(exc)})") from None
    except (zipfile.BadZipFile, KeyError, OSError) as exc:
        raise CosimError(f"{who}{path}: not an FMU ({one_line(exc)})") from None
    except Exception as exc:  # fmpy raises plain Exceptions for malformed XML
        raise CosimError(f"{who}{path}: cannot read the model description ({one_line(exc)})") from None
    if md.coSimulation is None:
        what = "a Model Exchange FMU" if md.modelExchange is not None else "an FMU"
        raise CosimError(f"{who}{path}: {what} without a co-simulation interface (no <CoSimulation>); "
                         f"only co-simulation FMUs are supported")
    if version == "3.0":
        for sv in md.modelVariables:  # the FMI 2.0 family of each type the master handles (module doc)
            sv.type = FMI3_ENUMERATION if sv.type == "Enumeration" else FMI3_KINDS.get(sv.type, sv.type)
        _clock_timing(path, md)
    return md


def _clock_timing(path: Path, md) -> None:
    """The intervalDecimal and shiftDecimal of an FMI 3.0 model description's clocks (fmpy 0.3 does not read them)
    on its variables."""
    clocks = {sv.valueReference: sv for sv in md.modelVariables if sv.type == "Clock"}
    if not clocks:
        return
    with zipfile.ZipFile(path) as z:
        root = ElementTree.fromstring(z.read("modelDescription.xml"))
    for element in root.iter("Clock"):
        sv = clocks.get(int(element.get("valueReference", -1)))
        for key in ("intervalDecimal", "shiftDecimal"):
            if sv is not None and element.get(key) is not None:
                try:
                    setattr(sv, key, float(element.get(key)))
                except ValueError:
                    raise CosimError(f"{path}: clock {sv.name!r}: {key}={element.get(key)!r} is not a number") from None


def fmi_major(md) -> int:
    """2 or 3: the FMI version of a model description (``read_description``'s)."""
    return 3 if str(md.fmiVersion).startswith("3") else 2


def convert_start(sv, value, where: str):
    """A start value in the Python type fmpy's setter of ``sv``'s type expects (an
    Enumeration: its integer value, or the name of one of its items)."""
    kind = sv.type
    try:
        if kind == "Real":
            if isinstance(value, bool):
                raise ValueError
            value = float(value)
            if not math.isfinite(value):
                raise CosimError(f"{where}: {value!r} is not a finite Real value")
            return value
        if kind in ("Integer", "Enumeration"):
            if isinstance(value, bool):
                raise ValueError
            if kind == "Enumeration" and isinstance(value, str):
                items = {item.name: int(item.value) for item in getattr(sv.declaredType, "items", None) or ()}
                if value.strip() in items:  # an item by its name
                    return items[value.strip()]
            if isinstance(value, str):
                value = float(value) if any(ch in value for ch in ".eE") else int(value, 0)
            if isinstance(value, float):
                if not value.is_integer():
                    raise ValueError
                value = int(value)
            return int(value)
        if kind == "Boolean":
            if isinstance(value, bool):
                return value
            if isinstance(value, (int, float)) and value in (0, 1):
                return bool(value)
            if isinstance(value, str) and value.strip().lower() in ("true", "false", "1", "0"):
                return value.strip().lower() in ("true", "1")
            raise ValueError
        if kind == "String":
            return value if isinstance(value, str) else str(value)
    except (ValueError, TypeError, OverflowError):
        pass
    items = getattr(getattr(sv, "declaredType", None), "items", None) if kind == "Enumeration" else None
    listed = f" (items: {', '.join(f'{item.name}={item.value}' for item in items)})" if items else ""
    raise CosimError(f"{where}: {value!r} is not a valid {kind} value{listed}")


class FmuInstance:
    """An FMU file, its model description and (after ``instantiate``) a live instance."""

    def __init__(self, name: str, path: Path):
        self.name = name
        self.path = Path(path)
        self.md = read_description(self.path, name)
        self.variables = {sv.name: sv for sv in self.md.modelVariables}
        self.model_identifier = self.md.coSimulation.modelIdentifier
        self.fmi = fmi_major(self.md)  #: 2 or 3
        self.event_mode = False  #: FMI 3.0: instantiated with eventModeUsed, its clocks ticked by the master
        self.fmu: FMU2Slave | FMU3Slave | None = None
        self.unzip_dir: str | None = None
        self.handle = None
        self.messages: list[tuple[int, str]] = []  #: (status, text) of every logged message
        self.worst_status = 0  #: the worst status an FMI call of this instance returned
        self._initialized = False
        self._mark = 0
        self._logger = fmi2CallbackLoggerTYPE(self._log)  # FMI 3.0: fmpy wraps _log3 itself
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = self._logger
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.lean: LeanCalls | None = None  #: set by instantiate()

    # -- model description look-ups ----------------------------------------------
    def variable(self, name: str, context: str = ""):
        sv = self.variables.get(name)
        if sv is None:
            ctx = f"{context}: " if context else ""
            raise CosimError(f"{ctx}{self.name} ({self.path.name}) has no variable {name!r}"
                             f"{close_matches(name, self.variables)}")
        return sv

    def clocks(self) -> dict[int, float]:
        """{value reference: interval [s]} of this unit's input clocks, for a unit with event mode (FMI 3.0); {} for
        one without. A clock the master cannot tick (not an input, not periodic with a constant interval given as
        intervalDecimal, shifted) is a CosimError naming it."""
        cs = self.md.coSimulation
        if self.fmi != 3 or not getattr(cs, "hasEventMode", False):
            return {}
        out = {}
        for sv in self.md.modelVariables:
            if sv.type != "Clock":
                continue
            interval = sv.intervalDecimal
            if (sv.causality != "input" or sv.intervalVariability != "constant" or interval is None
                    or not math.isfinite(float(interval)) or float(interval) <= 0 or float(sv.shiftDecimal or 0)):
                raise CosimError(f"{self.name} ({self.path.name}): clock {sv.name!r} is not a periodic input clock "
                                 f"with a constant interval (intervalVariability=\"constant\", intervalDecimal > 0, "
                                 f"no shift): the master ticks only those")
            out[sv.valueReference] = float(interval)
        return out

    def call(self, action: str, kind: str = "") -> str:
        """The name of this instance's FMI function: ``call("DoStep")`` is fmi2DoStep or fmi3DoStep,
        ``call("Get", "Real")`` fmi2GetReal or fmi3GetFloat64."""
        if self.fmi == 3 and kind:
            kind = FMI3_CALLS[kind]
        return f"fmi{self.fmi}{action}{kind}"

    # -- logging -----------------------------------------------------------------
    def _log(self, env, instance_name, status, category, message):
        text = message.decode("utf-8", "replace") if message else ""
        self.messages.append((int(status), text))

    def _log3(self, env, status, category, message):
        self._log(env, None, status, category, message)

    def last_problem(self) -> str:
        """Why the last call failed: the first error (else warning) logged since ``mark``."""
        recent = self.messages[self._mark:]
        for threshold in (3, 2, 1):
            for status, text in recent:
                if status >= threshold:
                    return fmu_reason(text)
        return fmu_reason(recent[-1][1]) if recent else ""

    def terminate_requested(self) -> bool:
        """fmi2GetBooleanStatus(fmi2Terminated): the slave asks to end the simulation (FMI 2.0:
        asked after an fmi2DoStep returned fmi2Discard). False if the FMU cannot say. FMI 3.0: the
        terminateSimulation of its last fmi3DoStep."""
        if self.fmi == 3:
            return self.lean is not None and bool(self.lean.flags[1])
        try:
            return self.fmu.getBooleanStatus(fmi2Terminated)
        except Exception:  # FMICallException, or a slave without the status
            return False

    def last_successful_time(self) -> float | None:
        """fmi2GetRealStatus(fmi2LastSuccessfulTime): where the FMU's last step ended (FMI 2.0: asked after an
        fmi2DoStep returned fmi2Discard; a step that ends the simulation may end inside it). None if the FMU
        cannot say, or says something that is not a finite number. FMI 3.0: the lastSuccessfulTime of its last
        fmi3DoStep."""
        if self.fmi == 3:
            value = self.lean.last.value if self.lean is not None else math.nan
            return value if math.isfinite(value) else None
        try:
            value = float(self.fmu.getRealStatus(fmi2LastSuccessfulTime))
        except Exception:  # FMICallException, or a slave without the status
            return None
        return value if math.isfinite(value) else None

    def logged_error(self) -> bool:
        """Whether a message of status fmi2Error or worse was logged since ``mark``."""
        return any(status >= FMI2_ERROR for status, _text in self.messages[self._mark:])

    def mark(self) -> None:
        """Forget older messages for ``last_problem`` (called before each FMI phase)."""
        self._mark = len(self.messages)

    def note_status(self, status: int) -> None:
        """Remember a failed call's status (``close`` must not call into a fatal instance)."""
        self.worst_status = max(self.worst_status, int(status))

    def _refused(self, action: str, exc: Exception | None = None) -> CosimError:
        if isinstance(exc, FMICallException):
            self.note_status(exc.status)
        elif exc is not None:  # a failed fmi2Instantiate: there is no instance to free
            self.note_status(FMI2_FATAL)
        reason = self.last_problem()
        if not reason and exc is not None:
            reason = one_line(exc)
        return CosimError(f"{self.name} ({self.path.name}): {action} refused" + (f": {reason}" if reason else ""))

    # -- life cycle -------------------------------------------------------------------
    def instantiate(self, start_time: float, stop_time: float, start_values: dict) -> None:
        """Extract, load, instantiate, setupExperiment, set start values, enterInitializationMode (FMI 3.0:
        instantiate, the start values, enterInitializationMode with the start and stop times)."""
        try:
            self.unzip_dir = extract(str(self.path))
        except Exception as exc:
            raise CosimError(f"{self.name}: cannot extract {self.path} ({one_line(exc)})") from None
        cwd = os.getcwd()
        try:
            kind = FMU3Slave if self.fmi == 3 else FMU2Slave
            self.fmu = kind(guid=self.md.guid, unzipDirectory=self.unzip_dir,
                            modelIdentifier=self.model_identifier, instanceName=self.name)
        except Exception as exc:
            raise CosimError(f"{self.name}: cannot load the FMU's binary ({one_line(exc)})") from None
        finally:
            os.chdir(cwd)  # fmpy changes to the binary's directory and stays there if loading fails
        reset_guard_at_exit(self.fmu.dll)
        python_fmu = (self.md.generationTool or "").startswith(PYTHONFMU_TOOL)
        if self.fmi == 3:
            self._instantiate3(start_time, stop_time, start_values, python_fmu)
            return
        try:
            self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)
        except Exception as exc:
            raise self._refused("fmi2Instantiate", exc) from None
        self.handle = self.fmu.component
        self.lean = LeanCalls(self.fmu, python_fmu)
        try:
            self.fmu.setupExperiment(startTime=start_time, stopTime=stop_time)
        except FMICallException as exc:
            raise self._refused("fmi2SetupExperiment", exc) from None
        for var, value in start_values.items():
            self.set_value(var, value, f"start value {self.name}.{var}")
        self.mark()
        try:
            self.fmu.enterInitializationMode()
        except FMICallException as exc:
            raise self._refused("fmi2EnterInitializationMode", exc) from None

    def _instantiate3(self, start_time: float, stop_time: float, start_values: dict, python_fmu: bool) -> None:
        try:
            self.fmu.instantiate(loggingOn=True, logMessage=self._log3, eventModeUsed=self.event_mode)
        except Exception as exc:
            raise self._refused("fmi3InstantiateCoSimulation", exc) from None
        self.handle = self.fmu.component
        self.lean = LeanCalls(self.fmu, python_fmu, fmi=3, clocks=list(self.clocks()) if self.event_mode else ())
        for var, value in start_values.items():
            self.set_value(var, value, f"start value {self.name}.{var}")
        self.mark()
        try:
            self.fmu.enterInitializationMode(startTime=start_time, stopTime=stop_time)
        except FMICallException as exc:
            raise self._refused("fmi3EnterInitializationMode", exc) from None

    def exit_initialization(self) -> None:
        self.mark()
        try:
            self.fmu.exitInitializationMode()
        except FMICallException as exc:
            raise self._refused(f"{self.call('ExitInitializationMode')} (start values)", exc) from None
        self._initialized = True
        self.mark()

    def check_settable(self, name: str, context: str):
        sv = self.variable(name, context)
        if sv.type not in (*VALUE_KINDS, "Enumeration"):
            raise CosimError(f"{context}: {self.name}.{name} is {sv.type}; the master sets Real (FMI 3.0: Float64), "
                             f"Integer (Int32), Enumeration, Boolean and String variables")
        ok = sv.causality in SETTABLE_CAUSALITIES or (
            sv.initial in ("exact", "approx") and sv.causality not in ("calculatedParameter", "independent"))
        if not ok or sv.variability == "constant":
            raise CosimError(f"{context}: {self.name}.{name} is a {sv.variability} {sv.causality} "
                             f"and cannot be set")
        return sv

    def set_value(self, name: str, value, context: str) -> None:
        """Set one variable by its type (Real/Integer/Enumeration/Boolean/String)."""
        sv = self.check_settable(name, context)
        value = convert_start(sv, value, context)
        vr = [sv.valueReference]
        self.mark()
        try:
            if self.fmi == 3:
                getattr(self.fmu, f"set{FMI3_CALLS[sv.type]}")(vr, [value])
            elif sv.type == "Real":
                self.fmu.setReal(vr, [value])
            elif sv.type in ("Integer", "Enumeration"):
                self.fmu.setInteger(vr, [value])
            elif sv.type == "Boolean":
                self.fmu.setBoolean(vr, [value])
            else:
                self.fmu.setString(vr, [value])
        except FMICallException as exc:
            raise self._refused(f"{name} = {value!r}", exc) from None

    def close(self) -> None:
        """Terminate and free the instance, unload the library, delete the extracted files.

        FMI 2.0: after fmi2Error only fmi2FreeInstance (or fmi2Reset) may be called, after
        fmi2Fatal nothing at all: such an instance is left as it is. (pythonfmu 0.7.0
        reports every Python exception as fmi2Fatal and frees its objects itself; freeing
        the instance once more can crash the process.)
        """
        if self.fmu is not None:
            if self.worst_status >= FMI2_FATAL:
                _ABANDONED.append((self.fmu, self._callbacks, self._logger))
            else:
                try:
                    if self._initialized and self.worst_status < FMI2_ERROR:
                        self.fmu.terminate()
                except Exception:
                    pass
                try:
                    self.fmu.freeInstance()
                except Exception:
                    pass
            self.fmu = None
            self.handle = None
        if self.lean is not None:
            self.lean.close()
            self.lean = None
        if self.unzip_dir is not None:
            shutil.rmtree(self.unzip_dir, ignore_errors=True)
            self.unzip_dir = None


class LeanCalls:
    """fmi2Get/fmi2Set of each type and fmi2DoStep of a loaded FMU, for the stepping loop (FMI 3.0:
    fmi3Get/fmi3Set of the types of :data:`FMI3_CALLS` and fmi3DoStep).

    fmpy's function objects declare ``argtypes``, and ctypes then checks and converts every
    argument on every call (for the pointer arguments that is the larger part of a call's
    cost). These copies have no ``argtypes`` for get/set and are called with arguments that
    already have their C types: the handle ``handle`` (``c_void_p``), a value-reference
    array, a ``c_size_t`` count (:meth:`count`) and a value array (FMI 3.0: the count again, as
    the number of values); :meth:`bind_get` and :meth:`bind_set` make such a call with its arguments
    bound. ``do_step(handle, t, h, flag)`` takes Python floats; ``do_step_typed`` is the same
    fmi2DoStep without argtypes, for arguments that have their C types already (the handle,
    ``c_double`` time and step size, a ``c_int`` flag); the compiled loop
    (:mod:`pmsm_cosim.engine.native`) calls it by its address. FMI 3.0's fmi3DoStep also writes
    eventHandlingNeeded, terminateSimulation and earlyReturn (``flags``, three C bools) and
    lastSuccessfulTime (``last``): both loops give it these buffers.

    For a Python FMU (``python_fmu``: pythonfmu) they come from a ``ctypes.PyDLL`` handle on
    the same library: the GIL is not released around the call, which the FMU would take back
    at once to run its Python code. Other FMUs keep the usual release.
    """

    def __init__(self, fmu, python_fmu: bool, fmi: int = 2, clocks=()):
        dll = fmu.dll
        self.fmi = fmi
        self._extra_handle = None
        if python_fmu:
            lib = ctypes.PyDLL(dll._name)  # the same library, one more reference to it
            self._extra_handle = lib._handle
        else:
            lib = ctypes.CDLL(dll._name, handle=dll._handle)
        self.handle = ctypes.c_void_p(fmu.component)
        names = {kind: FMI3_CALLS[kind] if fmi == 3 else kind for kind in VALUE_KINDS}
        self._get = {kind: self._function(lib, f"fmi{fmi}Get{names[kind]}", None) for kind in VALUE_KINDS}
        self._set = {kind: self._function(lib, f"fmi{fmi}Set{names[kind]}", None) for kind in VALUE_KINDS}
        self.get_real, self.set_real = self._get["Real"], self._set["Real"]
        self.flags = (ctypes.c_bool * 3)()  #: FMI 3.0: eventHandlingNeeded, terminateSimulation, earlyReturn
        self.last = ctypes.c_double(math.nan)  #: FMI 3.0: lastSuccessfulTime
        # lib[name] is a function object of its own (getattr's is kept on the library): no argtypes
        self.do_step_typed = lib[f"fmi{fmi}DoStep"]
        self.do_step_typed.restype = ctypes.c_int
        self.do_step_typed.argtypes = None
        #: FMI 3.0 with event mode: the clocks ticked (value references, their values: all true), the functions of a
        #: tick and fmi3UpdateDiscreteStates' five flags and its nextEventTime (``update_out``, 16 bytes)
        self.clock_refs = (ctypes.c_uint32 * len(clocks))(*clocks)
        self.clock_values = (ctypes.c_bool * len(clocks))(*([True] * len(clocks)))
        self.update_out = (ctypes.c_uint8 * 16)()
        self.tick_calls = tuple(self._function(lib, name, None) for name in TICK_CALLS) if clocks else ()
        if fmi == 3:
            step3 = self._function(lib, "fmi3DoStep", [ctypes.c_void_p, ctypes.c_double, ctypes.c_double,
                                                       ctypes.c_bool] + [ctypes.c_void_p] * 4)
            def do_step(handle, t, h, no_prior_state):  # into the buffers ``flags``, ``last`` of the moment
                flags = ctypes.addressof(self.flags)
                return step3(handle, t, h, bool(no_prior_state), flags, flags + 1, flags + 2,
                             ctypes.addressof(self.last))

            self.do_step = do_step
        else:
            self.do_step = self._function(lib, "fmi2DoStep",
                                          [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int])

    def tick(self) -> tuple[str, int]:
        """The tick of this unit's clocks (its FMI 3.0 calls, in order: :data:`TICK_CALLS`): ("", 0), or the call
        that failed and its status."""
        handle = self.handle
        out = ctypes.addressof(self.update_out)
        enter_event, set_clock, update, enter_step = self.tick_calls
        for name, call in zip(TICK_CALLS, (
                lambda: enter_event(handle),
                lambda: set_clock(handle, self.clock_refs, ctypes.c_size_t(len(self.clock_refs)), self.clock_values),
                lambda: update(handle, *(ctypes.c_void_p(out + k) for k in (0, 1, 2, 3, 4, 8))),
                lambda: enter_step(handle))):
            status = call()
            if status > 1:
                return name, status
        return "", 0

    @staticmethod
    def _function(lib, name, argtypes):
        f = getattr(lib, name)
        f.restype = ctypes.c_int
        f.argtypes = argtypes
        return f

    def getter(self, kind: str):
        """fmi2Get<kind> (kind: one of VALUE_KINDS; FMI 3.0: its fmi3Get)."""
        return self._get[kind]

    def setter(self, kind: str):
        """fmi2Set<kind> (kind: one of VALUE_KINDS; FMI 3.0: its fmi3Set)."""
        return self._set[kind]

    def bind_get(self, kind: str, refs, count, buf) -> functools.partial:
        """A zero-argument call of fmi2Get<kind> (FMI 3.0: fmi3Get) of ``count`` value references ``refs``
        (a ``c_size_t`` of :meth:`count`) into ``buf``."""
        return functools.partial(self._get[kind], self.handle, refs, count, buf, *((count,) if self.fmi == 3 else ()))

    def bind_set(self, kind: str, refs, count, buf) -> functools.partial:
        """A zero-argument call of fmi2Set<kind> (FMI 3.0: fmi3Set) of ``count`` values of ``buf``."""
        return functools.partial(self._set[kind], self.handle, refs, count, buf, *((count,) if self.fmi == 3 else ()))

    def value_type(self, kind: str):
        """The ctypes type of one value of ``kind`` in this FMU's calls (an FMI 3.0 Boolean is a C bool)."""
        if kind == "Boolean" and self.fmi == 3:
            return ctypes.c_bool
        return {"Real": ctypes.c_double, "Integer": ctypes.c_int, "Boolean": ctypes.c_int,
                "String": ctypes.c_char_p}[kind]

    @staticmethod
    def count(n: int) -> ctypes.c_size_t:
        return ctypes.c_size_t(n)

    def close(self) -> None:
        """Drop this object's reference to the library (fmpy frees its own)."""
        if self._extra_handle is not None:
            handle, self._extra_handle = self._extra_handle, None
            try:
                _ctypes.dlclose(handle)
            except OSError:
                pass


def real_array(values) -> ctypes.Array:
    return (ctypes.c_double * len(values))(*values)


def vr_array(refs) -> ctypes.Array:
    return (ctypes.c_uint * len(refs))(*refs)
