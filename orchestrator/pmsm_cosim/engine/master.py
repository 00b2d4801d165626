"""The co-simulation master: a fixed-step loop over FMI 2.0 and FMI 3.0 co-simulation FMUs.

FMI 3.0 units run beside FMI 2.0 ones in one system, with the same calls of their version
(:mod:`pmsm_cosim.engine.fmu`: fmi3GetFloat64 for fmi2GetReal, ...); below, "fmi2Get" and "fmi2DoStep" stand
for both. A connection of Booleans joins units of the same version (an FMI 3.0 Boolean is a C bool, FMI 2.0's
an int).

Clocks: an FMI 3.0 unit with event mode and periodic input clocks (``FmuInstance.clocks``) is ticked at its
clocks' interval, not at every communication step (``Master(event_mode=True)``, the default): its interval is a
whole number of its steps, and at the base steps n with ``n % tick == 0`` (``tick`` = interval / h) its tick
(fmi3EnterEventMode, fmi3SetClock, fmi3UpdateDiscreteStates, fmi3EnterStepMode) comes after its inputs are set and
before its fmi3DoStep from t_n. With ``event_mode=False`` (``pmsm-cosim run --no-event-mode``) it is instantiated
without event mode and its clocks are left to it (the project's controllers then sample at their own period inside
fmi3DoStep: fmus/README.md).

Time grid: base step ``h``; communication points ``t_n = n * h`` (an integer step
counter times the step, never an accumulated sum). A component with
``step_multiple = m`` is stepped at the base steps n with ``n % m == 0``, from t_n with
step size ``m * h``; its inputs are set only then.

Coupling, at each base step n (after the row of t_n is recorded):

* ``gauss-seidel`` (default): the due components are stepped in the order of the
  system file; each one first reads the outputs its inputs are connected to as they are
  at that moment, i.e. the freshest: a component earlier in the order has already
  advanced to t_{n+1}. With the order (controller, plant) this is the ordering of the
  monolithic reference: the controller reads the plant at t_n, steps, and the plant
  then advances with the new voltage.
* ``jacobi``: every due component reads the outputs as they are at t_n (all reads
  before any write), then all are stepped.

Scenario signals are evaluated as ``profile(n * h)`` (re-evaluated only when the
profile can have changed: every step on a linear ramp, at the breakpoints of a
piecewise-constant table) and an input they drive is set only when its value changed.
A linear table's input into a component that has Real connections (a speed reference
sampled as a table, which changes every step) goes in the same fmi2SetReal as those
connections' values, one more value in that call instead of a call of its own (unless
the input is itself a recorded column: then it is set at once, so that the row of t_n
shows it); the component sees the same value at its step either way.

Connections join variables of the same FMI type (Real, Integer, Boolean, String, or
Enumeration of the same enumeration type): per (destination, source, type) one fmi2Get and
one fmi2Set call of that type. A Real value read is checked to be finite before it is set;
a String read is copied at once (the FMU's strings are valid only until its next call).

Recording: the row of t_n is written before step n is taken, every output interval
and at the stop time: FMU variables as they are (a component's outputs as of its last
step), signals at t_n. Rows are streamed through :class:`~pmsm_cosim.engine.recording.ResultWriter`;
figures of merit, if any, are the caller's (``run(..., metrics=...)``): the master knows no
model.

Termination: an FMU whose fmi2DoStep from t_n returns fmi2Discard with
fmi2GetBooleanStatus(fmi2Terminated) true ends the run there as "completed", with
``terminated_by`` (the instance) and ``terminated_at`` in metrics.json; the rows
recorded up to t_n are kept. Where the FMU's fmi2GetRealStatus(fmi2LastSuccessfulTime) says its
step got further (t_n < t_end <= t_n + h: it ended the simulation inside the step, as the Modelica
Reference FMU Stair does at 9.0 s in its step from 8.8 s), one more row is recorded at t_end, as
fmpy does (the FMUs' variables as they are, the signals as at t_n), and ``terminated_at`` is
t_end; otherwise ``terminated_at`` is t_n. It is a failed step, like any other status above fmi2Warning,
if the FMU logged a message of status fmi2Error or worse during the run (a pythonfmu FMU
whose ``do_step`` returns False asks to terminate: with an error logged, that is a failure),
or if it discards the step without asking to terminate (this master does not retry a step
with a smaller size).

Two loops step the system, the same FMI calls in the same order (so bit-identical results):
the *compiled* one (the default), machine code that calls the FMUs' C functions by address
(:mod:`pmsm_cosim.engine.native`), and the *plain* one (:meth:`Master._plain_steps`), ordinary
Python over the components that a debugger can step through. ``Master(spec, loop=...)`` or the
environment variable ``PMSM_COSIM_LOOP`` selects one (``pmsm-cosim run --loop``,
``--plain-loop``). A system the compiled loop cannot step (String connections), or a Python
without numba, runs the plain loop, with one line (``note``) saying so and why; a loop asked for
by name that cannot step the system is an error naming why, and so is any other failure while
the compiled loop is set up (the cause chained).
"""

