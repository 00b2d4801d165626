"""The plant's kernels: the PMSM (eqs 10-13), friction (eq 8), the road load (eqs 2-4, 29), the
vehicle's motion (eqs 1, 6, 9 = 28) and the RK4 step over them (``plant_step``), and the
departures of a real motor and inverter from eqs 10-12, each off by default: the inverter's
dead time (``dead_time_error``), magnetic saturation (flux-form eqs 10-12, ``saturated_*``) and
the winding's temperature (``winding_resistance``, ``thermal_step``).

The parameter vector ``pp`` is laid out by ``pmsm_ev.kernels.layout.PLANT_PARAMS_LAYOUT`` (``P_*``).
"""

from __future__ import annotations

import math

from .jit import F as _F
from .jit import V as _V
from .jit import kernel
from .jit import sig as _sig
from .layout import (
    P_A_F,
    P_B_M,
    P_C_D,
    P_C_R,
    P_DT_I0,
    P_DT_V,
    P_ETA,
    P_G,
    P_J_EQ,
    P_K_DQ,
    P_L_D,
    P_L_Q,
    P_M_V,
    P_N,
    P_N_G,
    P_OMEGA_EPS,
    P_PAPER,
    P_PSI,
    P_R_S,
    P_R_W,
    P_RHO_A,
    P_SAT,
    P_SAT_AD,
    P_SAT_AQ,
    P_SUBSTEP_ANGLE,
    P_SUBSTEPS,
    P_T_M0,
    P_V_A,
    P_V_EPS,
)
from .transforms import inverse_park, wrap_angle


# -- PMSM, eqs 10-13 ---------------------------------------------------------------------------
@kernel()
def current_derivatives(i_d, i_q, omega_m, v_d, v_q, R_s, L_d, L_q, psi, N):
    """(di_d/dt, di_q/dt) [A/s] of eqs 10-11; omega_m is mechanical [rad/s]."""
    w_e = N * omega_m
    did = (-R_s * i_d + w_e * L_q * i_q + v_d) / L_d  # (10)
    diq = (-R_s * i_q - w_e * L_d * i_d - w_e * psi + v_q) / L_q  # (11)
    return did, diq


@kernel()
def electromagnetic_torque(i_d, i_q, psi, L_d, L_q, N):
    """T_e = N psi i_q + N L_d i_d i_q - N L_q i_q i_d [N m] (eq 12)."""
    return N * (psi * i_q + (L_d - L_q) * i_d * i_q)


@kernel()
def friction_torque(omega_m, B_m, T_m0, omega_eps, paper):
    """B_m omega_m + T_m0 [N m] (eq 8); not ``paper``: T_m0 tanh(omega_m / omega_eps)."""
    if paper:
        return B_m * omega_m + T_m0
    return B_m * omega_m + T_m0 * math.tanh(omega_m / omega_eps)


# -- departures of a real motor and inverter from eqs 10-12 (plant only, each off by default) ----
_SQRT3_2 = 0.5 * math.sqrt(3.0)
_INV_SQRT3 = 1.0 / math.sqrt(3.0)


@kernel()
def dead_time_error(i_alpha, i_beta, v_err, i0):
    """Voltage error (alpha, beta) [V] of an inverter with dead time for the current vector
    (i_alpha, i_beta): each phase x = a, b, c loses v_err * tanh(i_x / i0) of its pole voltage
    (v_err = v_dc t_d / T_s, the volt-seconds the dead time takes per switching period, of the
    sign of the phase current: the free-wheeling diode conducts during the dead time; tanh is
    the soft sign of the switches' output capacitance, which makes the error fall to zero with
    the current). The common mode of the three errors does not reach the star-connected
    winding; the amplitude-invariant Clarke transform drops it."""
    i_b = -0.5 * i_alpha + _SQRT3_2 * i_beta
    i_c = -0.5 * i_alpha - _SQRT3_2 * i_beta
    e_a = -v_err * math.tanh(i_alpha / i0)
    e_b = -v_err * math.tanh(i_b / i0)
    e_c = -v_err * math.tanh(i_c / i0)
    return (2.0 * e_a - e_b - e_c) / 3.0, (e_b - e_c) * _INV_SQRT3


