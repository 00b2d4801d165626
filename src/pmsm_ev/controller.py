"""Field-oriented control, eqs 14-20, plus what a drive needs and the paper omits:
a q-current limit, a voltage-vector limit and anti-windup (conditional integration).

All blocks are discrete with period dt (forward-Euler integrators and filters).
"""

from __future__ import annotations

import math

from .params import ControllerParams, MotorParams


class SpeedController:
    """Speed PI, eq 14: i_qref = K_pw e + K_iw int e dt, e = omega_ref - omega_est."""

    def __init__(self, p: ControllerParams, dt: float):
        self.p, self.dt = p, dt
        self.reset()

    def reset(self) -> None:
        self.integral = 0.0  # integral term K_iw int e dt [A]

    def step(self, omega_ref: float, omega_est: float) -> float:
        p = self.p
        e = omega_ref - omega_est
        unsat = p.kp_w * e + self.integral  # (14)
        i_qref = min(max(unsat, -p.i_q_max), p.i_q_max)
        # anti-windup: integrate unless the output is clamped and e pushes further out
        if i_qref == unsat or (unsat > p.i_q_max) != (e > 0):
            self.integral += p.ki_w * e * self.dt
        return i_qref


class CurrentController:
    """Current PIs (15-16), decoupling filters (17-18) and decoupling terms (19-20),
    with the voltage vector limited to u_max (integrators held while it is limited).
    """

    def __init__(self, p: ControllerParams, motor: MotorParams, dt: float):
        self.p, self.m, self.dt = p, motor, dt
        self._paper_signs = p.decoupling == "paper"
        self.reset()

    def reset(self) -> None:
        self.int_d = 0.0  # integral terms of (15), (16) [V]
        self.int_q = 0.0
        self.i_dl = 0.0  # low-pass filtered references of (17), (18) [A]
        self.i_ql = 0.0
        self.saturated = False

    def step(self, i_dref: float, i_qref: float, i_d: float, i_q: float,
             omega_est: float) -> tuple[float, float]:
        p, m, dt = self.p, self.m, self.dt
        e_d = i_dref - i_d
        e_q = i_qref - i_q
        u_d = p.kp_id * e_d + self.int_d  # (15)
        u_q = p.kp_iq * e_q + self.int_q  # (16)
        w_e = m.N * omega_est
        v_d = u_d - w_e * m.L_q * self.i_ql  # (19)
        if self._paper_signs:
            v_q = u_q - w_e * m.L_d * self.i_dl - w_e * m.psi  # (20) as printed
        else:
            v_q = u_q + w_e * m.L_d * self.i_dl + w_e * m.psi  # (20) corrected to cancel (11)
        self.i_dl += dt / p.T_d * (i_dref - self.i_dl)  # (17)
        self.i_ql += dt / p.T_d * (i_qref - self.i_ql)  # (18)
        mag = math.hypot(v_d, v_q)
        self.saturated = mag > p.u_max
        if self.saturated:
            scale = p.u_max / mag
            v_d *= scale
            v_q *= scale
        else:
            self.int_d += p.ki_id * e_d * dt
            self.int_q += p.ki_iq * e_q * dt
        return v_d, v_q

    def get_state(self) -> tuple:
        return (self.int_d, self.int_q, self.i_dl, self.i_ql, float(self.saturated))

    def set_state(self, state) -> None:
        self.int_d, self.int_q, self.i_dl, self.i_ql = (float(v) for v in state[:4])
        self.saturated = bool(state[4])
