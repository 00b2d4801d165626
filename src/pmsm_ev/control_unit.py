"""The controller-plus-observer: what the second FMU wraps.

Per control period, at t_k, with the plant's measured currents at t_k:

1. observer time update with the voltage held over [t_{k-1}, t_k] (eqs 23-24): the dq
   command, or the stationary-frame vector (v_alpha, v_beta) actually sent to the
   inverter for the stationary-frame EKF5, which turns it into its own frame;
2. the frame angle: the measured rotor angle ("measured", the paper's own simulation,
   whose EKF is fed dq currents in the true frame) or the observer's predicted angle
   ("estimated", truly sensorless); Park of the measured currents at that angle;
3. observer measurement update (eqs 25-27);
4. speed PI on omega_hat (14), current PIs + decoupling on omega_hat (15-20); with
   ``ControllerParams.reference`` "mtpa" or "fw" the speed PI commands a torque that the
   reference generator (``pmsm_ev.kernels.references``: MTPA, field weakening, MTPV, the
   current, torque and regenerative limits) turns into (i_dref, i_qref), docs/speed-range.md;
5. inverse Park at the control angle (measured, or the updated estimate), advanced by
   ``angle_advance`` periods of omega_hat, to v_alpha, v_beta held until t_{k+1}; with
   ``zoh_compensation`` the held vector is lengthened by a/sin(a), a = omega_e dt/2, so
   that its mean over the period, seen from the turning rotor, equals the command;
   with ``dead_time_comp`` the vector sent to the inverter gets the dead time's expected
   loss for the measured phase currents added (the observer keeps the command). With
   ``current_control = "high_speed"`` steps 4-5 are the high-speed current control and its
   ZOH gain sin(a)/a (docs/speed-range.md; ``pmsm_ev.kernels.current_step_hs``, ``modulate``).

The controller's motor model is its own ``MotorParams`` (nominal): a plant with another
R_s, psi, L_q, saturation, temperature or dead time is a model mismatch for the observer.
The PI gains are derived from that model and the bandwidths of ``ControllerParams`` when
the unit is built (``pmsm_ev.controller.controller_gains``, the unit's ``gains``), so the
model's L_d, L_q, R_s, N, psi and J_m also tune the controllers.

The step is ``pmsm_ev.kernels.control_step`` (compiled with numba when available, see
``pmsm_ev.accel``) on one state vector that the observer and the controllers share.

Observer "sensorless" is the truly sensorless unit from standstill: the stationary-frame
EKF5 with a low-speed range (alignment, I-f drive, handover to and from the EKF,
``pmsm_ev.params.StartupParams``); its step is ``pmsm_ev.kernels.sensorless_step``, it
never reads theta_meas or omega_meas, and it returns the mode, the fault and the control
frame's angle and speed as outputs 13-16.
"""

from __future__ import annotations

import functools
import math

from . import accel
from . import kernels as _k
from .controller import CurrentController, SpeedController, controller_gains, state_slot
from .observers import make_observer
from .params import (
    ANGLE_SOURCES,
    SENSORLESS_EKF,
    ControllerParams,
    EkfParams,
    InjectionParams,
    MotorParams,
    ParameterError,
    PlantParams,
    StartupParams,
    flux_model_coefficients,
)

#: mode names of the sensorless unit, by ``pmsm_ev.kernels`` MODE_* value: the I-f strategy's alignment and
#: I-f, FOC on the EKF, the injection strategy's acquisition, polarity test and FOC on the injection
MODES = ("align", "I-f", "EKF", "acquire", "polarity", "injection")

_STARTUP_SLOTS = (
    ("t_ramp", _k.C_T_RAMP), ("t_hold", _k.C_T_HOLD), ("t_sweep", _k.C_T_SWEEP), ("t_settle", _k.C_T_SETTLE),
    ("i_align", _k.C_I_ALIGN), ("i_if", _k.C_I_IF), ("if_accel", _k.C_IF_ACCEL), ("i_rate", _k.C_I_RATE),
    ("omega_up", _k.C_W_UP), ("omega_down", _k.C_W_DOWN), ("agree_tol", _k.C_AGREE_TOL),
    ("agree_time", _k.C_AGREE_TIME), ("if_margin", _k.C_IF_MARGIN), ("if_load_angle", _k.C_E_MAX),
    ("i_rate_load", _k.C_I_RATE_LOAD), ("sync_guard", _k.C_GUARD), ("guard_angle", _k.C_E_GUARD),
    ("slip_tol", _k.C_SLIP_TOL), ("slip_time", _k.C_SLIP_TIME), ("recover_time", _k.C_RECOVER_TIME),
    ("fault_time", _k.C_FAULT_TIME), ("align_damping", _k.C_ALIGN_DAMP),
    ("align_slip", _k.C_ALIGN_SLIP), ("align_slip_time", _k.C_ALIGN_SLIP_TIME),
    ("still_speed", _k.C_STILL), ("if_deadline", _k.C_IF_DEADLINE), ("stall_time", _k.C_STALL_TIME),
    ("realign_max", _k.C_REALIGN_MAX), ("anchor_speed", _k.C_ANCHOR_SPEED),
    ("soft_guard_angle", _k.C_SOFT_GUARD), ("guard_band", _k.C_GUARD_BAND), ("trust_move", _k.C_TRUST_MOVE),
    ("relock_time", _k.C_RELOCK_TIME), ("still_time", _k.C_STILL_TIME))
