"""State observers for the sensorless drive, one class each, one interface.

Every observer is called once per control period by the control unit:

1. ``predict(u0, u1)``: time update with the voltage held over the period that just
   ended (eqs 23-24): the dq command (v_d, v_q), or for observers whose
   ``voltage_frame`` is "alpha_beta" the stationary-frame vector (v_alpha, v_beta) the
   inverter applied. Afterwards ``theta_prior`` is the predicted angle.
2. ``correct(i_alpha, i_beta, i_d, i_q, theta_meas, omega_meas)``: measurement update
   (eqs 25-27). ``i_d, i_q`` are the measured currents in the controller's frame (true
   angle in paper mode, ``theta_prior`` when truly sensorless); each observer takes the
   measurement it is built on.

After ``correct`` the estimates are ``i_d_hat, i_q_hat, omega_hat, theta_hat, T_L_hat``
(``T_L_hat`` is 0.0 for observers without a load state).

EKF notes:

* The model is the forward-Euler discretisation of the appendix (A2-A6), with the
  paper's choice that the mechanical equation uses J_m only (eq 22), so ``T_L_hat``
  absorbs friction and the reflected vehicle inertia (eqs 30-31).
* Eq 25 prints J_h^-1; the Kalman gain needs J_h^T: K = P H^T (H P H^T + R)^-1.
* The appendix prints J_h, Q and R with every entry "2"; J_h follows from h(x), and Q, R
  are in ``EkfParams``.

The filter steps are ``pmsm_ev.kernels`` (``ekf5_predict``, ``ekf4_predict``,
``ekf5ab_predict``, ``ekf_correct_dq``, ``ekf5ab_correct``: scalar code exploiting the sparsity of J_f and J_h,
compiled with numba when available); the classes hold the constants and the state in the
slots of a control-unit vector and expose x, P and the model for inspection and tests.
"""

from __future__ import annotations

import math

import numpy as np

from . import accel
from . import kernels as _k
from .controller import state_slot
from .params import EkfParams, MotorParams

ID, IQ, W, TH, TL = range(5)


class _Observer:
    """Slots of a control unit's state and parameter vectors (shared or own)."""

    n_states = 0
    code = _k.OBS_SENSORED
    #: the voltage predict() takes: "dq" (the controller's dq command) or "alpha_beta"
    voltage_frame = "dq"

    def __init__(self, state=None, params=None):
        self._kernels = accel.kernels()
        self._s = state if state is not None else accel.vector(_k.UNIT_STATE)
        self._c = params if params is not None else accel.vector(_k.UNIT_PARAMS)
        self._c[_k.C_OBSERVER] = float(self.code)

    def predict(self, u0: float, u1: float) -> None:
        """Time update (23)-(24) with the voltage of the period that just ended (see
        ``voltage_frame``)."""
        self._kernels.observer_predict(self._s, self._c, u0, u1)

    def correct(self, i_alpha, i_beta, i_d, i_q, theta_meas=0.0, omega_meas=0.0) -> None:
        """Measurement update (25)-(27)."""
        self._kernels.observer_correct(self._s, self._c, i_alpha, i_beta, i_d, i_q, theta_meas, omega_meas)

    #: the estimates, read from the state (x of eqs 23-27)
    i_d_hat = state_slot(_k.S_X + ID, settable=False)
    i_q_hat = state_slot(_k.S_X + IQ, settable=False)
    omega_hat = state_slot(_k.S_X + W, settable=False)
    theta_hat = state_slot(_k.S_X + TH, settable=False)
    T_L_hat = state_slot(_k.S_X + TL, settable=False)  # stays 0.0 for observers without a load state
    theta_prior = state_slot(_k.S_THETA_PRIOR, settable=False)