@kernel()
def saturated_flux(i, L0, a):
    """Flux linkage and incremental inductance of one axis with self-saturation, the
    Froehlich-Kennelly magnetisation curve psi(i) = L0 i / (1 + a |i|), a = 1/I_sat [1/A]:
    apparent inductance psi/i = L0 / (1 + a|i|), incremental dpsi/di = L0 / (1 + a|i|)^2.
    Returns (psi [Wb], L_inc [H]); a = 0 gives (L0 i, L0)."""
    k = 1.0 + a * abs(i)
    return L0 * i / k, L0 / (k * k)


@kernel()
def saturated_current_derivatives(i_d, i_q, omega_m, v_d, v_q, R_s, L_d, L_q, psi, N, a_d, a_q):
    """Eqs 10-11 in flux form with saturated inductances: d psi_d/dt = v_d - R i_d + w_e psi_q,
    d psi_q/dt = v_q - R i_q - w_e psi_d, psi_d = psi + psi_dd(i_d), psi_q = psi_qq(i_q)
    (``saturated_flux``, no cross-saturation), so di/dt = (d psi/dt) / L_inc. With a_d = a_q =
    0 these are eqs 10-11."""
    w_e = N * omega_m
    f_d, l_d = saturated_flux(i_d, L_d, a_d)
    f_q, l_q = saturated_flux(i_q, L_q, a_q)
    did = (-R_s * i_d + w_e * f_q + v_d) / l_d  # (10) with psi_q = L_q,app i_q
    diq = (-R_s * i_q - w_e * (psi + f_d) + v_q) / l_q  # (11) with psi_d = psi + L_d,app i_d
    return did, diq


@kernel()
def saturated_torque(i_d, i_q, psi, L_d, L_q, N, a_d, a_q):
    """T_e = N (psi_d i_q - psi_q i_d) [N m]: eq 12 in its flux form with the saturated fluxes
    (``saturated_flux``); it equals the co-energy derivative (no cross-saturation, no slot
    harmonics) and eq 12 for a_d = a_q = 0."""
    f_d, _ = saturated_flux(i_d, L_d, a_d)
    f_q, _ = saturated_flux(i_q, L_q, a_q)
    return N * ((psi + f_d) * i_q - f_q * i_d)


@kernel()
def winding_resistance(R_s20, T, alpha_R, T_ref):
    """R_s(T) = R_s20 (1 + alpha_R (T - T_ref)) [Ohm]: copper's linear law."""
    return R_s20 * (1.0 + alpha_R * (T - T_ref))


@kernel()
def winding_thermal_step(T, i_d, i_q, R_s20, alpha_R, T_ref, T_amb, R_th, C_th, dt):
    """The winding heated over dt by its copper losses R_s(T) (i_d^2 + i_q^2) (``thermal_step``; the
    model's power scaling, p = v_d i_d + v_q i_q); returns the new temperature [degC] and R_s there."""
    r_s = winding_resistance(R_s20, T, alpha_R, T_ref)
    T_new = thermal_step(T, r_s * (i_d * i_d + i_q * i_q), T_amb, R_th, C_th, dt)
    return T_new, winding_resistance(R_s20, T_new, alpha_R, T_ref)


@kernel()
def thermal_step(T, P, T_amb, R_th, C_th, dt):
    """Winding temperature after dt [degC] of the first-order model C_th dT/dt = P - (T - T_amb) / R_th
    with the losses P [W] held over the step (exact solution: T relaxes to T_amb + P R_th with the
    time constant R_th C_th)."""
    T_inf = T_amb + P * R_th
    return T_inf + (T - T_inf) * math.exp(-dt / (R_th * C_th))


# -- road load, eqs 2-4 and 29 ---------------------------------------------------------------
@kernel()
def gradient_force(delta, m_v, g):
    """f_g = m_v g sin(delta) [N] (eq 2)."""
    return m_v * g * math.sin(delta)


@kernel()
def rolling_force(v_v, delta, c_r, m_v, g, v_eps, paper):
    """f_f = c_r m_v g cos(delta) [N] (eq 3); not ``paper``: times tanh(v_v / v_eps)."""
    f = c_r * m_v * g * math.cos(delta)
    if paper:
        return f
    return f * math.tanh(v_v / v_eps)