#: the injection's parameters (``InjectionParams``) that go into the parameter vector as they are
_INJECTION_SLOTS = (
    ("inj_blend_low", _k.C_BLEND_LO), ("inj_blend_high", _k.C_BLEND_HI), ("inj_hysteresis", _k.C_BLEND_HYST),
    ("inj_lock_time", _k.C_ACQ_TIME), ("inj_settle_time", _k.C_ACQ_SETTLE), ("pol_current", _k.C_POL_I),
    ("pol_ramp", _k.C_POL_RAMP), ("pol_hold", _k.C_POL_HOLD), ("pol_contrast", _k.C_POL_CONTRAST),
    ("inj_los_angle", _k.C_INJ_LOS_ANGLE), ("inj_los_time", _k.C_INJ_LOS_TIME),
    ("ekf_los_current", _k.C_EKF_LOS_I), ("ekf_los_time", _k.C_EKF_LOS_TIME),
    ("inj_current_limit", _k.C_INJ_I_MAX), ("pol_frame_band", _k.C_POL_BAND), ("id_time", _k.C_ID_TIME),
    ("saliency_min", _k.C_SALIENCY_MIN), ("saliency_trust", _k.C_SALIENCY_TRUST), ("inj_axis_cos", _k.C_AXIS_COS),
    ("inj_voltage_max", _k.C_INJ_V_MAX),
    ("rs_current", _k.C_RS_I), ("rs_time", _k.C_RS_TIME), ("ofs_time", _k.C_OFS_TIME),
    ("inj_angle_max", _k.C_ANGLE_MAX), ("emf_slip_speed", _k.C_EMF_SPEED), ("emf_slip_rel", _k.C_EMF_REL),
    ("inj_see_max", _k.C_SEE_MAX), ("gain_turns", _k.C_GAIN_TURNS), ("saliency_hold", _k.C_SALIENCY_HOLD),
    ("gain_standstill_se", _k.C_GAIN_SE))
#: the injection strategy's loss detectors low-pass filter their inputs over a third of ``inj_los_time`` (the time
#: constant): a step then reaches 95 % (1 - e^-3) of its size within the time the detector waits [chosen]
LOS_FILTER_CONSTANTS = 3.0


#: a controller FMU's sample clock (``pmsm_ev_fmus.foc_slave``): an instant within this fraction of dt of a
#: communication point counts as that point: far above the drift of time accumulated as t += h (1.6e-4 dt after
#: 350 s at h = dt, 7e-4 dt at h = dt/3), far below any step size that makes sense
SAMPLE_TOLERANCE = 1.0e-2
#: a controller FMU's Real inputs and the outputs its step writes, in the unit's buffer ``ControlUnit.io``
#: (``pmsm_ev.kernels.UNIT_IO_LAYOUT``; the outputs in the layout's order)
IO_INPUTS = ("i_alpha", "i_beta", "omega_ref", "theta_meas", "omega_meas", "v_dc_meas", "P_charge_max",
             "P_discharge_max")
IO_OUTPUTS = ("v_alpha", "v_beta", "v_d", "v_q", "i_d", "i_q", "i_qref", "i_d_hat", "i_q_hat", "omega_hat",
              "theta_hat", "T_L_hat", "mode", "fault", "theta_ctrl", "omega_ctrl")
#: their slots there, by name
IO_SLOTS = {name: getattr(_k, "UIO_" + name.upper()) for name in IO_INPUTS + IO_OUTPUTS}


def parameter_groups(observer: str) -> tuple:
    """The parameter groups of a unit with ``observer``, as a controller FMU declares them (a class: its defaults;
    an instance: its values): the controller's, the EKF's (``SENSORLESS_EKF`` for the sensorless unit), the motor
    model's, and the sensorless unit's start-up and injection (``ControlUnit.from_groups`` makes the unit)."""
    if observer == "sensorless":
        return (ControllerParams, SENSORLESS_EKF, MotorParams, StartupParams, InjectionParams)
    return (ControllerParams, EkfParams, MotorParams)


def _status(j: int, doc: str) -> property:
    """A read-only attribute of ``ControlUnit``: the output ``UNIT_STATUS_OUTPUTS[j]`` of its state
    (``ControlUnit._status_output``)."""
    return property(lambda self: self._status_output(j), doc=doc)


