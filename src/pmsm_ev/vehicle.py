"""Longitudinal vehicle model, eqs 1-9 and 29 of the paper.

Forces act on the vehicle along the road; the gear (eqs 6-7) reflects them to the
motor shaft. Speeds: v_v [m/s] vehicle, omega_w [rad/s] wheel, omega_m [rad/s] motor.
The road-load formulas that run at every step (eqs 2-4, 29) are in ``pmsm_ev.kernels``;
these functions take the parameters as a ``VehicleParams``.
"""

from __future__ import annotations

from . import kernels as _k
from .params import VehicleParams


def inertia_force(a_v: float, p: VehicleParams) -> float:
    """f_i = m_v a_v [N] (eq 1)."""
    return p.m_v * a_v


def gradient_force(delta: float, p: VehicleParams) -> float:
    """f_g = m_v g sin(delta) [N] (eq 2); delta is the road elevation angle [rad]."""
    return _k.gradient_force(delta, p.m_v, p.g)


def rolling_force(v_v: float, delta: float, p: VehicleParams) -> float:
    """f_f = c_r m_v g cos(delta) [N] (eq 3).

    ``load_model="paper"``: as printed, it always pushes back, even at standstill.
    ``"physical"``: it opposes motion, times tanh(v_v / v_eps).
    """
    return _k.rolling_force(v_v, delta, p.c_r, p.m_v, p.g, p.v_eps, p.load_model == "paper")


def aero_force(v_v: float, p: VehicleParams) -> float:
    """f_a = 0.5 rho_a c_d A_f (v_v + v_a)^2 [N] (eq 4).

    ``"physical"`` keeps the sign of the relative air speed: (v+v_a)|v+v_a|.
    """
    return _k.aero_force(v_v, p.rho_a, p.c_d, p.A_f, p.v_a, p.load_model == "paper")


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
    return _k.load_torque(omega_m, delta, p.m_v, p.g, p.c_r, p.rho_a, p.c_d, p.A_f, p.r_w, p.eta, p.n_g,
                          p.v_a, p.v_eps, p.load_model == "paper")