@kernel()
def aero_force(v_v, rho_a, c_d, A_f, v_a, paper):
    """f_a = 0.5 rho_a c_d A_f (v_v + v_a)^2 [N] (eq 4); not ``paper``: (v+v_a)|v+v_a|."""
    v_rel = v_v + v_a
    k = 0.5 * rho_a * c_d * A_f
    if paper:
        return k * v_rel * v_rel
    return k * v_rel * abs(v_rel)


@kernel()
def load_torque(omega_m, delta, m_v, g, c_r, rho_a, c_d, A_f, r_w, eta, n_g, v_a, v_eps, paper):
    """T_L-mech = r_w / (eta n_g) (f_g + f_f + f_a) [N m] (eq 29): the road load on the shaft."""
    v_v = r_w * omega_m / n_g
    forces = (gradient_force(delta, m_v, g) + rolling_force(v_v, delta, c_r, m_v, g, v_eps, paper)
              + aero_force(v_v, rho_a, c_d, A_f, v_a, paper))
    return r_w / (eta * n_g) * forces


# -- the plant ---------------------------------------------------------------------------------
#: the most RK4 sub-steps ``substep_angle`` adds to a step [-]: 64 x 0.1 rad keeps the angle per sub-step
#: within 0.1 rad up to 16000 rad/s at 10 kHz (10x the top speed); beyond, a state running away
#: (a diverging simulation) is stepped no slower than that
MAX_SUBSTEPS = 64

@kernel()
def plant_load_torque(omega_m, delta, pp):
    """Eq 29 with the plant's parameter vector."""
    return load_torque(omega_m, delta, pp[P_M_V], pp[P_G], pp[P_C_R], pp[P_RHO_A], pp[P_C_D], pp[P_A_F],
                       pp[P_R_W], pp[P_ETA], pp[P_N_G], pp[P_V_A], pp[P_V_EPS], pp[P_PAPER] != 0.0)


@kernel()
def plant_derivatives(i_d, i_q, omega_m, theta_e, v_alpha, v_beta, delta, pp):
    """d/dt of (i_d, i_q, omega_m, theta_e) for a stationary-frame voltage: eqs 10-11 (or their flux form
    with saturation) at the true angle, eq 12, the friction (eq 8), the road load (eq 29), the motion
    (eq 9 = 28) and eq 13; the dead time's error added to the voltage first."""
    c = math.cos(theta_e)
    s = math.sin(theta_e)
    if pp[P_DT_V] != 0.0:  # the inverter's dead time: the applied voltage loses its error
        e_alpha, e_beta = dead_time_error(c * i_d - s * i_q, s * i_d + c * i_q, pp[P_DT_V], pp[P_DT_I0])
        v_alpha = v_alpha + e_alpha
        v_beta = v_beta + e_beta
    v_d = c * v_alpha + s * v_beta  # Park at the true angle
    v_q = -s * v_alpha + c * v_beta
    N = pp[P_N]
    if pp[P_SAT] != 0.0:  # saturated inductances
        did, diq = saturated_current_derivatives(i_d, i_q, omega_m, v_d, v_q, pp[P_R_S], pp[P_L_D], pp[P_L_Q],
                                                 pp[P_PSI], N, pp[P_SAT_AD], pp[P_SAT_AQ])
        t_e = pp[P_K_DQ] * saturated_torque(i_d, i_q, pp[P_PSI], pp[P_L_D], pp[P_L_Q], N, pp[P_SAT_AD],
                                            pp[P_SAT_AQ])
    else:
        did, diq = current_derivatives(i_d, i_q, omega_m, v_d, v_q,
                                       pp[P_R_S], pp[P_L_D], pp[P_L_Q], pp[P_PSI], N)  # (10), (11)
        t_e = pp[P_K_DQ] * electromagnetic_torque(i_d, i_q, pp[P_PSI], pp[P_L_D], pp[P_L_Q], N)  # (12) x k_dq
    t_l = plant_load_torque(omega_m, delta, pp)  # (29)
    t_f = friction_torque(omega_m, pp[P_B_M], pp[P_T_M0], pp[P_OMEGA_EPS], pp[P_PAPER] != 0.0)  # (8)
    dw = (t_e - t_f - t_l) / pp[P_J_EQ]  # (9) = (28)
    dth = N * omega_m  # (13)
    return did, diq, dw, dth