def _cross_saturation_inductances(motor: MotorParams, step: float, n: int) -> list[tuple[float, float, float]]:
    """The incremental inductance matrix (L_dd, L_dq, L_qq) [H] at i_d = 0, i_q = 0, step, .. (n - 1) step [A] in
    the algebraic flux model with its default shape (``PlantParams``) on this motor's L_d, L_q and psi: the
    controller's model of the saturation."""
    coeffs = [float(x) for x in flux_model_coefficients(motor, PlantParams(flux_model="algebraic"))]
    return [_k.incremental_inductances(0.0, j * step, coeffs, 0) for j in range(n)]


def cross_saturation_admittances(motor: MotorParams, step: float = _k.CROSS_STEP,
                                 n: int = _k.CROSS_POINTS) -> list[tuple[float, float, float]]:
    """The incremental admittance matrix (g_dd, g_dq, g_qq) [1/H], the inverse of the incremental inductance
    matrix, at the points of ``cross_saturation_offsets``: what ``kernels.adaptation.cross_apply`` shifts by the
    identified motor's admittances at zero current (AD8)."""
    out = []
    for l_dd, l_dq, l_qq in _cross_saturation_inductances(motor, step, n):
        det = l_dd * l_qq - l_dq * l_dq
        out.append((l_qq / det, -l_dq / det, l_dd / det))
    return out


def cross_saturation_offsets(motor: MotorParams, step: float = _k.CROSS_STEP, n: int = _k.CROSS_POINTS) -> list[float]:
    """The injection's axis less the rotor's d axis [rad] at i_d = 0, i_q = 0, step, .. (n - 1) step [A]:
    the angle from d of the incremental inductance's least axis (the injection's error signal is 0 there,
    ``pmsm_ev.kernels.injection``) in the controller's model of the saturation (``_cross_saturation_inductances``)."""
    out = []
    for l_dd, l_dq, l_qq in _cross_saturation_inductances(motor, step, n):
        # the eigenvector (l_dq, lam - l_dd) of the least eigenvalue lam, its angle from d in (-pi/2, pi/2]
        lam = 0.5 * (l_dd + l_qq) - math.sqrt(0.25 * (l_dd - l_qq) ** 2 + l_dq * l_dq)
        phi = math.atan2(lam - l_dd, l_dq) if l_dq != 0.0 else 0.0
        out.append(phi - math.pi * math.ceil(phi / math.pi - 0.5))
    return out


