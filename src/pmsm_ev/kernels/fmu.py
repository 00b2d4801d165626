"""The FMUs' per-step path in compiled code: one ``fmi2DoStep`` of the plant FMU and of a controller FMU on
flat buffers, and the C functions (numba ``cfunc``) the lean binding calls with those buffers
(fmus/README.md, "The compiled step").

A slave of ``pmsm_ev_fmus`` that runs with compiled kernels hands the binding, when it is initialised, a buffer
``io`` laid out by ``PLANT_IO_LAYOUT`` (``PIO_*``) or ``UNIT_IO_LAYOUT`` (``UIO_*``): its Real inputs, its
outputs and the little state its ``do_step`` keeps outside the kernels' vectors (the plant's clock and sample
counter, the controller's sample clock), with two more vectors: the plant's parameter and energy vectors
(``PLANT_PARAMS_LAYOUT``, ``PLANT_ENERGY_LAYOUT``), the control unit's state and parameter vectors
(``UNIT_STATE_LAYOUT``, ``UNIT_PARAMS_LAYOUT``). The buffer is the physics object's own: ``Plant.io``, where the
plant keeps its state, and ``ControlUnit.io``, which the slave fills (``ControlUnit.load_io``). The binding writes
the inputs into ``io``, calls the C function at ``fmu_step_address(kind)`` with the three pointers and the
communication point and step, and reads the outputs from ``io``: no Python on the way.

``plant_fmu_step`` and ``unit_fmu_step`` are ``PmsmEvPlant.do_step`` and ``FocSlave.do_step`` on these buffers,
and they call the kernels those Python steps call, so the numbers are the same, bit for bit, and nothing is
written twice: the plant's step is ``plant_advance`` (``Plant.step`` calls it after the inverter's delay and
limit, which are Python's), the controller's periods ``unit_periods`` and its sample clock ``sample_instant``
(``FocSlave.do_step`` calls both), the brake's demand ``unit_t_brake`` (``ControlUnit.T_brake``); what is here is
what decides whether the compiled step is taken. A step they do not take returns
``STEP_DECLINED`` with nothing changed, and the binding runs the slave's Python ``do_step`` instead: a plant
with the inverter's delay (the slave does not offer it), a plant voltage at or near the
DC link's limit (the ideal link's v_dc / sqrt 3, or the battery's terminal voltage over sqrt 3, ``dc_link_limit``;
CPython's ``math.hypot``, which numba does not reproduce to the last bit, decides the limit
there), a controller's first step that rebuilds its unit, a non-finite plant state (the slave raises), a step
size <= 0. An exception in a kernel returns ``STEP_FAILED`` with the vectors as they were before the step (the
binding then hands the step to Python, which raises it as it would have).
"""

from __future__ import annotations

import math