@kernel(_sig(f"UniTuple({_F}, 5)", _F, _F, _F, _F, _F, _V))
def plant_outputs(i_d, i_q, omega_m, theta_e, delta, pp):
    """(i_alpha, i_beta, T_e, T_L_mech, v_vehicle) of a plant state: inverse Park, eq 12, eq 29, eqs 1, 6."""
    i_alpha, i_beta = inverse_park(i_d, i_q, theta_e)
    if pp[P_SAT] != 0.0:
        t_e = pp[P_K_DQ] * saturated_torque(i_d, i_q, pp[P_PSI], pp[P_L_D], pp[P_L_Q], pp[P_N], pp[P_SAT_AD],
                                            pp[P_SAT_AQ])
    else:
        t_e = pp[P_K_DQ] * electromagnetic_torque(i_d, i_q, pp[P_PSI], pp[P_L_D], pp[P_L_Q], pp[P_N])  # (12) x k_dq
    t_l = plant_load_torque(omega_m, delta, pp)  # (29)
    v_v = pp[P_R_W] * omega_m / pp[P_N_G]  # (1), (6)
    return i_alpha, i_beta, t_e, t_l, v_v


@kernel(_sig(f"UniTuple({_F}, 10)", _F, _F, _F, _F, _F, _F, _F, _F, _V))
def plant_step(i_d, i_q, omega_m, theta_e, v_alpha, v_beta, delta, dt, pp):
    """Advance the state by dt with the voltage and elevation held (RK4, ``P_SUBSTEPS``
    sub-steps, more where the rotor turns more than ``P_SUBSTEP_ANGLE`` electrical radians in one of
    them at the speed the step starts with); return the new (i_d, i_q, omega_m, theta_e) and the outputs at the new
    state: (i_alpha, i_beta) (clean), T_e, T_L_mech at ``delta``, v_vehicle; and the
    distance the vehicle moved [m]: r_w / (n_g N) times the (unwrapped) RK4 angle step of
    eq 13, i.e. eqs 1, 6 integrated by the same RK4."""
    n = int(pp[P_SUBSTEPS])
    if pp[P_SUBSTEP_ANGLE] > 0.0:  # at most that angle per sub-step: accurate at top speed
        m = abs(pp[P_N] * omega_m) * dt / pp[P_SUBSTEP_ANGLE]
        if m > n:  # (False for NaN) no more than MAX_SUBSTEPS: a state running away must not hang the step
            n = int(math.ceil(m)) if m < MAX_SUBSTEPS else max(n, MAX_SUBSTEPS)
    h = dt / n
    x0, x1, x2, x3 = i_d, i_q, omega_m, theta_e
    for _ in range(n):
        a0, a1, a2, a3 = plant_derivatives(x0, x1, x2, x3, v_alpha, v_beta, delta, pp)
        b0, b1, b2, b3 = plant_derivatives(x0 + 0.5 * h * a0, x1 + 0.5 * h * a1, x2 + 0.5 * h * a2,
                                           x3 + 0.5 * h * a3, v_alpha, v_beta, delta, pp)
        c0, c1, c2, c3 = plant_derivatives(x0 + 0.5 * h * b0, x1 + 0.5 * h * b1, x2 + 0.5 * h * b2,
                                           x3 + 0.5 * h * b3, v_alpha, v_beta, delta, pp)
        d0, d1, d2, d3 = plant_derivatives(x0 + h * c0, x1 + h * c1, x2 + h * c2, x3 + h * c3,
                                           v_alpha, v_beta, delta, pp)
        x0 += h / 6.0 * (a0 + 2.0 * b0 + 2.0 * c0 + d0)
        x1 += h / 6.0 * (a1 + 2.0 * b1 + 2.0 * c1 + d1)
        x2 += h / 6.0 * (a2 + 2.0 * b2 + 2.0 * c2 + d2)
        x3 += h / 6.0 * (a3 + 2.0 * b3 + 2.0 * c3 + d3)
    dx = pp[P_R_W] / (pp[P_N_G] * pp[P_N]) * (x3 - theta_e)
    x3 = wrap_angle(x3)
    i_alpha, i_beta, t_e, t_l, v_v = plant_outputs(x0, x1, x2, x3, delta, pp)
    return x0, x1, x2, x3, i_alpha, i_beta, t_e, t_l, v_v, dx