from __future__ import annotations

import array
import bisect
import ctypes
import math
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from .checks import check_wiring, drop_foreign_starts, time_grid, unconnected_inputs
from .errors import CosimError, one_line
from .fmu import FMI2_DISCARD, STATUS, FmuInstance, real_array, vr_array
from .recording import ResultWriter, write_metrics
from .system import COLUMN_CONVERSIONS, SystemSpec

#: the longest run of steps between two checks for Ctrl-C / progress updates
MAX_CHUNK = 2000
#: signals that stop a run at its next check (a second one stops it at once)
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_NEVER = sys.maxsize
#: the stepping loops: "compiled" (machine code, numba), "plain" (Python, for debugging)
LOOPS = ("compiled", "plain")
#: the environment variable that selects the loop when ``Master(loop=None)``
LOOP_ENV = "PMSM_COSIM_LOOP"


def loop_choice(loop: str | None = None) -> tuple[str, bool]:
    """(the stepping loop to use, whether it was asked for by name): ``loop`` if given, else
    $PMSM_COSIM_LOOP, else "compiled" (which falls back to "plain" where it cannot run)."""
    where = "loop"
    if loop is None:
        loop, where = os.environ.get(LOOP_ENV, "").strip(), LOOP_ENV
        if not loop:
            return "compiled", False
    if loop not in LOOPS:
        raise CosimError(f"{where}: {loop!r} is not a stepping loop; choose one of {', '.join(LOOPS)}")
    return loop, True


def _stderr_note(line: str) -> None:
    print(f"note: {line}", file=sys.stderr)


def hold_strings(buf) -> None:
    """Copy the strings an fmi2GetString just pointed ``buf`` at into Python bytes that ``buf``
    keeps alive (FMI 2.0: the FMU's own strings may change or go at its next call)."""
    buf[:] = buf[:]


def call_type(sv_type: str) -> str:
    """The FMI call family of a variable type: Enumeration values go through fmi2Get/SetInteger."""
    return "Integer" if sv_type == "Enumeration" else sv_type


class _StepFailed(Exception):
    """An FMU returned an error status in the stepping loop."""

    n: int | None = None  #: the base step that failed (= macro steps completed)


class _Terminated(_StepFailed):
    """An FMU asked to end the simulation (fmi2Discard + fmi2Terminated) in its step from t."""

    def __init__(self, instance: str, t: float):
        super().__init__(f"{instance} requested termination at t = {t:.9g} s")
        self.instance = instance
        self.t = t


class _Interrupted(Exception):
    """A second Ctrl-C inside the loop, with the base step it reached."""

    def __init__(self, n: int):
        super().__init__(n)
        self.n = n


@dataclass
class _SignalTarget:
    """An input driven by a scenario signal."""

    stepper: "_Stepper"
    set: object  #: zero-argument fmi2SetReal of this input from ``buf``
    buf: object  #: one-value buffer
    label: str
    immediate: bool  #: set at once when the value changes (single-rate), else queued
    queued: bool = False
    #: the value's slot is in a connection transfer's buffer: set with those values (no call of its own)
    merged: bool = False


@dataclass
class _Signal:
    name: str
    profile: object
    targets: list = field(default_factory=list)
    value: float = math.nan
    next_n: int = 0  #: the first base step at which the profile must be evaluated again
    ramp_end: int = 0  #: on a linear segment: the first step at or after its end
    #: that segment's constants (``Table.segment``): its value at t is v0 + dv * (t - t0) / dt
    segment: tuple = (0.0, 0.0, 0.0, 1.0)


@dataclass
class _Transfer:
    """The connections from one source instance to one destination of one FMI type."""

    get: object  #: zero-argument fmi2Get<kind> of the connected outputs into ``buf``
    set: object  #: zero-argument fmi2Set<kind> of the connected inputs from ``buf``
    src: str  #: the source instance
    kind: str  #: "Real", "Integer" (Integer and Enumeration), "Boolean", "String"
    buf: object  #: the ctypes value array the calls see
    conns: list  #: the connections, in the order of ``buf``
    #: Real: an array.array whose memory ``buf`` is (the loop sums it several times faster
    #: than it could index the ctypes array); other types: None. After the connections' values
    #: it may hold signal inputs (``_SignalTarget.merged``), set with them
    values: object = None
    signals: list = field(default_factory=list)  #: the labels of those signal inputs