from .control import control_step, unit_dc_link
from .jit import CACHE, JIT, kernel
from .jit import F as _F
from .jit import V as _V
from .jit import sig as _sig
from .layout import (
    ADAPT_OFF,
    C_ADAPT,
    C_I_D_REF,
    C_K_T,
    MODE_EKF,
    MODE_INJECTION,
    P_T_BRAKE,
    PIO_DELTA,
    PIO_SAVE,
    PIO_T_BRAKE,
    PIO_U_LIM,
    PIO_V_ALPHA,
    PIO_V_BETA,
    PLANT_ENERGY,
    PLANT_IO,
    PLANT_PARAMS,
    S_AD_PSI,
    S_AD_RS,
    S_AD_SEEN,
    S_AXIS_F,
    S_GAIN_RATIO,
    S_HOLD,
    S_I_DREF,
    S_I_MAG,
    S_I_QREF,
    S_ID_ACC,
    S_ID_BLIND,
    S_ID_NOISE_F,
    S_ID_OFS,
    S_ID_RS,
    S_ID_Y,
    S_MODE,
    S_REGION,
    S_T_BRAKE,
    S_T_REF,
    UIO_CLOCK,
    UIO_DT,
    UIO_FAULT,
    UIO_I_ALPHA,
    UIO_I_BETA,
    UIO_I_D,
    UIO_I_D_HAT,
    UIO_I_DREF,
    UIO_I_Q,
    UIO_I_Q_HAT,
    UIO_I_QREF,
    UIO_K_NEXT,
    UIO_KIND,
    UIO_MEASURED,
    UIO_MODE,
    UIO_OMEGA_CTRL,
    UIO_OMEGA_HAT,
    UIO_OMEGA_MEAS,
    UIO_OMEGA_REF,
    UIO_P_CHARGE_MAX,
    UIO_P_DISCHARGE_MAX,
    UIO_REF_REGION,
    UIO_REFERENCE,
    UIO_SAVE,
    UIO_STATUS,
    UIO_T0,
    UIO_T_BRAKE,
    UIO_T_L_HAT,
    UIO_T_REF,
    UIO_THETA_CTRL,
    UIO_THETA_HAT,
    UIO_THETA_MEAS,
    UIO_TOLERANCE,
    UIO_UNIT_DT,
    UIO_V_ALPHA,
    UIO_V_BETA,
    UIO_V_D,
    UIO_V_DC_MEAS,
    UIO_V_Q,
    UNIT_IO,
    UNIT_PARAMS,
    UNIT_STATE,
)
from .modes import injection_unit_step
from .plant import dc_link_limit, plant_advance
from .startup import sensorless_step

if JIT:
    from numba import carray
else:
    def carray(pointer, n):  # pragma: no cover - the C steps exist only compiled
        raise RuntimeError("the FMUs' C steps need the compiled kernels")

#: the returns of a compiled step: taken; not taken (nothing changed: the slave's Python step runs); an
#: exception in a kernel (the vectors restored: the slave's Python step runs, and raises it)
STEP_TAKEN, STEP_DECLINED, STEP_FAILED = 1, 0, -1

#: a plant voltage whose squared magnitude is below this share of the squared limit is inside the limit whatever
#: the last bit of its magnitude (``Plant.step`` takes it by ``math.hypot``); closer, the step is declined
U_LIMIT_MARGIN = 1.0 - 1e-9

#: the controller's kernels (``UIO_KIND``)
UNIT_KIND_CONTROL, UNIT_KIND_SENSORLESS, UNIT_KIND_INJECTION = 0.0, 1.0, 2.0


@kernel()
def plant_fmu_step(io, pp, ee, h):
    """``PmsmEvPlant.do_step`` over ``h`` on the plant's buffer ``io`` (``PLANT_IO_LAYOUT``: ``Plant.io``, the
    slave's inputs written into it), its parameter vector ``pp`` and energy vector ``ee``: ``Plant.step`` with the
    inputs held (without its inverter delay), that is its kernel ``plant_advance`` with the
    voltage inside the DC link's limit. ``STEP_TAKEN``, or ``STEP_DECLINED`` with nothing changed (the module
    doc)."""
    if not h > 0.0:
        return STEP_DECLINED
    v_alpha = io[PIO_V_ALPHA]
    v_beta = io[PIO_V_BETA]
    u_lim = dc_link_limit(pp, ee, io[PIO_U_LIM])  # the ideal link's, or the battery's of the step before
    if u_lim != 0.0 and not v_alpha * v_alpha + v_beta * v_beta < u_lim * u_lim * U_LIMIT_MARGIN:
        return STEP_DECLINED  # at or near the limit: math.hypot decides, in Python
    if not plant_advance(io, pp, ee, v_alpha, v_beta, io[PIO_DELTA], io[PIO_T_BRAKE], h, True):
        return STEP_DECLINED  # a state that is not finite: the slave raises, in its Python step
    return STEP_TAKEN


@kernel(_sig(_F, _V, _V))
def unit_t_brake(io, s):
    """``ControlUnit.T_brake`` of the state ``s`` (the unit's buffer ``io`` says its kind and reference mode): the
    friction brake's demand: the injection strategy's hill hold from enable to its first torque (``S_HOLD``), else
    0 in the paper's mode and in the sensorless unit's modes without FOC."""
    if s[S_HOLD] > 0.0:
        return s[S_HOLD]
    if io[UIO_REFERENCE] != 0.0 and (io[UIO_KIND] == UNIT_KIND_CONTROL or s[S_MODE] == MODE_EKF
                                     or s[S_MODE] == MODE_INJECTION):
        return s[S_T_BRAKE]
    return 0.0


