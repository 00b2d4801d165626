"""Field-oriented control, eqs 14-20, plus what a drive needs and the paper omits:
a q-current limit, a voltage-vector limit and anti-windup (conditional integration).

All blocks are discrete with period dt (forward-Euler integrators and filters). The
formulas are ``pmsm_ev.kernels.speed_step`` and ``current_step``; these classes hold the
parameters and the state in the slots of a control-unit vector (their own, or the one of
the ``ControlUnit`` they belong to).
"""

from __future__ import annotations

from . import accel
from . import kernels as _k
from .params import ControllerParams, MotorParams


class _Slots:
    """A block of a control unit's state and parameter vectors (shared or own)."""

    def __init__(self, state=None, params=None):
        self._kernels = accel.kernels()
        self._s = state if state is not None else accel.vector(_k.UNIT_STATE)
        self._c = params if params is not None else accel.vector(_k.UNIT_PARAMS)


def _slot(index: int, doc: str) -> property:
    def get(self) -> float:
        return float(self._s[index])

    def set_(self, value: float) -> None:
        self._s[index] = float(value)

    return property(get, set_, doc=doc)


class SpeedController(_Slots):
    """Speed PI, eq 14: i_qref = K_pw e + K_iw int e dt, e = omega_ref - omega_est."""

    integral = _slot(_k.S_W_INT, "integral term K_iw int e dt [A]")

    def __init__(self, p: ControllerParams, dt: float, state=None, params=None):
        super().__init__(state, params)
        self.p, self.dt = p, dt
        c = self._c
        c[_k.C_DT] = float(dt)
        c[_k.C_KP_W], c[_k.C_KI_W], c[_k.C_I_Q_MAX] = float(p.kp_w), float(p.ki_w), float(p.i_q_max)
        self.reset()

    def reset(self) -> None:
        self.integral = 0.0

    def step(self, omega_ref: float, omega_est: float) -> float:
        return self._kernels.speed_step(self._s, self._c, omega_ref, omega_est)


class CurrentController(_Slots):
    """Current PIs (15-16), decoupling filters (17-18) and decoupling terms (19-20),
    with the voltage vector limited to u_max (integrators held while it is limited).
    """

    int_d = _slot(_k.S_INT_D, "integral term of (15) [V]")
    int_q = _slot(_k.S_INT_Q, "integral term of (16) [V]")
    i_dl = _slot(_k.S_I_DL, "low-pass filtered d reference of (17) [A]")
    i_ql = _slot(_k.S_I_QL, "low-pass filtered q reference of (18) [A]")

    def __init__(self, p: ControllerParams, motor: MotorParams, dt: float, state=None, params=None):
        super().__init__(state, params)
        self.p, self.m, self.dt = p, motor, dt
        c = self._c
        c[_k.C_DT] = float(dt)
        for slot, value in ((_k.C_KP_ID, p.kp_id), (_k.C_KI_ID, p.ki_id), (_k.C_KP_IQ, p.kp_iq),
                            (_k.C_KI_IQ, p.ki_iq), (_k.C_T_D, p.T_d), (_k.C_U_MAX, p.u_max),
                            (_k.C_N, motor.N), (_k.C_L_D, motor.L_d), (_k.C_L_Q, motor.L_q),
                            (_k.C_PSI, motor.psi), (_k.C_PAPER_SIGNS, p.decoupling == "paper")):
            c[slot] = float(value)
        self.reset()

    @property
    def saturated(self) -> bool:
        """Whether the last voltage vector was limited to u_max."""
        return bool(self._s[_k.S_SAT])

    @saturated.setter
    def saturated(self, value: bool) -> None:
        self._s[_k.S_SAT] = 1.0 if value else 0.0

    def reset(self) -> None:
        self.int_d = self.int_q = 0.0
        self.i_dl = self.i_ql = 0.0
        self.saturated = False

    def step(self, i_dref: float, i_qref: float, i_d: float, i_q: float,
             omega_est: float) -> tuple[float, float]:
        return self._kernels.current_step(self._s, self._c, i_dref, i_qref, i_d, i_q, omega_est)

    def get_state(self) -> tuple:
        return (self.int_d, self.int_q, self.i_dl, self.i_ql, float(self.saturated))

    def set_state(self, state) -> None:
        self.int_d, self.int_q, self.i_dl, self.i_ql = (float(v) for v in state[:4])
        self.saturated = bool(state[4])