class ExtendedKalmanFilter(_Observer):
    """Discrete EKF, steps 23-27.

    The filter is small (n = 4 or 5) and J_f is the identity plus a few entries, so the
    covariance work is written out for that sparsity (``pmsm_ev.kernels``): no 5x5
    matrix products in the per-step path. ``x`` and ``P`` are available as numpy arrays
    for inspection; ``tests`` keep a dense numpy implementation of eqs 23-27 as the
    oracle this one is checked against.
    """

    def __init__(self, motor: MotorParams, dt: float, q_diag, r_diag, p0_diag, x0=None,
                 state=None, params=None, J: float | None = None, discretisation: str = "euler"):
        super().__init__(state, params)
        self.motor = motor
        self.dt = dt
        n = self.n_states
        self.p0 = [float(v) for v in p0_diag]
        self.x0 = [0.0] * n if x0 is None else [float(v) for v in x0]
        m = motor
        #: inertia of the model's mechanical equation (A4): J_m (eq 22) unless given
        self.J = J_m = J if J else m.J_m
        c = self._c
        # constants of A2-A6 and A8-A32
        for slot, value in (
                (_k.C_A_RD, 1.0 - m.R_s * dt / m.L_d),  # (A8)
                (_k.C_A_RQ, 1.0 - m.R_s * dt / m.L_q),  # (A14)
                (_k.C_C_WQ, m.N * m.L_q * dt / m.L_d),  # (A9)/omega, (A10)/i_q
                (_k.C_C_WD, m.N * m.L_d * dt / m.L_q),  # (A13)/omega
                (_k.C_C_WPSI, m.N * m.psi * dt / m.L_q),  # (A15), psi part
                (_k.C_C_VD, dt / m.L_d),
                (_k.C_C_VQ, dt / m.L_q),
                (_k.C_C_TPSI, m.k_dq * m.N * m.psi * dt / J_m),  # (A19), psi part (x k_dq)
                (_k.C_C_TDQ, m.k_dq * m.N * (m.L_d - m.L_q) * dt / J_m),  # (A18)/i_q, (A19)/i_d
                (_k.C_C_TL, -dt / J_m),  # (A22)
                (_k.C_C_TH, m.N * dt)):  # (A25)
            c[slot] = float(value)
        # the current model's discretisation (``EkfParams.discretisation``): forward Euler, or Tustin's rule
        c[_k.C_EKF_BILINEAR] = 1.0 if discretisation == "bilinear" else 0.0
        c[_k.C_R0], c[_k.C_R1] = (float(v) for v in r_diag)
        for i, q in enumerate(q_diag):
            c[_k.C_Q + i] = float(q)
        for i, p0 in enumerate(self.p0):  # for a restart inside the kernels (sensorless start-up)
            c[_k.C_P0 + i] = p0
        self.reset()

    def reset(self) -> None:
        n = self.n_states
        s = self._s
        for i in range(5):
            s[_k.S_X + i] = self.x0[i] if i < n else 0.0
        for i in range(n * n):
            s[_k.S_P + i] = 0.0
        for i in range(n):
            s[_k.S_P + i * n + i] = self.p0[i]
        s[_k.S_THETA_PRIOR] = s[_k.S_X + TH]

    @property
    def q(self) -> list[float]:
        """Diagonal of Q."""
        return [float(self._c[_k.C_Q + i]) for i in range(self.n_states)]

    @property
    def r0(self) -> float:
        return float(self._c[_k.C_R0])

    @property
    def r1(self) -> float:
        return float(self._c[_k.C_R1])

    @property
    def x(self) -> np.ndarray:
        return np.array([self._s[_k.S_X + i] for i in range(self.n_states)], dtype=float)

    @property
    def P(self) -> np.ndarray:
        n = self.n_states
        return np.array([self._s[_k.S_P + i] for i in range(n * n)], dtype=float).reshape(n, n)

    def get_state(self) -> tuple:
        n, s = self.n_states, self._s
        return (tuple(float(s[_k.S_X + i]) for i in range(n)) + tuple(float(s[_k.S_P + i]) for i in range(n * n))
                + (self.theta_prior,))

    def set_state(self, state) -> None:
        n, s = self.n_states, self._s
        for i in range(n):
            s[_k.S_X + i] = float(state[i])
        for i in range(n * n):
            s[_k.S_P + i] = float(state[n + i])
        s[_k.S_THETA_PRIOR] = float(state[n + n * n])

    # -- the model as functions of a state vector (for tests and inspection) ---------
    def _scratch(self, x, identity_p: bool):
        """A copy of the vectors with the estimate x (and P = I): the kernels' workspace."""
        s = accel.vector(_k.UNIT_STATE)
        s[_k.S_STARTED] = 1.0  # a time update, not the stationary-frame EKF5's first sample
        for i, v in enumerate(x):
            s[_k.S_X + i] = float(v)
        if identity_p:
            n = self.n_states
            for i in range(n):
                s[_k.S_P + i * n + i] = 1.0
        return s

    def f(self, x, v_d, v_q) -> np.ndarray:
        """The discrete model f(x) of eq 23 (A2-A6)."""
        s = self._scratch(x, False)
        self._kernels.observer_predict(s, self._c, v_d, v_q)
        return np.array([s[_k.S_X + i] for i in range(self.n_states)], dtype=float)

    def jacobian_f(self, x, v_d, v_q) -> np.ndarray:
        """J_f at x (A8-A32), as the kernel computes it: J_f P with P = I."""
        n = self.n_states
        s = self._scratch(x, True)
        self._kernels.observer_predict(s, self._c, v_d, v_q)
        return np.array([s[_k.S_A + i] for i in range(n * n)], dtype=float).reshape(n, n)


