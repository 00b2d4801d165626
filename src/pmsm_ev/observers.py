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
"""

from __future__ import annotations

import math

import numpy as np

from .params import EkfParams, MotorParams
from .transforms import wrap_angle

ID, IQ, W, TH, TL = range(5)


class ExtendedKalmanFilter:
    """Discrete EKF, steps 23-27, in scalar Python.

    The filter is small (n = 4 or 5) and J_f is the identity plus a few entries, so the
    covariance work is written out for that sparsity on lists of floats: no numpy on 5x5
    matrices in the per-step path (numpy's per-call overhead dominates at this size).
    ``x`` and ``P`` are available as numpy arrays for inspection; ``tests`` keep a dense
    numpy implementation of eqs 23-27 as the oracle this one is checked against.

    Subclasses give f (``_predict_state``), the entries of J_f (``_jacobian_entries``),
    h and J_h (``_measurement_update``).
    """

    n_states = 0
    #: the voltage predict() takes: "dq" (the controller's dq command) or "alpha_beta"
    voltage_frame = "dq"

    def __init__(self, motor: MotorParams, dt: float, q_diag, r_diag, p0_diag, x0=None):
        self.motor = motor
        self.dt = dt
        n = self.n_states
        self.q = [float(v) for v in q_diag]
        self.r0, self.r1 = (float(v) for v in r_diag)
        self.p0 = [float(v) for v in p0_diag]
        self.x0 = [0.0] * n if x0 is None else [float(v) for v in x0]
        m = motor
        # constants of A2-A6 and A8-A32
        self._a_rd = 1.0 - m.R_s * dt / m.L_d  # (A8)
        self._a_rq = 1.0 - m.R_s * dt / m.L_q  # (A14)
        self._c_wq = m.N * m.L_q * dt / m.L_d  # (A9)/omega, (A10)/i_q
        self._c_wd = m.N * m.L_d * dt / m.L_q  # (A13)/omega
        self._c_wpsi = m.N * m.psi * dt / m.L_q  # (A15), psi part
        self._c_vd = dt / m.L_d
        self._c_vq = dt / m.L_q
        self._c_tpsi = m.N * m.psi * dt / m.J_m  # (A19), psi part
        self._c_tdq = m.N * (m.L_d - m.L_q) * dt / m.J_m  # (A18)/i_q, (A19)/i_d
        self._c_tl = -dt / m.J_m  # (A22)
        self._c_th = m.N * dt  # (A25)
        self.reset()

    def reset(self) -> None:
        n = self.n_states
        self._x = list(self.x0)
        self._P = [[self.p0[i] if i == j else 0.0 for j in range(n)] for i in range(n)]
        self.theta_prior = self._x[TH]

    # -- shared model pieces -------------------------------------------------------
    def _predict_currents(self, i_d, i_q, w, v_d, v_q):
        """f1, f2 of A2-A3 (forward Euler of eqs 10-11)."""
        return (self._a_rd * i_d + self._c_wq * w * i_q + self._c_vd * v_d,  # (A2)
                self._a_rq * i_q - self._c_wd * w * i_d - self._c_wpsi * w + self._c_vq * v_q)  # (A3)

    def _update(self, pht, s00, s01, s11, y0, y1) -> None:
        """Eqs 25-27 from PH^T (n x 2 rows), S = H P H^T + R and the innovation y."""
        det = s00 * s11 - s01 * s01
        i00, i01, i11 = s11 / det, -s01 / det, s00 / det  # S^-1
        x, P = self._x, self._P
        n = self.n_states
        K = [(a * i00 + b * i01, a * i01 + b * i11) for a, b in pht]  # (25): P H^T S^-1
        for i in range(n):
            k0, k1 = K[i]
            x[i] += k0 * y0 + k1 * y1  # (26)
        # (27): P - K (P H^T)^T, symmetric by construction; compute the upper half
        for i in range(n):
            k0, k1 = K[i]
            Pi = P[i]
            for j in range(i, n):
                v = Pi[j] - k0 * pht[j][0] - k1 * pht[j][1]
                Pi[j] = v
                P[j][i] = v
        x[TH] = wrap_angle(x[TH])

    # -- estimates ---------------------------------------------------------------
    @property
    def x(self) -> np.ndarray:
        return np.array(self._x)

    @property
    def P(self) -> np.ndarray:
        return np.array(self._P)

    @property
    def i_d_hat(self) -> float:
        return self._x[ID]

    @property
    def i_q_hat(self) -> float:
        return self._x[IQ]

    @property
    def omega_hat(self) -> float:
        return self._x[W]

    @property
    def theta_hat(self) -> float:
        return self._x[TH]

    @property
    def T_L_hat(self) -> float:
        return self._x[TL] if self.n_states > TL else 0.0

    def get_state(self) -> tuple:
        return tuple(self._x) + tuple(v for row in self._P for v in row) + (self.theta_prior,)

    def set_state(self, state) -> None:
        n = self.n_states
        self._x = [float(v) for v in state[:n]]
        flat = [float(v) for v in state[n:n + n * n]]
        self._P = [flat[i * n:(i + 1) * n] for i in range(n)]
        self.theta_prior = float(state[n + n * n])

    # -- the model as functions of a state vector (for tests and inspection) ---------
    def f(self, x, v_d, v_q) -> np.ndarray:
        saved = self._x
        self._x = [float(v) for v in x]
        try:
            self._predict_state(v_d, v_q)
            return np.array(self._x)
        finally:
            self._x = saved

    def jacobian_f(self, x, v_d, v_q) -> np.ndarray:
        F = np.eye(self.n_states)
        for (i, j), v in self._jacobian_entries(*(float(v) for v in x[:3])).items():
            F[i, j] = v
        return F


class Ekf5(ExtendedKalmanFilter):
    """The paper's fifth-order EKF: x = [i_d, i_q, omega_m, theta, T_L] (21), z = [i_d, i_q]."""

    n_states = 5

    def __init__(self, motor: MotorParams, dt: float, ekf: EkfParams | None = None, x0=None):
        e = ekf or EkfParams()
        super().__init__(motor, dt,
                         (e.q_i, e.q_i, e.q_omega, e.q_theta, e.q_TL), (e.r_i, e.r_i),
                         (e.p0_i, e.p0_i, e.p0_omega, e.p0_theta, e.p0_TL),
                         x0 if x0 is not None else (0.0, 0.0, e.x0_omega, e.x0_theta, 0.0))

    def _predict_state(self, v_d, v_q) -> None:
        x = self._x
        i_d, i_q, w, th, t_l = x
        x[0], x[1] = self._predict_currents(i_d, i_q, w, v_d, v_q)  # (A2), (A3)
        x[2] = w + self._c_tpsi * i_q + self._c_tdq * i_d * i_q + self._c_tl * t_l  # (A4)
        x[3] = th + self._c_th * w  # (A5)
        # x[4] = t_l  (A6)

    def _jacobian_entries(self, i_d, i_q, w) -> dict:
        """Off-identity entries of J_f (A8-A32); the rest are 0 or 1."""
        return {
            (0, 0): self._a_rd, (0, 1): self._c_wq * w, (0, 2): self._c_wq * i_q,  # (A8-A10)
            (1, 0): -self._c_wd * w, (1, 1): self._a_rq, (1, 2): -self._c_wd * i_d - self._c_wpsi,  # (A13-A15)
            (2, 0): self._c_tdq * i_q, (2, 1): self._c_tpsi + self._c_tdq * i_d, (2, 4): self._c_tl,  # (A18, A19, A22)
            (3, 2): self._c_th,  # (A25)
        }

    def predict(self, v_d: float, v_q: float) -> None:
        """Eqs 23-24: x^f = f(x^e), P^f = J_f P J_f^T + Q, with J_f at x^e_{k-1}."""
        i_d, i_q, w = self._x[0], self._x[1], self._x[2]
        # J_f rows (A8-A32): r0 = [f00 f01 f02 0 0], r1 = [f10 f11 f12 0 0],
        # r2 = [f20 f21 1 0 f24], r3 = [0 0 f32 1 0], r4 = [0 0 0 0 1]
        f00, f01, f02 = self._a_rd, self._c_wq * w, self._c_wq * i_q
        f10, f11, f12 = -self._c_wd * w, self._a_rq, -self._c_wd * i_d - self._c_wpsi
        f20, f21, f24 = self._c_tdq * i_q, self._c_tpsi + self._c_tdq * i_d, self._c_tl
        f32 = self._c_th
        self._predict_state(v_d, v_q)  # (23)
        P0, P1, P2, P3, P4 = self._P
        # A = J_f P, row by row
        A0 = [f00 * a + f01 * b + f02 * c for a, b, c in zip(P0, P1, P2)]
        A1 = [f10 * a + f11 * b + f12 * c for a, b, c in zip(P0, P1, P2)]
        A2 = [f20 * a + f21 * b + c + f24 * e for a, b, c, e in zip(P0, P1, P2, P4)]
        A3 = [f32 * c + d for c, d in zip(P2, P3)]
        A4 = P4
        # P^f = A J_f^T + Q (24): column j of A J_f^T is A @ (row j of J_f)
        rows = []
        for A in (A0, A1, A2, A3, A4):
            a0, a1, a2, a3, a4 = A
            rows.append([f00 * a0 + f01 * a1 + f02 * a2,
                         f10 * a0 + f11 * a1 + f12 * a2,
                         f20 * a0 + f21 * a1 + a2 + f24 * a4,
                         f32 * a2 + a3,
                         a4])
        q = self.q
        for i in range(5):
            rows[i][i] += q[i]
        self._P = rows
        self.theta_prior = self._x[TH]

    def correct(self, i_alpha, i_beta, i_d, i_q, theta_meas=0.0, omega_meas=0.0) -> None:
        """Eqs 25-27 with z = [i_d, i_q], h(x) = [x0, x1], J_h = [I_2 0] (A33)."""
        P = self._P
        pht = [(row[0], row[1]) for row in P]
        self._update(pht, P[0][0] + self.r0, P[0][1], P[1][1] + self.r1,
                     i_d - self._x[0], i_q - self._x[1])

    def h(self, x) -> np.ndarray:
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

    and then steps A2-A6 as the EKF5 does. Two reasons, both physics:

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

    #: predict() takes the stationary-frame voltage held over the period
    voltage_frame = "alpha_beta"

    def __init__(self, motor: MotorParams, dt: float, ekf: EkfParams | None = None, x0=None):
        self._c_mid = 0.5 * motor.N * dt  # d(theta at mid-period)/d(omega_m)
        super().__init__(motor, dt, ekf, x0)

    def reset(self) -> None:
        super().reset()
        self._started = False  # no predict() before the first sample

    def get_state(self) -> tuple:
        return super().get_state() + (float(self._started),)

    def set_state(self, state) -> None:
        super().set_state(state[:-1])
        self._started = bool(state[-1])

    def _rotor_voltage(self, v_alpha, v_beta):
        """(v_d, v_q): Park of the held vector at the filter's mid-period angle."""
        x = self._x
        th_m = x[TH] + self._c_mid * x[W]
        c, s = math.cos(th_m), math.sin(th_m)
        return c * v_alpha + s * v_beta, -s * v_alpha + c * v_beta

    def _predict_state(self, v_alpha, v_beta) -> None:
        Ekf5._predict_state(self, *self._rotor_voltage(v_alpha, v_beta))

    def jacobian_f(self, x, v_alpha, v_beta) -> np.ndarray:
        saved = self._x
        self._x = [float(v) for v in x]
        try:
            v_d, v_q = self._rotor_voltage(v_alpha, v_beta)
        finally:
            self._x = saved
        f03, f13 = self._c_vd * v_q, -self._c_vq * v_d  # d v_d/d theta = v_q, d v_q/d theta = -v_d
        F = Ekf5.jacobian_f(self, x, v_alpha, v_beta)
        F[0, 3] = f03
        F[1, 3] = f13
        F[0, 2] += f03 * self._c_mid  # theta_mid depends on omega too
        F[1, 2] += f13 * self._c_mid
        return F

    def predict(self, v_alpha: float, v_beta: float) -> None:
        """Eqs 23-24 with the stationary-frame voltage (see the class notes)."""
        if not self._started:  # x0 is the estimate at the first sample
            self._started = True
            return
        i_d, i_q, w = self._x[0], self._x[1], self._x[2]
        v_d, v_q = self._rotor_voltage(v_alpha, v_beta)
        f03, f13 = self._c_vd * v_q, -self._c_vq * v_d  # d v_d/d theta = v_q, d v_q/d theta = -v_d
        # J_f rows: r0 = [f00 f01 f02 f03 0], r1 = [f10 f11 f12 f13 0],
        # r2 = [f20 f21 1 0 f24], r3 = [0 0 f32 1 0], r4 = [0 0 0 0 1]
        f00, f01, f02 = self._a_rd, self._c_wq * w, self._c_wq * i_q + f03 * self._c_mid
        f10, f11, f12 = -self._c_wd * w, self._a_rq, -self._c_wd * i_d - self._c_wpsi + f13 * self._c_mid
        f20, f21, f24 = self._c_tdq * i_q, self._c_tpsi + self._c_tdq * i_d, self._c_tl
        f32 = self._c_th
        Ekf5._predict_state(self, v_d, v_q)  # (23)
        P0, P1, P2, P3, P4 = self._P
        A0 = [f00 * a + f01 * b + f02 * c + f03 * d for a, b, c, d in zip(P0, P1, P2, P3)]
        A1 = [f10 * a + f11 * b + f12 * c + f13 * d for a, b, c, d in zip(P0, P1, P2, P3)]
        A2 = [f20 * a + f21 * b + c + f24 * e for a, b, c, e in zip(P0, P1, P2, P4)]
        A3 = [f32 * c + d for c, d in zip(P2, P3)]
        A4 = P4
        rows = []
        for A in (A0, A1, A2, A3, A4):
            a0, a1, a2, a3, a4 = A
            rows.append([f00 * a0 + f01 * a1 + f02 * a2 + f03 * a3,
                         f10 * a0 + f11 * a1 + f12 * a2 + f13 * a3,
                         f20 * a0 + f21 * a1 + a2 + f24 * a4,
                         f32 * a2 + a3,
                         a4])
        q = self.q
        for i in range(5):
            rows[i][i] += q[i]
        self._P = rows  # (24)
        self.theta_prior = self._x[TH]

    def correct(self, i_alpha, i_beta, i_d, i_q, theta_meas=0.0, omega_meas=0.0) -> None:
        x, P = self._x, self._P
        c, s = math.cos(x[TH]), math.sin(x[TH])
        xd, xq = x[ID], x[IQ]
        # J_h rows: [c, -s, 0, h03, 0], [s, c, 0, h13, 0]
        h03 = -s * xd - c * xq
        h13 = c * xd - s * xq
        pht = [(c * row[0] - s * row[1] + h03 * row[3], s * row[0] + c * row[1] + h13 * row[3]) for row in P]
        s00 = c * pht[0][0] - s * pht[1][0] + h03 * pht[3][0] + self.r0
        s01 = c * pht[0][1] - s * pht[1][1] + h03 * pht[3][1]
        s11 = s * pht[0][1] + c * pht[1][1] + h13 * pht[3][1] + self.r1
        self._update(pht, s00, s01, s11, i_alpha - (c * xd - s * xq), i_beta - (s * xd + c * xq))

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

    def __init__(self, motor: MotorParams, dt: float, ekf: EkfParams | None = None, x0=None):
        e = ekf or EkfParams()
        super().__init__(motor, dt,
                         (e.q_i, e.q_i, e.q_omega_ekf4, e.q_theta), (e.r_i, e.r_i),
                         (e.p0_i, e.p0_i, e.p0_omega, e.p0_theta),
                         x0 if x0 is not None else (0.0, 0.0, e.x0_omega, e.x0_theta))

    def _predict_state(self, v_d, v_q) -> None:
        x = self._x
        i_d, i_q, w, th = x
        x[0], x[1] = self._predict_currents(i_d, i_q, w, v_d, v_q)  # (A2), (A3)
        # x[2] = w: no load model, omega is a random walk
        x[3] = th + self._c_th * w  # (A5)

    def _jacobian_entries(self, i_d, i_q, w) -> dict:
        return {
            (0, 0): self._a_rd, (0, 1): self._c_wq * w, (0, 2): self._c_wq * i_q,
            (1, 0): -self._c_wd * w, (1, 1): self._a_rq, (1, 2): -self._c_wd * i_d - self._c_wpsi,
            (3, 2): self._c_th,
        }

    def predict(self, v_d: float, v_q: float) -> None:
        i_d, i_q, w = self._x[0], self._x[1], self._x[2]
        f00, f01, f02 = self._a_rd, self._c_wq * w, self._c_wq * i_q
        f10, f11, f12 = -self._c_wd * w, self._a_rq, -self._c_wd * i_d - self._c_wpsi
        f32 = self._c_th
        self._predict_state(v_d, v_q)  # (23)
        P0, P1, P2, P3 = self._P
        A0 = [f00 * a + f01 * b + f02 * c for a, b, c in zip(P0, P1, P2)]
        A1 = [f10 * a + f11 * b + f12 * c for a, b, c in zip(P0, P1, P2)]
        A3 = [f32 * c + d for c, d in zip(P2, P3)]
        rows = []
        for A in (A0, A1, P2, A3):
            a0, a1, a2, a3 = A
            rows.append([f00 * a0 + f01 * a1 + f02 * a2,
                         f10 * a0 + f11 * a1 + f12 * a2,
                         a2,
                         f32 * a2 + a3])
        q = self.q
        for i in range(4):
            rows[i][i] += q[i]
        self._P = rows  # (24)
        self.theta_prior = self._x[TH]

    correct = Ekf5.correct
    h = Ekf5.h
    jacobian_h = Ekf5.jacobian_h


class Sensored:
    """Baseline: passes the measured speed and angle through; currents as measured."""

    n_states = 0
    voltage_frame = "dq"

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
