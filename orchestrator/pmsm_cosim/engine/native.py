"""The stepping loop in machine code: the plain loop's FMI calls (``Master._plain_steps``), in the
same order, made by a numba-compiled function through the FMUs' C entry points (``Master(loop="compiled")``).

Why: per macro step a system of two FMUs makes six FMI calls. From Python each goes through
ctypes (argument conversion, libffi) and the loop's own bytecode; together with the scenario
signal's update that is 2-4 us of a step that costs 10-15 us with pythonfmu FMUs. Here the
loop over a chunk of steps is one call: fmi2Get*/fmi2Set*/fmi2DoStep are called by address
(``_call_io``, ``_call_step``: an LLVM indirect call, no ctypes), the connections' Real
values are checked finite in place, and a linear table merged into a component's
connections (``Master._merge_ramp_inputs``) is evaluated in the loop with the operations of
``Master._update_signals`` (``v0 + dv * (t - t0) / dt``), so the values the FMUs see are the
same doubles and results.csv is the same, byte for byte (``tests/test_engine_loops.py``).

What stays in Python (``NativeSteps.__call__``, once per chunk): every other signal evaluation
(the chunk ends at the step where one is due), the error reports (a status above fmi2Warning
or a value that is not finite ends the chunk at that step with its code; the wrapper raises
the exception the plain loop would), a Ctrl-C (the slaves' Python sees it; the master's
checks run between chunks, at most ``MAX_CHUNK`` steps apart), and the steps of a multi-rate
component's queued signal input: from the step the signal changed to that component's next
step, the plain loop's own steps (``Master._plain_steps``, which set the input before that
component's fmi2DoStep), then machine code again.

An FMI 3.0 unit's calls take one more argument (fmi3Get/fmi3Set: the number of values; fmi3DoStep: the
addresses of its eventHandlingNeeded, terminateSimulation, earlyReturn and lastSuccessfulTime, the unit's own
buffers, ``LeanCalls.flags`` and ``last``): a flag per transfer and per component says which call to make, and an
fmi3DoStep that returns fmi3OK or fmi3Warning with terminateSimulation set is an fmi2Discard, as in the plain
loop. A unit ticked in event mode (``Master``'s module doc, "Clocks") has its tick's four calls by address too
(``_tick``), at the steps its tick is due.

A system it cannot step (String connections: the strings are copied between the calls) has
``unsupported(master)``; ``Master`` then runs the plain loop, with a line saying so, unless
this one was asked for by name. numba is imported only here, when this loop is used (the
physics kernels' FMUs load it anyway); its compiled code is cached on disk like any numba
function (numba's cache locator: next to this file, or the user's cache directory).
"""

from __future__ import annotations

import ctypes

import numpy as np
from numba import njit, types  # before llvmlite: without numba, the ImportError names numba (Master's fallback)
from numba.extending import intrinsic

# isort: split
from llvmlite import ir

from .fmu import TICK_CALLS

#: codes of the first step that did not complete, as returned by ``_steps``
OK, GET_FAILED, NOT_FINITE, SET_FAILED, STEP_FAILED, TICK_FAILED = 0, 1, 2, 3, 4, 5
# columns of the tick table (one row per component): base steps between ticks (0: none), the addresses of
# fmi3EnterEventMode, fmi3SetClock, fmi3UpdateDiscreteStates, fmi3EnterStepMode, of the clocks' value references,
# their number, the address of their values and of fmi3UpdateDiscreteStates' outputs
_EVERY, _ENTER_EVENT, _SET_CLOCK, _UPDATE, _ENTER_STEP, _CLOCK_VR, _NCLOCK, _CLOCK_VALUES, _UPDATE_OUT = range(9)
# columns of the transfer table ``io`` (one row per transfer, in the order of the loop); _GET3, _SET3: 1 where
# the get (set) is FMI 3.0's
_GET, _SRC, _SVR, _NGET, _SET, _DST, _DVR, _NSET, _BUF, _GET3, _SET3 = range(11)
_COLUMNS = 11


