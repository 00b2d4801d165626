"""Field-oriented control, eqs 14-20, plus what a drive needs and the paper omits:
a q-current limit, a voltage-vector limit and anti-windup (conditional integration).

All blocks are discrete with period dt (forward-Euler integrators and filters). The
formulas are ``pmsm_ev.kernels.speed_step`` and ``current_step``; these classes hold the
parameters and the state in the slots of a control-unit vector (their own, or the one of
the ``ControlUnit`` they belong to). Their gains are ``controller_gains``: derived when a
block (or the control unit) is built, from the bandwidths in ``ControllerParams`` and the
controller's own motor model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from . import accel
from . import kernels as _k
from .params import ControllerParams, MotorParams, StartupParams


@dataclass(frozen=True)
class ControllerGains:
    """The gains of a control unit, as ``controller_gains`` derives them."""

    kp_w: float  #: speed PI proportional gain [A s/rad] (eq 14)
    ki_w: float  #: speed PI integral gain [A/rad] (eq 14)
    kp_id: float  #: d-current PI proportional gain [V/A] (eq 15)
    ki_id: float  #: d-current PI integral gain [V/(A s)] (eq 15)
    kp_iq: float  #: q-current PI proportional gain [V/A] (eq 16)
    ki_iq: float  #: q-current PI integral gain [V/(A s)] (eq 16)
    T_d: float  #: time constant of the decoupling low-pass filters [s] (eqs 17-18)
    #: the sensorless unit's I-f damping gain times sqrt(i) [rad s sqrt(A)]; 0 without one
    k_if: float = 0.0


def controller_gains(p: ControllerParams, motor: MotorParams, startup: StartupParams | None = None,
                     J_if: float = 0.0) -> ControllerGains:
    """The gains of the PIs (eqs 14-16), the decoupling filters (17-18) and, with ``startup``,
    of the sensorless unit's I-f damping, from the design in ``p`` (``omega_c``, ``omega_n``,
    ``zeta``, ``J_load``) and the controller's motor model ``motor``. A gain of ``p`` other
    than 0 is taken as it is.

    * Current PIs (15-16), the PI zero on the stator's R/L pole (internal model control:
      Harnefors and Nee, "Model-based current control of AC machines using the internal
      model control method", IEEE Trans. Ind. Appl. 34(1), 1998):
      K_p = L omega_c, K_i = R_s omega_c, with L = L_d (d axis) or L_q (q axis). With the
      back-EMF and cross-coupling cancelled by the decoupling (19-20) the loop is
      omega_c / (s + omega_c): first order, time constant 1 / omega_c.
    * Decoupling filters (17-18): T_d = 1 / omega_c, so that i_dl, i_ql follow the
      references the way the closed-loop currents do.
    * Speed PI (14) on the closed current loop seen as ideal (omega_c >> omega_n) and the
      torque of eq 12 with i_d = 0, T_e = k_t i_q, k_t = k_dq N psi (``MotorParams.k_dq``: 1 in the
      paper's scaling, no 3/2),
      driving J = J_m + J_load (eq 9): J s^2 + k_t K_p s + k_t K_i = 0 is
      s^2 + 2 zeta omega_n s + omega_n^2 = 0 with K_p = 2 zeta omega_n J / k_t,
      K_i = omega_n^2 J / k_t.
    * I-f damping of the sensorless unit (``StartupParams.if_damping``): the rotor on a
      current vector of magnitude i is a spring N psi i per rad on the inertia ``J_if`` of
      the EKF's model; pulling the vector back by k (omega_hat - omega_if) gives the
      linearised swing J s^2 + N psi i (k s + N) = 0, damped with zeta_if at
      k = 2 zeta_if sqrt(J / (psi i)): ``k_if`` = 2 zeta_if sqrt(J / psi), divided by sqrt(i)
      in use (``pmsm_ev.kernels.sensorless_step``).

    The anti-windup is conditional integration (no gain): the integrators hold while their
    output is limited (``pmsm_ev.kernels.speed_step``, ``current_step``).
    """
    wc, wn, zeta = p.omega_c, p.omega_n, p.zeta
    j = motor.J_m + p.J_load  # J_eq of eq 9 with the controller's J_m
    k_t = motor.k_dq * motor.N * motor.psi  # torque constant of eq 12 with i_d = 0 [N m/A] (x k_dq)
    return ControllerGains(
        kp_w=p.kp_w or 2 * zeta * wn * j / k_t,
        ki_w=p.ki_w or wn**2 * j / k_t,
        kp_id=p.kp_id or motor.L_d * wc,
        ki_id=p.ki_id or motor.R_s * wc,
        kp_iq=p.kp_iq or motor.L_q * wc,
        ki_iq=p.ki_iq or motor.R_s * wc,
        T_d=p.T_d or 1.0 / wc,
        k_if=2.0 * startup.if_damping * math.sqrt(J_if / motor.psi) if startup is not None else 0.0)


class _Slots:
    """A block of a control unit's state and parameter vectors (shared or own)."""

    def __init__(self, state=None, params=None):
        self._kernels = accel.kernels()
        self._s = state if state is not None else accel.vector(_k.UNIT_STATE)
        self._c = params if params is not None else accel.vector(_k.UNIT_PARAMS)


def state_slot(index: int, doc: str | None = None, settable: bool = True) -> property:
    """An attribute held, as a float, in a control unit's state vector ``self._s`` at ``index`` (read-only unless
    ``settable``)."""
    def get(self) -> float:
        return float(self._s[index])

    def set_(self, value: float) -> None:
        self._s[index] = float(value)

    return property(get, set_ if settable else None, doc=doc)


class SpeedController(_Slots):
    """Speed PI, eq 14: i_qref = K_pw e + K_iw int e dt, e = omega_ref - omega_est (gains:
    ``gains``, by default ``controller_gains(p, motor)``)."""

    integral = state_slot(_k.S_W_INT, "integral term K_iw int e dt [A]")

    def __init__(self, p: ControllerParams, motor: MotorParams, dt: float, state=None, params=None,
                 gains: ControllerGains | None = None):
        super().__init__(state, params)
        self.p, self.dt = p, dt
        self.gains = g = gains or controller_gains(p, motor)
        c = self._c
        c[_k.C_DT] = float(dt)
        c[_k.C_KP_W], c[_k.C_KI_W], c[_k.C_I_Q_MAX] = float(g.kp_w), float(g.ki_w), float(p.i_q_max)
        self.reset()

    def reset(self) -> None:
        self.integral = 0.0

    def step(self, omega_ref: float, omega_est: float) -> float:
        return self._kernels.speed_step(self._s, self._c, omega_ref, omega_est)


class CurrentController(_Slots):
    """Current PIs (15-16), decoupling filters (17-18) and decoupling terms (19-20),
    with the voltage vector limited to u_max, or v_dc / sqrt(3) when ``v_dc`` is given
    (``ControllerParams.u_limit``; integrators held while it is limited).
    """

    int_d = state_slot(_k.S_INT_D, "integral term of (15) [V]")
    int_q = state_slot(_k.S_INT_Q, "integral term of (16) [V]")
    i_dl = state_slot(_k.S_I_DL, "low-pass filtered d reference of (17) [A]")
    i_ql = state_slot(_k.S_I_QL, "low-pass filtered q reference of (18) [A]")

    def __init__(self, p: ControllerParams, motor: MotorParams, dt: float, state=None, params=None,
                 gains: ControllerGains | None = None):
        super().__init__(state, params)
        self.p, self.m, self.dt = p, motor, dt
        self.gains = g = gains or controller_gains(p, motor)
        c = self._c
        c[_k.C_DT] = float(dt)
        for slot, value in ((_k.C_KP_ID, g.kp_id), (_k.C_KI_ID, g.ki_id), (_k.C_KP_IQ, g.kp_iq),
                            (_k.C_KI_IQ, g.ki_iq), (_k.C_T_D, g.T_d), (_k.C_U_MAX, p.u_limit),
                            (_k.C_N, motor.N), (_k.C_L_D, motor.L_d), (_k.C_L_Q, motor.L_q),
                            (_k.C_PSI, motor.psi), (_k.C_PAPER_SIGNS, p.decoupling == "paper")):
            c[slot] = float(value)
        # the high-speed current control (``ControllerParams.current_control``): the share of the error
        # the first-order loop makes up by the middle of the applied period, angle_advance periods on
        c[_k.C_CC_HS] = 1.0 if p.current_control == "high_speed" else 0.0
        c[_k.C_CC_PRED] = 1.0 - math.exp(-p.omega_c * dt * p.angle_advance) if c[_k.C_CC_HS] else 0.0
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
