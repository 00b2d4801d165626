"""The plant's kernels: the PMSM (eqs 10-13), friction (eq 8), the road load (eqs 2-4, 29), the
vehicle's motion (eqs 1, 6, 9 = 28) and the RK4 step over them (``plant_step``), and the
departures of a real motor and inverter from eqs 10-12, each off by default: the inverter's
dead time (``dead_time_error``), magnetic saturation (flux-form eqs 10-12: per axis,
``saturated_*``, or the algebraic magnetic model with cross-saturation, ``flux_*``,
``incremental_inductances``) and the motor's temperatures (``winding_resistance``,
``thermal_network_step``: a lumped-parameter thermal network heated by the losses, R_s and psi
following it); the friction brake, the gear model ``power_flow`` (``power_flow_gear``), the
inverter's losses (``inverter_loss``) and the energy accounting (``plant_rates``' powers,
integrated by ``plant_step`` with the RK4 weights of the state; ``stored_energies``),
docs/speed-range.md; the current sensors (``gaussian_pair``, ``measured_currents``) and
the step with its measurement in one call (``plant_step_measured``).

The parameter vector ``pp`` is laid out by ``pmsm_ev.kernels.layout.PLANT_PARAMS_LAYOUT`` (``P_*``).
"""

from __future__ import annotations

import math

