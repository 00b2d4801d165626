"""Longitudinal vehicle model, eqs 1-9 and 29 of the paper.

Forces act on the vehicle along the road; the gear (eqs 6-7) reflects them to the
motor shaft. Speeds: v_v [m/s] vehicle, omega_w [rad/s] wheel, omega_m [rad/s] motor.
"""

from __future__ import annotations

import math

from .params import VehicleParams


def inertia_force(a_v: float, p: VehicleParams) -> float:
    """f_i = m_v a_v [N] (eq 1)."""
    return p.m_v * a_v


def gradient_force(delta: float, p: VehicleParams) -> float:
    """f_g = m_v g sin(delta) [N] (eq 2); delta is the road elevation angle [rad]."""
    return p.m_v * p.g * math.sin(delta)


def rolling_force(v_v: float, delta: float, p: VehicleParams) -> float:
    """f_f = c_r m_v g cos(delta) [N] (eq 3).

    ``load_model="paper"``: as printed, it always pushes back, even at standstill.
    ``"physical"``: it opposes motion, times tanh(v_v / v_eps).
    """
    f = p.c_r * p.m_v * p.g * math.cos(delta)
    if p.load_model == "paper":
        return f
    return f * math.tanh(v_v / p.v_eps)


def aero_force(v_v: float, p: VehicleParams) -> float:
    """f_a = 0.5 rho_a c_d A_f (v_v + v_a)^2 [N] (eq 4).

    ``"physical"`` keeps the sign of the relative air speed: (v+v_a)|v+v_a|.
    """
    v_rel = v_v + p.v_a
    k = 0.5 * p.rho_a * p.c_d * p.A_f
    if p.load_model == "paper":
        return k * v_rel * v_rel
    return k * v_rel * abs(v_rel)


def wheel_torque(f_i: float, f_g: float, f_f: float, f_a: float, p: VehicleParams) -> float:
    """T_w = r_w (f_i + f_g + f_f + f_a) [N m] (eq 5)."""
    return p.r_w * (f_i + f_g + f_f + f_a)


def wheel_speed(omega_m: float, p: VehicleParams) -> float:
    """omega_w = omega_m / n_g [rad/s] (eq 6)."""
    return omega_m / p.n_g


def vehicle_speed(omega_m: float, p: VehicleParams) -> float:
    """v_v = r_w omega_w [m/s] (eqs 1, 6)."""
    return p.r_w * omega_m / p.n_g


def motor_side_torque(t_w: float, p: VehicleParams) -> float:
    """T_m = T_w / (eta n_g) [N m] (eq 7)."""
    return t_w / (p.eta * p.n_g)


def load_torque(omega_m: float, delta: float, p: VehicleParams) -> float:
    """T_L-mech = r_w / (eta n_g) (f_g + f_f + f_a) [N m] (eq 29): the road load on the shaft."""
    v_v = p.r_w * omega_m / p.n_g
    forces = gradient_force(delta, p) + rolling_force(v_v, delta, p) + aero_force(v_v, p)
    return p.r_w / (p.eta * p.n_g) * forces