@kernel(_sig(f"UniTuple({_F}, 3)", _V, _V, _V))
def unit_reference_outputs(io, s, c):
    """(``ControlUnit.i_dref``, ``T_ref``, ``ref_region``) of the state ``s`` (the unit's buffer ``io`` says its kind
    and reference mode; ``c`` its parameters): the reference generator's d-current reference [A], torque given
    [N m] and region where the unit runs FOC and has a generator; with no generator (the paper's references) the
    d-current reference ``C_I_D_REF`` and k_t i_qref, region 0; in the sensorless unit's alignment and I-f the
    vector's magnitude (on its d axis), 0, 0."""
    if not (io[UIO_KIND] == UNIT_KIND_CONTROL or s[S_MODE] == MODE_EKF or s[S_MODE] == MODE_INJECTION):
        return s[S_I_MAG], 0.0, 0.0
    if io[UIO_REFERENCE] != 0.0:
        return s[S_I_DREF], s[S_T_REF], s[S_REGION]
    return c[C_I_D_REF], c[C_K_T] * s[S_I_QREF], 0.0


@kernel(_sig("void", _V, _V, _V))
def unit_status_outputs(io, s, c):
    """Write the outputs ``UNIT_STATUS_OUTPUTS`` of the state ``s`` into the buffer ``io`` from ``UIO_STATUS`` on
    (``ControlUnit.psi_est`` ... ``axis_cos`` read them there; the compiled step writes them after each step): the
    adaptation's estimates and flags (0 with adaptation off, as before the first step); the identification's values, 0
    for a unit without injection (``UIO_KIND``) and until identified; L_q_id / L_d_id; sensor b's offset from the
    alpha, beta ones (i_beta = (i_a + 2 i_b) / sqrt 3); cos 2e of the axis in FOC on the injection, else 0."""
    o = UIO_STATUS
    adapt = c[C_ADAPT] != ADAPT_OFF
    io[o] = s[S_AD_PSI] if adapt else 0.0
    io[o + 1] = s[S_AD_RS] if adapt else 0.0
    io[o + 2] = s[S_AD_SEEN]
    io[o + 3] = s[S_AD_SEEN + 1]
    inj = io[UIO_KIND] == UNIT_KIND_INJECTION
    y_d = s[S_ID_Y] if inj else 0.0
    y_q = s[S_ID_Y + 1] if inj else 0.0
    l_d = 1.0 / y_d if y_d > 0.0 else 0.0
    l_q = 1.0 / y_q if y_q > 0.0 else 0.0
    io[o + 4] = l_d
    io[o + 5] = l_q
    io[o + 6] = l_q / l_d if l_d > 0.0 else 0.0
    io[o + 7] = s[S_ID_RS] if inj else 0.0
    io[o + 8] = s[S_ID_NOISE_F] if inj else 0.0
    io[o + 9] = s[S_ID_OFS] if inj else 0.0
    io[o + 10] = 0.5 * (math.sqrt(3.0) * s[S_ID_OFS + 1] - s[S_ID_OFS]) if inj else 0.0
    io[o + 11] = s[S_ID_ACC] if inj else 0.0
    io[o + 12] = s[S_ID_BLIND] if inj else 0.0
    io[o + 13] = s[S_AXIS_F] if inj and s[S_MODE] == MODE_INJECTION else 0.0
    io[o + 14] = s[S_GAIN_RATIO] if inj else 0.0


@kernel(_sig("int64", _F, _F, _F, _F))
def sample_instant(t, t0, dt, tolerance):
    """The index of the first sample instant t0 + k dt at or after t of a controller FMU's sample clock, an
    instant within ``tolerance`` dt before t counting as t (``pmsm_ev_fmus.foc_slave``)."""
    return math.ceil((t - t0) / dt - tolerance)