class Ekf5(ExtendedKalmanFilter):
    """The paper's fifth-order EKF: x = [i_d, i_q, omega_m, theta, T_L] (21), z = [i_d, i_q]."""

    n_states = 5
    code = _k.OBS_EKF5

    def __init__(self, motor: MotorParams, dt: float, ekf: EkfParams | None = None, x0=None,
                 state=None, params=None):
        e = ekf or EkfParams()
        super().__init__(motor, dt,
                         (e.q_i, e.q_i, e.q_omega, e.q_theta, e.q_TL), (e.r_i, e.r_i),
                         (e.p0_i, e.p0_i, e.p0_omega, e.p0_theta, e.p0_TL),
                         x0 if x0 is not None else (0.0, 0.0, e.x0_omega, e.x0_theta, 0.0), state, params,
                         e.inertia(motor), e.discretisation)

    def h(self, x) -> np.ndarray:
        """Measurement model: z = [i_d, i_q]."""
        return np.array([x[ID], x[IQ]], dtype=float)

    def jacobian_h(self, x) -> np.ndarray:
        H = np.zeros((2, self.n_states))
        H[0, ID] = H[1, IQ] = 1.0  # (A33)
        return H


class Ekf5AlphaBeta(Ekf5):
    """EKF5 measuring the stationary-frame currents: z = [i_alpha, i_beta].

    h(x) = inverse Park of (i_d, i_q) at theta, so theta enters the measurement and is
    observable from the currents alone: the physically sensorless form.

    Its input is the stationary-frame voltage (v_alpha, v_beta) the inverter held over
    the period, not a dq command: ``predict(v_alpha, v_beta)``. The model turns it into
    the rotor frame at the filter's *own* angle, at mid-period,

        (v_d, v_q) = Park(v_alpha, v_beta, theta + N omega_m dt / 2),

    and then steps A2-A6 as the EKF5 does (``kernels.ekf5ab_predict``). Two reasons, both
    physics:

    * The angle information of a sensorless drive is the direction of the applied
      voltage against the back-EMF. A dq voltage handed over as fixed numbers makes
      the model blind to it (df/dtheta = 0): a wrong theta could then only show up by
      rotating the measured current vector, which carries no angle information while the
      currents are small. Here df/dtheta = (dt/L) dPark/dtheta v (entries (0,3), (1,3)),
      the path by which a stationary-frame EKF recovers an unknown initial angle.
    * The voltage is the one the inverter applied, so the model does not depend on the
      frame the controller computed it in (with a measured angle the controller's frame
      is the true one, not the filter's; a dq command would then be misread by the angle
      error).

    The mid-period angle is the consistent choice for the forward-Euler step: against the
    exact map of a vector held in the stationary frame over a turning rotor, the residual
    is of order (omega_e dt)^2 times the current (0.0064 at 200 rad/s, 10 kHz). Measured
    steady angle error at 200 rad/s: -1.5e-4 rad, shrinking about 4x per halved dt
    (tests/test_realism.py); a 0.5 rad wrong start is recovered within a few ms.

    ``x0`` is the estimate at the first sample: the first ``predict`` (the period before
    the first sample, when the inverter held no vector yet) is no time update. Stepping
    the model over it with zero volts would model a short-circuited motor: started at
    speed (a flying start), the filter would predict N omega psi dt / L_q = 25 A of
    braking current at 200 rad/s against the measured 0 A and take the mismatch out on
    its speed estimate (200 -> 90 rad/s in one step). The dq EKFs keep the paper's
    sequence (a time update before every correction, pinned results); from standstill
    with x0 = 0 the first one only adds to P.
    """

    code = _k.OBS_EKF5AB
    #: predict() takes the stationary-frame voltage held over the period
    voltage_frame = "alpha_beta"

    def __init__(self, motor: MotorParams, dt: float, ekf: EkfParams | None = None, x0=None,
                 state=None, params=None):
        super().__init__(motor, dt, ekf, x0, state, params)
        self._c[_k.C_C_MID] = 0.5 * motor.N * dt  # d(theta at mid-period)/d(omega_m)

    def reset(self) -> None:
        super().reset()
        self._s[_k.S_STARTED] = 0.0  # no time update before the first sample

    def get_state(self) -> tuple:
        return super().get_state() + (float(self._s[_k.S_STARTED]),)

    def set_state(self, state) -> None:
        super().set_state(state[:-1])
        self._s[_k.S_STARTED] = float(state[-1])

    def h(self, x) -> np.ndarray:
        c, s = math.cos(x[TH]), math.sin(x[TH])
        return np.array([c * x[ID] - s * x[IQ], s * x[ID] + c * x[IQ]])

    def jacobian_h(self, x) -> np.ndarray:
        c, s = math.cos(x[TH]), math.sin(x[TH])
        i_d, i_q = x[ID], x[IQ]
        return np.array([
            [c, -s, 0.0, -s * i_d - c * i_q, 0.0],
            [s, c, 0.0, c * i_d - s * i_q, 0.0],
        ])