from .jit import F as _F
from .jit import V as _V
from .jit import kernel
from .jit import sig as _sig
from .layout import (
    BAT_OCV_MAX,
    E_AERO,
    E_BAT_CHEM,
    E_BAT_I,
    E_BAT_LOSS,
    E_BAT_P_CHG,
    E_BAT_P_DIS,
    E_BAT_Q,
    E_BAT_SOC,
    E_BAT_V,
    E_BAT_VRC,
    E_BAT_W,
    E_BRAKE,
    E_COPPER,
    E_DC,
    E_DC_ABS,
    E_FRICTION,
    E_GEAR,
    E_GRADE,
    E_INVERTER,
    E_IRON,
    E_P_DC,
    E_REGEN,
    E_ROLL,
    E_SHAFT,
    E_TH_IN,
    E_TH_OUT,
    E_TH_OVER,
    E_TH_T,
    P_A_F,
    P_ALPHA_PSI,
    P_ALPHA_R,
    P_B_M,
    P_BAT,
    P_BAT_C1,
    P_BAT_I_CHG,
    P_BAT_I_DIS,
    P_BAT_N,
    P_BAT_OCV,
    P_BAT_Q,
    P_BAT_R0,
    P_BAT_R1,
    P_BAT_SOC0,
    P_BAT_SOC_TAPER,
    P_BAT_TAU,
    P_BAT_V_MAX,
    P_BAT_V_MIN,
    P_C_D,
    P_C_R,
    P_DT_I0,
    P_DT_K,
    P_DT_V,
    P_ETA,
    P_FE_E,
    P_FE_H,
    P_FLUX,
    P_FLUX_C,
    P_FLUX_MEMO,
    P_G,
    P_GEAR_PF,
    P_INV,
    P_INV_DR,
    P_INV_DV,
    P_INV_K,
    P_INV_KSW,
    P_INV_R,
    P_INV_V,
    P_INV_V0,
    P_INV_VDC,
    P_J_EQ,
    P_J_M,
    P_K_DQ,
    P_K_W,
    P_L_D,
    P_L_Q,
    P_M_R,
    P_M_V,
    P_N,
    P_N_G,
    P_OMEGA_EPS,
    P_PAPER,
    P_PSI,
    P_PSI20,
    P_R_S,
    P_R_S20,
    P_R_W,
    P_RHO_A,
    P_SAT,
    P_SAT_AD,
    P_SAT_AQ,
    P_SUBSTEP_ANGLE,
    P_SUBSTEPS,
    P_T_BRAKE,
    P_T_M0,
    P_TH,
    P_TH_AMB,
    P_TH_G,
    P_TH_INV_C,
    P_TH_LIM_M,
    P_TH_LIM_W,
    P_TH_RES,
    P_TH_ROTOR,
    P_TH_YOKE,
    P_V_A,
    P_V_EPS,
    PIO_CLOCK,
    PIO_I_ALPHA,
    PIO_I_ALPHA_TRUE,
    PIO_I_BETA,
    PIO_I_BETA_TRUE,
    PIO_I_D,
    PIO_I_Q,
    PIO_OMEGA_M,
    PIO_PLANT_DELTA,
    PIO_PLANT_T_BRAKE,
    PIO_SAMPLES,
    PIO_SAVE,
    PIO_SEED,
    PIO_SENSOR_ARGS,
    PIO_SENSORS,
    PIO_T_E,
    PIO_T_L_MECH,
    PIO_THETA_E,
    PIO_V_ALPHA_APPLIED,
    PIO_V_BETA_APPLIED,
    PIO_V_VEHICLE,
    PIO_X_VEHICLE,
    PLANT_ENERGY,
    TH_G_MA,
    TH_G_TM,
    TH_G_TW,
    TH_G_WC,
    TH_G_WM,
    TH_G_YC,
    TH_G_YT,
    TH_G_YW,
    TH_M,
    TH_OVER_MAGNET,
    TH_OVER_WINDING,
    TH_T,
    TH_W,
    TH_Y,
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


@kernel()
def windage_torque(omega_m, k_w):
    """The rotor's windage, k_w omega_m |omega_m| [N m]: the air's drag on a turning cylinder and its end
    faces at a constant moment coefficient (turbulent flow), a power k_w |omega_m|^3
    (``MotorParams.k_wind``)."""
    return k_w * omega_m * abs(omega_m)


@kernel()
def plant_friction(omega_m, pp):
    """The motor's mechanical drag with the plant's vector [N m]: eq 8's friction (``friction_torque``)
    plus the windage (``windage_torque``) when ``P_K_W`` is not 0 (eq 8 alone otherwise, unchanged)."""
    t_f = friction_torque(omega_m, pp[P_B_M], pp[P_T_M0], pp[P_OMEGA_EPS], pp[P_PAPER] != 0.0)
    if pp[P_K_W] != 0.0:
        t_f = t_f + windage_torque(omega_m, pp[P_K_W])
    return t_f


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


# -- the motor's thermal network ----------------------------------------------------------------
@kernel()
def thermal_apply(pp, ee):
    """R_s and psi at the network's temperatures (``E_TH_T``): R_s = R_s20 (1 + alpha_R (T_w - 20)) (copper's
    linear law, IEC 60028's coefficient) and psi = psi20 (1 + alpha_psi (T_m - 20)) (the remanence's), into the
    slots eqs 10-12 read; with the algebraic magnetic model (``P_FLUX``) what the magnet sets there: its equivalent
    current i_f = (a_d0 + a_dd psi_T^S) psi_T, the flux at zero current psi_T and the energy's zero w0, as
    ``pmsm_ev.params.flux_model_coefficients`` puts them for a magnet at psi_T (the iron's curve, a_d0 .. V, is the
    20 degC one: a hot magnet has less MMF, not other iron)."""
    pp[P_R_S] = winding_resistance(pp[P_R_S20], ee[E_TH_T + TH_W], pp[P_ALPHA_R], 20.0)
    psi_t = pp[P_PSI20] * (1.0 + pp[P_ALPHA_PSI] * (ee[E_TH_T + TH_M] - 20.0))
    pp[P_PSI] = psi_t
    if pp[P_FLUX] != 0.0:
        o = P_FLUX_C
        pp[o + FX_IF] = (pp[o + FX_AD0] + pp[o + FX_ADD] * psi_t ** pp[o + FX_S]) * psi_t
        pp[o + FX_PSI0] = psi_t
        pp[o + FX_W0] = 0.0
        pp[o + FX_W0] = flux_energy(psi_t, 0.0, pp, o)
        pp[P_FLUX_MEMO] = 0.0  # psi(i) of the cooler magnet no longer holds (``plant_flux_linkages``)


@kernel()
def thermal_network_step(q_cu, q_res, dt, pp, ee):
    """The motor's lumped-parameter thermal network over a step of ``dt`` [s] that put the copper losses ``q_cu``
    and the residual losses ``q_res`` (iron and friction) [J] in (the step's RK4 integrals, ``E_COPPER``,
    ``E_IRON`` + ``E_FRICTION``): Wallscheid and Boecker's four nodes (IEEE Trans. Energy Convers. 31(1), 2016),
    stator yoke Y, stator tooth T, winding W, magnet M, C_i dT_i/dt = P_i - sum_j G_ij (T_i - T_j) - G_i0 (T_i -
    T_0), T_0 the coolant's temperature (``P_TH_AMB``), the copper losses into W, the residual ones split: the
    rotor's share (``P_TH_ROTOR``) into M, the stator's into Y (``P_TH_YOKE``) and T. One explicit Euler step with
    the temperatures at the step's start: the network's time constants are tens of seconds and more (16 s .. 65 min
    with Wallscheid's figures), so over 1e-4 s Euler's error is ~ dt / tau ~ 1e-5 of a step's change, and its
    update conserves heat exactly, the flows between nodes cancelling (heat in = stored + to the coolant, to
    round-off). Then ``thermal_apply`` (R_s, psi for the next step) and the over-temperature flags ``E_TH_OVER``."""
    o = E_TH_T
    t_y = ee[o + TH_Y]
    t_t = ee[o + TH_T]
    t_w = ee[o + TH_W]
    t_m = ee[o + TH_M]
    t_0 = pp[P_TH_AMB]
    g = P_TH_G
    f_yc = pp[g + TH_G_YC] * (t_y - t_0)  # the flows [W], from the first node to the second
    f_yw = pp[g + TH_G_YW] * (t_y - t_w)
    f_yt = pp[g + TH_G_YT] * (t_y - t_t)
    f_tw = pp[g + TH_G_TW] * (t_t - t_w)
    f_tm = pp[g + TH_G_TM] * (t_t - t_m)
    f_wm = pp[g + TH_G_WM] * (t_w - t_m)
    f_ma = pp[g + TH_G_MA] * (t_m - t_0)
    f_wc = pp[g + TH_G_WC] * (t_w - t_0)
    q = pp[P_TH_RES] * q_res
    q_rotor = pp[P_TH_ROTOR] * q
    q_stator = q - q_rotor
    q_yoke = pp[P_TH_YOKE] * q_stator
    c = P_TH_INV_C
    ee[o + TH_Y] = t_y + pp[c + TH_Y] * (q_yoke - dt * (f_yc + f_yw + f_yt))
    ee[o + TH_T] = t_t + pp[c + TH_T] * ((q_stator - q_yoke) + dt * (f_yt - f_tw - f_tm))
    ee[o + TH_W] = t_w + pp[c + TH_W] * (q_cu + dt * (f_yw + f_tw - f_wm - f_wc))
    ee[o + TH_M] = t_m + pp[c + TH_M] * (q_rotor + dt * (f_tm + f_wm - f_ma))
    ee[E_TH_IN] += q_cu + q
    ee[E_TH_OUT] += dt * (f_yc + f_ma + f_wc)
    thermal_apply(pp, ee)
    over = 0.0
    if ee[o + TH_W] >= pp[P_TH_LIM_W]:
        over += TH_OVER_WINDING
    if ee[o + TH_M] >= pp[P_TH_LIM_M]:
        over += TH_OVER_MAGNET
    ee[E_TH_OVER] = over


@kernel()
def inverter_loss(i_alpha, i_beta, v_loss, r_on):
    """Conduction and switching losses of a two-level three-phase inverter [W] for the current vector
    (i_alpha, i_beta) (amplitude-invariant Clarke: the phase currents are i_a = i_alpha, i_b, i_c):
    each phase x loses v_loss |i_x| + r_on i_x^2, the part of the losses that does not depend on the
    modulation (``inverter_modulation_loss`` adds the part that does). Conduction: the threshold-and-slope
    model of the data sheets, V_CE = V_CE0 + r_CE i (IGBT), V_F = V_F0 + r_F i (diode); a phase current
    flows through the IGBT for the duty d and the opposite diode for 1 - d (i > 0: upper IGBT, lower diode;
    i < 0: lower IGBT for 1 - d, upper diode for d), so that v_loss holds (V_CE0 + V_F0) / 2 and r_on
    (r_CE + r_F) / 2. Switching: E_sw (v_dc / V_ref) (|i_x| / I_ref) per switching period, linear in
    current and voltage (Graovac and Puerschel, "IGBT Power Losses Calculation Using the Data-Sheet
    Parameters", Infineon application note, 2009; the SEMIKRON application manual, ch. 3.10), a voltage
    f_sw E_sw v_dc / (V_ref I_ref) per ampere: ``v_loss`` holds it too."""
    i_b = -0.5 * i_alpha + _SQRT3_2 * i_beta
    i_c = -0.5 * i_alpha - _SQRT3_2 * i_beta
    return (v_loss * (abs(i_alpha) + abs(i_b) + abs(i_c))
            + r_on * (i_alpha * i_alpha + i_b * i_b + i_c * i_c))


@kernel()
def inverter_modulation_loss(i_alpha, i_beta, v_alpha, v_beta, dv, dr, inv_vdc):
    """The conduction losses' part that depends on the modulation [W]: where the IGBT's knee and slope differ
    from the diode's (dv = V_CE0 - V_F0, dr = r_CE - r_F), a phase x loses (d_x - 1/2) (dv i_x + dr i_x |i_x|)
    besides ``inverter_loss``'s mean (the IGBT conducts for the duty d_x when i_x > 0, for 1 - d_x when
    i_x < 0). The duty is the pole voltage's, d_x = 1/2 + (v_x + v_0) inv_vdc, with the space-vector
    modulation's common mode v_0 = -(max + min) / 2 of the phase voltages (the linear range up to
    v_dc / sqrt 3 that the plant's limit allows), clipped to [0, 1]. Averaged over a sinusoidal period it
    gives the textbook forms (the IGBT's V_CE0 I (1/(2 pi) + M cos(phi) / 8), the diode's V_F0 I (1/(2 pi)
    - M cos(phi) / 8) for the knees, M = 2 |v| / v_dc; the forms of Graovac and Puerschel's application note,
    2009, checked against this kernel in tests/test_losses_sourced.py)."""
    v_b = -0.5 * v_alpha + _SQRT3_2 * v_beta
    v_c = -0.5 * v_alpha - _SQRT3_2 * v_beta
    v_0 = -0.5 * (max(v_alpha, v_b, v_c) + min(v_alpha, v_b, v_c))
    i_b = -0.5 * i_alpha + _SQRT3_2 * i_beta
    i_c = -0.5 * i_alpha - _SQRT3_2 * i_beta
    p = 0.0
    for v_x, i_x in ((v_alpha, i_alpha), (v_b, i_b), (v_c, i_c)):
        m = min(max((v_x + v_0) * inv_vdc, -0.5), 0.5)
        p += m * (dv * i_x + dr * i_x * abs(i_x))
    return p


@kernel()
def iron_torque(omega_m, psi_d, psi_q, N, c_h, c_e, omega_eps):
    """The iron losses as a drag on the shaft [N m]: P_fe = (c_h |omega_e| + c_e omega_e^2) psi_s^2
    (Steinmetz's separation into hysteresis, ~ f B^2, and eddy-current losses, ~ f^2 B^2, with the
    stator's flux linkage psi_s^2 = psi_d^2 + psi_q^2 standing for B^2: field weakening lowers
    them), taken from the shaft, T_fe = P_fe / omega_m = N psi_s^2 (c_h tanh(omega_m / omega_eps) +
    c_e N omega_m); the soft sign of the friction's (eq 8) at standstill."""
    psi2 = psi_d * psi_d + psi_q * psi_q
    return N * psi2 * (c_h * math.tanh(omega_m / omega_eps) + c_e * N * omega_m)


@kernel()
def field_energy(i, L0, a):
    """The field energy [J] of one axis, W = integral of i dpsi = i psi(i) - W'(i), stored by the
    current i on the Froehlich-Kennelly curve psi(i) = L0 i / (1 + a |i|) (``saturated_flux``): the
    co-energy W' = L0 / a^2 (a |i| - ln(1 + a |i|)); a = 0: L0 i^2 / 2 (in the model's power
    scaling; times k_dq in the dq convention's)."""
    if a == 0.0:
        return 0.5 * L0 * i * i
    u = a * abs(i)
    return L0 * i * i / (1.0 + u) - L0 / (a * a) * (u - math.log1p(u))


# -- the algebraic magnetic model (``PlantParams.flux_model`` 'algebraic') -----------------------
#: the offsets of the algebraic model's coefficients from the start of their slot (``P_FLUX_C`` in the
#: plant's vector; the kernels take the vector and that start, ``c, o``): the inverse-inductance
#: coefficients a_d0, a_dd [1/H], the exponent S [-] (d axis), a_q0, a_qq, T (q axis), a_dq, U, V
#: (cross-saturation), the magnet's equivalent current i_f [A], the flux linkage at zero current psi0
#: [Wb] (Newton's start) and the field energy there w0 [J] (the zero of ``flux_energy``); the units of
#: a_dd, a_qq and a_dq are 1/H over the powers of Wb of their terms. ``pmsm_ev.params.flux_model_coefficients``
#: derives them from the parameters.
FX_AD0, FX_ADD, FX_S, FX_AQ0, FX_AQQ, FX_T, FX_ADQ, FX_U, FX_V, FX_IF, FX_PSI0, FX_W0 = range(12)
#: Newton's iterations at most for psi(i) (``flux_linkages``): from the linear guess it takes 3-6 to
#: round-off over the drive's currents; the bound keeps a step finite whatever the state
FLUX_NEWTON_MAX = 30


#: the largest whole exponent ``flux_pow`` takes by multiplication [-]: the model's exponents are small whole
#: numbers (S = 4, T = 6, U = V = 1 by default; the energy's S + 2 .. V + 2), at most 5 multiplications up to
#: 16 by squaring, each rounded once: within a few ulp of the library's pow, at a fraction of its cost
FLUX_POW_INT_MAX = 16.0


@kernel()
def flux_pow(x, e):
    """x ** e for x >= 0, the powers of the algebraic model's terms: x itself where e = 1, a whole e up to
    ``FLUX_POW_INT_MAX`` by repeated squaring (the model's exponents are whole numbers: a pow was most of
    its arithmetic), the library's pow otherwise."""
    if e == 1.0:
        return x
    if 0.0 <= e <= FLUX_POW_INT_MAX and e == math.floor(e):
        n = int(e)
        if n <= 8:  # the squaring's products below written out (the same products: the same bits), no loop
            x2 = x * x
            if n == 2:
                return x2
            if n == 3:
                return x * x2
            x4 = x2 * x2
            if n == 4:
                return x4
            if n == 5:
                return x * x4
            if n == 6:
                return x2 * x4
            if n == 7:
                return (x * x2) * x4
            if n == 8:
                return x4 * x4
            return 1.0  # n = 0
        r = 1.0
        b = x
        while n > 0:
            if n & 1:
                r *= b
            b *= b
            n >>= 1
        return r
    return x ** e


@kernel()
def flux_model(psi_d, psi_q, c, o):
    """The algebraic magnetic model at the flux linkages (psi_d, psi_q) [Wb]: its currents (i_d, i_q) [A]
    (``flux_currents``) and their Jacobian (g_dd, g_dq, g_qq) [1/H] (``flux_jacobian``) from one evaluation
    of the terms' powers, which both share: the model of Hinkkanen, Pescetto, Moelsae, Saarakkala, Pellegrino
    and Bojoi ("Sensorless self-commissioning of synchronous reluctance motors at standstill without rotor
    locking", IEEE Trans. Ind. Appl. 53(3), 2017), the magnet as a constant current i_f on the d axis in
    series with the stator's (Awan, Song, Saarakkala and Hinkkanen, "Optimal torque control of saturated
    synchronous motors: plug-and-play method", IEEE Trans. Ind. Appl. 54(6), 2018):
    i_d = (a_d0 + a_dd |psi_d|^S + a_dq / (V + 2) |psi_d|^U |psi_q|^(V + 2)) psi_d - i_f,
    i_q = (a_q0 + a_qq |psi_q|^T + a_dq / (U + 2) |psi_d|^(U + 2) |psi_q|^V) psi_q,
    the gradient of the energy ``flux_energy`` (so reciprocal: di_d/dpsi_q = di_q/dpsi_d), and in closed
    form g_dd = di_d/dpsi_d, g_dq = di_d/dpsi_q = di_q/dpsi_d, g_qq = di_q/dpsi_q; the coefficients from
    ``c[o + FX_*]``."""
    ad = abs(psi_d)
    aq = abs(psi_q)
    a_dq = c[o + FX_ADQ]
    s = c[o + FX_S]
    t = c[o + FX_T]
    u = c[o + FX_U]
    v = c[o + FX_V]
    ds = flux_pow(ad, s)
    qt = flux_pow(aq, t)
    du = flux_pow(ad, u)
    qv = flux_pow(aq, v)
    g_d = c[o + FX_AD0] + c[o + FX_ADD] * ds + a_dq / (v + 2.0) * du * qv * aq * aq
    g_q = c[o + FX_AQ0] + c[o + FX_AQQ] * qt + a_dq / (u + 2.0) * du * ad * ad * qv
    g_dd = (c[o + FX_AD0] + (s + 1.0) * c[o + FX_ADD] * ds
            + a_dq * (u + 1.0) / (v + 2.0) * du * qv * aq * aq)
    g_qq = (c[o + FX_AQ0] + (t + 1.0) * c[o + FX_AQQ] * qt
            + a_dq * (v + 1.0) / (u + 2.0) * du * ad * ad * qv)
    g_dq = a_dq * du * psi_d * qv * psi_q
    return g_d * psi_d - c[o + FX_IF], g_q * psi_q, g_dd, g_dq, g_qq


@kernel()
def flux_currents(psi_d, psi_q, c, o):
    """The currents (i_d, i_q) [A] of the flux linkages (psi_d, psi_q) [Wb] in the algebraic magnetic
    model (``flux_model``, whose first two results they are)."""
    r = flux_model(psi_d, psi_q, c, o)
    return r[0], r[1]


@kernel()
def flux_jacobian(psi_d, psi_q, c, o):
    """The Jacobian of ``flux_currents``, the incremental inverse inductances [1/H]:
    (di_d/dpsi_d, di_d/dpsi_q = di_q/dpsi_d, di_q/dpsi_q), in closed form (``flux_model``'s last three)."""
    r = flux_model(psi_d, psi_q, c, o)
    return r[2], r[3], r[4]


@kernel()
def flux_linkages(i_d, i_q, c, o):
    """(psi_d, psi_q) [Wb] of the currents (i_d, i_q) [A] in the algebraic model (``flux_currents``):
    Newton on the 2x2 system from the linear guess psi0 + L_d0 i_d, L_q0 i_q (the incremental
    inductances at zero current), each step shortened while it does not lower the residual (the
    model's energy is convex: the residual has one zero), until the step is below 1e-14 of the flux
    (then the flux is exact to round-off), ``FLUX_NEWTON_MAX`` iterations at most. Each point is
    evaluated once (``flux_model``: the currents and the Jacobian together); the Jacobian of the point a
    step lands on is the next step's."""
    psi0 = c[o + FX_PSI0]
    _, _, g_dd, _, g_qq = flux_model(psi0, 0.0, c, o)
    psi_d = psi0 + i_d / g_dd
    psi_q = i_q / g_qq
    f_d, f_q, j_dd, j_dq, j_qq = flux_model(psi_d, psi_q, c, o)
    r_d = f_d - i_d
    r_q = f_q - i_q
    res = abs(r_d) + abs(r_q)
    for _ in range(FLUX_NEWTON_MAX):
        g_dd, g_dq, g_qq = j_dd, j_dq, j_qq  # at (psi_d, psi_q)
        det = g_dd * g_qq - g_dq * g_dq
        s_d = (g_qq * r_d - g_dq * r_q) / det
        s_q = (g_dd * r_q - g_dq * r_d) / det
        h = 1.0
        n_d = psi_d - s_d
        n_q = psi_q - s_q
        landed = False  # the last point evaluated is the one the step lands on
        for _ in range(8):
            f_d, f_q, j_dd, j_dq, j_qq = flux_model(n_d, n_q, c, o)
            new = abs(f_d - i_d) + abs(f_q - i_q)
            if new <= res or res < 1e-9:
                landed = True
                break
            h = 0.5 * h
            n_d = psi_d - h * s_d
            n_q = psi_q - h * s_q
        psi_d = n_d
        psi_q = n_q
        r_d = f_d - i_d  # (after eight halvings: the residual of the last point evaluated, as it was)
        r_q = f_q - i_q
        res = abs(r_d) + abs(r_q)
        if h * (abs(s_d) + abs(s_q)) <= 1e-14 * (abs(psi_d) + abs(psi_q) + psi0):
            break
        if not landed:  # the Jacobian where the step landed
            _, _, j_dd, j_dq, j_qq = flux_model(psi_d, psi_q, c, o)
    return psi_d, psi_q


@kernel()
def plant_flux_linkages(i_d, i_q, pp):
    """``flux_linkages`` of the plant's algebraic model (``P_FLUX_C``) with a memo of one entry in ``P_FLUX_MEMO``:
    the currents a step ends with are those the outputs' torque, the shaft's iron losses and the next step's
    start need, so the same Newton solve is asked for three times; the memo answers the repeats with the very
    result (the key compares the currents and their signs, so -0.0 and 0.0 are told apart). A vector whose
    coefficients change must clear the memo (``P_FLUX_MEMO`` = 0)."""
    m = P_FLUX_MEMO
    if (pp[m] != 0.0 and pp[m + 1] == i_d and pp[m + 2] == i_q
            and math.copysign(1.0, pp[m + 1]) == math.copysign(1.0, i_d)
            and math.copysign(1.0, pp[m + 2]) == math.copysign(1.0, i_q)):
        return pp[m + 3], pp[m + 4]
    psi_d, psi_q = flux_linkages(i_d, i_q, pp, P_FLUX_C)
    pp[m] = 1.0
    pp[m + 1] = i_d
    pp[m + 2] = i_q
    pp[m + 3] = psi_d
    pp[m + 4] = psi_q
    return psi_d, psi_q


@kernel()
def incremental_inductances(i_d, i_q, c, o):
    """The incremental inductance matrix (L_dd, L_dq, L_qq) [H] at the currents (i_d, i_q) [A] of the
    algebraic model: d psi / d i, the inverse of ``flux_jacobian`` at ``flux_linkages``' fluxes
    (symmetric: L_dq = L_qd). What a high-frequency voltage sees: a small current ripple di answers
    dpsi = L di."""
    psi_d, psi_q = flux_linkages(i_d, i_q, c, o)
    g_dd, g_dq, g_qq = flux_jacobian(psi_d, psi_q, c, o)
    det = g_dd * g_qq - g_dq * g_dq
    return g_qq / det, -g_dq / det, g_dd / det


@kernel()
def flux_energy(psi_d, psi_q, c, o):
    """The field energy [J] the stator's current stores at (psi_d, psi_q), zero at zero current: the
    model's energy W(psi) = a_d0 psi_d^2 / 2 + a_dd |psi_d|^(S+2) / (S+2) + a_q0 psi_q^2 / 2 +
    a_qq |psi_q|^(T+2) / (T+2) + a_dq |psi_d|^(U+2) |psi_q|^(V+2) / ((U+2)(V+2)), whose gradient is
    ``flux_currents`` plus i_f, less i_f psi_d (the magnet's constant current does no work on the
    stator) and less w0: its rate is i_d dpsi_d/dt + i_q dpsi_q/dt, what the winding's power puts in
    besides the copper losses and the shaft's work (in the model's power scaling; times k_dq in the
    dq convention's)."""
    ad = abs(psi_d)
    aq = abs(psi_q)
    s = c[o + FX_S]
    t = c[o + FX_T]
    u = c[o + FX_U]
    v = c[o + FX_V]
    w = (0.5 * c[o + FX_AD0] * psi_d * psi_d + c[o + FX_ADD] * flux_pow(ad, s + 2.0) / (s + 2.0)
         + 0.5 * c[o + FX_AQ0] * psi_q * psi_q + c[o + FX_AQQ] * flux_pow(aq, t + 2.0) / (t + 2.0)
         + c[o + FX_ADQ] * flux_pow(ad, u + 2.0) * flux_pow(aq, v + 2.0) / ((u + 2.0) * (v + 2.0)))
    return w - c[o + FX_IF] * psi_d - c[o + FX_W0]


@kernel()
def flux_torque(i_d, i_q, psi_d, psi_q, N):
    """T_e = N (psi_d i_q - psi_q i_d) [N m]: eq 12 in its flux form (times k_dq in the dq
    convention's scaling); with a reciprocal model it is the co-energy's derivative in the angle."""
    return N * (psi_d * i_q - psi_q * i_d)


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


# -- the gear --------------------------------------------------------------------------------
@kernel()
def power_flow_gear(x, y, j_m, m_r, eta, omega_m):
    """The gear with its efficiency in the direction the power flows (``VehicleParams.gear_model``
    'power_flow'): the rotor J_m driven by x = T_e - T_f, the vehicle m_r = m_v r_w^2 / n_g^2 at the
    shaft loaded by y = r_w F / n_g (F: the wheel forces, without eta), the gear's input torque
    T_gear: J_m domega/dt = x - T_gear, m_r domega/dt = e T_gear - y, e = eta while the power flows
    to the wheels (omega T_gear > 0) and 1/eta while it flows back. Hence
    domega/dt = (x - y/e) / (J_m + m_r/e), T_gear = (x m_r + J_m y) / (e J_m + m_r), whose sign does
    not depend on e: the direction is sign(omega (x m_r + J_m y)), and domega/dt is continuous
    (= -y/m_r) where T_gear = 0. Returns (domega/dt [rad/s^2], T_gear [N m], e [-]); the gear loses
    omega T_gear (1 - e) >= 0."""
    num = x * m_r + j_m * y
    e = eta if omega_m * num >= 0.0 else 1.0 / eta
    return (x - y / e) / (j_m + m_r / e), num / (e * j_m + m_r), e


# -- the plant ---------------------------------------------------------------------------------
#: the most RK4 sub-steps ``substep_angle`` adds to a step [-]: 64 x 0.1 rad keeps the angle per sub-step
#: within 0.1 rad up to 16000 rad/s at 10 kHz (10x the top speed); beyond, a state running away
#: (a diverging simulation) is stepped no slower than that
MAX_SUBSTEPS = 64
#: the largest electrical angle one sub-step of the stationary frame's RK6 turns [rad] (``stationary_frame``,
#: ``rk6_substep``): the held voltage is constant there, what turns within a step is the current's ripple about the
#: straight line the flux moves on (the zero-order hold at speed), which the RK6 resolves to ~1e-6 of the step's
#: energy at 0.62 rad (131 km/h at 1e-4 s; its error falls as the angle's 7th power: 1e-9 at 0.24 rad, 50 km/h).
#: 0.7 rad keeps one sub-step, seven stages, to 148 km/h at 10 kHz: a cost that does not grow with the speed over
#: the drive cycles' range
STATIONARY_SUBSTEP_ANGLE = 0.7

@kernel()
def plant_load_torque(omega_m, delta, pp):
    """Eq 29 with the plant's parameter vector."""
    return load_torque(omega_m, delta, pp[P_M_V], pp[P_G], pp[P_C_R], pp[P_RHO_A], pp[P_C_D], pp[P_A_F],
                       pp[P_R_W], pp[P_ETA], pp[P_N_G], pp[P_V_A], pp[P_V_EPS], pp[P_PAPER] != 0.0)


@kernel()
def brake_torque(omega_m, pp):
    """The friction brake at the shaft without the gear's eta, T_brake tanh(v / v_eps) / n_g [N m]: the
    brake torque at the wheels (``P_T_BRAKE`` >= 0) opposing the motion with the smooth sign of the
    rolling resistance of load_model 'physical', reflected by the gear ratio (eq 7 without eta)."""
    v_v = pp[P_R_W] * omega_m / pp[P_N_G]
    return pp[P_T_BRAKE] * math.tanh(v_v / pp[P_V_EPS]) / pp[P_N_G]


@kernel()
def shaft_load(i_d, i_q, omega_m, delta, t_e, pp):
    """T_L_mech, the load the vehicle puts on the shaft [N m]: eq 29 (r_w / (eta n_g) times the road
    forces) plus the brake over eta (the paper's gear); with the power_flow gear, the road forces and
    the brake at the shaft, r_w F / n_g, over e of the direction the power flows (``power_flow_gear``,
    which needs T_e and the shaft's drag, hence the currents of the iron losses)."""
    if pp[P_GEAR_PF] == 0.0:
        t_l = plant_load_torque(omega_m, delta, pp)  # (29)
        if pp[P_T_BRAKE] != 0.0:
            t_l = t_l + brake_torque(omega_m, pp) / pp[P_ETA]
        return t_l
    v_v = pp[P_R_W] * omega_m / pp[P_N_G]
    paper = pp[P_PAPER] != 0.0
    # the soft signs, each evaluated once: tanh(v / v_eps) of the rolling resistance and the brake (``rolling_force``,
    # ``brake_torque``), tanh(omega_m / omega_eps) of the friction and the iron losses (``friction_torque``,
    # ``iron_torque``)
    th_v = math.tanh(v_v / pp[P_V_EPS])
    f_f = pp[P_C_R] * pp[P_M_V] * pp[P_G] * math.cos(delta)
    if not paper:
        f_f = f_f * th_v
    forces = (gradient_force(delta, pp[P_M_V], pp[P_G]) + f_f
              + aero_force(v_v, pp[P_RHO_A], pp[P_C_D], pp[P_A_F], pp[P_V_A], paper))
    y = pp[P_R_W] / pp[P_N_G] * forces + pp[P_T_BRAKE] * th_v / pp[P_N_G]
    iron = pp[P_FE_H] != 0.0 or pp[P_FE_E] != 0.0
    th_w = math.tanh(omega_m / pp[P_OMEGA_EPS]) if iron or not paper else 0.0
    t_f = pp[P_B_M] * omega_m + (pp[P_T_M0] if paper else pp[P_T_M0] * th_w)
    if pp[P_K_W] != 0.0:
        t_f = t_f + windage_torque(omega_m, pp[P_K_W])
    x = t_e - t_f
    if iron:
        if pp[P_FLUX] != 0.0:  # the algebraic model's flux linkages
            f_d, f_q = plant_flux_linkages(i_d, i_q, pp)
        else:
            f_d, _ = saturated_flux(i_d, pp[P_L_D], pp[P_SAT_AD])
            f_d = pp[P_PSI] + f_d
            f_q, _ = saturated_flux(i_q, pp[P_L_Q], pp[P_SAT_AQ])
        x = x - pp[P_N] * (f_d * f_d + f_q * f_q) * (pp[P_FE_H] * th_w + pp[P_FE_E] * pp[P_N] * omega_m)
    _, _, e = power_flow_gear(x, y, pp[P_J_M], pp[P_M_R], pp[P_ETA], omega_m)
    return y / e


#: Butcher's seven-stage Runge-Kutta method of order 6 (J. C. Butcher, "On Runge-Kutta processes of high order",
#: J. Austral. Math. Soc. 4(2), 1964; Butcher, "Numerical Methods for Ordinary Differential Equations", 3rd ed.,
#: Wiley 2016, section 325): its nodes c_2 .. c_7 and weights b_1 .. b_7 (b_2 = 0); its coefficients a_ij are
#: written out in ``rk6_substep``
RK6_C = (1.0 / 3.0, 2.0 / 3.0, 1.0 / 3.0, 0.5, 0.5, 1.0)
RK6_B = (11.0 / 120.0, 0.0, 27.0 / 40.0, 27.0 / 40.0, -4.0 / 15.0, -4.0 / 15.0, 11.0 / 120.0)


@kernel()
def stage_energies(acc, r, b):
    """``acc`` plus ``b`` times a stage's powers (``frame_rates``' 5th .. 15th results): the 13 integrands the step
    accumulates, (p_dc, |p_dc|, max(-p_dc, 0), p_cu, p_fric, p_shaft, p_gear, p_aero, p_roll, p_grade, p_brake,
    p_inv, p_iron)."""
    return (acc[0] + b * r[4], acc[1] + b * abs(r[4]), acc[2] + b * _regen(r[4]), acc[3] + b * r[5],
            acc[4] + b * r[6], acc[5] + b * r[7], acc[6] + b * r[8], acc[7] + b * r[9], acc[8] + b * r[10],
            acc[9] + b * r[11], acc[10] + b * r[12], acc[11] + b * r[13], acc[12] + b * r[14])


@kernel()
def rk6_substep(x0, x1, x2, x3, h, v_alpha, v_beta, f_g, f_r, pp, acc, c1, s1):
    """One sub-step h [s] of Butcher's RK6 (``RK6_B``) in the stationary frame (``frame_rates``): the new
    (psi_alpha, psi_beta, omega_m, theta_e) and ``acc`` plus h times the RK6 quadrature of the step's powers
    (``stage_energies``): the energies integrated with the weights of the state, as RK4's are. ``f_g``, ``f_r``: the
    road's parts the step holds (``road_constants``); ``c1``, ``s1``: cos and sin of x3, the first stage's angle."""
    r1 = frame_rates_at(x0, x1, x2, c1, s1, v_alpha, v_beta, f_g, f_r, pp, True)
    h3 = h / 3.0
    r2 = _stage(x0 + h3 * r1[0], x1 + h3 * r1[1], x2 + h3 * r1[2], x3 + h3 * r1[3],
                     v_alpha, v_beta, f_g, f_r, pp)
    g = 2.0 * h / 3.0
    r3 = _stage(x0 + g * r2[0], x1 + g * r2[1], x2 + g * r2[2], x3 + g * r2[3], v_alpha, v_beta, f_g, f_r, pp)
    a1, a2, a3 = h / 12.0, h / 3.0, -h / 12.0
    r4 = _stage(x0 + a1 * r1[0] + a2 * r2[0] + a3 * r3[0], x1 + a1 * r1[1] + a2 * r2[1] + a3 * r3[1],
                     x2 + a1 * r1[2] + a2 * r2[2] + a3 * r3[2], x3 + a1 * r1[3] + a2 * r2[3] + a3 * r3[3],
                     v_alpha, v_beta, f_g, f_r, pp)
    a1, a2, a3, a4 = -h / 16.0, 9.0 * h / 8.0, -3.0 * h / 16.0, -3.0 * h / 8.0
    r5 = _stage(x0 + a1 * r1[0] + a2 * r2[0] + a3 * r3[0] + a4 * r4[0],
                     x1 + a1 * r1[1] + a2 * r2[1] + a3 * r3[1] + a4 * r4[1],
                     x2 + a1 * r1[2] + a2 * r2[2] + a3 * r3[2] + a4 * r4[2],
                     x3 + a1 * r1[3] + a2 * r2[3] + a3 * r3[3] + a4 * r4[3], v_alpha, v_beta, f_g, f_r, pp)
    a2, a3, a4, a5 = 9.0 * h / 8.0, -3.0 * h / 8.0, -3.0 * h / 4.0, h / 2.0
    r6 = _stage(x0 + a2 * r2[0] + a3 * r3[0] + a4 * r4[0] + a5 * r5[0],
                     x1 + a2 * r2[1] + a3 * r3[1] + a4 * r4[1] + a5 * r5[1],
                     x2 + a2 * r2[2] + a3 * r3[2] + a4 * r4[2] + a5 * r5[2],
                     x3 + a2 * r2[3] + a3 * r3[3] + a4 * r4[3] + a5 * r5[3], v_alpha, v_beta, f_g, f_r, pp)
    a1, a2, a3, a4, a6 = 9.0 * h / 44.0, -9.0 * h / 11.0, 63.0 * h / 44.0, 18.0 * h / 11.0, -16.0 * h / 11.0
    r7 = _stage(x0 + a1 * r1[0] + a2 * r2[0] + a3 * r3[0] + a4 * r4[0] + a6 * r6[0],
                     x1 + a1 * r1[1] + a2 * r2[1] + a3 * r3[1] + a4 * r4[1] + a6 * r6[1],
                     x2 + a1 * r1[2] + a2 * r2[2] + a3 * r3[2] + a4 * r4[2] + a6 * r6[2],
                     x3 + a1 * r1[3] + a2 * r2[3] + a3 * r3[3] + a4 * r4[3] + a6 * r6[3],
                     v_alpha, v_beta, f_g, f_r, pp)
    b1, b3, b5 = h * RK6_B[0], h * RK6_B[2], h * RK6_B[4]  # b_7 = b_1, b_4 = b_3, b_6 = b_5, b_2 = 0
    acc = stage_energies(acc, r1, b1)
    acc = stage_energies(acc, r3, b3)
    acc = stage_energies(acc, r4, b3)
    acc = stage_energies(acc, r5, b5)
    acc = stage_energies(acc, r6, b5)
    acc = stage_energies(acc, r7, b1)
    return (x0 + b1 * (r1[0] + r7[0]) + b3 * (r3[0] + r4[0]) + b5 * (r5[0] + r6[0]),
            x1 + b1 * (r1[1] + r7[1]) + b3 * (r3[1] + r4[1]) + b5 * (r5[1] + r6[1]),
            x2 + b1 * (r1[2] + r7[2]) + b3 * (r3[2] + r4[2]) + b5 * (r5[2] + r6[2]),
            x3 + b1 * (r1[3] + r7[3]) + b3 * (r3[3] + r4[3]) + b5 * (r5[3] + r6[3]), acc)


@kernel()
def _rk4_stage(x0, x1, x2, x3, v_alpha, v_beta, f_g, f_r, pp, stationary):
    """A stage of ``plant_step``'s RK4: ``frame_rates_at`` at the angle x3."""
    return frame_rates_at(x0, x1, x2, math.cos(x3), math.sin(x3), v_alpha, v_beta, f_g, f_r, pp, stationary)


@kernel()
def _stage(x0, x1, x2, x3, v_alpha, v_beta, f_g, f_r, pp):
    """A stage of ``rk6_substep``: ``frame_rates_at`` in the stationary frame at the angle x3."""
    return frame_rates_at(x0, x1, x2, math.cos(x3), math.sin(x3), v_alpha, v_beta, f_g, f_r, pp, True)


@kernel()
def stationary_frame(pp):
    """True where the plant integrates in the stationary frame (``PlantParams.integrator`` 'rk6_stationary'): its
    vector holds the bound on a sub-step's angle negated (``P_SUBSTEP_ANGLE`` < 0, ``STATIONARY_SUBSTEP_ANGLE``)."""
    return pp[P_SUBSTEP_ANGLE] < 0.0


@kernel()
def plant_fluxes(i_d, i_q, pp):
    """The flux linkages (psi_d, psi_q) [Wb] of the currents (i_d, i_q) [A] in the plant's magnetic model: the
    algebraic model's (``plant_flux_linkages``: its memo holds the fluxes the last step ended with, so no Newton
    solve per step), the per-axis saturation's psi + psi_dd(i_d), psi_qq(i_q) (``saturated_flux``) or eqs 10-11's
    psi + L_d i_d, L_q i_q."""
    if pp[P_FLUX] != 0.0:
        return plant_flux_linkages(i_d, i_q, pp)
    f_d, _ = saturated_flux(i_d, pp[P_L_D], pp[P_SAT_AD])
    f_q, _ = saturated_flux(i_q, pp[P_L_Q], pp[P_SAT_AQ])
    return pp[P_PSI] + f_d, f_q


@kernel()
def axis_current(f, L0, a):
    """The current [A] of one axis's flux f [Wb] on the Froehlich-Kennelly curve f = L0 i / (1 + a |i|)
    (``saturated_flux``), explicit: i = f / (L0 - a |f|); a = 0: f / L0."""
    return f / (L0 - a * abs(f))


@kernel()
def plant_currents(psi_d, psi_q, pp):
    """The currents (i_d, i_q) [A] of the flux linkages (psi_d, psi_q) [Wb] in the plant's magnetic model, each
    explicit (the inverse of ``plant_fluxes``): the algebraic model's ``flux_currents``, the per-axis saturation's
    ``axis_current`` of psi_d - psi and psi_q, eqs 10-11's (psi_d - psi) / L_d, psi_q / L_q."""
    if pp[P_FLUX] != 0.0:
        return flux_currents(psi_d, psi_q, pp, P_FLUX_C)
    return (axis_current(psi_d - pp[P_PSI], pp[P_L_D], pp[P_SAT_AD]),
            axis_current(psi_q, pp[P_L_Q], pp[P_SAT_AQ]))


@kernel()
def remember_fluxes(i_d, i_q, psi_d, psi_q, pp):
    """Keep the fluxes a step ended with as the algebraic model's memo of psi(i) (``plant_flux_linkages``) for the
    currents they give: the flux linkages are the state the step carries to the outputs and the next step, the
    currents their explicit function; no Newton solve per step."""
    m = P_FLUX_MEMO
    pp[m] = 1.0
    pp[m + 1] = i_d
    pp[m + 2] = i_q
    pp[m + 3] = psi_d
    pp[m + 4] = psi_q


@kernel()
def plant_rates(x_d, x_q, omega_m, theta_e, v_alpha, v_beta, delta, pp):
    """``frame_rates`` in the rotor's frame: the state's first two entries the currents, or with the algebraic
    magnetic model (``P_FLUX``) the flux linkages (psi_d, psi_q), whatever frame the plant's step integrates in."""
    return frame_rates(x_d, x_q, omega_m, theta_e, v_alpha, v_beta, delta, pp, False)


@kernel()
def frame_rates(x_d, x_q, omega_m, theta_e, v_alpha, v_beta, delta, pp, stationary):
    """d/dt of (i_d, i_q, omega_m, theta_e) for a stationary-frame voltage and the powers [W] at that
    state: eqs 10-11 (or their flux form with saturation) at the true angle, eq 12 (times k_dq), the
    friction (eq 8), the road forces (eqs 2-4), the friction brake, the gear (eq 9 = 28, or
    ``power_flow_gear``) and eq 13; the dead time's error added to the voltage first.

    Returns (di_d/dt, di_q/dt, domega_m/dt, dtheta_e/dt, p_dc, p_cu, p_fric, p_shaft, p_gear, p_aero,
    p_roll, p_grade, p_brake, p_inv, p_iron): the DC-link power p_dc = k_dq (v_d i_d + v_q i_q) + p_inv at
    the voltage the winding sees (after the dead time's error: a distortion of the voltage, which the
    winding's power includes, not a loss of its own), the copper losses k_dq R_s (i_d^2 + i_q^2), the
    friction omega T_f, the shaft's omega T_e, the gear's losses, the wheel's v f_a, v f_f, v f_g,
    the brake's omega_w T_brake tanh(v / v_eps), the inverter's losses (``inverter_loss``, times
    k_dq / (3/2)) and the iron losses (``iron_torque``, a drag on the shaft beside the friction). With
    eqs 10-12 they balance: p_dc = p_cu + p_inv + d/dt W_mag + p_shaft, p_shaft = p_fric + p_iron +
    p_gear + p_aero + p_roll + p_grade + p_brake + d/dt E_kin (``stored_energies``).

    With the algebraic magnetic model (``P_FLUX``) the state's first two entries (x_d, x_q) are the
    flux linkages (psi_d, psi_q) [Wb] and the first two rates d psi_d/dt, d psi_q/dt [V] (eqs 10-11 in
    flux form: v_d - R_s i_d + w_e psi_q, v_q - R_s i_q - w_e psi_d), the currents ``flux_currents``
    of them, the torque k_dq N (psi_d i_q - psi_q i_d) (eq 12's flux form); otherwise they are the
    currents (i_d, i_q). In the stationary frame (``stationary``, any magnetic model) they are the flux
    linkages (psi_alpha, psi_beta) [Wb] and the first two rates v_alpha - R_s i_alpha, v_beta - R_s i_beta [V]
    (eqs 10-11 in the frame where the held voltage is constant), the currents those of the fluxes Park
    transforms at the true angle (``plant_currents``)."""
    f_g, f_r = road_constants(delta, pp)
    return frame_rates_at(x_d, x_q, omega_m, math.cos(theta_e), math.sin(theta_e), v_alpha, v_beta, f_g, f_r, pp,
                          stationary)


@kernel()
def road_constants(delta, pp):
    """The road forces' parts that a step holds (the elevation is held over it): the gradient's force (eq 2) and
    the rolling resistance's c_r m_v g cos(delta) before its soft sign (eq 3), the same products as
    ``gradient_force`` and ``rolling_force`` [N]. ``frame_rates_at`` takes them, so that a step's stages do not
    evaluate them again."""
    return gradient_force(delta, pp[P_M_V], pp[P_G]), pp[P_C_R] * pp[P_M_V] * pp[P_G] * math.cos(delta)


@kernel()
def frame_rates_at(x_d, x_q, omega_m, c, s, v_alpha, v_beta, f_g, f_r, pp, stationary):
    """``frame_rates`` at the angle whose cosine and sine are ``c``, ``s``, with the road's held parts ``f_g``,
    ``f_r`` (``road_constants``): the same arithmetic, each soft sign evaluated once (the friction's and the iron
    losses' tanh(omega_m / omega_eps), the rolling resistance's and the brake's tanh(v / v_eps): one argument each)."""
    flux = pp[P_FLUX] != 0.0
    if stationary:  # the state holds (psi_alpha, psi_beta): Park at the true angle, the currents explicit
        psi_d = c * x_d + s * x_q
        psi_q = -s * x_d + c * x_q
        i_d, i_q = plant_currents(psi_d, psi_q, pp)
    elif flux:  # the algebraic model: the state holds the flux linkages, the currents follow
        psi_d, psi_q = x_d, x_q
        i_d, i_q = flux_currents(psi_d, psi_q, pp, P_FLUX_C)
    else:
        i_d, i_q = x_d, x_q
        psi_d = psi_q = 0.0
    v_alpha0, v_beta0 = v_alpha, v_beta  # the commanded voltage: the pole voltages' duties
    if pp[P_DT_V] != 0.0:  # the inverter's dead time: the applied voltage loses its error
        e_alpha, e_beta = dead_time_error(c * i_d - s * i_q, s * i_d + c * i_q, pp[P_DT_V], pp[P_DT_I0])
        v_alpha = v_alpha + e_alpha
        v_beta = v_beta + e_beta
    v_d = c * v_alpha + s * v_beta  # Park at the true angle
    v_q = -s * v_alpha + c * v_beta
    N = pp[P_N]
    k = pp[P_K_DQ]
    if stationary:  # (10), (11) in the stationary frame, d psi_ab/dt = v_ab - R_s i_ab; (12) in flux form x k_dq
        did = v_alpha - pp[P_R_S] * (c * i_d - s * i_q)
        diq = v_beta - pp[P_R_S] * (s * i_d + c * i_q)
        t_e = k * flux_torque(i_d, i_q, psi_d, psi_q, N)
    elif flux:  # (10), (11) in flux form; (12) in flux form x k_dq
        w_e = N * omega_m
        did = v_d - pp[P_R_S] * i_d + w_e * psi_q
        diq = v_q - pp[P_R_S] * i_q - w_e * psi_d
        t_e = k * flux_torque(i_d, i_q, psi_d, psi_q, N)
    elif pp[P_SAT] != 0.0:  # saturated inductances
        did, diq = saturated_current_derivatives(i_d, i_q, omega_m, v_d, v_q, pp[P_R_S], pp[P_L_D], pp[P_L_Q],
                                                 pp[P_PSI], N, pp[P_SAT_AD], pp[P_SAT_AQ])
        t_e = k * saturated_torque(i_d, i_q, pp[P_PSI], pp[P_L_D], pp[P_L_Q], N, pp[P_SAT_AD], pp[P_SAT_AQ])
    else:
        did, diq = current_derivatives(i_d, i_q, omega_m, v_d, v_q,
                                       pp[P_R_S], pp[P_L_D], pp[P_L_Q], pp[P_PSI], N)  # (10), (11)
        t_e = k * electromagnetic_torque(i_d, i_q, pp[P_PSI], pp[P_L_D], pp[P_L_Q], N)  # (12) x k_dq
    paper = pp[P_PAPER] != 0.0
    iron = pp[P_FE_H] != 0.0 or pp[P_FE_E] != 0.0
    # the soft sign of the speed, tanh(omega_m / omega_eps), which the friction (eq 8) and the iron losses share
    th_w = math.tanh(omega_m / pp[P_OMEGA_EPS]) if iron or not paper else 0.0
    t_f = pp[P_B_M] * omega_m + (pp[P_T_M0] if paper else pp[P_T_M0] * th_w)  # (8) (``friction_torque``)
    if pp[P_K_W] != 0.0:  # the windage (``plant_friction``)
        t_f = t_f + windage_torque(omega_m, pp[P_K_W])
    t_drag = t_f  # the shaft's drag: friction, and the iron losses when on
    p_iron = 0.0
    if iron:
        if flux or stationary:
            f_d, f_q = psi_d, psi_q
        else:
            f_d, _ = saturated_flux(i_d, pp[P_L_D], pp[P_SAT_AD])
            f_d = pp[P_PSI] + f_d
            f_q, _ = saturated_flux(i_q, pp[P_L_Q], pp[P_SAT_AQ])
        # (``iron_torque``)
        t_fe = N * (f_d * f_d + f_q * f_q) * (pp[P_FE_H] * th_w + pp[P_FE_E] * N * omega_m)
        t_drag = t_f + t_fe
        p_iron = omega_m * t_fe
    # the road forces at the wheel (eqs 2-4) and the brake
    r_w, n_g, eta = pp[P_R_W], pp[P_N_G], pp[P_ETA]
    v_v = r_w * omega_m / n_g  # (1), (6)
    brake = pp[P_T_BRAKE] != 0.0
    # the soft sign of the vehicle's speed, tanh(v / v_eps), which the rolling resistance and the brake share
    th_v = math.tanh(v_v / pp[P_V_EPS]) if brake or not paper else 0.0
    f_f = f_r if paper else f_r * th_v  # (3) (``rolling_force``)
    f_a = aero_force(v_v, pp[P_RHO_A], pp[P_C_D], pp[P_A_F], pp[P_V_A], paper)  # (4)
    forces = f_g + f_f + f_a  # f_g: (2)
    y_b = 0.0
    if brake:
        y_b = pp[P_T_BRAKE] * th_v / n_g  # (``brake_torque``)
    y = r_w / n_g * forces + y_b  # the wheel forces at the shaft, without eta
    if pp[P_GEAR_PF] == 0.0:  # the paper's gear, eq 9 = 28
        t_l = r_w / (eta * n_g) * forces  # (29)
        if y_b != 0.0:
            t_l = t_l + y_b / eta
        dw = (t_e - t_drag - t_l) / pp[P_J_EQ]  # (9) = (28)
        p_gear = omega_m * (t_l - y)
    else:  # eta in the direction the power flows
        dw, t_gear, e = power_flow_gear(t_e - t_drag, y, pp[P_J_M], pp[P_M_R], eta, omega_m)
        p_gear = omega_m * t_gear * (1.0 - e)
    dth = N * omega_m  # (13)
    p_term = k * (v_d * i_d + v_q * i_q)
    p_inv = 0.0
    if pp[P_INV] != 0.0:  # drawn from the DC link only: the winding's voltage is the same
        i_alpha = c * i_d - s * i_q
        i_beta = s * i_d + c * i_q
        p_inv = inverter_loss(i_alpha, i_beta, pp[P_INV_V], pp[P_INV_R])
        if pp[P_INV_DV] != 0.0 or pp[P_INV_DR] != 0.0:  # the IGBT's and the diode's shares differ
            p_inv = p_inv + inverter_modulation_loss(i_alpha, i_beta, v_alpha0, v_beta0, pp[P_INV_DV],
                                                     pp[P_INV_DR], pp[P_INV_VDC])
        p_inv = pp[P_INV_K] * p_inv
    return (did, diq, dw, dth, p_term + p_inv, k * pp[P_R_S] * (i_d * i_d + i_q * i_q), omega_m * t_f,
            omega_m * t_e, p_gear, v_v * f_a, v_v * f_f, v_v * f_g, omega_m * y_b, p_inv, p_iron)


@kernel()
def plant_derivatives(i_d, i_q, omega_m, theta_e, v_alpha, v_beta, delta, pp):
    """d/dt of (i_d, i_q, omega_m, theta_e) for a stationary-frame voltage (``plant_rates``' first four;
    with the algebraic magnetic model di/dt = (di/dpsi) dpsi/dt at the fluxes of the currents)."""
    if pp[P_FLUX] != 0.0:
        psi_d, psi_q = plant_flux_linkages(i_d, i_q, pp)
        r = plant_rates(psi_d, psi_q, omega_m, theta_e, v_alpha, v_beta, delta, pp)
        g_dd, g_dq, g_qq = flux_jacobian(psi_d, psi_q, pp, P_FLUX_C)
        return g_dd * r[0] + g_dq * r[1], g_dq * r[0] + g_qq * r[1], r[2], r[3]
    r = plant_rates(i_d, i_q, omega_m, theta_e, v_alpha, v_beta, delta, pp)
    return r[0], r[1], r[2], r[3]


@kernel(_sig(f"UniTuple({_F}, 5)", _F, _F, _F, _F, _F, _V))
def plant_outputs(i_d, i_q, omega_m, theta_e, delta, pp):
    """(i_alpha, i_beta, T_e, T_L_mech, v_vehicle) of a plant state: inverse Park, eq 12 (or its flux form), eq 29 (or
    ``shaft_load`` with the brake or the power_flow gear), eqs 1, 6."""
    i_alpha, i_beta = inverse_park(i_d, i_q, theta_e)
    if pp[P_FLUX] != 0.0:  # the algebraic model: eq 12's flux form x k_dq
        psi_d, psi_q = plant_flux_linkages(i_d, i_q, pp)
        t_e = pp[P_K_DQ] * flux_torque(i_d, i_q, psi_d, psi_q, pp[P_N])
    elif pp[P_SAT] != 0.0:
        t_e = pp[P_K_DQ] * saturated_torque(i_d, i_q, pp[P_PSI], pp[P_L_D], pp[P_L_Q], pp[P_N], pp[P_SAT_AD],
                                            pp[P_SAT_AQ])
    else:
        t_e = pp[P_K_DQ] * electromagnetic_torque(i_d, i_q, pp[P_PSI], pp[P_L_D], pp[P_L_Q], pp[P_N])  # (12) x k_dq
    if pp[P_GEAR_PF] == 0.0 and pp[P_T_BRAKE] == 0.0:
        t_l = plant_load_torque(omega_m, delta, pp)  # (29)
    else:
        t_l = shaft_load(i_d, i_q, omega_m, delta, t_e, pp)
    v_v = pp[P_R_W] * omega_m / pp[P_N_G]  # (1), (6)
    return i_alpha, i_beta, t_e, t_l, v_v


@kernel(_sig(f"UniTuple({_F}, 2)", _F, _F, _F, _V))
def stored_energies(i_d, i_q, omega_m, pp):
    """(W_mag, E_kin) [J] of a plant state: the field energy k_dq (L_d i_d^2 + L_q i_q^2) / 2 (with
    saturation, ``field_energy`` of each axis; the magnet's own flux is constant and stores nothing
    that changes; with the algebraic model ``flux_energy``) and the kinetic energy, 1/2 J_eq omega^2
    with the paper's gear (eq 9's inertia, the vehicle's mass over eta) or 1/2 J_m omega^2 + 1/2 m_v v^2
    with the power_flow gear."""
    if pp[P_FLUX] != 0.0:
        psi_d, psi_q = plant_flux_linkages(i_d, i_q, pp)
        w = flux_energy(psi_d, psi_q, pp, P_FLUX_C)
    elif pp[P_SAT] != 0.0:
        w = field_energy(i_d, pp[P_L_D], pp[P_SAT_AD]) + field_energy(i_q, pp[P_L_Q], pp[P_SAT_AQ])
    else:
        w = 0.5 * (pp[P_L_D] * i_d * i_d + pp[P_L_Q] * i_q * i_q)
    if pp[P_GEAR_PF] == 0.0:
        e_kin = 0.5 * pp[P_J_EQ] * omega_m * omega_m
    else:
        e_kin = 0.5 * (pp[P_J_M] + pp[P_M_R]) * omega_m * omega_m
    return pp[P_K_DQ] * w, e_kin


# -- the battery (``PlantParams.battery`` 'ecm'; docs/speed-range.md, "The battery") ------------------------------
@kernel()
def battery_ocv(soc, pp):
    """The battery's open-circuit voltage [V] at the state of charge ``soc`` [-]: the table ``P_BAT_OCV`` (``P_BAT_N``
    points, states of charge rising from 0 to 1), interpolated linearly, held at its ends outside [0, 1]."""
    n = int(pp[P_BAT_N])
    o = P_BAT_OCV
    v = P_BAT_OCV + BAT_OCV_MAX
    if soc <= pp[o]:
        return pp[v]
    if soc >= pp[o + n - 1]:
        return pp[v + n - 1]
    k = 1
    while soc > pp[o + k]:
        k += 1
    z0 = pp[o + k - 1]
    v0 = pp[v + k - 1]
    return v0 + (pp[v + k] - v0) * (soc - z0) / (pp[o + k] - z0)


@kernel()
def battery_link(pp, ee):
    """The inverter's slots that depend on the DC link's voltage set at the battery's terminal voltage ``E_BAT_V``
    (held over the step, as the inverter measures its DC link once a period): the switching losses' share of the
    loss voltage (``P_INV_V``), 1 / v_dc of the duties (``P_INV_VDC``) and the dead time's error (``P_DT_V``)."""
    v_dc = ee[E_BAT_V]
    if pp[P_INV] != 0.0:
        pp[P_INV_V] = pp[P_INV_V0] + pp[P_INV_KSW] * v_dc
        pp[P_INV_VDC] = 1.0 / v_dc
    if pp[P_DT_K] != 0.0:
        pp[P_DT_V] = v_dc * pp[P_DT_K]


@kernel()
def dc_link_limit(pp, ee, u_lim):
    """The inverter's voltage limit for the next step [V]: ``u_lim`` (v_dc / sqrt 3 of the ideal link, 0 = none), or
    with the battery its terminal voltage over sqrt 3 (the linear range of the space-vector modulation)."""
    if pp[P_BAT] != 0.0:
        return ee[E_BAT_V] / math.sqrt(3.0)
    return u_lim


@kernel()
def battery_limits(pp, ee):
    """The battery's charge acceptance and discharge power now [W] (``E_BAT_P_CHG``, ``E_BAT_P_DIS``), what a battery
    management system tells the drive: the charge current ``P_BAT_I_CHG``, falling linearly to 0 from the state of
    charge ``P_BAT_SOC_TAPER`` to 1 and bounded so that the terminal voltage stays at or below ``P_BAT_V_MAX``; the
    discharge current ``P_BAT_I_DIS`` (0 at a state of charge of 0 or less), bounded so that it stays at or above
    ``P_BAT_V_MIN``; each power at the terminal voltage that current gives through R0 behind the open-circuit voltage
    less the RC pair's (the pair's own response left out: an instant's limit, as a 10 s pulse power is quoted)."""
    soc = ee[E_BAT_SOC]
    e = battery_ocv(soc, pp) - ee[E_BAT_VRC]
    r0 = pp[P_BAT_R0]
    i_c = pp[P_BAT_I_CHG]
    taper = pp[P_BAT_SOC_TAPER]
    if soc >= 1.0:
        i_c = 0.0
    elif soc > taper:
        i_c = i_c * (1.0 - soc) / (1.0 - taper)
    i_d = pp[P_BAT_I_DIS] if soc > 0.0 else 0.0
    if r0 > 0.0:
        i_c = min(i_c, max((pp[P_BAT_V_MAX] - e) / r0, 0.0))
        i_d = min(i_d, max((e - pp[P_BAT_V_MIN]) / r0, 0.0))
    ee[E_BAT_P_CHG] = (e + r0 * i_c) * i_c
    ee[E_BAT_P_DIS] = (e - r0 * i_d) * i_d


@kernel()
def battery_reset(pp, ee):
    """The battery at rest at its initial state of charge: the RC pair discharged, the terminal voltage the
    open-circuit voltage, its limits (``battery_limits``)."""
    ee[E_BAT_SOC] = pp[P_BAT_SOC0]
    ee[E_BAT_VRC] = 0.0
    ee[E_BAT_V] = battery_ocv(pp[P_BAT_SOC0], pp)
    ee[E_BAT_I] = 0.0
    battery_limits(pp, ee)


@kernel()
def battery_step(p_dc, dt, pp, ee):
    """The battery over a step of ``dt`` [s] delivering the DC power ``p_dc`` [W] (the step's mean, from the RK4 of the
    motor; negative: charging): the equivalent circuit v = OCV(soc) - R0 i - v_rc, C1 dv_rc/dt = i - v_rc / R1, with
    the current i held over the step. The current is the one whose mean terminal voltage times it is ``p_dc``: with
    v_rc exact over the step, its mean is phi v_rc0 + R1 (1 - phi) i (phi = tau / dt (1 - exp(-dt / tau))), so that
    p_dc = (E - R i) i with E = OCV(soc0) - phi v_rc0, R = R0 + R1 (1 - phi): the algebraic loop of the DC link
    through the internal resistance, closed within the step (the smaller root, 2 p / (E + sqrt(E^2 - 4 R p)); a power
    beyond E^2 / (4 R), more than the battery can give, leaves the current NaN: the plant fails the step). Then the
    charge, the state of charge (the start's less the charge over the capacity), v_rc (exact), the terminal voltage at
    the end of the step (the next step's DC link) and the energies: chemical OCV(soc0) i dt, the losses R0 i^2 dt plus
    the RC pair's R1 share (the energy into the pair less the change of its capacitor's), the capacitor's energy; then
    the limits (``battery_limits``). Chemical = terminal + losses + the capacitor's change, to round-off."""
    soc0 = ee[E_BAT_SOC]
    v_rc0 = ee[E_BAT_VRC]
    ocv = battery_ocv(soc0, pp)
    r0 = pp[P_BAT_R0]
    r1 = pp[P_BAT_R1]
    a = 0.0
    phi = 0.0
    if r1 > 0.0:
        tau = pp[P_BAT_TAU]
        a = math.exp(-dt / tau)
        phi = tau / dt * (1.0 - a)
    e = ocv - phi * v_rc0
    r = r0 + r1 * (1.0 - phi)
    disc = e * e - 4.0 * r * p_dc
    i = 2.0 * p_dc / (e + math.sqrt(disc)) if disc >= 0.0 else math.nan
    v_rc_mean = phi * v_rc0 + r1 * (1.0 - phi) * i
    v_rc = r1 * i + (v_rc0 - r1 * i) * a
    w0 = ee[E_BAT_W]
    w1 = 0.5 * pp[P_BAT_C1] * v_rc * v_rc
    ee[E_BAT_CHEM] += ocv * i * dt
    ee[E_BAT_LOSS] += r0 * i * i * dt + (v_rc_mean * i * dt - (w1 - w0))
    ee[E_BAT_W] = w1
    ee[E_BAT_Q] += i * dt
    soc = pp[P_BAT_SOC0] - ee[E_BAT_Q] / pp[P_BAT_Q]
    ee[E_BAT_SOC] = soc
    ee[E_BAT_VRC] = v_rc
    ee[E_BAT_I] = i
    ee[E_BAT_V] = battery_ocv(soc, pp) - r0 * i - v_rc
    battery_limits(pp, ee)


@kernel()
def _stage_sum(ra, rb, rc, rd, i):
    """RK4's weighted sum of power i of the four stages, a + 2 b + 2 c + d (times h/6 by the caller)."""
    return ra[i] + 2.0 * rb[i] + 2.0 * rc[i] + rd[i]


@kernel()
def _regen(p):
    """The power returned to the DC link, max(-p, 0) [W]."""
    return -p if p < 0.0 else 0.0


@kernel(_sig(f"UniTuple({_F}, 10)", _F, _F, _F, _F, _F, _F, _F, _F, _V, _V))
def plant_step(i_d, i_q, omega_m, theta_e, v_alpha, v_beta, delta, dt, pp, ee):
    """Advance the state by dt with the voltage and elevation held (RK4, ``P_SUBSTEPS``
    sub-steps, more where the rotor turns more than ``P_SUBSTEP_ANGLE`` electrical radians in one of
    them at the speed the step starts with); return the new (i_d, i_q, omega_m, theta_e) and the outputs at the new
    state: (i_alpha, i_beta) (clean), T_e, T_L_mech at ``delta``, v_vehicle; and the
    distance the vehicle moved [m]: r_w / (n_g N) times the (unwrapped) RK4 angle step of
    eq 13, i.e. eqs 1, 6 integrated by the same RK4.

    The energies (the vector ``ee``, ``PLANT_ENERGY_LAYOUT``) get the step's integrals of
    ``plant_rates``' powers, taken at the RK4 stages with the RK4 weights h/6, h/3, h/3, h/6: the
    RK4 step of the state extended by the energies, so that the balance closes to RK4's truncation
    error (the state's arithmetic is the same as without them); ``E_P_DC`` gets the step's mean DC
    power.

    With the algebraic magnetic model (``P_FLUX``) the RK4 integrates the flux linkages: the step
    starts from the fluxes the last step ended with (``plant_flux_linkages``' memo, which the step keeps:
    ``remember_fluxes``; a Newton solve only for currents set from outside) and returns the currents
    ``flux_currents`` of the fluxes it ends with (explicit); the state and the outputs stay the currents.

    In the stationary frame (``PlantParams.integrator`` 'rk6_stationary', ``stationary_frame``; any magnetic
    model) Butcher's RK6 (``rk6_substep``) integrates (psi_alpha, psi_beta, omega_m, theta_e): the held voltage
    is constant there, the rotor's turning enters through the Park transform at the integrated angle and the
    resistive drop R_s i_alpha-beta, and one sub-step of order 6 resolves the ripple of a step that turns up to
    ``PlantParams.stationary_substep_angle`` (``STATIONARY_SUBSTEP_ANGLE``: 0.7 rad, 148 km/h at 1e-4 s): seven
    stages a step at any speed of the drive cycles (docs/performance.md, "The plant's integrator")."""
    battery = pp[P_BAT] != 0.0
    if battery:  # the inverter at the battery's terminal voltage of the step before
        battery_link(pp, ee)
    n = int(pp[P_SUBSTEPS])
    stationary = stationary_frame(pp)
    angle = abs(pp[P_SUBSTEP_ANGLE])
    if angle > 0.0:  # at most that angle per sub-step: accurate at top speed
        m = abs(pp[P_N] * omega_m) * dt / angle
        if m > n:  # (False for NaN) no more than MAX_SUBSTEPS: a state running away must not hang the step
            n = int(math.ceil(m)) if m < MAX_SUBSTEPS else max(n, MAX_SUBSTEPS)
    h = dt / n
    s_dc = s_abs = s_reg = s_cu = s_fr = s_sh = s_gear = s_aero = s_roll = s_grade = s_brake = s_inv = s_fe = 0.0
    x0, x1, x2, x3 = i_d, i_q, omega_m, theta_e
    flux = pp[P_FLUX] != 0.0
    f_g, f_r = road_constants(delta, pp)  # held over the step
    c1 = s1 = 0.0
    if stationary:  # RK4 on (psi_alpha, psi_beta) (``plant_rates``): the inverse Park of the state's fluxes
        f_d, f_q = plant_fluxes(i_d, i_q, pp)
        c1 = math.cos(theta_e)  # (``inverse_park``; the first stage's angle too)
        s1 = math.sin(theta_e)
        x0, x1 = c1 * f_d - s1 * f_q, s1 * f_d + c1 * f_q
    elif flux:  # the algebraic model: RK4 on the flux linkages (``plant_rates``), from the state's currents
        x0, x1 = plant_flux_linkages(i_d, i_q, pp)
    if stationary:  # Butcher's RK6 (``rk6_substep``), the energies with its weights
        acc = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        for j in range(n):
            if j > 0:
                c1 = math.cos(x3)
                s1 = math.sin(x3)
            x0, x1, x2, x3, acc = rk6_substep(x0, x1, x2, x3, h, v_alpha, v_beta, f_g, f_r, pp, acc, c1, s1)
        (s_dc, s_abs, s_reg, s_cu, s_fr, s_sh, s_gear, s_aero, s_roll, s_grade, s_brake, s_inv,
         s_fe) = acc
        n = 0  # and no RK4 sub-step; the sums are the integrals: their weight is 1 (``w`` below)
    for _ in range(n):
        ra = _rk4_stage(x0, x1, x2, x3, v_alpha, v_beta, f_g, f_r, pp, stationary)
        a0, a1, a2, a3 = ra[0], ra[1], ra[2], ra[3]
        rb = _rk4_stage(x0 + 0.5 * h * a0, x1 + 0.5 * h * a1, x2 + 0.5 * h * a2,
                        x3 + 0.5 * h * a3, v_alpha, v_beta, f_g, f_r, pp, stationary)
        b0, b1, b2, b3 = rb[0], rb[1], rb[2], rb[3]
        rc = _rk4_stage(x0 + 0.5 * h * b0, x1 + 0.5 * h * b1, x2 + 0.5 * h * b2,
                        x3 + 0.5 * h * b3, v_alpha, v_beta, f_g, f_r, pp, stationary)
        c0, c1, c2, c3 = rc[0], rc[1], rc[2], rc[3]
        rd = _rk4_stage(x0 + h * c0, x1 + h * c1, x2 + h * c2, x3 + h * c3,
                        v_alpha, v_beta, f_g, f_r, pp, stationary)
        d0, d1, d2, d3 = rd[0], rd[1], rd[2], rd[3]
        # the energies: the same RK4 weights on the stages' powers
        s_dc += _stage_sum(ra, rb, rc, rd, 4)
        s_abs += abs(ra[4]) + 2.0 * abs(rb[4]) + 2.0 * abs(rc[4]) + abs(rd[4])
        s_reg += _regen(ra[4]) + 2.0 * _regen(rb[4]) + 2.0 * _regen(rc[4]) + _regen(rd[4])
        s_cu += _stage_sum(ra, rb, rc, rd, 5)
        s_fr += _stage_sum(ra, rb, rc, rd, 6)
        s_sh += _stage_sum(ra, rb, rc, rd, 7)
        s_gear += _stage_sum(ra, rb, rc, rd, 8)
        s_aero += _stage_sum(ra, rb, rc, rd, 9)
        s_roll += _stage_sum(ra, rb, rc, rd, 10)
        s_grade += _stage_sum(ra, rb, rc, rd, 11)
        s_brake += _stage_sum(ra, rb, rc, rd, 12)
        s_inv += _stage_sum(ra, rb, rc, rd, 13)
        s_fe += _stage_sum(ra, rb, rc, rd, 14)
        x0 += h / 6.0 * (a0 + 2.0 * b0 + 2.0 * c0 + d0)
        x1 += h / 6.0 * (a1 + 2.0 * b1 + 2.0 * c1 + d1)
        x2 += h / 6.0 * (a2 + 2.0 * b2 + 2.0 * c2 + d2)
        x3 += h / 6.0 * (a3 + 2.0 * b3 + 2.0 * c3 + d3)
    w = 1.0 if stationary else h / 6.0
    ee[E_DC] += w * s_dc
    ee[E_DC_ABS] += w * s_abs
    ee[E_REGEN] += w * s_reg
    ee[E_COPPER] += w * s_cu
    ee[E_FRICTION] += w * s_fr
    ee[E_SHAFT] += w * s_sh
    ee[E_GEAR] += w * s_gear
    ee[E_AERO] += w * s_aero
    ee[E_ROLL] += w * s_roll
    ee[E_GRADE] += w * s_grade
    ee[E_BRAKE] += w * s_brake
    ee[E_INVERTER] += w * s_inv
    ee[E_IRON] += w * s_fe
    ee[E_P_DC] = w * s_dc / dt
    if stationary:  # the fluxes in the rotor's frame at the angle the step ends with, the currents of them (before
        # the thermal step changes R_s and psi: the currents, the state, are continuous across it, as in the rotor's
        # frame)
        c_e = math.cos(x3)
        s_e = math.sin(x3)
        f_d = c_e * x0 + s_e * x1
        f_q = -s_e * x0 + c_e * x1
        x0, x1 = plant_currents(f_d, f_q, pp)
        if flux:
            remember_fluxes(x0, x1, f_d, f_q, pp)
    if battery:  # the battery delivers the step's DC power
        battery_step(ee[E_P_DC], dt, pp, ee)
    if pp[P_TH] != 0.0:  # the step's losses heat the motor; R_s and psi follow for the next step
        thermal_network_step(w * s_cu, w * (s_fe + s_fr), dt, pp, ee)
    dx = pp[P_R_W] / (pp[P_N_G] * pp[P_N]) * (x3 - theta_e)
    x3 = wrap_angle(x3)
    if flux and not stationary:  # the currents of the new fluxes, which stay the memo's: no Newton solve next
        f_d, f_q = x0, x1
        x0, x1 = flux_currents(f_d, f_q, pp, P_FLUX_C)
        remember_fluxes(x0, x1, f_d, f_q, pp)
    i_alpha, i_beta, t_e, t_l, v_v = plant_outputs(x0, x1, x2, x3, delta, pp)
    return x0, x1, x2, x3, i_alpha, i_beta, t_e, t_l, v_v, dx


# -- the current sensors' noise ---------------------------------------------------------------
MASK64 = (1 << 64) - 1  #: the low 64 bits (plain Python's integers do not wrap; numba's uint64 do)


@kernel()
def splitmix64(x):
    """The splitmix64 mix of the 64-bit integer x (Steele, Lea and Flood 2014)."""
    x = (x + 0x9E3779B97F4A7C15) & MASK64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & MASK64
    return x ^ (x >> 31)


@kernel(_sig("UniTuple(float64, 2)", "uint64", "uint64"))
def gaussian_pair(seed, n):
    """Two independent standard normal numbers for sample n of stream ``seed`` (both 0 <= ... < 2**64).

    Counter-based (splitmix64 + Box-Muller): the n-th sample depends only on (seed, n),
    so a saved and restored plant continues the same noise sequence. Compiled, the integers are
    uint64 and wrap; in plain Python the masks wrap them: the same numbers either way (n + n, not
    n * 2: numba types a uint64 times an integer literal as int64, whose shifts keep the sign).
    """
    base = splitmix64(seed & MASK64) ^ ((n + n) & MASK64)
    u1 = 1.0 - (splitmix64(base) >> 11) * (1.0 / 9007199254740992.0)  # (0, 1]
    u2 = (splitmix64(base ^ 0xD1B54A32D192ED03) >> 11) * (1.0 / 9007199254740992.0)
    r = math.sqrt(-2.0 * math.log(u1))
    return r * math.cos(2.0 * math.pi * u2), r * math.sin(2.0 * math.pi * u2)


_SQRT3 = math.sqrt(3.0)


@kernel(_sig(f"UniTuple({_F}, 2)", _F, _F, "uint64", "uint64", _F, _F, _F, _F, _F, _F, _F))
def measured_currents(i_alpha, i_beta, seed, n, gain_a, offset_a, gain_b, offset_b, noise, lsb, adc_range):
    """The currents (i_alpha, i_beta) as the controller measures them, sample n: phases a and b through
    their sensors (gain, offset [A], the noise ``noise`` [A] x ``gaussian_pair(seed, n)``), the ADC's
    quantisation (step ``lsb`` [A], 0 = none; clipped to +-``adc_range``), back to alpha-beta with
    i_c = -i_a - i_b (two sensors). Amplitude-invariant Clarke as ``pmsm_ev.transforms``."""
    i_b = -0.5 * i_alpha + 0.5 * _SQRT3 * i_beta
    m_a = gain_a * i_alpha + offset_a
    m_b = gain_b * i_b + offset_b
    if noise > 0:
        n_a, n_b = gaussian_pair(seed, n)
        m_a += noise * n_a
        m_b += noise * n_b
    if lsb > 0:
        m_a = min(max(round(m_a / lsb) * lsb, -adc_range), adc_range)
        m_b = min(max(round(m_b / lsb) * lsb, -adc_range), adc_range)
    m_c = -m_a - m_b
    return (2.0 * m_a - m_b - m_c) / 3.0, (m_b - m_c) / _SQRT3


@kernel(_sig(f"UniTuple({_F}, 12)", _F, _F, _F, _F, _F, _F, _F, _F, _V, _V, "uint64", "uint64",
             _F, _F, _F, _F, _F, _F, _F))
def plant_step_measured(i_d, i_q, omega_m, theta_e, v_alpha, v_beta, delta, dt, pp, ee, seed, n,
                        gain_a, offset_a, gain_b, offset_b, noise, lsb, adc_range):
    """``plant_step``, then ``measured_currents`` of its (clean) currents for sample n, in one call (the
    plant's per-step path with current sensors): ``plant_step``'s ten results, then the measured
    (i_alpha, i_beta). The same operations as the two calls one after the other."""
    r = plant_step(i_d, i_q, omega_m, theta_e, v_alpha, v_beta, delta, dt, pp, ee)
    m = measured_currents(r[4], r[5], seed, n, gain_a, offset_a, gain_b, offset_b, noise, lsb, adc_range)
    return r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], r[9], m[0], m[1]