@kernel(_sig("void", _V, _V, _V, "int64"))
def unit_periods(io, s, c, n):
    """n control periods of a controller FMU's unit on the inputs held in its buffer ``io`` (``UNIT_IO_LAYOUT``:
    ``ControlUnit.io``) and its state and parameter vectors ``s``, ``c``, the outputs written into ``io``: the
    unit's kernel (``control_step``, ``sensorless_step``, ``injection_unit_step`` by ``UIO_KIND``), then the control
    frame. ``FocSlave.do_step`` and the compiled step (``unit_fmu_step``) both run the periods so. On a measured DC
    link (the input v_dc_meas > 0, a battery's) the unit's limits follow it first (``unit_dc_link``)."""
    if io[UIO_V_DC_MEAS] > 0.0:
        unit_dc_link(c, io[UIO_V_DC_MEAS], io[UIO_P_CHARGE_MAX], io[UIO_P_DISCHARGE_MAX])
    kind = io[UIO_KIND]
    while n > 0:
        if kind == UNIT_KIND_CONTROL:
            (io[UIO_V_ALPHA], io[UIO_V_BETA], io[UIO_V_D], io[UIO_V_Q], io[UIO_I_D], io[UIO_I_Q], io[UIO_I_QREF],
             io[UIO_I_D_HAT], io[UIO_I_Q_HAT], io[UIO_OMEGA_HAT], io[UIO_THETA_HAT], io[UIO_T_L_HAT]) = control_step(
                s, c, io[UIO_I_ALPHA], io[UIO_I_BETA], io[UIO_OMEGA_REF], io[UIO_THETA_MEAS], io[UIO_OMEGA_MEAS])
            io[UIO_OMEGA_CTRL] = io[UIO_OMEGA_HAT]
            io[UIO_THETA_CTRL] = io[UIO_THETA_MEAS] if io[UIO_MEASURED] != 0.0 else io[UIO_THETA_HAT]
        elif kind == UNIT_KIND_SENSORLESS:  # never reads theta_meas, omega_meas
            (io[UIO_V_ALPHA], io[UIO_V_BETA], io[UIO_V_D], io[UIO_V_Q], io[UIO_I_D], io[UIO_I_Q], io[UIO_I_QREF],
             io[UIO_I_D_HAT], io[UIO_I_Q_HAT], io[UIO_OMEGA_HAT], io[UIO_THETA_HAT], io[UIO_T_L_HAT], io[UIO_MODE],
             io[UIO_FAULT], io[UIO_THETA_CTRL], io[UIO_OMEGA_CTRL]) = sensorless_step(
                s, c, io[UIO_I_ALPHA], io[UIO_I_BETA], io[UIO_OMEGA_REF])
        else:
            (io[UIO_V_ALPHA], io[UIO_V_BETA], io[UIO_V_D], io[UIO_V_Q], io[UIO_I_D], io[UIO_I_Q], io[UIO_I_QREF],
             io[UIO_I_D_HAT], io[UIO_I_Q_HAT], io[UIO_OMEGA_HAT], io[UIO_THETA_HAT], io[UIO_T_L_HAT], io[UIO_MODE],
             io[UIO_FAULT], io[UIO_THETA_CTRL], io[UIO_OMEGA_CTRL]) = injection_unit_step(
                s, c, io[UIO_I_ALPHA], io[UIO_I_BETA], io[UIO_OMEGA_REF])
        n -= 1


