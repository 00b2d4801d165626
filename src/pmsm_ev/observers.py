"""State observers for the sensorless drive, one class each, one interface.

Every observer is called once per control period by the control unit:

1. ``predict(v_d, v_q)``: time update with the dq voltage commanded over the period
   that just ended (eqs 23-24). Afterwards ``theta_prior`` is the predicted angle.
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
"""

from __future__ import annotations

import math

import numpy as np

from .params import EkfParams, MotorParams
from .transforms import wrap_angle

ID, IQ, W, TH, TL = range(5)


class ExtendedKalmanFilter:
    """Discrete EKF, steps 23-27; subclasses give f, J_f, h, J_h and the measurement."""

    n_states = 0

    def __init__(self, motor: MotorParams, dt: float, q_diag, r_diag, p0_diag, x0=None):
        self.motor = motor
        self.dt = dt
        self.Q = np.diag(np.asarray(q_diag, dtype=float))
        self.R = np.diag(np.asarray(r_diag, dtype=float))
        self._p0 = np.diag(np.asarray(p0_diag, dtype=float))
        self._x0 = np.zeros(self.n_states) if x0 is None else np.asarray(x0, dtype=float).copy()
        self._eye = np.eye(self.n_states)
        self.reset()

    def reset(self) -> None:
        self.x = self._x0.copy()
        self.P = self._p0.copy()
        self.theta_prior = float(self.x[TH])

    # -- model, overridden -------------------------------------------------------
    def f(self, x, v_d, v_q):  # pragma: no cover - abstract
        raise NotImplementedError

    def jacobian_f(self, x, v_d, v_q):  # pragma: no cover - abstract
        raise NotImplementedError

    def h(self, x):  # pragma: no cover - abstract
        raise NotImplementedError

    def jacobian_h(self, x):  # pragma: no cover - abstract
        raise NotImplementedError

    def measurement(self, i_alpha, i_beta, i_d, i_q):  # pragma: no cover - abstract
        raise NotImplementedError

    # -- steps 23-27 -------------------------------------------------------------
    def predict(self, v_d: float, v_q: float) -> None:
        F = self.jacobian_f(self.x, v_d, v_q)  # J_f at x_{k-1}^e
        self.x = self.f(self.x, v_d, v_q)  # (23)
        self.P = F @ self.P @ F.T + self.Q  # (24)
        self.theta_prior = float(self.x[TH])

    def correct(self, i_alpha, i_beta, i_d, i_q, theta_meas=0.0, omega_meas=0.0) -> None:
        z = self.measurement(i_alpha, i_beta, i_d, i_q)
        H = self.jacobian_h(self.x)
        PHt = self.P @ H.T
        S = H @ PHt + self.R
        K = PHt @ np.linalg.inv(S)  # (25), with J_h^T where the paper prints J_h^-1
        self.x = self.x + K @ (z - self.h(self.x))  # (26)
        self.P = (self._eye - K @ H) @ self.P  # (27)
        self.P = 0.5 * (self.P + self.P.T)  # keep P symmetric against round-off
        self.x[TH] = wrap_angle(self.x[TH])

    # -- estimates ---------------------------------------------------------------
    @property
    def i_d_hat(self) -> float:
        return float(self.x[ID])

    @property
    def i_q_hat(self) -> float:
        return float(self.x[IQ])

    @property
    def omega_hat(self) -> float:
        return float(self.x[W])

    @property
    def theta_hat(self) -> float:
        return float(self.x[TH])

    @property
    def T_L_hat(self) -> float:
        return float(self.x[TL]) if self.n_states > TL else 0.0

    def get_state(self) -> tuple:
        return tuple(self.x.tolist()) + tuple(self.P.ravel().tolist()) + (self.theta_prior,)

    def set_state(self, state) -> None:
        n = self.n_states
        self.x = np.array(state[:n], dtype=float)
        self.P = np.array(state[n:n + n * n], dtype=float).reshape(n, n)
        self.theta_prior = float(state[n + n * n])