@dataclass
class _Stepper:
    """Everything the loop needs to step one component, prebuilt."""

    inst: FmuInstance
    multiple: int
    step_size: float
    handle: object = None
    do_step: object = None
    do_step_typed: object = None  #: fmi2DoStep without argtypes (``LeanCalls.do_step_typed``)
    flags: object = None  #: FMI 3.0: fmi3DoStep's eventHandlingNeeded, terminateSimulation, earlyReturn
    tick: int = 0  #: FMI 3.0 in event mode: base steps between the ticks of its clocks (0: no clock ticked)
    transfers: list = field(default_factory=list)  #: [_Transfer] into this component's inputs
    pending: list = field(default_factory=list)  #: queued signal targets (multi-rate)


class Master:
    """Check a :class:`SystemSpec` against its FMUs and run it."""

    def __init__(self, spec: SystemSpec, loop: str | None = None, note=None, event_mode: bool = True):
        """``note(line)``: where the line goes that says the plain loop runs instead of the compiled one,
        and why (default: ``note: ...`` on stderr). ``event_mode``: tick the FMI 3.0 units' clocks in event mode
        (module doc, "Clocks")."""
        #: "compiled" or "plain" (see the module's docstring); after the set-up, the one that runs
        self.loop, self._loop_named = loop_choice(loop)
        self._note = note if note is not None else _stderr_note
        self.loop_note = ""  #: after the set-up: why the plain loop runs where the compiled one was the default
        self.spec = spec
        self.h = spec.step_size
        self.n_steps, self.every = time_grid(spec)
        self.instances: dict[str, FmuInstance] = {}
        try:
            for comp in spec.components:
                self.instances[comp.name] = FmuInstance(comp.name, comp.fmu)
            self.ticks = self._ticks(spec, event_mode)
            dropped = drop_foreign_starts(spec, self.instances)
            check_wiring(spec, self.instances)
        except BaseException:
            self.close()
            raise
        self.warnings: list[str] = dropped + unconnected_inputs(spec, self.instances)
        self._stop_requested = False
        self._stop_signal = ""  #: the name of the signal that asked for the stop
        self._finishing = False
        self.loop_cpu_time = 0.0
        self.terminated: tuple[str, float] | None = None  #: (instance, t) of a termination request

    # -- set-up --------------------------------------------------------------------
    def _ticks(self, spec: SystemSpec, event_mode: bool) -> dict[str, int]:
        """{instance: base steps between its clocks' ticks} of the units ticked in event mode (module doc)."""
        ticks = {}
        for comp in spec.components if event_mode else ():
            inst = self.instances[comp.name]
            clocks = inst.clocks()
            if not clocks:
                continue
            intervals = sorted(set(clocks.values()))
            interval = intervals[0]
            m = round(interval / self.h)
            if len(intervals) > 1 or m < 1 or abs(m * self.h - interval) > 1e-9 * interval or m % comp.step_multiple:
                raise CosimError(f"{comp.name}: its clocks tick every {', '.join(f'{i:g}' for i in intervals)} s, "
                                 f"which is not one whole number of its steps ({comp.step_multiple * self.h:g} s); "
                                 f"choose a step that divides it, or run without event mode")
            inst.event_mode = True
            ticks[comp.name] = m
        return ticks

    def _build(self) -> None:
        """Instantiate every FMU and prebuild the loop's arrays."""
        s = self.spec
        stop = self.n_steps * self.h
        for comp in s.components:
            self.instances[comp.name].instantiate(0.0, stop, comp.start)
        self.steppers = []
        by_name = {}
        for comp in s.components:
            inst = self.instances[comp.name]
            st = _Stepper(inst, comp.step_multiple, comp.step_multiple * self.h,
                          handle=inst.lean.handle, do_step=inst.lean.do_step,
                          do_step_typed=inst.lean.do_step_typed,
                          flags=inst.lean.flags if inst.fmi == 3 else None, tick=self.ticks.get(comp.name, 0))
            self.steppers.append(st)
            by_name[comp.name] = st
        # connections grouped by (destination, source, type): one get and one set per group
        groups: dict[tuple[str, str, str], list] = {}
        for conn in s.connections:
            kind = call_type(self.instances[conn.src].variables[conn.src_var].type)
            groups.setdefault((conn.dst, conn.src, kind), []).append(conn)
        for (dst, src, kind), conns in groups.items():
            si, di = self.instances[src], self.instances[dst]
            svr = vr_array([si.variables[c.src_var].valueReference for c in conns])
            dvr = vr_array([di.variables[c.dst_var].valueReference for c in conns])
            values = None
            if kind == "Real":
                # the values in an array.array, seen by the FMI calls through a ctypes array on
                # its memory: the loop reads them from the array.array, several times faster
                # than indexing (or iterating) the ctypes array
                values = array.array("d", [0.0] * len(conns))
                buf = (ctypes.c_double * len(conns)).from_buffer(values)
            else:  # String: pointers, copied at once by hold_strings (the source owns the strings)
                buf = (si.lean.value_type(kind) * len(conns))()
            count = si.lean.count(len(conns))
            by_name[dst].transfers.append(_Transfer(si.lean.bind_get(kind, svr, count, buf),
                                                    di.lean.bind_set(kind, dvr, count, buf),
                                                    src, kind, buf, conns, values))
        # scenario signals; their inputs get the value at t = 0 in initialization mode
        self.signals = []
        for spec in s.signals.values():
            sig = _Signal(spec.name, spec.profile)
            for inst_name, var in spec.drives:
                inst, st = self.instances[inst_name], by_name[inst_name]
                buf = real_array([0.0])
                setter = inst.lean.bind_set("Real", vr_array([inst.variables[var].valueReference]),
                                            inst.lean.count(1), buf)
                sig.targets.append(_SignalTarget(st, setter, buf, f"{inst_name}.{var}", st.multiple == 1))
            self.signals.append(sig)
        try:
            self._update_signals(0)
            for st in self.steppers:
                self._flush_pending(st, 0.0)
        except _StepFailed as exc:
            raise CosimError(str(exc)) from None
        self._merge_ramp_inputs()
        for comp in s.components:
            self.instances[comp.name].exit_initialization()
        self._build_recorder()
        if self.loop == "compiled":
            self._steps = self._native_steps()
        if self.loop == "plain":
            self._steps = self._plain_steps

    def _native_steps(self):
        """The compiled loop of this system (``pmsm_cosim.engine.native``), compiled (or loaded from
        numba's cache) now. Where it cannot step this system (String connections) or numba is not
        installed: None, ``self.loop`` "plain" and a line saying why, or a CosimError with the reason if
        it was asked for by name. Any other failure of the set-up is a CosimError naming it (chained)."""
        try:
            from . import native  # noqa: PLC0415 - numba (LLVM) is heavy and optional: imported for this loop only
        except ImportError as exc:
            if exc.name != "numba":  # not a missing numba: one that cannot be imported, or something else
                raise self._setup_failed(exc) from exc
            reason = f"numba is not installed ({one_line(exc)})"
        else:
            try:
                reason = native.unsupported(self)
                if not reason:
                    steps = native.NativeSteps(self, _Interrupted)
                    steps.compile()
                    return steps
            except Exception as exc:
                raise self._setup_failed(exc) from exc
        if self._loop_named:
            raise CosimError(f"the compiled loop cannot step {self.spec.name}: {reason}")
        self.loop = "plain"
        self.loop_note = f"the plain loop steps {self.spec.name}: {reason}"
        self._note(self.loop_note)
        return None

    def _setup_failed(self, exc: BaseException) -> CosimError:
        return CosimError(f"setting up the compiled loop of {self.spec.name} failed: "
                          f"{type(exc).__name__}: {one_line(exc)}")

    def _merge_ramp_inputs(self) -> None:
        """Give each input of a linear table (set at once by the initialisation) a slot in the buffer of
        its component's first Real transfer, set with it from now on (see the module's docstring)."""
        recorded = {(col.instance, col.variable) for col in self.spec.columns if col.kind == "variable"}
        for sig in self.signals:
            if getattr(sig.profile, "interpolation", None) != "linear" or len(sig.profile.times) < 2:
                continue
            for tg in sig.targets:
                inst_name, _, var = tg.label.partition(".")
                real = [tr for tr in tg.stepper.transfers if tr.kind == "Real"]
                if not real or (inst_name, var) in recorded:
                    continue
                tr, inst = real[0], tg.stepper.inst
                src = self.instances[tr.src]
                k = len(tr.values) - len(tr.signals)  # the connections' values
                svr = vr_array([src.variables[c.src_var].valueReference for c in tr.conns])
                dvr = vr_array([inst.variables[c.dst_var].valueReference for c in tr.conns]
                               + [inst.variables[label.partition(".")[2]].valueReference
                                  for label in tr.signals + [tg.label]])
                values = array.array("d", list(tr.values) + [sig.value])
                buf = (ctypes.c_double * len(values)).from_buffer(values)
                tr.get = src.lean.bind_get("Real", svr, src.lean.count(k), buf)
                tr.set = inst.lean.bind_set("Real", dvr, inst.lean.count(len(values)), buf)
                tr.values, tr.buf = values, buf
                tr.signals.append(tg.label)
                tg.buf = (ctypes.c_double * 1).from_buffer(values, 8 * (len(values) - 1))
                tg.merged = True

    def _build_recorder(self) -> None:
        """Per instance, one get call per type for the recorded variables; a row plan."""
        reads: dict[tuple[str, str], list] = {}
        for col in self.spec.columns:
            if col.kind == "variable":
                sv = self.instances[col.instance].variables[col.variable]
                kind = "Real" if sv.type == "Real" else ("Boolean" if sv.type == "Boolean" else "Integer")
                refs = reads.setdefault((col.instance, kind), [])
                if sv.valueReference not in refs:
                    refs.append(sv.valueReference)
        self.record_reads = []
        buffers = {}
        for (name, kind), refs in reads.items():
            inst = self.instances[name]
            buf = (inst.lean.value_type(kind) * len(refs))()
            self.record_reads.append((inst.lean.bind_get(kind, vr_array(refs), inst.lean.count(len(refs)), buf), name))
            buffers[(name, kind)] = (buf, refs)
        sig_by_name = {sig.name: sig for sig in self.signals}
        plan = []
        for col in self.spec.columns:
            conv = COLUMN_CONVERSIONS[col.unit][1] if col.unit else None
            if col.kind == "time":
                plan.append(("time", None, None, None, col.name))
            elif col.kind == "signal":
                plan.append(("signal", sig_by_name[col.variable], None, conv, col.name))
            else:
                sv = self.instances[col.instance].variables[col.variable]
                kind = "Real" if sv.type == "Real" else ("Boolean" if sv.type == "Boolean" else "Integer")
                buf, refs = buffers[(col.instance, kind)]
                plan.append(("var", buf, refs.index(sv.valueReference), conv, f"{col.instance}.{col.variable}"))
        self.row_plan = plan

    # -- scenario signals --------------------------------------------------------------
    def _first_step_at(self, t_event: float, n: int) -> int:
        """The first base step m > n with m * h >= t_event."""
        h = self.h
        m = max(n + 1, math.ceil(t_event / h))
        while m - 1 > n and (m - 1) * h >= t_event:
            m -= 1
        while m * h < t_event:
            m += 1
        return m

    def _next_eval(self, sig: _Signal, n: int) -> tuple[int, int]:
        """(next step at which ``sig.profile`` can differ from ``profile(n h)``, end of the ramp);
        on a ramp, its constants in ``sig.segment``."""
        profile = sig.profile
        ts = profile.times
        i = bisect.bisect_right(ts, n * self.h) - 1
        if i + 1 >= len(ts):
            return _NEVER, 0  # after the last breakpoint: constant
        if profile.interpolation == "linear" and i >= 0:
            sig.segment = profile.segment(i)
            return n + 1, self._first_step_at(ts[i + 1], n)  # on a ramp: every step
        return self._first_step_at(ts[i + 1], n), 0  # constant until the next breakpoint

    def _update_signals(self, n: int) -> int:
        """Evaluate the signals due at step n, set (or queue) the inputs whose value changed;
        return the next step at which a signal must be evaluated."""
        t = n * self.h
        nxt = _NEVER
        for sig in self.signals:
            if n >= sig.next_n:
                if n < sig.ramp_end:  # on the ramp of the last evaluation: profile(t), its constants kept
                    v0, dv, t0, dts = sig.segment
                    v = v0 + dv * (t - t0) / dts
                else:
                    v = sig.profile(t)
                if v != sig.value:
                    sig.value = v
                    for tg in sig.targets:
                        tg.buf[0] = v
                        if tg.merged:  # set with its component's connections
                            continue
                        if tg.immediate:
                            status = tg.set()
                            if status > 1:
                                raise self._set_failed(tg, t, status)
                        elif not tg.queued:
                            tg.queued = True
                            tg.stepper.pending.append(tg)
                if n + 1 < sig.ramp_end:
                    sig.next_n = n + 1
                else:
                    sig.next_n, sig.ramp_end = self._next_eval(sig, n)
            if sig.next_n < nxt:
                nxt = sig.next_n
        return nxt

    def _flush_pending(self, st: _Stepper, t: float) -> None:
        """Set the queued signal inputs of a multi-rate component (when it is stepped)."""
        for tg in st.pending:
            tg.queued = False
            status = tg.set()
            if status > 1:
                raise self._set_failed(tg, t, status)
        st.pending.clear()

    # -- stepping ---------------------------------------------------------------------
    def _describe(self, inst: FmuInstance, action: str, t: float) -> str:
        reason = inst.last_problem()
        return f"{inst.name}: {action} failed at t = {t:.9g} s" + (f": {reason}" if reason else "")

    def _set_failed(self, tg: _SignalTarget, t: float, status: int = 3) -> _StepFailed:
        tg.stepper.inst.note_status(status)
        return _StepFailed(self._describe(tg.stepper.inst, f"setting {tg.label} = {tg.buf[0]!r}", t))

    def _get_failed(self, st: _Stepper, j: int, t: float, status: int) -> _StepFailed:
        tr = st.transfers[j]
        src = self.instances[tr.src]
        src.note_status(status)
        return _StepFailed(self._describe(src, src.call("Get", tr.kind), t))

    def _put_failed(self, st: _Stepper, j: int, t: float, status: int) -> _StepFailed:
        tr = st.transfers[j]
        st.inst.note_status(status)
        extra = "".join(f", {label}" for label in tr.signals)
        return _StepFailed(self._describe(st.inst, f"{st.inst.call('Set', tr.kind)} of the inputs from {tr.src}{extra}",
                                          t))

    def _check_finite(self, st: _Stepper, j: int, t: float) -> None:
        """Raise if a Real value just read for a connection is NaN or infinite (the loop calls
        this when the sum of the values is not finite, which a finite overflow can also cause)."""
        tr = st.transfers[j]
        for k, conn in enumerate(tr.conns):
            if not math.isfinite(tr.buf[k]):
                raise _StepFailed(f"{conn.src}.{conn.src_var} is not finite ({tr.buf[k]!r}) at t = {t:.9g} s, "
                                  f"before it reached {conn.dst}.{conn.dst_var}")

    def _tick_failed(self, st: _Stepper, t: float, call: str, status: int) -> _StepFailed:
        st.inst.note_status(status)
        return _StepFailed(self._describe(st.inst, f"the tick of its clock ({call})", t))

    def _step_failed(self, st: _Stepper, t: float, status: int = 3) -> _StepFailed:
        """The exception for an fmi2DoStep from t that returned ``status`` > fmi2Warning:
        :class:`_Terminated` if the FMU discarded the step to end the simulation."""
        st.inst.note_status(status)
        if status == FMI2_DISCARD and st.inst.terminate_requested() and not st.inst.logged_error():
            return _Terminated(st.inst.name, t)
        return _StepFailed(self._describe(st.inst, st.inst.call("DoStep"), t))

    def _plain_steps(self, n0: int, n1: int, sig_next: int) -> int:
        """The stepping loop as ordinary Python, for reading and debugging: the same calls, in the same
        order, as the compiled one (:mod:`pmsm_cosim.engine.native`). ``steps(n0, n1, sig_next)`` takes the
        base steps n0 .. n1-1 and returns the next step at which a signal must be evaluated; a failing
        call raises ``_StepFailed`` carrying the step it failed at."""
        h = self.h
        jacobi = self.spec.algorithm == "jacobi"
        n = n0
        try:
            for n in range(n0, n1):
                if n >= sig_next:
                    sig_next = self._update_signals(n)
                t = n * h
                due = [st for st in self.steppers if n % st.multiple == 0]
                if jacobi:  # every due component reads the outputs at t_n, then all are stepped
                    for st in due:
                        self._read_inputs(st, t)
                    for st in due:
                        self._write_inputs(st, t)
                    for st in due:
                        self._do_step(st, n, t)
                else:  # Gauss-Seidel: component by component, the freshest outputs
                    for st in due:
                        self._read_inputs(st, t)
                        self._write_inputs(st, t)
                        self._do_step(st, n, t)
        except _StepFailed as exc:
            exc.n = n
            raise
        except KeyboardInterrupt:
            raise _Interrupted(n) from None
        return sig_next

    def _read_inputs(self, st: _Stepper, t: float) -> None:
        """fmi2Get<type> of the outputs connected to ``st``'s inputs; Real values checked finite."""
        for j, tr in enumerate(st.transfers):
            status = tr.get()
            if status > 1:
                raise self._get_failed(st, j, t, status)
            if tr.kind == "Real" and not all(math.isfinite(v) for v in tr.values):
                self._check_finite(st, j, t)
            elif tr.kind == "String":
                hold_strings(tr.buf)

    def _write_inputs(self, st: _Stepper, t: float) -> None:
        """fmi2Set<type> of ``st``'s connected inputs, then its queued signal inputs."""
        for j, tr in enumerate(st.transfers):
            status = tr.set()
            if status > 1:
                raise self._put_failed(st, j, t, status)
        if st.pending:
            self._flush_pending(st, t)

    def _do_step(self, st: _Stepper, n: int, t: float) -> None:
        if st.tick and n % st.tick == 0:
            call, status = st.inst.lean.tick()
            if status > 1:
                raise self._tick_failed(st, t, call, status)
        status = st.do_step(st.handle, t, st.step_size, 1)
        if status <= 1 and st.flags is not None and st.flags[1]:  # FMI 3.0: terminateSimulation
            status = FMI2_DISCARD
        if status > 1:
            raise self._step_failed(st, t, status)

    # -- recording -------------------------------------------------------------------
    def _row(self, n: int, t: float | None = None) -> list:
        """The row of t_n (``t``: of that time instead, the variables and signals as they are)."""
        t = n * self.h if t is None else t
        for read, name in self.record_reads:
            status = read()
            if status > 1:
                self.instances[name].note_status(status)
                raise _StepFailed(self._describe(self.instances[name], "reading the recorded variables", t))
        row = []
        for kind, a, b, conv, label in self.row_plan:
            if kind == "time":
                v = t
            elif kind == "signal":
                v = a.value
            else:
                v = a[b]
            if conv is not None:
                v = conv(v)
            v = float(v)
            if not math.isfinite(v):
                raise _StepFailed(f"{label} is not finite ({v}) at t = {t:.9g} s")
            row.append(v)
        return row

    # -- the run -----------------------------------------------------------------------
    def request_stop(self, signum=None, _frame=None) -> None:
        """Ask the loop to stop at its next check (the SIGINT and SIGTERM handler)."""
        if self._finishing:
            return  # the loop is over: metrics.json is being written
        if self._stop_requested:
            raise KeyboardInterrupt  # a second Ctrl-C (or SIGTERM) stops at once
        self._stop_requested = True
        if signum is not None:
            self._stop_signal = signal.Signals(signum).name

    def run(self, out_dir, progress=None, extra_settings: dict | None = None,
            catch_sigint: bool = True, metrics_of=None) -> dict:
        """Initialize, step to the stop time, stream ``results.csv``, write ``metrics.json``.

        ``metrics_of(out_dir, columns, rows)`` -> dict: the caller's figures of merit of the
        run (called after the last row, whatever the status; its keys come first in
        metrics.json, then the bookkeeping). Returns metrics.json's content.

        A CosimError during initialization (a start value refused by an FMU, ...) is raised
        before anything is written: ``out_dir`` is left as it was.
        Once the FMUs are initialized, ``results.csv`` is (re)created and ``metrics.json``
        says ``"status": "running"``; a failure or an interruption (SIGINT or SIGTERM, with
        ``catch_sigint``) during the steps ends the run with that status, the rows kept.
        metrics.json is written before the FMU instances are freed.
        """
        out = Path(out_dir)
        self._finishing = False
        handlers = {}
        if catch_sigint and threading.current_thread() is threading.main_thread():
            for signum in STOP_SIGNALS:
                handlers[signum] = signal.signal(signum, self.request_stop)
        writer = None
        try:
            t_init = time.perf_counter()
            self._build()
            init_time = time.perf_counter() - t_init
            # from here on, a previous run's files in out_dir are replaced
            out.mkdir(parents=True, exist_ok=True)
            writer = ResultWriter(out, [c.name for c in self.spec.columns])
            write_metrics(out, self._bookkeeping("running", 0, 0.0, init_time, 0, extra_settings))
            status, n, wall = "interrupted", 0, 0.0
            try:
                status, n, wall = self._loop(writer, progress)
            except Exception as exc:  # e.g. the disk is full: say so in metrics.json too
                status = f"failed: {type(exc).__name__}: {one_line(exc)}"
                raise
            finally:
                self._finishing = True
                writer.close()
                metrics = self._metrics(out, status, n, wall, init_time, writer.rows, extra_settings, metrics_of)
                write_metrics(out, metrics)
        finally:
            if writer is not None:
                writer.close()
            for signum, handler in handlers.items():
                signal.signal(signum, handler)
            if progress is not None:
                progress.close()
            self.close()
        return metrics

    def _loop(self, writer: ResultWriter, progress) -> tuple[str, int, float]:
        N, every, h = self.n_steps, self.every, self.h
        steps = self._steps
        status = "completed"
        self.terminated = None
        n = 0
        sig_next = self._update_signals(0)
        t0, cpu0 = time.perf_counter(), time.process_time()
        try:
            while True:
                if n >= sig_next:
                    sig_next = self._update_signals(n)
                if n % every == 0 or n == N:
                    writer.write(self._row(n))
                if n == N:
                    break
                if self._stop_requested:
                    status = "interrupted"
                    break
                if progress is not None:
                    progress.update(n * h)
                n1 = min(N, (n // every + 1) * every, n + MAX_CHUNK)
                sig_next = steps(n, n1, sig_next)
                n = n1
        except _Terminated as exc:
            n, self.terminated = exc.n, (exc.instance, exc.t)
            self._record_termination(writer, exc)
        except _StepFailed as exc:
            n = exc.n if exc.n is not None else n
            status = f"failed: {exc}"
        except _Interrupted as exc:
            n, status = exc.n, "interrupted"
        except KeyboardInterrupt:
            status = "interrupted"
        wall = time.perf_counter() - t0
        self.loop_cpu_time = time.process_time() - cpu0  #: CPU time of the loop [s] (benchmarks)
        if status.startswith("failed") and self._stop_requested:
            status = "interrupted"  # an FMU that saw the Ctrl-C itself
        return status, n, wall

    def _record_termination(self, writer: ResultWriter, exc: _Terminated) -> None:
        """The row at the terminating FMU's last successful time, where its step ended the simulation beyond
        t_n (module doc, "Termination"), and that time as ``terminated_at``."""
        inst = self.instances[exc.instance]
        step = next((st.step_size for st in self.steppers if st.inst is inst), self.h)
        t_end = inst.last_successful_time()
        if t_end is None or not exc.t < t_end <= exc.t + step * (1.0 + 1e-9):
            return
        try:
            writer.write(self._row(exc.n, t_end))
        except _StepFailed:  # a variable that cannot be read there: the run ends at t_n, as it would have
            return
        self.terminated = (exc.instance, t_end)

    def _metrics(self, out: Path, status: str, n: int, wall: float, init_time: float, rows: int,
                 extra: dict | None, metrics_of) -> dict:
        metrics: dict = {}
        if metrics_of is not None:
            try:
                metrics = dict(metrics_of(out, [col.name for col in self.spec.columns], rows))
            except Exception as exc:  # a partial or odd result set: keep the bookkeeping
                metrics = {"metrics_error": one_line(f"{type(exc).__name__}: {exc}")}
        metrics.update(self._bookkeeping(status, n, wall, init_time, rows, extra))
        return metrics

    def _bookkeeping(self, status: str, n: int, wall: float, init_time: float, rows: int,
                     extra: dict | None) -> dict:
        s = self.spec
        out = {"status": status}
        if status == "interrupted" and self._stop_signal:
            out["stop_signal"] = self._stop_signal
        if status == "completed" and self.terminated:
            out["terminated_by"], out["terminated_at"] = self.terminated
        out.update({
            "wall_time_s": wall,
            "init_time_s": init_time,
            "macro_steps": n,
            "us_per_step": 1e6 * wall / max(n, 1),
            "rows": rows,
            "scenario": s.name,
            "algorithm": s.algorithm,
            "step_size": s.step_size,
            "stop_time": s.stop_time,
            "output_interval": s.output_interval,
            "loop": self.loop,
            **({"loop_note": self.loop_note} if self.loop_note else {}),
            "settings": {**s.settings(), **(extra or {})},
        })
        return out

    def close(self) -> None:
        for inst in self.instances.values():
            inst.close()


def status_name(code: int) -> str:
    return STATUS[code] if 0 <= code < len(STATUS) else str(code)


class SignalClock:
    """The master's evaluation of a system's scenario signals, without FMUs: ``Master._update_signals`` and
    the methods it calls, on the signals alone. ``events(n_steps)`` gives, per signal, where its value is
    evaluated from the profile and where it follows a ramp's formula, as the stepping loops evaluate it, so that
    another loop (the whole-loop reference of ``pmsm-cosim bench``) gives its inputs the master's values, bit for
    bit."""

    _first_step_at = Master._first_step_at
    _next_eval = Master._next_eval
    _update_signals = Master._update_signals

    def __init__(self, spec: SystemSpec):
        self.h = spec.step_size
        self.signals = [_Signal(sig.name, sig.profile) for sig in spec.signals.values()]

    def events(self, n_steps: int) -> dict[str, list[tuple]]:
        """{signal: [(n, value, ramp_end, v0, dv, t0, dt), ...]} for base steps 0 .. n_steps: at step n the
        value is ``value``; at the steps after it up to ``ramp_end`` (exclusive; 0: none) it is
        ``v0 + dv * (t - t0) / dt``, t the step's time (``_update_signals``' formula); from the next event
        on, that event's."""
        out: dict[str, list[tuple]] = {sig.name: [] for sig in self.signals}
        n = 0
        while n <= n_steps:
            due = [sig for sig in self.signals if n >= sig.next_n]
            self._update_signals(n)
            for sig in due:
                if sig.next_n == n + 1 and sig.ramp_end > n + 1:  # on a ramp: the formula to its end
                    out[sig.name].append((n, sig.value, sig.ramp_end, *sig.segment))
                    v0, dv, t0, dts = sig.segment  # as the compiled loop leaves it at the ramp's last step
                    sig.value = v0 + dv * ((sig.ramp_end - 1) * self.h - t0) / dts
                    sig.next_n = sig.ramp_end
                else:
                    out[sig.name].append((n, sig.value, 0, 0.0, 0.0, 0.0, 1.0))
            n = min((sig.next_n for sig in self.signals), default=_NEVER)
        return out