@kernel()
def unit_fmu_step(io, s, c, t, h):
    """``FocSlave.do_step(t, h)`` on the unit's buffer ``io`` (``UNIT_IO_LAYOUT``: ``ControlUnit.io``, the slave's
    inputs, outputs and sample clock written into it) and its state and parameter vectors ``s``, ``c``: the sample
    clock, then ``unit_periods`` for the instants in [t, t + h) not yet run, on the inputs held. ``STEP_TAKEN``, or
    ``STEP_DECLINED`` with nothing changed (the module doc)."""
    if not h > 0.0:
        return STEP_DECLINED
    tolerance = io[UIO_TOLERANCE]
    dt = io[UIO_DT]
    if io[UIO_CLOCK] == 0.0:  # the first step starts the clock (FocSlave._start_clock)
        if dt == 0.0:
            if h != io[UIO_UNIT_DT]:
                return STEP_DECLINED  # the unit is rebuilt for dt = h: in Python
            dt = h
        k_next = sample_instant(t, io[UIO_T0], dt, tolerance)
        io[UIO_DT] = dt
        io[UIO_K_NEXT] = k_next
        io[UIO_CLOCK] = 1.0
    else:
        k_next = int(io[UIO_K_NEXT])
    k_end = sample_instant(t + h, io[UIO_T0], dt, tolerance)
    if k_end > k_next:
        unit_periods(io, s, c, k_end - k_next)
        io[UIO_K_NEXT] = k_end
    io[UIO_T_BRAKE] = unit_t_brake(io, s)
    io[UIO_I_DREF], io[UIO_T_REF], io[UIO_REF_REGION] = unit_reference_outputs(io, s, c)
    unit_status_outputs(io, s, c)
    return STEP_TAKEN


# -- the C functions (compiled kernels only) --------------------------------------------------------------------
#: kind -> the compiled C function (numba's ``CFunc``), made when first asked for
_CFUNCS: dict = {}


def _plant_c(io, pp, ee, t, h):
    """The plant's C step: ``plant_fmu_step`` on the buffers at the three addresses."""
    a = carray(io, PLANT_IO)
    b = carray(ee, PLANT_ENERGY)
    p = carray(pp, PLANT_PARAMS)
    t_brake = p[P_T_BRAKE]
    try:
        return plant_fmu_step(a, p, b, h)
    except Exception:  # the vectors as they were: the Python step raises it
        for i in range(PLANT_ENERGY):
            b[i] = a[PIO_SAVE + i]
        p[P_T_BRAKE] = t_brake
        return STEP_FAILED


def _unit_c(io, s, c, t, h):
    """A controller's C step: ``unit_fmu_step`` on the buffers at the three addresses."""
    a = carray(io, UNIT_IO)
    state = carray(s, UNIT_STATE)
    for i in range(UNIT_STATE):
        a[UIO_SAVE + i] = state[i]
    clock = a[UIO_CLOCK]
    dt = a[UIO_DT]
    k_next = a[UIO_K_NEXT]
    try:
        return unit_fmu_step(a, state, carray(c, UNIT_PARAMS), t, h)
    except Exception:  # the state as it was: the Python step raises it
        for i in range(UNIT_STATE):
            state[i] = a[UIO_SAVE + i]
        a[UIO_CLOCK] = clock
        a[UIO_DT] = dt
        a[UIO_K_NEXT] = k_next
        return STEP_FAILED


def _pass_c(io, a, b, t, h):
    """The benchmark's pass-through units' C step (``PassThroughPlant``, ``PassThroughFoc``): nothing computed,
    the outputs keep their values, as their Python ``do_step``."""
    return STEP_TAKEN


_C_STEPS = {"plant": _plant_c, "unit": _unit_c, "pass": _pass_c}


def fmu_step_address(kind: str) -> int:
    """The address of the C function ``int32 step(double *io, double *a, double *b, double t, double h)`` of
    ``kind`` ("plant": a, b the parameter and energy vectors; "unit": the state and parameter vectors; "pass": the
    benchmark's pass-through units, nothing computed), compiled
    (or loaded from numba's cache) when first asked for; 0 where the kernels run as plain Python."""
    if not JIT:
        return 0
    if kind not in _CFUNCS:
        from numba import cfunc, types  # noqa: PLC0415 - numba only when the kernels are compiled

        double = types.CPointer(types.float64)
        signature = types.int32(double, double, double, types.float64, types.float64)
        # the first one made is kept for good (another thread's, made meanwhile, is dropped before any address of
        # it is handed out): the instances call it by its address
        _CFUNCS.setdefault(kind, cfunc(signature, cache=CACHE)(_C_STEPS[kind]))
    return _CFUNCS[kind].address