class Ekf5(ExtendedKalmanFilter):
    """The paper's fifth-order EKF: x = [i_d, i_q, omega_m, theta, T_L] (21), z = [i_d, i_q]."""

    n_states = 5

    def __init__(self, motor: MotorParams, dt: float, ekf: EkfParams | None = None, x0=None):
        e = ekf or EkfParams()
        super().__init__(motor, dt,
                         (e.q_i, e.q_i, e.q_omega, e.q_theta, e.q_TL), (e.r_i, e.r_i),
                         (e.p0_i, e.p0_i, e.p0_omega, e.p0_theta, e.p0_TL), x0)
        self._H = np.zeros((2, 5))
        self._H[0, ID] = self._H[1, IQ] = 1.0

    def f(self, x, v_d, v_q):
        m, dt = self.motor, self.dt
        i_d, i_q, w, th, t_l = x
        return np.array([
            i_d - m.R_s * i_d * dt / m.L_d + m.N * w * m.L_q * i_q * dt / m.L_d + v_d * dt / m.L_d,  # (A2)
            i_q - m.R_s * i_q * dt / m.L_q - m.N * w * m.L_d * i_d * dt / m.L_q
            - m.N * w * m.psi * dt / m.L_q + v_q * dt / m.L_q,  # (A3)
            w + (m.N * m.psi * i_q + m.N * (m.L_d - m.L_q) * i_d * i_q - t_l) * dt / m.J_m,  # (A4)
            th + m.N * w * dt,  # (A5)
            t_l,  # (A6)
        ])

    def jacobian_f(self, x, v_d, v_q):
        m, dt = self.motor, self.dt
        i_d, i_q, w = x[ID], x[IQ], x[W]
        F = np.eye(5)
        F[0, 0] = 1.0 - m.R_s * dt / m.L_d  # (A8)
        F[0, 1] = m.N * w * m.L_q * dt / m.L_d  # (A9)
        F[0, 2] = m.N * m.L_q * i_q * dt / m.L_d  # (A10)
        F[1, 0] = -m.N * w * m.L_d * dt / m.L_q  # (A13)
        F[1, 1] = 1.0 - m.R_s * dt / m.L_q  # (A14)
        F[1, 2] = -(m.N * m.L_d * i_d + m.N * m.psi) * dt / m.L_q  # (A15)
        F[2, 0] = m.N * (m.L_d - m.L_q) * i_q * dt / m.J_m  # (A18)
        F[2, 1] = (m.N * m.psi + m.N * (m.L_d - m.L_q) * i_d) * dt / m.J_m  # (A19)
        F[2, 4] = -dt / m.J_m  # (A22)
        F[3, 2] = m.N * dt  # (A25)
        return F  # all other entries 0 or 1: (A11-12, A16-17, A20-21, A23-24, A26-32)

    def h(self, x):
        return x[:2].copy()

    def jacobian_h(self, x):
        return self._H  # (A33): [I_2 0]

    def measurement(self, i_alpha, i_beta, i_d, i_q):
        return np.array([i_d, i_q])


class Ekf5AlphaBeta(Ekf5):
    """EKF5 measuring the stationary-frame currents: z = [i_alpha, i_beta].

    h(x) = inverse Park of (i_d, i_q) at theta, so theta enters the measurement and is
    observable from the currents alone: the physically sensorless form.
    """

    def h(self, x):
        c, s = math.cos(x[TH]), math.sin(x[TH])
        return np.array([c * x[ID] - s * x[IQ], s * x[ID] + c * x[IQ]])

    def jacobian_h(self, x):
        c, s = math.cos(x[TH]), math.sin(x[TH])
        i_d, i_q = x[ID], x[IQ]
        return np.array([
            [c, -s, 0.0, -s * i_d - c * i_q, 0.0],
            [s, c, 0.0, c * i_d - s * i_q, 0.0],
        ])

    def measurement(self, i_alpha, i_beta, i_d, i_q):
        return np.array([i_alpha, i_beta])


