"""The controller-plus-observer: what the second FMU wraps.

Per control period, at t_k, with the plant's measured currents at t_k:

1. observer time update with the voltage held over [t_{k-1}, t_k] (eqs 23-24): the dq
   command, or the stationary-frame vector (v_alpha, v_beta) actually sent to the
   inverter for the stationary-frame EKF5, which turns it into its own frame;
2. the frame angle: the measured rotor angle ("measured", the paper's own simulation,
   whose EKF is fed dq currents in the true frame) or the observer's predicted angle
   ("estimated", truly sensorless); Park of the measured currents at that angle;
3. observer measurement update (eqs 25-27);
4. speed PI on omega_hat (14), current PIs + decoupling on omega_hat (15-20);
5. inverse Park at the control angle (measured, or the updated estimate), advanced by
   ``angle_advance`` periods of omega_hat, to v_alpha, v_beta held until t_{k+1}; with
   ``zoh_compensation`` the held vector is lengthened by a/sin(a), a = omega_e dt/2, so
   that its mean over the period, seen from the turning rotor, equals the command.
"""

from __future__ import annotations

import math

from .controller import CurrentController, SpeedController
from .observers import make_observer
from .params import ANGLE_SOURCES, ControllerParams, EkfParams, MotorParams, ParameterError
from .transforms import inverse_park, park


class ControlUnit:
    def __init__(self, observer: str = "ekf5", angle_source: str = "measured",
                 motor: MotorParams | None = None, controller: ControllerParams | None = None,
                 ekf: EkfParams | None = None, dt: float = 1e-4):
        self.motor = motor or MotorParams()
        self.params = controller or ControllerParams()
        self.ekf_params = ekf or EkfParams()
        for group in (self.motor, self.params, self.ekf_params):
            group.validate()
        if angle_source not in ANGLE_SOURCES:
            raise ParameterError(f"angle_source must be one of {ANGLE_SOURCES} (got {angle_source!r})")
        if not dt > 0:
            raise ParameterError(f"dt must be > 0 s (got {dt})")
        self.dt = dt
        self.observer_name = observer
        self.observer = make_observer(observer, self.motor, dt, self.ekf_params)
        # the sensored baseline has no angle estimate of its own: always the measured angle
        self.angle_source = "measured" if observer == "sensored" else angle_source
        self._estimated = self.angle_source == "estimated"
        self.speed = SpeedController(self.params, dt)
        self.current = CurrentController(self.params, self.motor, dt)
        self._advance = self.params.angle_advance * dt * self.motor.N
        self._half_period_n = 0.5 * dt * self.motor.N
        self._zoh = bool(self.params.zoh_compensation)
        self._delayed = bool(self.params.delay_compensation)
        self._ab_voltage = self.observer.voltage_frame == "alpha_beta"
        self.reset()

    def reset(self) -> None:
        self.observer.reset()
        self.speed.reset()
        self.current.reset()
        self.v_d = self.v_q = 0.0
        # the observer's voltage input of one period earlier (dq, or alpha-beta)
        self.u_prev0 = self.u_prev1 = 0.0
        self.v_alpha = self.v_beta = 0.0
        self.i_d = self.i_q = 0.0
        self.i_qref = 0.0

    def step(self, i_alpha: float, i_beta: float, omega_ref: float,
             theta_meas: float = 0.0, omega_meas: float = 0.0) -> None:
        obs = self.observer
        # (23)-(24) with the voltage applied over the last period: the last command, or
        # with a one-period actuation delay, the command before it
        if self._ab_voltage:
            u0, u1 = self.v_alpha, self.v_beta
        else:
            u0, u1 = self.v_d, self.v_q
        if self._delayed:
            obs.predict(self.u_prev0, self.u_prev1)
            self.u_prev0, self.u_prev1 = u0, u1
        else:
            obs.predict(u0, u1)
        theta_frame = obs.theta_prior if self._estimated else theta_meas
        i_d, i_q = park(i_alpha, i_beta, theta_frame)
        obs.correct(i_alpha, i_beta, i_d, i_q, theta_meas, omega_meas)  # (25)-(27)
        if self._estimated:
            theta_ctrl = obs.theta_hat
            i_d, i_q = park(i_alpha, i_beta, theta_ctrl)
        else:
            theta_ctrl = theta_meas
        omega_hat = obs.omega_hat
        self.i_d, self.i_q = i_d, i_q
        self.i_qref = self.speed.step(omega_ref, omega_hat)  # (14)
        self.v_d, self.v_q = self.current.step(self.params.i_d_ref, self.i_qref, i_d, i_q, omega_hat)  # (15)-(20)
        half_arc = self._half_period_n * omega_hat  # a = omega_e dt / 2
        gain = half_arc / math.sin(half_arc) if self._zoh and abs(half_arc) > 1e-6 else 1.0
        self.v_alpha, self.v_beta = inverse_park(gain * self.v_d, gain * self.v_q,
                                                 theta_ctrl + self._advance * omega_hat)

    # outputs of the observer, for recording
    @property
    def estimates(self) -> tuple[float, float, float, float, float]:
        o = self.observer
        return o.i_d_hat, o.i_q_hat, o.omega_hat, o.theta_hat, o.T_L_hat

    def get_state(self) -> tuple:
        return ((self.v_d, self.v_q, self.v_alpha, self.v_beta, self.i_d, self.i_q, self.i_qref,
                 self.speed.integral, self.u_prev0, self.u_prev1)
                + self.current.get_state() + self.observer.get_state())

    def set_state(self, state) -> None:
        state = tuple(float(v) for v in state)
        (self.v_d, self.v_q, self.v_alpha, self.v_beta, self.i_d, self.i_q, self.i_qref,
         self.speed.integral, self.u_prev0, self.u_prev1) = state[:10]
        self.current.set_state(state[10:15])
        self.observer.set_state(state[15:])
