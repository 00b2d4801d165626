"""dq model of the PMSM, eqs 10-13 (the paper's scaling: T_e = N psi i_q + ..., no 3/2).

The formulas are in ``pmsm_ev.kernels`` (the per-step code, compiled with numba when
available); these functions take the motor's parameters as a ``MotorParams``.
"""

from __future__ import annotations

from . import kernels as _k
from .params import MotorParams


def current_derivatives(i_d: float, i_q: float, omega_m: float, v_d: float, v_q: float,
                        m: MotorParams) -> tuple[float, float]:
    """(di_d/dt, di_q/dt) [A/s] of eqs 10-11; omega_m is mechanical [rad/s]."""
    return _k.current_derivatives(i_d, i_q, omega_m, v_d, v_q, m.R_s, m.L_d, m.L_q, m.psi, m.N)


def electromagnetic_torque(i_d: float, i_q: float, m: MotorParams) -> float:
    """T_e = N psi i_q + N L_d i_d i_q - N L_q i_q i_d [N m] (eq 12)."""
    return _k.electromagnetic_torque(i_d, i_q, m.psi, m.L_d, m.L_q, m.N)


def friction_torque(omega_m: float, m: MotorParams, load_model: str = "physical") -> float:
    """B_m omega_m + T_m0 [N m] (eq 8), plus the windage k_wind omega_m |omega_m| when ``k_wind`` > 0.

    "paper": T_m0 as printed, a constant; "physical": T_m0 tanh(omega_m/omega_eps)
    so that it opposes rotation and vanishes at standstill.
    """
    t_f = _k.friction_torque(omega_m, m.B_m, m.T_m0, m.omega_eps, load_model == "paper")
    if m.k_wind:
        t_f += _k.windage_torque(omega_m, m.k_wind)
    return t_f