class Ekf4(ExtendedKalmanFilter):
    """Fourth-order EKF of the paper's refs 3-5: x = [i_d, i_q, omega_m, theta], dw/dt = 0."""

    n_states = 4

    def __init__(self, motor: MotorParams, dt: float, ekf: EkfParams | None = None, x0=None):
        e = ekf or EkfParams()
        super().__init__(motor, dt,
                         (e.q_i, e.q_i, e.q_omega_ekf4, e.q_theta), (e.r_i, e.r_i),
                         (e.p0_i, e.p0_i, e.p0_omega, e.p0_theta), x0)
        self._H = np.zeros((2, 4))
        self._H[0, ID] = self._H[1, IQ] = 1.0

    def f(self, x, v_d, v_q):
        m, dt = self.motor, self.dt
        i_d, i_q, w, th = x
        return np.array([
            i_d - m.R_s * i_d * dt / m.L_d + m.N * w * m.L_q * i_q * dt / m.L_d + v_d * dt / m.L_d,  # (A2)
            i_q - m.R_s * i_q * dt / m.L_q - m.N * w * m.L_d * i_d * dt / m.L_q
            - m.N * w * m.psi * dt / m.L_q + v_q * dt / m.L_q,  # (A3)
            w,  # no load model: omega is a random walk
            th + m.N * w * dt,  # (A5)
        ])

    def jacobian_f(self, x, v_d, v_q):
        m, dt = self.motor, self.dt
        i_d, i_q, w = x[ID], x[IQ], x[W]
        F = np.eye(4)
        F[0, 0] = 1.0 - m.R_s * dt / m.L_d
        F[0, 1] = m.N * w * m.L_q * dt / m.L_d
        F[0, 2] = m.N * m.L_q * i_q * dt / m.L_d
        F[1, 0] = -m.N * w * m.L_d * dt / m.L_q
        F[1, 1] = 1.0 - m.R_s * dt / m.L_q
        F[1, 2] = -(m.N * m.L_d * i_d + m.N * m.psi) * dt / m.L_q
        F[3, 2] = m.N * dt
        return F

    def h(self, x):
        return x[:2].copy()

    def jacobian_h(self, x):
        return self._H

    def measurement(self, i_alpha, i_beta, i_d, i_q):
        return np.array([i_d, i_q])


class Sensored:
    """Baseline: passes the measured speed and angle through; currents as measured."""

    n_states = 0

    def __init__(self, motor: MotorParams | None = None, dt: float = 0.0, ekf=None, x0=None):
        self.reset()

    def reset(self) -> None:
        self.i_d_hat = self.i_q_hat = self.omega_hat = self.theta_hat = 0.0
        self.T_L_hat = 0.0
        self.theta_prior = 0.0

    def predict(self, v_d: float, v_q: float) -> None:
        pass

    def correct(self, i_alpha, i_beta, i_d, i_q, theta_meas=0.0, omega_meas=0.0) -> None:
        self.i_d_hat, self.i_q_hat = i_d, i_q
        self.omega_hat, self.theta_hat = omega_meas, theta_meas
        self.theta_prior = theta_meas

    def get_state(self) -> tuple:
        return (self.i_d_hat, self.i_q_hat, self.omega_hat, self.theta_hat, self.theta_prior)

    def set_state(self, state) -> None:
        self.i_d_hat, self.i_q_hat, self.omega_hat, self.theta_hat, self.theta_prior = (float(v) for v in state)


OBSERVER_CLASSES = {"ekf5": Ekf5, "ekf4": Ekf4, "ekf5ab": Ekf5AlphaBeta, "sensored": Sensored}


def make_observer(name: str, motor: MotorParams, dt: float, ekf: EkfParams | None = None):
    try:
        cls = OBSERVER_CLASSES[name]
    except KeyError:
        raise ValueError(f"unknown observer {name!r}; choose one of {sorted(OBSERVER_CLASSES)}") from None
    return cls(motor, dt, ekf)