#: the slots ``plant_advance`` writes as runs: the outputs i_alpha .. v_vehicle, the state delta .. i_beta_true
_PIO_OUTPUTS, _PIO_STATE = 9, 8
if ((PIO_I_ALPHA, PIO_I_BETA, PIO_I_D, PIO_I_Q, PIO_OMEGA_M, PIO_THETA_E, PIO_T_E, PIO_T_L_MECH, PIO_V_VEHICLE)
        != tuple(range(PIO_I_ALPHA, PIO_I_ALPHA + _PIO_OUTPUTS))
        or (PIO_PLANT_DELTA, PIO_PLANT_T_BRAKE, PIO_CLOCK, PIO_SAMPLES, PIO_V_ALPHA_APPLIED, PIO_V_BETA_APPLIED,
            PIO_I_ALPHA_TRUE, PIO_I_BETA_TRUE) != tuple(range(PIO_PLANT_DELTA, PIO_PLANT_DELTA + _PIO_STATE))):
    raise ImportError("PLANT_IO_LAYOUT: the outputs and the plant's state are not in plant_advance's order")


@kernel(_sig("boolean", _V, _V, _V, _F, _F, _F, _F, _F, "boolean"))
def plant_advance(io, pp, ee, v_alpha, v_beta, delta, t_brake_in, h, finite_only):
    """One step of ``Plant`` over h on its buffer ``io`` (``PLANT_IO_LAYOUT``: its state, outputs and constants),
    its parameter and energy vectors ``pp``, ``ee``, with the voltage (v_alpha, v_beta) as applied (after the
    inverter's delay and limit, which ``Plant.step`` takes before), the elevation and the friction brake's torque
    (a negative or NaN one taken as 0) held: ``plant_step``, with the current sensors ``plant_step_measured``, and
    the plant's bookkeeping (the brake, its clock, the sample counter, the distance, the applied voltage). Both
    ``Plant.step`` and the plant FMU's compiled step (``plant_fmu_step``) are this kernel. True; with
    ``finite_only``, False where the state after the step is not finite, with nothing changed (the energy vector
    saved in ``io``'s ``PIO_SAVE`` before the step and restored)."""
    if finite_only:
        for i in range(PLANT_ENERGY):
            io[PIO_SAVE + i] = ee[i]
    t_brake = io[PIO_PLANT_T_BRAKE]
    pp_t_brake = pp[P_T_BRAKE]
    if t_brake_in != t_brake:
        t_brake = t_brake_in if t_brake_in > 0.0 else 0.0
        pp[P_T_BRAKE] = t_brake
    sample = io[PIO_SAMPLES]
    if io[PIO_SENSORS] != 0.0:
        seed = (int(io[PIO_SEED]) << 32) | int(io[PIO_SEED + 1])
        (i_d, i_q, omega_m, theta_e, i_alpha_true, i_beta_true, t_e, t_l, v_v, dx, i_alpha,
         i_beta) = plant_step_measured(io[PIO_I_D], io[PIO_I_Q], io[PIO_OMEGA_M], io[PIO_THETA_E], v_alpha, v_beta,
                                       delta, h, pp, ee, seed, int(sample), io[PIO_SENSOR_ARGS],
                                       io[PIO_SENSOR_ARGS + 1], io[PIO_SENSOR_ARGS + 2], io[PIO_SENSOR_ARGS + 3],
                                       io[PIO_SENSOR_ARGS + 4], io[PIO_SENSOR_ARGS + 5], io[PIO_SENSOR_ARGS + 6])
    else:
        i_d, i_q, omega_m, theta_e, i_alpha, i_beta, t_e, t_l, v_v, dx = plant_step(
            io[PIO_I_D], io[PIO_I_Q], io[PIO_OMEGA_M], io[PIO_THETA_E], v_alpha, v_beta, delta, h, pp, ee)
        i_alpha_true = i_alpha
        i_beta_true = i_beta
    if finite_only and not math.isfinite(omega_m + i_d + i_q + ee[E_BAT_V]):  # a state, or the battery's voltage
        # when it cannot give the power (0 with the ideal link)
        for i in range(PLANT_ENERGY):
            ee[i] = io[PIO_SAVE + i]
        pp[P_T_BRAKE] = pp_t_brake
        return False
    # the outputs and the plant's other state, each a run of slots in the layout's order
    outputs = (i_alpha, i_beta, i_d, i_q, omega_m, theta_e, t_e, t_l, v_v)
    for j in range(_PIO_OUTPUTS):
        io[PIO_I_ALPHA + j] = outputs[j]
    io[PIO_X_VEHICLE] += dx
    state = (delta, t_brake, io[PIO_CLOCK] + h, sample + 1.0, v_alpha, v_beta, i_alpha_true, i_beta_true)
    for j in range(_PIO_STATE):
        io[PIO_PLANT_DELTA + j] = state[j]
    return True
