"""dq model of the PMSM, eqs 10-13 (the paper's scaling: T_e = N psi i_q + ..., no 3/2)."""

from __future__ import annotations

from math import tanh

from .params import MotorParams


def current_derivatives(i_d: float, i_q: float, omega_m: float, v_d: float, v_q: float,
                        m: MotorParams) -> tuple[float, float]:
    """(di_d/dt, di_q/dt) [A/s] of eqs 10-11; omega_m is mechanical [rad/s]."""
    w_e = m.N * omega_m
    did = (-m.R_s * i_d + w_e * m.L_q * i_q + v_d) / m.L_d  # (10)
    diq = (-m.R_s * i_q - w_e * m.L_d * i_d - w_e * m.psi + v_q) / m.L_q  # (11)
    return did, diq


def electromagnetic_torque(i_d: float, i_q: float, m: MotorParams) -> float:
    """T_e = N psi i_q + N L_d i_d i_q - N L_q i_q i_d [N m] (eq 12)."""
    return m.N * (m.psi * i_q + (m.L_d - m.L_q) * i_d * i_q)


def friction_torque(omega_m: float, m: MotorParams, load_model: str = "physical") -> float:
    """B_m omega_m + T_m0 [N m] (eq 8).

    "paper": T_m0 as printed, a constant; "physical": T_m0 tanh(omega_m/omega_eps)
    so that it opposes rotation and vanishes at standstill.
    """
    if load_model == "paper":
        return m.B_m * omega_m + m.T_m0
    return m.B_m * omega_m + m.T_m0 * tanh(omega_m / m.omega_eps)