class Ekf4(ExtendedKalmanFilter):
    """Fourth-order EKF of the paper's refs 3-5: x = [i_d, i_q, omega_m, theta], dw/dt = 0."""

    n_states = 4
    code = _k.OBS_EKF4

    def __init__(self, motor: MotorParams, dt: float, ekf: EkfParams | None = None, x0=None,
                 state=None, params=None):
        e = ekf or EkfParams()
        super().__init__(motor, dt,
                         (e.q_i, e.q_i, e.q_omega_ekf4, e.q_theta), (e.r_i, e.r_i),
                         (e.p0_i, e.p0_i, e.p0_omega, e.p0_theta),
                         x0 if x0 is not None else (0.0, 0.0, e.x0_omega, e.x0_theta), state, params,
                         e.inertia(motor), e.discretisation)

    h = Ekf5.h
    jacobian_h = Ekf5.jacobian_h


class Sensored(_Observer):
    """Baseline: passes the measured speed and angle through; currents as measured."""

    n_states = 0
    code = _k.OBS_SENSORED

    def __init__(self, motor: MotorParams | None = None, dt: float = 0.0, ekf=None, x0=None,
                 state=None, params=None):
        super().__init__(state, params)
        self.reset()

    def reset(self) -> None:
        for i in range(5):
            self._s[_k.S_X + i] = 0.0
        self._s[_k.S_THETA_PRIOR] = 0.0

    def get_state(self) -> tuple:
        return (self.i_d_hat, self.i_q_hat, self.omega_hat, self.theta_hat, self.theta_prior)

    def set_state(self, state) -> None:
        for i, slot in enumerate((_k.S_X, _k.S_X + 1, _k.S_X + 2, _k.S_X + 3, _k.S_THETA_PRIOR)):
            self._s[slot] = float(state[i])


#: "sensorless" is the stationary-frame EKF5 with the start-up of ``pmsm_ev.control_unit``
OBSERVER_CLASSES = {"ekf5": Ekf5, "ekf4": Ekf4, "ekf5ab": Ekf5AlphaBeta, "sensored": Sensored,
                    "sensorless": Ekf5AlphaBeta}


def make_observer(name: str, motor: MotorParams, dt: float, ekf: EkfParams | None = None,
                  state=None, params=None):
    """An observer by name; ``state``/``params``: the control unit's vectors it works in."""
    try:
        cls = OBSERVER_CLASSES[name]
    except KeyError:
        raise ValueError(f"unknown observer {name!r}; choose one of {sorted(OBSERVER_CLASSES)}") from None
    return cls(motor, dt, ekf, state=state, params=params)
