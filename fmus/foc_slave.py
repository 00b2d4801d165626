"""The controller-plus-observer slave shared by FocEkf5, FocEkf4, FocEkf5AB, FocSensored and
FocSensorless: ``pmsm_ev.control_unit.ControlUnit`` as an FMI 2.0 co-simulation unit.

No equations here: the control periods of a step are the kernel ``unit_periods`` on the unit's buffer
``ControlUnit.io`` (``ControlUnit.step``'s kernel, then the control frame), the inputs written into it and the
outputs copied from it into the output variables. With the kernels compiled, the lean binding runs the whole
step in compiled code instead (``pmsm_ev.kernels.unit_fmu_step``: the same sample clock, ``sample_instant``, and
the same ``unit_periods``, on the buffers of ``compiled_step``; fmus/README.md, "The compiled step").

The unit keeps its own sample clock: the sample period ``dt`` is a parameter (0, the
default: the size of the first communication step), the sample instants are
``t0 + k dt`` (``t0`` the start time of fmi2SetupExperiment), and ``do_step(t, h)`` runs
one control period for each instant in ``[t, t + h)`` not yet run, all on the inputs
held at ``t``. An instant within ``SAMPLE_TOLERANCE dt`` of ``t`` counts as ``t`` (and
one within it of ``t + h`` as ``t + h``, i.e. the next step's), so that a master's time
arithmetic (an accumulated sum ``t += h``, integer nanoseconds) neither moves a period
to another step nor runs it twice, and a sliver step at the end of a run runs none. With
``h = dt`` every step runs exactly one period, as the unit did before it had a clock.
(``SAMPLE_TOLERANCE`` is ``pmsm_ev.control_unit``'s, which the whole-loop reference uses too.)
"""

from __future__ import annotations

import math

from pmsm_ev import __version__, accel
from pmsm_ev import kernels as _k
from pmsm_ev.control_unit import IO_SLOTS, SAMPLE_TOLERANCE, ControlUnit, parameter_groups
from pmsm_ev.params import (
    DT_DEFAULT,
    ParameterError,
)
from pmsm_ev_fmus.slave_support import DriveSlave, FmuUsageError, check_fields, compiled_offer

DESCRIPTION = (
    "Speed and current control of a sensorless EV drive (Wicaksono, Harini, Yusivar, "
    "'Sensorless PMSM Control using Fifth Order EKF in Electric Vehicle Application'): "
    "field-oriented control (speed PI, current PIs, decoupling, eqs 14-20) with {observer}. "
    "A control period reads the inputs (measured currents i_alpha, i_beta; omega_ref; theta_meas, "
    "omega_meas, used only with angle_source = 'measured' or by the sensored observer), runs the "
    "observer and the controller, and sets the voltage v_alpha, v_beta that the plant must hold "
    "until the next period. "
    "The outputs change only inside fmi2DoStep, so no output depends directly on an input at the "
    "same communication point (a one-step delay, as in a sampled drive); before the first step "
    "all outputs are 0. Its own sample clock: the sample period is the parameter dt (0, the "
    "default: the size of the first communication step) and fmi2DoStep(t, h) runs one control "
    "period at each sample instant start + k dt in [t, t+h) (an instant within 1e-2 dt of t counts "
    "as t), on the inputs at t: a step shorter than dt runs one period or none, a longer one "
    "several (the later ones on the inputs held from t), so the outputs change only at the sample "
    "instants whatever the communication step size. The parameters of the motor are the "
    "controller's model of the motor and need not equal the plant's. A Python FMU (pythonfmu): it "
    "needs a Python 3 interpreter with numpy; the project code it runs is bundled in resources/."
)


#: what the controller's parameters that share a name with the plant's mean here
_CONTROLLER_NOTES = {
    "v_dc": "the controller's: its current PIs and field weakening limit the voltage to v_dc/sqrt(3); 0 = not "
            "given (u_max)",
    "n_g": "the controller's: converts the friction-brake demand T_brake to the wheels",
    "eta": "the controller's: converts the friction-brake demand T_brake to the wheels",
}