class ControlUnit:
    v_d = state_slot(_k.S_V_D, "commanded d voltage (eq 19, limited) [V]")
    v_q = state_slot(_k.S_V_Q, "commanded q voltage (eq 20, limited) [V]")
    u_prev0 = state_slot(_k.S_U_PREV_0, "the observer's voltage input of one period earlier, d or alpha [V]")
    u_prev1 = state_slot(_k.S_U_PREV_1, "the observer's voltage input of one period earlier, q or beta [V]")
    v_alpha = state_slot(_k.S_V_ALPHA, "voltage held until the next step, alpha axis [V]")
    v_beta = state_slot(_k.S_V_BETA, "voltage held until the next step, beta axis [V]")
    i_d = state_slot(_k.S_I_D, "d current in the control frame [A]")
    i_q = state_slot(_k.S_I_Q, "q current in the control frame [A]")
    i_qref = state_slot(_k.S_I_QREF, "q current reference (eq 14) [A]")

    def __init__(self, observer: str = "ekf5", angle_source: str = "measured",
                 motor: MotorParams | None = None, controller: ControllerParams | None = None,
                 ekf: EkfParams | None = None, dt: float = 1e-4, startup: StartupParams | None = None,
                 injection: InjectionParams | None = None):
        self.motor = motor or MotorParams()
        self.params = controller or ControllerParams()
        self.sensorless = observer == "sensorless"
        self.ekf_params = ekf or (SENSORLESS_EKF if self.sensorless else EkfParams())
        self.startup = startup or StartupParams()
        self.injection = injection or InjectionParams()
        for group in (self.motor, self.params, self.ekf_params, self.startup):
            group.validate()
        if angle_source not in ANGLE_SOURCES:
            raise ParameterError(f"angle_source must be one of {ANGLE_SOURCES} (got {angle_source!r})")
        if not dt > 0:
            raise ParameterError(f"dt must be > 0 s (got {dt})")
        self.dt = dt
        #: the sensorless unit's strategy at and near zero speed: injection (``pmsm_ev.kernels.modes``)
        self.injecting = self.sensorless and self.injection.low_speed == "injection"
        if self.sensorless:  # the injection's voltage and frequency checked where it runs
            self.injection.validate(dt if self.injecting else None, self.params.u_limit if self.injecting else None)
        self.observer_name = observer
        self._kernels = accel.kernels()
        self._s = accel.vector(_k.UNIT_STATE)
        self._c = accel.vector(_k.UNIT_PARAMS)
        #: the step's kernel on this unit's vectors (what ``step`` calls, for a caller's hot loop):
        #: ``(i_alpha, i_beta, omega_ref)`` of the sensorless unit, ``(i_alpha, i_beta, omega_ref,
        #: theta_meas, omega_meas)`` of the others; returns ``step``'s outputs
        self.kernel_step = functools.partial(
            accel.direct(self._kernels.injection_unit_step if self.injecting else
                         self._kernels.sensorless_step if observer == "sensorless" else self._kernels.control_step),
            self._s, self._c)
        self.observer = make_observer(observer, self.motor, dt, self.ekf_params, state=self._s, params=self._c)
        # the sensored baseline has no angle estimate of its own: always the measured angle;
        # the sensorless unit has no other
        self.angle_source = ("measured" if observer == "sensored" else
                             "estimated" if self.sensorless else angle_source)
        # the gains, from the design and this unit's own motor model (and, for the I-f damping,
        # the inertia of its EKF's model)
        self.gains = controller_gains(self.params, self.motor, self.startup if self.sensorless else None,
                                      self.observer.J if self.sensorless else 0.0)
        self.speed = SpeedController(self.params, self.motor, dt, state=self._s, params=self._c, gains=self.gains)
        self.current = CurrentController(self.params, self.motor, dt, state=self._s, params=self._c,
                                         gains=self.gains)
        c = self._c
        c[_k.C_I_D_REF] = float(self.params.i_d_ref)
        c[_k.C_ADVANCE] = self.params.angle_advance * dt * self.motor.N
        c[_k.C_HALF_PERIOD_N] = 0.5 * dt * self.motor.N
        c[_k.C_ZOH] = 1.0 if self.params.zoh_compensation else 0.0
        c[_k.C_DELAYED] = 1.0 if self.params.delay_compensation else 0.0
        c[_k.C_ESTIMATED] = 1.0 if self.angle_source == "estimated" else 0.0
        c[_k.C_DTC_V] = float(self.params.dead_time_comp)
        c[_k.C_DTC_I0] = float(self.params.dead_time_comp_i0)
        self.psi_adapt = self.ekf_params.psi_adapt > 0
        if self.psi_adapt and observer not in ("ekf5ab", "sensorless"):
            raise ParameterError(f"psi_adapt needs the stationary-frame EKF5 (observer ekf5ab or sensorless; "
                                 f"got {observer})")
        c[_k.C_PSI_ADAPT] = float(self.ekf_params.psi_adapt)
        c[_k.C_PSI_ADAPT_W] = float(self.ekf_params.psi_adapt_speed)
        for name, slot in _STARTUP_SLOTS:
            c[slot] = float(getattr(self.startup, name))
        # the EKF's restart after the alignment: its P0, with the speed and angle known
        st = self.startup
        e = self.ekf_params
        for i, p0 in enumerate((e.p0_i, e.p0_i, st.p0_omega_aligned, st.p0_theta_aligned, e.p0_TL)):
            c[_k.C_P0_ALIGNED + i] = float(p0)
        c[_k.C_IF_DAMP] = self.gains.k_if  # the I-f damping gain times sqrt(i)
        c[_k.C_SLIP_FILTER] = min(dt / st.if_damping_filter, 1.0) if st.if_damping_filter > 0 else 1.0
        # the I-f sizing: the EKF model's inertia and the sine of the design load angle
        c[_k.C_J_IF] = float(self.observer.J) if self.sensorless else 0.0
        c[_k.C_SIN_E] = math.sin(st.if_load_angle)
        # the reference generator (docs/speed-range.md): off ("paper") by default
        pr, m = self.params, self.motor
        pr.validate_limits(m)
        self.reference = _k.REFERENCE_CODES[pr.reference]
        c[_k.C_REF_MODE] = self.reference
        c[_k.C_I_MAX] = float(pr.i_max)
        c[_k.C_T_MAX] = float(pr.T_max or pr.torque_at_current_limit(m))
        c[_k.C_U_FW] = pr.fw_margin * pr.u_limit if pr.reference == "fw" else 0.0
        c[_k.C_FW_MARGIN] = pr.fw_margin if pr.reference == "fw" else 0.0  # on a measured DC link (``dc_link``)
        c[_k.C_K_T] = m.k_dq * m.N * m.psi
        c[_k.C_K_DQN] = m.k_dq * m.N
        c[_k.C_P_REGEN] = float(pr.P_regen_max)
        c[_k.C_BRAKE_GAIN] = pr.n_g * pr.eta
        # the speed loop's feedforward: off ("none") by default
        c[_k.C_FF] = 0.0 if pr.speed_feedforward == "none" else 1.0
        c[_k.C_J_FF] = m.J_m + pr.J_load if c[_k.C_FF] else 0.0
        road = pr.speed_feedforward == "inertia+road"
        c[_k.C_FF_T0] = float(pr.ff_T0) if road else 0.0
        c[_k.C_FF_T1] = float(pr.ff_T1) if road else 0.0
        c[_k.C_FF_T2] = float(pr.ff_T2) if road else 0.0
        self._set_adaptation()
        self._set_injection()
        #: the controller FMU's buffer of its step (``pmsm_ev.kernels.UNIT_IO_LAYOUT``): its inputs, outputs and
        #: sample clock (``load_io``), which ``pmsm_ev.kernels.unit_fmu_step`` and ``unit_periods`` step on
        self.io = accel.vector(_k.UNIT_IO)
        self._t_brake = accel.direct(self._kernels.unit_t_brake)
        self._reference_outputs = accel.direct(self._kernels.unit_reference_outputs)
        self._status_outputs = accel.direct(self._kernels.unit_status_outputs)
        #: ``io`` read and written from Python (``FocSlave.do_step``): a memoryview of the numpy vector, whose items
        #: are Python floats (the same doubles, without numpy's scalar per read), or the list
        self._io_items = self.io if isinstance(self.io, list) else memoryview(self.io)
        io = self._io_items
        io[_k.UIO_UNIT_DT] = dt
        io[_k.UIO_TOLERANCE] = SAMPLE_TOLERANCE
        io[_k.UIO_KIND] = (_k.UNIT_KIND_INJECTION if self.injecting else _k.UNIT_KIND_SENSORLESS if self.sensorless
                           else _k.UNIT_KIND_CONTROL)
        io[_k.UIO_MEASURED] = 1.0 if self.angle_source == "measured" else 0.0
        io[_k.UIO_REFERENCE] = self.reference
        self.reset()
        self.load_io(self.outputs(), None)  # the outputs before the first period (the mode and fault of a unit
        # without them stay so)

    @classmethod
    def from_groups(cls, observer: str, angle_source: str, group, dt: float) -> ControlUnit:
        """The unit of ``observer`` from its ``parameter_groups``, ``group(cls)`` giving the group of that class."""
        sensorless = observer == "sensorless"
        return cls(observer, angle_source, group(MotorParams), group(ControllerParams), group(EkfParams), dt,
                   group(StartupParams) if sensorless else None, group(InjectionParams) if sensorless else None)

    def outputs(self, theta_meas: float = 0.0) -> dict[str, float]:
        """A controller FMU's outputs of the unit's state (``IO_OUTPUTS``, by name), ``theta_meas`` the control
        frame's angle of a unit on the measured angle."""
        i_d_hat, i_q_hat, omega_hat, theta_hat, T_L_hat = self.estimates
        v_alpha, v_beta = self.v_out
        return {"v_alpha": v_alpha, "v_beta": v_beta, "v_d": self.v_d, "v_q": self.v_q, "i_d": self.i_d,
                "i_q": self.i_q, "i_qref": self.i_qref, "i_d_hat": i_d_hat, "i_q_hat": i_q_hat,
                "omega_hat": omega_hat, "theta_hat": theta_hat, "T_L_hat": T_L_hat, "mode": self.mode,
                "fault": self.fault,
                "theta_ctrl": self.theta_ctrl if self.sensorless or self.angle_source == "estimated" else theta_meas,
                "omega_ctrl": self.omega_ctrl}

    def load_io(self, values, dt: float | None, t0: float = 0.0, k_next: int | None = None) -> None:
        """Fill ``io`` for a controller FMU's step in compiled code (``pmsm_ev.kernels.unit_fmu_step``): the FMU's
        inputs and outputs from ``values`` (by name: ``IO_INPUTS``, ``IO_OUTPUTS``; an input not there is 0), the
        friction brake's demand of the state, and its sample clock: the sample period ``dt`` (None: not fixed
        yet, the first step's size), the start time ``t0`` and the index of the next sample instant (None: the
        first step starts the clock)."""
        io = self._io_items
        for name, slot in IO_SLOTS.items():
            io[slot] = values.get(name, 0.0)
        io[_k.UIO_T_BRAKE] = self.T_brake
        io[_k.UIO_I_DREF], io[_k.UIO_T_REF], io[_k.UIO_REF_REGION] = self._reference_outputs(self.io, self._s, self._c)
        self._status_outputs(self.io, self._s, self._c)
        io[_k.UIO_DT] = dt or 0.0
        io[_k.UIO_T0] = t0
        io[_k.UIO_CLOCK] = 0.0 if k_next is None else 1.0
        io[_k.UIO_K_NEXT] = k_next or 0

    def _set_injection(self) -> None:
        """The injection strategy's parameters (``InjectionParams``) into the parameter vector; the
        tracking observer's gains from its bandwidth a (three poles at -a, ``pmsm_ev.kernels.injection``
        (I3)): l1 = 3 a, l2 = 3 a^2 / N, l3 = a^3 J / N, J the EKF model's inertia."""
        c, p, m = self._c, self.injection, self.motor
        c[_k.C_LOW_SPEED] = _k.LOW_SPEED_CODES[p.low_speed]
        c[_k.C_INJ_V] = float(p.inj_voltage)
        c[_k.C_INJ_M] = float(p.half_wave(self.dt))
        c[_k.C_INJ_Y] = 0.5 * (1.0 / m.L_d - 1.0 / m.L_q)
        a = float(p.inj_bandwidth)
        j = float(self.observer.J) if self.sensorless else m.J_m
        c[_k.C_TRK_L1] = 3.0 * a
        c[_k.C_TRK_L2] = 3.0 * a * a / m.N
        c[_k.C_TRK_L3] = a ** 3 * j / m.N
        c[_k.C_TRK_J] = j
        for name, slot in _INJECTION_SLOTS:
            c[slot] = float(getattr(p, name))
        c[_k.C_LOS_FILTER] = min(LOS_FILTER_CONSTANTS * self.dt / p.inj_los_time, 1.0)
        c[_k.C_EKF_LOS_EMF] = self.dt * m.N * m.psi / m.L_q
        offsets = cross_saturation_offsets(m) if p.inj_cross_comp else [0.0] * _k.CROSS_POINTS
        for j, phi in enumerate(offsets):
            c[_k.C_CROSS + j] = phi
            c[_k.C_MODEL0_CROSS + j] = phi
        # the identified motor's offsets and current limit (AD8, ``kernels.adaptation.cross_apply``) from the given
        # model's admittances: its offset at the given limit is the limit's measure
        c[_k.C_MODEL0_INJ_I_MAX] = c[_k.C_INJ_I_MAX]
        admittances = cross_saturation_admittances(m) if p.inj_cross_comp else [(0.0, 0.0, 0.0)] * _k.CROSS_POINTS
        for j, g in enumerate(admittances):
            c[_k.C_CROSS_G + 3 * j:_k.C_CROSS_G + 3 * j + 3] = g
        c[_k.C_INJ_TILT_MAX] = _k.cross_offset(c, c[_k.C_INJ_I_MAX])
        c[_k.C_HOLD_BRAKE] = float(p.hold_brake) * c[_k.C_T_MAX] * c[_k.C_BRAKE_GAIN]

    def _set_adaptation(self) -> None:
        """Adaptation while driving (``ControllerParams.adaptation``, ``pmsm_ev.kernels.adaptation``) into the
        parameter vector: its mode, thresholds (speeds as electrical rad/s) and where its estimates start, the
        model's psi and R_s, with the EKF's psi-proportional constants at that psi."""
        c, p, m = self._c, self.params, self.motor
        c[_k.C_ADAPT] = _k.ADAPT_CODES[p.adaptation]
        c[_k.C_AD_GAIN] = min(self.dt / p.adapt_time, 1.0)
        c[_k.C_AD_PSI_W] = m.N * p.adapt_psi_speed
        c[_k.C_AD_RS_W] = m.N * p.adapt_rs_speed
        c[_k.C_AD_RS_I] = float(p.adapt_rs_current)
        c[_k.C_AD_RATE] = float(p.adapt_current_rate)
        c[_k.C_AD_PSI0] = m.psi
        c[_k.C_AD_RS0] = m.R_s
        c[_k.C_AD_NOM_WPSI] = c[_k.C_C_WPSI]
        c[_k.C_AD_NOM_TPSI] = c[_k.C_C_TPSI]
        # the controller's model from the identification (``model_source``, AD7): the given one kept to go back to
        c[_k.C_MODEL_SRC] = _k.MODEL_CODES[p.model_source]
        for i, value in enumerate((m.L_d, m.L_q, m.R_s, c[_k.C_KP_ID], c[_k.C_KI_ID], c[_k.C_KP_IQ], c[_k.C_KI_IQ])):
            c[_k.C_MODEL0 + i] = float(value)

    def reset(self) -> None:
        """The unit as enabled: every slot of the state at its declared reset value (``UNIT_STATE_LAYOUT.reset``), then
        what depends on the parameters: the observer's start (x0, P0), the model and the adaptation's estimates, and
        with injection the acquisition."""
        _k.UNIT_STATE_LAYOUT.reset(self._s)
        self.observer.reset()
        if self._c[_k.C_MODEL_SRC] == _k.MODEL_IDENTIFIED:  # the given model until the identification (AD7)
            self._kernels.model_apply(self._s, self._c)
        self._kernels.adapt_reset(self._s, self._c)  # psi_hat, R_s_hat on the model's (and with "use", the model)
        if self.injecting:  # enabled: the acquisition first
            self._s[_k.S_MODE] = float(_k.MODE_ACQUIRE)
            self._s[_k.S_HOLD] = self._c[_k.C_HOLD_BRAKE]  # the hill hold until the first torque
            self._kernels.enter_acquire(self._s, self._c, 0.0, 0.0)

    @property
    def v_out(self) -> tuple[float, float]:
        """The vector sent to the inverter: (v_alpha, v_beta), plus the dead-time compensation
        of the last step when ``dead_time_comp`` is on."""
        if self.params.dead_time_comp:
            return float(self._s[_k.S_V_OUT_ALPHA]), float(self._s[_k.S_V_OUT_BETA])
        return self.v_alpha, self.v_beta

    @property
    def psi_ratio(self) -> float:
        """The EKF's magnet flux over the nominal psi (1 without ``EkfParams.psi_adapt``)."""
        return float(self._s[_k.S_PSI_RATIO])

    def _status_output(self, j: int) -> float:
        """The output ``UNIT_STATUS_OUTPUTS[j]`` of the state (the kernel ``unit_status_outputs``, which the compiled
        step calls too)."""
        self._status_outputs(self.io, self._s, self._c)
        return float(self.io[_k.UIO_STATUS + j])

    # adaptation while driving (``pmsm_ev.kernels.adaptation``)
    psi_est = _status(0, "The estimated magnet flux [Wb] (eq AD3): the model's psi until psi is observable; 0 with "
                         'adaptation "off".')
    R_s_est = _status(1, "The estimated stator resistance [Ohm] (eq AD4): the identification's R_s_id or the model's "
                         'R_s until R_s is observable; 0 with adaptation "off".')
    psi_observable = _status(2, "1.0 where the last period let psi_hat move (AD5: fast enough, the currents "
                                "quasi-steady), else 0.")
    R_s_observable = _status(3, "1.0 where the last period let R_s_hat move (AD5: slow enough, current enough, "
                                "quasi-steady), else 0.")

    @property
    def fault(self) -> float:
        """The sensorless unit's fault (``pmsm_ev.kernels`` FAULT_*): 0 none, 1 a loss of synchronism
        being recovered, 2 the recovery failed, the safe state latched; 0 for the others."""
        return float(self._kernels.fault_output(self._s)) if self.sensorless else _k.FAULT_NONE

    # the injection strategy's identification at enable (``pmsm_ev.kernels.identify``)
    L_d_id = _status(4, "The identified incremental d inductance at zero current [H] (1 / (Y_s + Y_x) from the d "
                        "admittances the injection measured on the found axes and its cross answers, eq ID5); 0 "
                        "until identified, and for a unit without injection.")
    L_q_id = _status(5, "The identified incremental q inductance at zero current [H]; 0 until identified.")
    saliency_id = _status(6, "The identified saliency L_q / L_d [-]; 0 until identified.")
    R_s_id = _status(7, "The identified stator resistance [Ohm] (the R_s test at enable, "
                        "``pmsm_ev.kernels.identify_rs``); 0 until identified, and for a unit without injection.")
    noise_id = _status(8, "The current measurement's noise floor from the identification's answers: a phase sensor's "
                          "sigma [A] (``pmsm_ev.kernels.identify_noise``); 0 until identified, and for a unit without "
                          "injection.")
    offset_a_id = _status(9, "Current sensor a's offset measured at enable with no voltage [A] "
                             "(``InjectionParams.ofs_time``), subtracted from the measurements from then on; 0 until "
                             "measured, and for a unit without injection.")
    offset_b_id = _status(10, "Current sensor b's offset measured at enable [A]: i_alpha = i_a, "
                              "i_beta = (i_a + 2 i_b) / sqrt 3.")
    angle_accuracy = _status(11, "The rms angle error injection gives at a stop from the measured saliency and noise "
                                 "floor [rad] (``pmsm_ev.kernels.angle_accuracy``, eq ID3); 0 until identified.")
    blind = _status(12, "1.0 where the identified saliency is below ``InjectionParams.saliency_min`` or the angle "
                        "accuracy (``angle_accuracy``) beyond ``InjectionParams.inj_angle_max``: the injection cannot "
                        "see the rotor's axis well enough; else 0.")
    axis_cos = _status(13, "cos 2e of the tracking observer's axis error from the d admittance, filtered "
                           "(``S_AXIS_F``) in FOC on the injection; 0 there and for a unit without injection).")
    gain_ratio_id = _status(14, "The phase sensors' relative gain g_a / g_b [-] measured on the EKF (eqs SG1-SG2, "
                                "``pmsm_ev.kernels.balance_sensors``), taken out of the measurements from then on; 0 "
                                "until measured, and for a unit without injection.")

    @property
    def theta_ctrl(self) -> float:
        """The control frame's electrical angle of the last period [rad] (before the angle advance):
        the I-f or alignment vector's for the sensorless unit in those modes, else the EKF's angle;
        NaN for a unit on the measured angle (the caller has it: theta_meas)."""
        if self.sensorless:
            return float(self._s[_k.S_THETA_CTRL])
        return float(self._s[_k.S_THETA_HAT]) if self.angle_source == "estimated" else math.nan

    @property
    def omega_ctrl(self) -> float:
        """The control frame's mechanical speed of the last period [rad/s]: the I-f speed in I-f,
        else the speed the controller uses (omega_hat; the measured speed for the sensored drive)."""
        return float(self._s[_k.S_OMEGA_CTRL]) if self.sensorless else float(self._s[_k.S_OMEGA_HAT])

    # the reference generator's outputs (docs/speed-range.md); in the paper's mode computed here from the
    # paper's references (no work on its per-step path)
    def _foc(self) -> bool:
        return not self.sensorless or self._s[_k.S_MODE] in (_k.MODE_EKF, _k.MODE_INJECTION)

    @property
    def i_dref(self) -> float:
        """The d-current reference of the last period [A]: the generator's (``reference`` "mtpa", "fw"), else
        ``i_d_ref``; the sensorless unit in alignment and I-f: the vector's magnitude (on its d axis) (the kernel
        ``unit_reference_outputs``, which the compiled step calls too)."""
        return float(self._reference_outputs(self.io, self._s, self._c)[0])

    @property
    def T_ref(self) -> float:
        """The motor's torque reference of the last period, after the limits [N m]: the generator's torque
        given, else k_t i_qref (k_t = k_dq N psi); 0 in alignment and I-f (``unit_reference_outputs``)."""
        return float(self._reference_outputs(self.io, self._s, self._c)[1])

    @property
    def T_brake(self) -> float:
        """The friction brake's demand at the wheels of the last period [N m, >= 0]: the braking shaft torque
        the motor does not give (the regen limit, the envelope) x n_g eta; 0 in the paper's mode and in the
        sensorless unit's modes without FOC (the kernel ``unit_t_brake``, which the compiled step calls too)."""
        return self._t_brake(self.io, self._s)

    @property
    def ref_region(self) -> float:
        """The reference generator's region of the last period (``pmsm_ev.kernels.references`` REGION_*: 0 MTPA,
        1 field weakening, 2 MTPV, 3 current and voltage limits, 4 torque or current limit on MTPA, 5 no
        torque within the limits); 0 in the paper's mode and in alignment and I-f (``unit_reference_outputs``)."""
        return float(self._reference_outputs(self.io, self._s, self._c)[2])

    @property
    def T_avail(self) -> float:
        """The torque available at the speed of the last period, either sign [N m] (the speed PI's clamp of
        the generator's modes; 0 in the paper's mode)."""
        return float(self._s[_k.S_T_AVAIL]) if self.reference and self._foc() else 0.0

    @property
    def mode(self) -> float:
        """The sensorless unit's mode: 0 alignment, 1 I-f, 2 EKF (``MODES``); 2 for the others."""
        return float(self._s[_k.S_MODE]) if self.sensorless else float(_k.MODE_EKF)

    def dc_link(self, v_dc: float, p_charge: float, p_discharge: float) -> None:
        """On a measured DC link of ``v_dc`` [V] > 0: the voltage limits follow it and the torque is held within the
        battery's charge acceptance and discharge power [W] (``pmsm_ev.kernels.unit_dc_link``)."""
        self._kernels.unit_dc_link(self._c, v_dc, p_charge, p_discharge)

    def step(self, i_alpha: float, i_beta: float, omega_ref: float,
             theta_meas: float = 0.0, omega_meas: float = 0.0) -> tuple:
        """One control period with the measured currents at t_k (see the module doc).

        Returns (v_alpha, v_beta, v_d, v_q, i_d, i_q, i_qref, i_d_hat, i_q_hat, omega_hat,
        theta_hat, T_L_hat), which are also the attributes of the same names (the estimates
        via ``estimates``); the sensorless unit adds its mode and ignores theta_meas and
        omega_meas."""
        if self.sensorless:
            return self.kernel_step(i_alpha, i_beta, omega_ref)
        return self.kernel_step(i_alpha, i_beta, omega_ref, theta_meas, omega_meas)

    # outputs of the observer, for recording
    @property
    def estimates(self) -> tuple[float, float, float, float, float]:
        o = self.observer
        return o.i_d_hat, o.i_q_hat, o.omega_hat, o.theta_hat, o.T_L_hat

    def get_state(self) -> dict:
        """The unit's state as {field: [floats]} (JSON-serialisable): every saved slot of its state
        vector by name (``pmsm_ev.kernels.layout.UNIT_STATE_LAYOUT``; the scratch slots left out), the
        same fields whatever the observer and options."""
        return _k.UNIT_STATE_LAYOUT.save(self._s)

    def set_state(self, state) -> None:
        """Restore a ``get_state`` dict; ``LayoutError`` (naming the field) if its fields or their
        lengths are not this version's."""
        _k.UNIT_STATE_LAYOUT.restore(self._s, state)
        if self._c[_k.C_MODEL_SRC] == _k.MODEL_IDENTIFIED:  # the model follows the restored identification (AD7)
            self._kernels.model_apply(self._s, self._c)  # (and the estimates, with "use")
        elif self._c[_k.C_ADAPT] == _k.ADAPT_USE:  # the model follows the restored estimates
            self._kernels.adapt_apply(self._s, self._c)