@intrinsic
def _call_io(typingctx, fn, comp, vr, nvr, value):
    """``fmi2Status fn(fmi2Component, const fmi2ValueReference*, size_t, void*)`` at the address ``fn``
    (fmi2Get*/fmi2Set* of any type; every pointer an address, uintp)."""
    sig = types.int32(types.uintp, types.uintp, types.uintp, types.uintp, types.uintp)

    def codegen(context, builder, signature, args):
        ptr = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.IntType(32), [ptr, ptr, context.get_value_type(types.uintp), ptr])
        f = builder.inttoptr(args[0], fnty.as_pointer())
        return builder.call(f, [builder.inttoptr(args[1], ptr), builder.inttoptr(args[2], ptr), args[3],
                                builder.inttoptr(args[4], ptr)])

    return sig, codegen


@intrinsic
def _call_step(typingctx, fn, comp, t, h):
    """``fmi2Status fmi2DoStep(comp, t, h, fmi2True)`` at the address ``fn``."""
    sig = types.int32(types.uintp, types.uintp, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        ptr, dbl, i32 = ir.IntType(8).as_pointer(), ir.DoubleType(), ir.IntType(32)
        f = builder.inttoptr(args[0], ir.FunctionType(i32, [ptr, dbl, dbl, i32]).as_pointer())
        return builder.call(f, [builder.inttoptr(args[1], ptr), args[2], args[3], ir.Constant(i32, 1)])

    return sig, codegen


@intrinsic
def _call_io3(typingctx, fn, comp, vr, nvr, value, nvalues):
    """``fmi3Status fn(fmi3Instance, const fmi3ValueReference*, size_t, void*, size_t)`` at the address ``fn``
    (fmi3Get*/fmi3Set* of any type)."""
    sig = types.int32(types.uintp, types.uintp, types.uintp, types.uintp, types.uintp, types.uintp)

    def codegen(context, builder, signature, args):
        ptr, size = ir.IntType(8).as_pointer(), context.get_value_type(types.uintp)
        fnty = ir.FunctionType(ir.IntType(32), [ptr, ptr, size, ptr, size])
        f = builder.inttoptr(args[0], fnty.as_pointer())
        return builder.call(f, [builder.inttoptr(args[1], ptr), builder.inttoptr(args[2], ptr), args[3],
                                builder.inttoptr(args[4], ptr), args[5]])

    return sig, codegen


@intrinsic
def _call_step3(typingctx, fn, comp, t, h, out):
    """``fmi3DoStep(comp, t, h, fmi3True, out, out + 1, out + 2, out + 8)`` at the address ``fn``: ``out`` the
    address of the unit's three flags (eventHandlingNeeded, terminateSimulation, earlyReturn), followed, at
    ``out + 8``, by its lastSuccessfulTime (``NativeSteps``' ``outs`` rows)."""
    sig = types.int32(types.uintp, types.uintp, types.float64, types.float64, types.uintp)

    def codegen(context, builder, signature, args):
        ptr, dbl, i32 = ir.IntType(8).as_pointer(), ir.DoubleType(), ir.IntType(32)
        # the C bool noSetFMUStatePriorToCurrentPoint as an int of value 1: its register holds 1 however read
        fnty = ir.FunctionType(i32, [ptr, dbl, dbl, i32, ptr, ptr, ptr, ptr])
        f = builder.inttoptr(args[0], fnty.as_pointer())
        base = builder.inttoptr(args[4], ptr)
        flag = [builder.gep(base, [ir.Constant(i32, k)]) for k in (0, 1, 2, 8)]
        return builder.call(f, [builder.inttoptr(args[1], ptr), args[2], args[3], ir.Constant(i32, 1),
                                *flag])

    return sig, codegen


@intrinsic
def _call_plain(typingctx, fn, comp):
    """``fmi3Status fn(fmi3Instance)`` at the address ``fn`` (fmi3EnterEventMode, fmi3EnterStepMode)."""
    sig = types.int32(types.uintp, types.uintp)

    def codegen(context, builder, signature, args):
        ptr = ir.IntType(8).as_pointer()
        f = builder.inttoptr(args[0], ir.FunctionType(ir.IntType(32), [ptr]).as_pointer())
        return builder.call(f, [builder.inttoptr(args[1], ptr)])

    return sig, codegen


@intrinsic
def _call_update(typingctx, fn, comp, out):
    """``fmi3UpdateDiscreteStates(comp, out, out + 1, out + 2, out + 3, out + 4, out + 8)`` at the address ``fn``:
    its five flags and its nextEventTime in the 16 bytes at ``out``."""
    sig = types.int32(types.uintp, types.uintp, types.uintp)

    def codegen(context, builder, signature, args):
        ptr, i32 = ir.IntType(8).as_pointer(), ir.IntType(32)
        f = builder.inttoptr(args[0], ir.FunctionType(i32, [ptr] * 7).as_pointer())
        base = builder.inttoptr(args[2], ptr)
        outs = [builder.gep(base, [ir.Constant(i32, k)]) for k in (0, 1, 2, 3, 4, 8)]
        return builder.call(f, [builder.inttoptr(args[1], ptr), *outs])

    return sig, codegen


@njit(cache=True)
def _tick(c, comp, ticks):
    """The tick of component c's clocks: (0, 0), or (which of its four calls failed, its status)."""
    s = _call_plain(ticks[c, _ENTER_EVENT], comp[c])
    if s > 1:
        return 0, s
    s = _call_io(ticks[c, _SET_CLOCK], comp[c], ticks[c, _CLOCK_VR], ticks[c, _NCLOCK], ticks[c, _CLOCK_VALUES])
    if s > 1:
        return 1, s
    s = _call_update(ticks[c, _UPDATE], comp[c], ticks[c, _UPDATE_OUT])
    if s > 1:
        return 2, s
    s = _call_plain(ticks[c, _ENTER_STEP], comp[c])
    if s > 1:
        return 3, s
    return 0, 0


@njit(cache=True)
def _get(k, io):
    if io[k, _GET3]:
        return _call_io3(io[k, _GET], io[k, _SRC], io[k, _SVR], io[k, _NGET], io[k, _BUF], io[k, _NGET])
    return _call_io(io[k, _GET], io[k, _SRC], io[k, _SVR], io[k, _NGET], io[k, _BUF])


@njit(cache=True)
def _set(k, io):
    if io[k, _SET3]:
        return _call_io3(io[k, _SET], io[k, _DST], io[k, _DVR], io[k, _NSET], io[k, _BUF], io[k, _NSET])
    return _call_io(io[k, _SET], io[k, _DST], io[k, _DVR], io[k, _NSET], io[k, _BUF])


@njit(cache=True)
def _step(c, n, t, step_fn, comp, step_size, outs, flags, ticks):
    """fmi2DoStep of component c (FMI 3.0: fmi3DoStep into its row of ``outs``; terminateSimulation with
    fmi3OK or fmi3Warning is fmi2Discard), after its tick where one is due: (STEP_FAILED or OK, status), or
    (TICK_FAILED, status) with the call that failed in ``flags[c, 15]``."""
    every = ticks[c, _EVERY]
    if every != 0 and (every == 1 or n % every == 0):  # a tick every step (the usual clock): no division a step
        which, s = _tick(c, comp, ticks)
        if s > 1:
            flags[c, 15] = which
            return TICK_FAILED, s
    if outs[c] == 0:
        return STEP_FAILED, _call_step(step_fn[c], comp[c], t, step_size[c])
    s = _call_step3(step_fn[c], comp[c], t, step_size[c], outs[c])
    if s <= 1 and flags[c, 1] != 0:
        return STEP_FAILED, 2
    return STEP_FAILED, s


@njit(cache=True)
def _read(k, io, values, offset, real):
    """fmi2Get of transfer k; its Real values checked finite. A code (OK, GET_FAILED, NOT_FINITE), status."""
    s = _get(k, io)
    if s > 1:
        return GET_FAILED, s
    if real[k]:
        x = 0.0
        for i in range(offset[k], offset[k] + io[k, _NGET]):
            x += values[i]
        if x - x != 0.0:  # NaN or inf in the values, or a finite overflow of their sum
            for i in range(offset[k], offset[k] + io[k, _NGET]):
                if not np.isfinite(values[i]):
                    return NOT_FINITE, 0
    return OK, 0


@njit(cache=True)
def _steps(n0, n1, h, jacobi, io, values, offset, real, first, last, step_fn, comp, step_size, multiple,
           outs, flags, ticks, ramp_slot, ramp):
    """Take the base steps n0 .. n1-1. Returns (n, code, index, status): n = n1 and code OK, or the step
    n at which transfer (GET_FAILED, NOT_FINITE, SET_FAILED) or component (STEP_FAILED) ``index`` failed.

    Component c's transfers are rows first[c] .. last[c]-1 of ``io``; a Real transfer's values are
    ``values[offset[k]:]``. ``ramp`` row r: the constants (v0, dv, t0, dt) of the segment whose value
    goes into ``values[ramp_slot[r]]`` at the steps after n0 (at n0 it is set already). ``outs[c]``: 0 for an
    FMI 2.0 component, else the address of its fmi3DoStep outputs, which ``flags[c]`` (bytes) sees."""
    for n in range(n0, n1):
        t = n * h
        if n > n0:
            for r in range(ramp_slot.shape[0]):
                values[ramp_slot[r]] = ramp[r, 0] + ramp[r, 1] * (t - ramp[r, 2]) / ramp[r, 3]
        if jacobi:  # every due component reads the outputs at t_n, then all write, then all step
            for c in range(first.shape[0]):
                if n % multiple[c] == 0:
                    for k in range(first[c], last[c]):
                        code, s = _read(k, io, values, offset, real)
                        if code != OK:
                            return n, code, k, s
            for c in range(first.shape[0]):
                if n % multiple[c] == 0:
                    for k in range(first[c], last[c]):
                        s = _set(k, io)
                        if s > 1:
                            return n, SET_FAILED, k, s
            for c in range(first.shape[0]):
                if n % multiple[c] == 0:
                    code, s = _step(c, n, t, step_fn, comp, step_size, outs, flags, ticks)
                    if s > 1:
                        return n, code, c, s
        else:  # Gauss-Seidel: component by component, the freshest outputs
            for c in range(first.shape[0]):
                if n % multiple[c] != 0:
                    continue
                for k in range(first[c], last[c]):
                    code, s = _read(k, io, values, offset, real)
                    if code != OK:
                        return n, code, k, s
                    s = _set(k, io)
                    if s > 1:
                        return n, SET_FAILED, k, s
                code, s = _step(c, n, t, step_fn, comp, step_size, outs, flags, ticks)
                if s > 1:
                    return n, code, c, s
    return n1, OK, 0, 0


def _address(function) -> int:
    return ctypes.cast(function, ctypes.c_void_p).value


def unsupported(master) -> str:
    """Why this loop cannot step ``master``'s system ('' if it can)."""
    for st in master.steppers:
        for tr in st.transfers:
            if tr.kind == "String":
                return f"{st.inst.name} has String connections (copied between the calls)"
    return ""


class NativeSteps:
    """``steps(n0, n1, sig_next)`` of a built ``Master`` (its steppers, transfers and signals) in machine code.

    Built after ``Master._merge_ramp_inputs``: the Real values of every transfer move into one
    float64 array (``values``) that the FMI calls, the finiteness check and the merged signal inputs
    share; the transfers' ``buf``/``values``/``get``/``set`` and the merged targets' ``buf`` are
    re-pointed to it, so the rest of the master (the signal update, the error reports) works on the
    same memory."""

    def __init__(self, master, interrupted):
        self.master = master
        self.interrupted = interrupted  #: the exception class of an interrupted chunk, called with n
        self.h = master.h
        self.jacobi = master.spec.algorithm == "jacobi"
        n_real = sum(len(tr.values) for st in master.steppers for tr in st.transfers if tr.kind == "Real")
        self.values = np.zeros(max(n_real, 1))
        self.where = []  # row k of io -> (stepper index, transfer index)
        io, offset, real, slot_of = [], [], [], {}
        first, last = [], []
        off = 0
        for i, st in enumerate(master.steppers):
            first.append(len(io))
            for j, tr in enumerate(st.transfers):
                nget, nset = tr.get.args[2].value, tr.set.args[2].value
                if tr.kind == "Real":
                    off = self._rehome(tr, off, slot_of)
                    offset.append(off - len(tr.values))
                else:
                    offset.append(0)
                real.append(tr.kind == "Real")
                get, set_ = tr.get, tr.set
                io.append([_address(get.func), get.args[0].value, ctypes.addressof(get.args[1]), nget,
                           _address(set_.func), set_.args[0].value, ctypes.addressof(set_.args[1]), nset,
                           ctypes.addressof(tr.buf), int(len(get.args) == 5), int(len(set_.args) == 5)])
                self.where.append((i, j))
            last.append(len(io))
        self.io = np.array(io, dtype=np.uintp).reshape(len(io), _COLUMNS)
        self.offset = np.array(offset, dtype=np.intp)
        self.real = np.array(real, dtype=np.bool_)
        self.first, self.last = np.array(first, dtype=np.intp), np.array(last, dtype=np.intp)
        steppers = master.steppers
        self.step_fn = np.array([_address(st.do_step_typed) for st in steppers], dtype=np.uintp)
        self.comp = np.array([st.handle.value for st in steppers], dtype=np.uintp)
        self.step_size = np.array([st.step_size for st in steppers], dtype=np.float64)
        self.multiple = np.array([st.multiple for st in steppers], dtype=np.intp)
        # FMI 3.0 components: fmi3DoStep's flags and lastSuccessfulTime in a row of 16 bytes of ``flags``, which
        # their instances' ``LeanCalls.flags`` and ``last`` are re-pointed to (the master reads them there)
        self.flags = np.zeros((len(steppers), 16), dtype=np.uint8)
        self.outs = np.zeros(len(steppers), dtype=np.uintp)
        for c, st in enumerate(steppers):
            if st.flags is not None:
                lean = st.inst.lean
                lean.flags = st.flags = (ctypes.c_bool * 3).from_buffer(self.flags, 16 * c)
                lean.last = ctypes.c_double.from_buffer(self.flags, 16 * c + 8)
                lean.last.value = np.nan
                self.outs[c] = self.flags.ctypes.data + 16 * c
        self.ticks = np.zeros((len(steppers), 9), dtype=np.uintp)
        for c, st in enumerate(steppers):
            if st.tick:
                lean = st.inst.lean
                self.ticks[c] = [st.tick, *(_address(f) for f in lean.tick_calls), ctypes.addressof(lean.clock_refs),
                                 len(lean.clock_refs), ctypes.addressof(lean.clock_values),
                                 ctypes.addressof(lean.update_out)]
        # signals evaluated in the loop: linear tables whose every input is merged into a transfer
        self.inline = []  # (signal, [slots of its inputs in values])
        for sig in master.signals:
            if sig.targets and all(tg.merged for tg in sig.targets):
                self.inline.append((sig, [slot_of[id(tg)] for tg in sig.targets]))
        self._no_ramp = (np.zeros(0, dtype=np.intp), np.zeros((0, 4)))
        #: multi-rate components with signal inputs queued until their step (stepped by the plain loop then)
        self.queued = [st for st in steppers if st.multiple > 1
                       and any(tg.stepper is st and not tg.merged for sig in master.signals for tg in sig.targets)]

    def compile(self) -> None:
        """Compile the loop for this system's argument types (or load it from numba's cache): no step taken."""
        self._run(0, 0, *self._no_ramp)

    def _run(self, n0: int, n1: int, slots, consts):
        return _steps(n0, n1, self.h, self.jacobi, self.io, self.values, self.offset, self.real, self.first,
                      self.last, self.step_fn, self.comp, self.step_size, self.multiple, self.outs, self.flags,
                      self.ticks, slots, consts)

    def _rehome(self, tr, off: int, slot_of: dict) -> int:
        """Move transfer ``tr``'s Real values to ``values[off:]``; return the offset after them."""
        n = len(tr.values)
        self.values[off:off + n] = tr.values
        buf = (ctypes.c_double * n).from_buffer(self.values, 8 * off)
        get, set_ = tr.get, tr.set
        tr.get = type(get)(get.func, *get.args[:3], buf, *get.args[4:])
        tr.set = type(set_)(set_.func, *set_.args[:3], buf, *set_.args[4:])
        tr.buf, tr.values = buf, self.values[off:off + n]
        k = n - len(tr.signals)  # the merged signal inputs follow the connections' values
        for sig in self.master.signals:
            for tg in sig.targets:
                if tg.merged and tg.label in tr.signals:
                    slot = off + k + tr.signals.index(tg.label)
                    tg.buf = (ctypes.c_double * 1).from_buffer(self.values, 8 * slot)
                    slot_of[id(tg)] = slot
        return off + n

    def __call__(self, n0: int, n1: int, sig_next: int) -> int:
        m = self.master
        n = n0
        try:
            while n < n1:
                if n >= sig_next:
                    sig_next = m._update_signals(n)
                if self.queued and any(st.pending for st in self.queued):
                    # a queued signal input: the plain loop's steps up to its component's next step
                    due = min(-(-n // st.multiple) * st.multiple for st in self.queued if st.pending)
                    end = min(n1, due + 1)
                    sig_next = m._plain_steps(n, end, sig_next)
                    n = end
                    continue
                # the chunk: up to n1 or the next step at which Python must evaluate a signal; a merged
                # linear table on its ramp (evaluated at n + 1 .. ramp_end - 1 by the formula) in the loop
                lim, ramping, slots, consts = n1, [], [], []
                for sig, sig_slots in self.inline:
                    if sig.next_n == n + 1 and sig.ramp_end > n + 1:
                        ramping.append((sig, sig_slots[0]))
                        slots += sig_slots
                        consts += [sig.segment] * len(sig_slots)
                        lim = min(lim, sig.ramp_end)
                in_loop = {id(sig) for sig, _ in ramping}
                for sig in m.signals:
                    if id(sig) not in in_loop:
                        lim = min(lim, sig.next_n)
                ramp = ((np.array(slots, dtype=np.intp), np.array(consts, dtype=np.float64).reshape(-1, 4))
                        if slots else self._no_ramp)
                reached, code, index, status = self._run(n, lim, *ramp)
                if code != OK:
                    n = reached
                    raise self._failure(code, index, status, reached)
                if reached - 1 > n:  # the ramping signals as _update_signals leaves them at step reached - 1
                    for sig, slot in ramping:
                        sig.value = float(self.values[slot])
                        sig.next_n = reached
                n = reached
                sig_next = min((sig.next_n for sig in m.signals), default=sig_next)
        except KeyboardInterrupt:
            raise self.interrupted(n) from None
        return sig_next

    def _failure(self, code: int, index: int, status: int, n: int):
        """The exception the plain loop raises for the failure ``code`` at base step n."""
        m, t = self.master, n * self.h
        if code == STEP_FAILED:
            exc = m._step_failed(m.steppers[index], t, status)
        elif code == TICK_FAILED:
            exc = m._tick_failed(m.steppers[index], t, TICK_CALLS[int(self.flags[index, 15])], status)
        else:
            i, j = self.where[index]
            st = m.steppers[i]
            if code == GET_FAILED:
                exc = m._get_failed(st, j, t, status)
            elif code == SET_FAILED:
                exc = m._put_failed(st, j, t, status)
            else:
                try:
                    m._check_finite(st, j, t)  # raises, naming the connection
                except Exception as raised:
                    exc = raised
                else:  # pragma: no cover - the loop found a value that is not finite
                    raise AssertionError("a value that is not finite was found, but not by the master")
        exc.n = n
        return exc