class FocSlave(DriveSlave):
    """FMU slave around ``ControlUnit`` with the observer given by the subclass."""

    def __init__(self, observer: str, observer_text: str, parameter_notes=None, **kwargs):
        super().__init__(**kwargs)
        self.parameter_notes.update(_CONTROLLER_NOTES)
        self.parameter_notes.update(parameter_notes or {})
        self.description = DESCRIPTION.format(observer=observer_text)
        self.version = __version__
        self._observer = observer

        self.add_input("i_alpha", "A", "measured stator current, alpha axis (stationary frame)")
        self.add_input("i_beta", "A", "measured stator current, beta axis (stationary frame)")
        self.add_input("omega_ref", "rad/s", "mechanical speed reference", display_unit="rpm")
        self.add_input("theta_meas", "rad", "measured electrical rotor angle (angle_source 'measured', "
                                            "sensored observer)")
        self.add_input("omega_meas", "rad/s", "measured mechanical rotor speed (sensored observer)",
                       display_unit="rpm")
        self.add_input("v_dc_meas", "V", "the DC link's measured voltage (a battery's: the plant's v_bat output); "
                                         "> 0: the voltage limit follows it (v_dc_meas / sqrt 3, field weakening at "
                                         "fw_margin of it) and the torque is held within P_charge_max, "
                                         "P_discharge_max; 0 (unconnected): the parameters' constant DC link")
        self.add_input("P_charge_max", "W", "the battery's charge acceptance (the plant's P_charge_max output): a "
                                            "braking torque's power at the shaft at most this, the friction brake "
                                            "takes the rest (read only when v_dc_meas > 0)", display_unit="kW")
        self.add_input("P_discharge_max", "W", "the battery's discharge power (the plant's P_discharge_max output): a "
                                               "motoring torque's power at the shaft at most this (read only when "
                                               "v_dc_meas > 0)", display_unit="kW")

        hold = ", computed at the last step"
        self.add_output("v_alpha", "V", "commanded stator voltage, alpha axis, to be held until the next "
                                        "step (inverse Park at the control angle advanced by angle_advance "
                                        "periods)", discrete=True)
        self.add_output("v_beta", "V", "commanded stator voltage, beta axis, to be held until the next step",
                        discrete=True)
        self.add_output("v_d", "V", "commanded d-axis voltage (eq 19, limited to u_max)" + hold, discrete=True)
        self.add_output("v_q", "V", "commanded q-axis voltage (eq 20, limited to u_max)" + hold, discrete=True)
        self.add_output("i_d_hat", "A", "observer estimate of the d-axis current" + hold, discrete=True)
        self.add_output("i_q_hat", "A", "observer estimate of the q-axis current" + hold, discrete=True)
        self.add_output("omega_hat", "rad/s", "observer estimate of the mechanical speed" + hold,
                        discrete=True, display_unit="rpm")
        self.add_output("theta_hat", "rad", "observer estimate of the electrical angle" + hold, discrete=True)
        self.add_output("T_L_hat", "N.m", "observer estimate of the load torque (0 for observers without "
                                          "a load state)" + hold, discrete=True)
        self.add_output("i_d", "A", "d-axis current as the controller sees it (measured currents, Park at "
                                    "the control angle)" + hold, discrete=True)
        self.add_output("i_q", "A", "q-axis current as the controller sees it" + hold, discrete=True)
        self.add_output("i_qref", "A", "q-current reference from the speed PI (eq 14), limited to i_q_max"
                        + hold, discrete=True)

        self.add_output("mode", None, "operating mode: 0 alignment at standstill, 1 I-f (current-frequency) "
                                      "drive, 2 FOC on the observer's angle and speed; with low_speed = "
                                      "'injection' 3 the angle's acquisition by injection, 4 the magnet's "
                                      "polarity test, 5 FOC on the injection's tracking observer (only the "
                                      "sensorless unit has modes other than 2)" + hold,
                        discrete=True, start=0.0 if observer == "sensorless" else 2.0)
        self.add_output("fault", None, "fault: 0 none, 1 a loss of synchronism (or the current limit reached "
                                       "under a load the drive cannot hold) detected and being recovered, 2 the "
                                       "recovery failed: the safe state latched (stop and hold at the current "
                                       "limit) until the unit is reset (only the sensorless unit detects; the "
                                       "others are always 0)" + hold, discrete=True)
        self.add_output("theta_ctrl", "rad", "electrical angle of the control frame (before angle_advance): the "
                                             "alignment or I-f current vector's in those modes, else the angle the "
                                             "controller uses (theta_hat, or theta_meas)" + hold, discrete=True)
        self.add_output("omega_ctrl", "rad/s", "mechanical speed of the control frame: the I-f speed in I-f, else "
                                               "the speed the controller uses (omega_hat)" + hold, discrete=True,
                        display_unit="rpm")
        # the reference generator's (docs/speed-range.md): properties reading the unit, no work per step
        self.add_output("i_dref", "A", "d-current reference: the reference generator's (reference 'mtpa', 'fw'), "
                                       "else i_d_ref; in alignment and I-f the current vector's magnitude" + hold,
                        discrete=True)
        self.add_output("T_ref", "N.m", "the motor's torque reference after the limits (current, torque, voltage, "
                                        "regenerative power): the reference generator's, else k_t i_qref, "
                                        "k_t = k_dq N psi (0 in alignment and I-f)" + hold, discrete=True)
        self.add_output("T_brake", "N.m", "friction-brake demand at the wheels, >= 0, opposing the motion: the "
                                          "braking shaft torque the motor does not give (P_regen_max, the envelope) "
                                          "x n_g eta (0 with reference 'paper')" + hold, discrete=True)
        self.add_output("ref_region", None, "the reference generator's region: 0 MTPA, 1 field weakening, 2 MTPV, "
                                            "3 the current and voltage limits met, 4 the torque or current limit on "
                                            "MTPA, 5 no torque within the limits (0 with reference 'paper')" + hold,
                        discrete=True)
        # adaptation while driving (``pmsm_ev.kernels.adaptation``): properties reading the unit, no work per step
        adapt = " (adaptation 'observe' or 'use'; 0 with 'off')"
        self.add_output("psi_est", "Wb", "the estimated magnet flux: the q voltage equation's least-squares fit where "
                                         "|omega| >= adapt_psi_speed and the currents are quasi-steady, frozen "
                                         "elsewhere" + adapt + hold, discrete=True)
        self.add_output("R_s_est", "Ohm", "the estimated stator resistance: the voltage equation projected on the "
                                          "current, fitted where |omega| <= adapt_rs_speed, |i| >= adapt_rs_current "
                                          "and the currents are quasi-steady, frozen elsewhere; it starts from R_s_id "
                                          "where the unit identified one" + adapt + hold, discrete=True)
        self.add_output("psi_observable", None, "1: the last period moved psi_est (psi observable), 0: frozen" + adapt,
                        discrete=True)
        self.add_output("R_s_observable", None, "1: the last period moved R_s_est (R_s observable), 0: frozen" + adapt,
                        discrete=True)
        # the injection strategy's identification at enable (``pmsm_ev.kernels.identify``): properties reading the
        # unit, no work per step
        ident = " (low_speed = 'injection'; 0 until identified and for the other units)"
        self.add_output("L_d_id", "H", "the identified incremental d inductance at zero current: 1 / (Y_s + Y_x) "
                                       "from the injection's answers on the found d and q axes, in-axis and cross "
                                       "(eq ID5)" + ident, discrete=True)
        self.add_output("L_q_id", "H", "the identified incremental q inductance at zero current: 1 / (Y_s - Y_x) "
                                       "from the same answers (eq ID5)" + ident, discrete=True)
        self.add_output("saliency_id", None, "the identified saliency L_q_id / L_d_id" + ident, discrete=True)
        self.add_output("R_s_id", "Ohm", "the identified stator resistance: the d PI's voltage difference over the "
                                         "current difference of two d current levels at standstill" + ident,
                        discrete=True)
        self.add_output("noise_id", "A", "the current measurement's noise floor from the identification's answers: "
                                         "a phase sensor's sigma" + ident, discrete=True)
        self.add_output("offset_a_id", "A", "current sensor a's offset, measured at enable with no voltage and "
                                            "subtracted from then on" + ident, discrete=True)
        self.add_output("offset_b_id", "A", "current sensor b's offset, measured at enable with no voltage and "
                                            "subtracted from then on" + ident, discrete=True)
        self.add_output("angle_accuracy", "rad", "the rms angle error injection gives at a stop from the measured "
                                                 "saliency and noise floor (eq ID3)" + ident, discrete=True)
        self.add_output("blind", None, "1: the identified saliency is below saliency_min or the angle accuracy beyond "
                                       "inj_angle_max, the injection cannot see the rotor's axis well enough; 0 "
                                       "otherwise", discrete=True)
        self.add_output("axis_cos", None, "cos 2e of the tracking observer's axis error from the d admittance and "
                                          "the identified admittances, filtered, in FOC on the injection (0 in the "
                                          "other modes)" + hold, discrete=True)
        self.add_output("gain_ratio_id", None, "the phase sensors' relative gain g_a / g_b measured on the EKF over "
                                               "gain_turns electrical turns (eq SG1), or at standstill from a parked "
                                               "unit's answers (eq SG0), and taken out of the measurements from "
                                               "then on (eq SG2)" + ident, discrete=True)
        self._sensorless = observer == "sensorless"
        if self._sensorless:  # it never reads the measured angle and speed: any value there, NaN included
            self.unread_inputs = frozenset(("theta_meas", "omega_meas"))
        self.add_parameters(*parameter_groups(observer))
        self.add_parameter("angle_source", "measured")  # the same interface for every controller
        self.add_parameter("dt", 0.0)
        self._unit = None
        self._dt = None  # sample period, fixed by the parameter or the first do_step
        self._t0 = 0.0  # start time (fmi2SetupExperiment): the instants are t0 + k dt
        self._k_next = None  # index of the next sample instant to run, set by the first do_step

    # -- the reference generator's outputs: read from the unit when asked (the FMU state and the start
    # values set them; the unit's state holds them, so the values set are not kept) --------------------
    def _unit_output(name: str, doc: str) -> property:
        def get(self) -> float:
            return getattr(self._unit, name) if self._unit is not None else 0.0

        def set_(self, value) -> None:
            pass

        return property(get, set_, doc=doc)

    i_dref = _unit_output("i_dref", "``ControlUnit.i_dref``")
    T_ref = _unit_output("T_ref", "``ControlUnit.T_ref``")
    T_brake = _unit_output("T_brake", "``ControlUnit.T_brake``")
    ref_region = _unit_output("ref_region", "``ControlUnit.ref_region``")
    psi_est = _unit_output("psi_est", "``ControlUnit.psi_est``")
    R_s_est = _unit_output("R_s_est", "``ControlUnit.R_s_est``")
    psi_observable = _unit_output("psi_observable", "``ControlUnit.psi_observable``")
    R_s_observable = _unit_output("R_s_observable", "``ControlUnit.R_s_observable``")
    L_d_id = _unit_output("L_d_id", "``ControlUnit.L_d_id``")
    L_q_id = _unit_output("L_q_id", "``ControlUnit.L_q_id``")
    saliency_id = _unit_output("saliency_id", "``ControlUnit.saliency_id``")
    R_s_id = _unit_output("R_s_id", "``ControlUnit.R_s_id``")
    noise_id = _unit_output("noise_id", "``ControlUnit.noise_id``")
    offset_a_id = _unit_output("offset_a_id", "``ControlUnit.offset_a_id``")
    offset_b_id = _unit_output("offset_b_id", "``ControlUnit.offset_b_id``")
    angle_accuracy = _unit_output("angle_accuracy", "``ControlUnit.angle_accuracy``")
    blind = _unit_output("blind", "``ControlUnit.blind``")
    axis_cos = _unit_output("axis_cos", "``ControlUnit.axis_cos``")
    gain_ratio_id = _unit_output("gain_ratio_id", "``ControlUnit.gain_ratio_id``")
    del _unit_output

    # -- physics hooks ---------------------------------------------------------------
    def build(self) -> None:
        if not (math.isfinite(self.dt) and self.dt >= 0.0):
            raise ParameterError(f"dt must be > 0 s, or 0 for the size of the first communication step "
                                 f"(got {self.dt!r})")
        self._build_unit(self.dt or DT_DEFAULT)
        self._dt = self.dt or None
        self._k_next = None

    def _build_unit(self, dt: float) -> None:
        self._unit = ControlUnit.from_groups(self._observer, self.angle_source, self.parameters, dt)
        kernels = self._unit._kernels
        self._periods = accel.direct(kernels.unit_periods)
        self._sample_instant = accel.direct(kernels.sample_instant)
        self.mark_built()
        self._copy_outputs()

    def physics_state(self):
        """The sample clock and the control unit's state (``ControlUnit.get_state``: its vector's
        slots by name)."""
        return {"dt": self._dt, "unit_dt": self._unit.dt, "unit": self._unit.get_state(),
                "t0": self._t0, "k_next": self._k_next}

    def restore_physics(self, snapshot) -> None:
        check_fields(f"{type(self).__name__} FMU state, physics", snapshot, ("dt", "unit_dt", "unit", "t0", "k_next"))
        if self._unit is None or self.needs_rebuild() or self._unit.dt != snapshot["unit_dt"]:
            self._build_unit(snapshot["unit_dt"])
        self._unit.set_state(snapshot["unit"])
        self._dt, self._t0, self._k_next = snapshot["dt"], snapshot["t0"], snapshot["k_next"]
        self._copy_outputs()

    def forget_physics(self) -> None:
        self._unit = None
        self._dt = self._k_next = None

    def _copy_outputs(self) -> None:
        for name, value in self._unit.outputs(self.theta_meas).items():
            setattr(self, name, value)

    def _start_clock(self, current_time: float, step_size: float) -> None:
        """First step: the sample period (the parameter, else ``step_size``) and the first
        sample instant at or after ``current_time``."""
        if not self._initialized:
            raise FmuUsageError("fmi2DoStep before fmi2ExitInitializationMode")
        if self._dt is None:  # the unit is untouched: rebuild it with dt = h
            if step_size != self._unit.dt:
                self._build_unit(step_size)
            self._dt = step_size
        self._k_next = self._sample_instant(current_time, self._t0, self._dt, SAMPLE_TOLERANCE)

    # -- the compiled step (``pmsm_ev.kernels.fmu``: ``unit_fmu_step`` on these buffers) -------------------------
    def compiled_slots(self) -> dict[str, int]:
        return {**IO_SLOTS, "T_brake": _k.UIO_T_BRAKE, "i_dref": _k.UIO_I_DREF, "T_ref": _k.UIO_T_REF,
                "ref_region": _k.UIO_REF_REGION,
                **{name: _k.UIO_STATUS + j for j, name in enumerate(_k.UNIT_STATUS_OUTPUTS)}}

    def compiled_step(self):
        """(the controllers' C step, the unit's buffer ``ControlUnit.io`` filled from the slave, the unit's state and
        parameter vectors: ``compiled_offer``); None where the kernels run as plain Python."""
        u = self._unit
        if u is None or not getattr(u._kernels, "JIT", False):
            return None
        step = self.__dict__.get("_step_address")
        if step is None:
            step = self._step_address = u._kernels.fmu_step_address("unit")
        u.load_io({name: getattr(self, name) for name in IO_SLOTS}, self._dt, self._t0, self._k_next)
        return compiled_offer(step, u.io, u._s, u._c)

    def compiled_pull(self) -> None:
        values = self._unit.io.tolist()
        for name, slot in IO_SLOTS.items():
            setattr(self, name, values[slot])
        if values[_k.UIO_CLOCK]:
            self._dt = values[_k.UIO_DT]
            self._k_next = int(values[_k.UIO_K_NEXT])

    # -- FMI -------------------------------------------------------------------------
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        super().setup_experiment(start_time, stop_time, tolerance)
        self._t0 = float(start_time)

    def do_step(self, current_time, step_size):
        try:
            if not step_size > 0.0:
                raise FmuUsageError(f"communication step size must be > 0 s (got {step_size!r})")
            if self._k_next is None:
                self._start_clock(current_time, step_size)
            k_end = self._sample_instant(current_time + step_size, self._t0, self._dt, SAMPLE_TOLERANCE)
            if k_end > self._k_next:  # the instants in [t, t + h), run on the inputs at t
                u = self._unit
                io = u._io_items
                io[_k.UIO_I_ALPHA] = self.i_alpha
                io[_k.UIO_I_BETA] = self.i_beta
                io[_k.UIO_OMEGA_REF] = self.omega_ref
                io[_k.UIO_THETA_MEAS] = self.theta_meas
                io[_k.UIO_OMEGA_MEAS] = self.omega_meas
                io[_k.UIO_V_DC_MEAS] = self.v_dc_meas  # a measured DC link (0: the parameters')
                io[_k.UIO_P_CHARGE_MAX] = self.P_charge_max
                io[_k.UIO_P_DISCHARGE_MAX] = self.P_discharge_max
                self._periods(u.io, u._s, u._c, k_end - self._k_next)
                (self.v_alpha, self.v_beta, self.v_d, self.v_q, self.i_d, self.i_q, self.i_qref, self.i_d_hat,
                 self.i_q_hat, self.omega_hat, self.theta_hat, self.T_L_hat, self.mode, self.fault, self.theta_ctrl,
                 self.omega_ctrl) = io[_k.UIO_V_ALPHA:_k.UIO_T_BRAKE]
                self._k_next = k_end
        except Exception as exc:
            self._fail("fmi2DoStep", exc)
            raise
        return True
