"""Adaptation while driving: the magnet flux psi and the stator resistance R_s tracked as the motor warms, by a
model-reference estimator on the controller's own voltage and measured currents (``ControllerParams.adaptation``;
docs/sensorless.md, "Adaptation while driving").

The reference model is the motor's dq voltage equations (eqs 10-11, the paper's dq convention, ``MotorParams``):

    v_d = R_s i_d + L_d di_d/dt - omega_e L_q i_q
    v_q = R_s i_q + L_q di_q/dt + omega_e (L_d i_d + psi)

with the model's L_d, L_q (the controller's, ``C_L_D``, ``C_L_Q``). Each control period, at its end, the unit
compares them over the period just gone, [t_{k-1}, t_k]:

    (u_d, u_q) = sin(a)/a Park(v_alpha, v_beta, theta_{k-1} + a),  a = omega_e dt / 2              (AD1)

the mean, seen from the frame turning at omega_e, of the vector the inverter held (the command: the dead-time
compensation's aim is that the motor sees it);

    i = (i_k + i_{k-1}) / 2,   di/dt = (i_k - i_{k-1}) / dt                                        (AD2)

each current in the frame of its own instant (sensor noise in i and in di/dt is then uncorrelated). Two scalar
least-squares fits with exponential forgetting (memory ``ControllerParams.adapt_time``), each updated only in a
period where its parameter is observable and frozen otherwise:

    y_psi = u_q - R_s_hat i_q - L_q di_q/dt - omega_e L_d i_d = omega_e psi,
    psi_hat = S[omega_e y_psi] / S[omega_e^2]                                                      (AD3)

    y_R = u . i - L_d di_d/dt i_d - L_q di_q/dt i_q - omega_e (psi_hat i_q + (L_d - L_q) i_d i_q) = R_s |i|^2,
    R_s_hat = S[|i|^2 y_R] / S[|i|^4]                                                              (AD4)

(S[x]: x low-pass filtered over the observable periods, ``S_AD_SUM``; started with a tenth of the weight of one
memory of data at the threshold that agree with the model, ``AD_PRIOR``, so that an estimate leaves the model's value
smoothly but at once). AD4 is the
voltage equation projected on the current (the power balance): the dot product is the same in any frame, so an
angle error enters only through the omega_e terms.

**When each is observable** (AD5). R_s and psi are not separable at one steady operating point when the angle is
estimated: two voltage equations, three unknowns with the angle error (Boileau, Nahid-Mobarakeh, Meibody-Tabar,
"On-line identification of PMSM parameters: parameter identifiability and estimator comparative study", IEEE
Trans. Ind. Appl. 47(4), 2011; Hinkkanen, Tuovinen, Harnefors, Luomi, "A combined position and stator-resistance
observer for salient PMSM drives: design and stability analysis", IEEE Trans. Power Electron. 27(2), 2012). So each
is taken where the other's error and the voltage errors are small against its own term:

* psi where |omega_e| >= ``C_AD_PSI_W``: the back-EMF omega_e psi large against the R_s error's Delta R i_q and the
  inverter's residual voltage (psi_hat errs by Delta V / omega_e);
* R_s where |omega_e| <= ``C_AD_RS_W`` and |i| >= ``C_AD_RS_I``: R_s |i|^2 large against omega_e Delta psi i_q (R_s_hat
  errs by omega_e Delta psi i_q / |i|^2) and the voltage errors;
* both only while the currents are quasi-steady, |di/dt| low-pass filtered (``AD_RATE_FILTER``) at most
  ``C_AD_RATE``: the L di/dt terms carry the inductances' model error.

Outside, the fits hold their sums and the estimates stay where they are (frozen). R_s_hat starts from the
identification's R_s_id where the unit has one (the R_s test at enable, ``S_ID_RS``), else from the model's.

**Used** (``ADAPT_USE``, AD6): psi_hat in the controller's model everywhere it reads psi (``C_PSI``: the
decoupling and back-EMF feed-forward, the reference generator, the I-f sizing) and in the EKF's model (A3, A4:
``C_C_WPSI``, ``C_C_TPSI``), R_s_hat in the EKF's (A8, A14: ``C_A_RD``, ``C_A_RQ``); the speed loop's k_t, a design
constant of its gains, stays. ``ADAPT_OBSERVE`` computes them and changes nothing; ``ADAPT_OFF`` does not run.

**The identified model** (``MODEL_IDENTIFIED``, AD7; ``ControllerParams.model_source``): the injection unit's
identification at a stop (eqs ID1, ID2 in ``kernels.modes``) measures L_d = 1 / y_d and L_q = 1 / y_q, the incremental
inductances at zero current, and R_s; ``model_apply`` puts them in the controller's model in place of the given
ones (``C_MODEL0``), where it reads them: the EKF's A8-A15 and A18-A19 (``C_A_RD`` .. ``C_C_TDQ``), the
decoupling, the back-EMF feed-forward, the reference generator and the I-f sizing (``C_L_D``, ``C_L_Q``), the EKF's
loss detector (``C_EKF_LOS_EMF``), and the current PIs' gains, K_p = L omega_c and K_i = R_s omega_c at the given
model's bandwidth (``C_MODEL0``'s gains scaled by the measured over the given). With ``ADAPT_USE`` the adaptation's
psi and R_s go in after it (AD6). The given model stays wherever a value was not measured.
"""

from __future__ import annotations

import math

from .injection import CROSS_STEP
from .jit import kernel
from .layout import (
    ADAPT_USE,
    C_A_RD,
    C_A_RQ,
    C_AD_GAIN,
    C_AD_NOM_TPSI,
    C_AD_NOM_WPSI,
    C_AD_PSI0,
    C_AD_PSI_W,
    C_AD_RATE,
    C_AD_RS0,
    C_AD_RS_I,
    C_AD_RS_W,
    C_ADAPT,
    C_C_TDQ,
    C_C_TPSI,
    C_C_VD,
    C_C_VQ,
    C_C_WD,
    C_C_WPSI,
    C_C_WQ,
    C_CROSS,
    C_CROSS_G,
    C_DT,
    C_EKF_LOS_EMF,
    C_INJ_I_MAX,
    C_INJ_TILT_MAX,
    C_KI_ID,
    C_KI_IQ,
    C_KP_ID,
    C_KP_IQ,
    C_L_D,
    C_L_Q,
    C_MODEL0_CROSS,
    C_MODEL0_INJ_I_MAX,
    C_MODEL0_KI_ID,
    C_MODEL0_KI_IQ,
    C_MODEL0_KP_ID,
    C_MODEL0_KP_IQ,
    C_MODEL0_L_D,
    C_MODEL0_L_Q,
    C_MODEL0_R_S,
    C_MODEL_SRC,
    C_N,
    C_PSI,
    CROSS_POINTS,
    MODEL_IDENTIFIED,
    S_AD_I2Y,
    S_AD_I4,
    S_AD_ID_PREV,
    S_AD_IQ_PREV,
    S_AD_PREV,
    S_AD_PRIMED,
    S_AD_PRIMED_RS,
    S_AD_PRIMED_V,
    S_AD_PSI,
    S_AD_RATE,
    S_AD_RATE_D,
    S_AD_RATE_Q,
    S_AD_RS,
    S_AD_SEEN,
    S_AD_SEEN_PSI,
    S_AD_SEEN_RS,
    S_AD_THETA_PREV,
    S_AD_V,
    S_AD_V_ALPHA,
    S_AD_V_BETA,
    S_AD_W2,
    S_AD_WY,
    S_ID_RS,
    S_ID_Y_D,
    S_ID_Y_Q,
    S_V_ALPHA,
    S_V_BETA,
)
from .transforms import park, wrap_angle

#: the quasi-steady test's filter time constant [s]: the sensor noise's derivative (sigma = 1 A over dt = 100 us,
#: 1.4e4 A/s rms a period) filtered to about 450 A/s rms, a quarter of C_AD_RATE's default, while a current ramp
#: of the speed loop (tens of ms) is seen whole
AD_RATE_FILTER = 0.05
#: the estimates are held within these shares of the model's values: psi from a magnet at 20 degC to one 400 K
#: hotter (-0.12 %/K: 0.52) and no stronger than 1.5x; R_s from copper at -100 degC (0.53) to one at 530 degC
#: (3.0): beyond them a fit is wrong, not the motor
AD_PSI_MIN, AD_PSI_MAX = 0.5, 1.5
AD_RS_MIN, AD_RS_MAX = 0.5, 3.0
#: the fits' priors weigh this share of one memory of data at the threshold (``adapt_reset``): the model's value is
#: where an estimate starts, not a belief that outweighs the first seconds of data (with 1, a fit 1 s into data at
#: 1.3 times the threshold still leant 17 % on the model's value; with 0.1, 2 %)
AD_PRIOR = 0.1


@kernel()
def adapt_reset(s, c):
    """The estimates back on the model's psi and R_s, their fits on their priors (``AD_PRIOR`` of one memory of data
    at the threshold that agree with the model), the period's memory empty."""
    w2 = AD_PRIOR * c[C_AD_PSI_W] * c[C_AD_PSI_W]
    i4 = AD_PRIOR * c[C_AD_RS_I] ** 4
    s[S_AD_PSI] = c[C_AD_PSI0]
    s[S_AD_RS] = c[C_AD_RS0]
    s[S_AD_W2] = w2
    s[S_AD_WY] = w2 * c[C_AD_PSI0]
    s[S_AD_I4] = i4
    s[S_AD_I2Y] = i4 * c[C_AD_RS0]
    for j in range(3):
        s[S_AD_PREV + j] = 0.0
    for j in range(2):
        s[S_AD_V + j] = 0.0
        s[S_AD_RATE + j] = 0.0
        s[S_AD_SEEN + j] = 0.0
        s[S_AD_PRIMED + j] = 0.0
    if c[C_ADAPT] == ADAPT_USE:
        adapt_apply(s, c)


@kernel()
def model_apply(s, c):
    """(AD7) The controller's model of the motor from what the identification measured (``C_MODEL_SRC`` =
    ``MODEL_IDENTIFIED``; the module's doc): L_d = 1 / y_d, L_q = 1 / y_q (``S_ID_Y``, eq ID1) and R_s (``S_ID_RS``,
    eq ID2) where measured, else the given (``C_MODEL0``), into every constant made of them, psi where it is
    (``C_PSI``); with ``ADAPT_USE`` the adaptation's psi and R_s on top (``adapt_apply``). Idempotent: the state
    says what the model is, so that a restored FMU state and a reset put it back."""
    l_d = c[C_MODEL0_L_D]
    l_q = c[C_MODEL0_L_Q]
    r_s = c[C_MODEL0_R_S]
    if c[C_MODEL_SRC] == MODEL_IDENTIFIED:
        if s[S_ID_Y_D] > 0.0 and s[S_ID_Y_Q] > 0.0:
            l_d = 1.0 / s[S_ID_Y_D]
            l_q = 1.0 / s[S_ID_Y_Q]
        if s[S_ID_RS] > 0.0:
            r_s = s[S_ID_RS]
    dt = c[C_DT]
    n = c[C_N]
    kt_j = c[C_C_TPSI] / c[C_PSI]  # k_dq N dt / J (A19 over psi)
    c[C_L_D] = l_d
    c[C_L_Q] = l_q
    c[C_A_RD] = 1.0 - r_s * dt / l_d  # (A8)
    c[C_A_RQ] = 1.0 - r_s * dt / l_q  # (A14)
    c[C_C_WQ] = n * l_q * dt / l_d  # (A9, A10)
    c[C_C_WD] = n * l_d * dt / l_q  # (A13)
    c[C_C_WPSI] = n * c[C_PSI] * dt / l_q  # (A15)
    c[C_C_VD] = dt / l_d
    c[C_C_VQ] = dt / l_q
    c[C_C_TDQ] = kt_j * (l_d - l_q)  # (A18, A19)
    c[C_EKF_LOS_EMF] = dt * n * c[C_PSI] / l_q
    c[C_AD_NOM_WPSI] = n * c[C_AD_PSI0] * dt / l_q
    c[C_KP_ID] = c[C_MODEL0_KP_ID] * l_d / c[C_MODEL0_L_D]
    c[C_KI_ID] = c[C_MODEL0_KI_ID] * r_s / c[C_MODEL0_R_S]
    c[C_KP_IQ] = c[C_MODEL0_KP_IQ] * l_q / c[C_MODEL0_L_Q]
    c[C_KI_IQ] = c[C_MODEL0_KI_IQ] * r_s / c[C_MODEL0_R_S]
    cross_apply(c, 1.0 / l_d - 1.0 / c[C_MODEL0_L_D], 1.0 / l_q - 1.0 / c[C_MODEL0_L_Q])
    if c[C_ADAPT] == ADAPT_USE:
        adapt_apply(s, c)


@kernel()
def cross_apply(c, dy_d, dy_q):
    """(AD8) Cross-saturation on the identified motor: the injection's axis less the d axis (``C_CROSS``) and the
    injection's q current limit (``C_INJ_I_MAX``) from the given model's incremental admittances (``C_CROSS_G``) at
    each of the table's q currents, shifted by what the identification measured at zero current less the given
    model's, ``dy_d`` = 1/L_d - 1/L_d0 and ``dy_q`` = 1/L_q - 1/L_q0 [1/H] (the algebraic model's admittance is its
    zero-current admittance plus the saturation's terms, ``flux_model``):

        g = G0(i_q) + diag(dy_d, dy_q),   phi = atan2(2 g_dq, g_dd - g_qq) / 2                                 (AD8)

    phi the axis of g's larger eigenvalue, the least inductance the injection locks onto. The tilt grows with i_q as
    2 g_dq over g_dd - g_qq: a motor with a third of the data sheet's saliency tilts three times as far (the low-
    saliency corner's L_d +10 %, L_q -7 %: 30 deg at 150 A, where the data sheet's model has 6 deg and the plant 48;
    compensated with the data sheet's, the injection locked onto the q axis under a drive-off's load and slipped a
    turn). The limit: the q current at which phi reaches the given model's phi at the given limit
    (``C_INJ_TILT_MAX``; the tilt the limit was measured safe at), at most the given limit. Where both shifts are 0
    (the given model) the given table and limit are put back as they were computed; no compensation (``C_CROSS_G``
    0) leaves both as given."""
    limit = c[C_MODEL0_INJ_I_MAX]
    given = (dy_d == 0.0 and dy_q == 0.0) or c[C_CROSS_G] == 0.0
    phi_max = c[C_INJ_TILT_MAX]
    prev = 0.0
    for j in range(CROSS_POINTS):
        if given:
            c[C_CROSS + j] = c[C_MODEL0_CROSS + j]
            continue
        k = C_CROSS_G + 3 * j
        phi = 0.5 * math.atan2(2.0 * c[k + 1], c[k] + dy_d - (c[k + 2] + dy_q))
        c[C_CROSS + j] = phi
        if phi >= phi_max and (j == 0 or prev < phi_max):  # (none at all where already there at no current)
            limit = min(limit, 0.0 if j == 0 else CROSS_STEP * (j - 1 + (phi_max - prev) / (phi - prev)))
        prev = phi
    c[C_INJ_I_MAX] = limit


@kernel()
def adapt_apply(s, c):
    """(AD6) The estimates into the controller's and the EKF's model: psi_hat into C_PSI and the EKF's A3, A4
    constants (scaled from their values at the model's psi), R_s_hat into A8, A14."""
    r = s[S_AD_PSI] / c[C_AD_PSI0]
    c[C_PSI] = s[S_AD_PSI]
    c[C_C_WPSI] = c[C_AD_NOM_WPSI] * r
    c[C_C_TPSI] = c[C_AD_NOM_TPSI] * r
    c[C_A_RD] = 1.0 - s[S_AD_RS] * c[C_DT] / c[C_L_D]
    c[C_A_RQ] = 1.0 - s[S_AD_RS] * c[C_DT] / c[C_L_Q]


@kernel()
def adapt_period(s, c, i_alpha, i_beta, theta, omega_m, on_rotor):
    """The end of a control period: (AD1-AD5) the estimator over the period just gone, on the measured currents
    ``i_alpha``, ``i_beta`` at its end in the control frame at ``theta`` [rad] turning at ``omega_m`` [rad/s,
    mechanical], and the vector the unit held over it; then the vector just commanded (``S_V_ALPHA``, ``S_V_BETA``)
    kept for the next period, and with ``ADAPT_USE`` the estimates into the model (AD6). ``on_rotor`` 0.0: the
    frame is not the rotor's estimated one (the I-f strategy's alignment and I-f: the current vector's), neither
    fit updates. Returns nothing: the estimates and the observability flags are in ``S_AD_PSI``, ``S_AD_RS``,
    ``S_AD_SEEN``."""
    dt = c[C_DT]
    i_d, i_q = park(i_alpha, i_beta, theta)
    if s[S_AD_PRIMED_RS] == 0.0 and s[S_ID_RS] > 0.0:  # the R_s test at enable measured it: R_s_hat starts there
        s[S_AD_RS] = min(max(s[S_ID_RS], AD_RS_MIN * c[C_AD_RS0]), AD_RS_MAX * c[C_AD_RS0])
        s[S_AD_I2Y] = s[S_AD_I4] * s[S_AD_RS]
        s[S_AD_PRIMED_RS] = 1.0
    seen_psi = 0.0
    seen_rs = 0.0
    if s[S_AD_PRIMED_V] != 0.0 and on_rotor != 0.0:
        w_e = c[C_N] * omega_m
        a = 0.5 * w_e * dt
        u_d, u_q = park(s[S_AD_V_ALPHA], s[S_AD_V_BETA], s[S_AD_THETA_PREV] + a)  # (AD1)
        if abs(a) > 1e-6:
            g = math.sin(a) / a
            u_d *= g
            u_q *= g
        i_dm = 0.5 * (i_d + s[S_AD_ID_PREV])  # (AD2)
        i_qm = 0.5 * (i_q + s[S_AD_IQ_PREV])
        di_d = (i_d - s[S_AD_ID_PREV]) / dt
        di_q = (i_q - s[S_AD_IQ_PREV]) / dt
        f = min(dt / AD_RATE_FILTER, 1.0)
        s[S_AD_RATE_D] += f * (di_d - s[S_AD_RATE_D])
        s[S_AD_RATE_Q] += f * (di_q - s[S_AD_RATE_Q])
        steady = s[S_AD_RATE_D] * s[S_AD_RATE_D] + s[S_AD_RATE_Q] * s[S_AD_RATE_Q] <= c[C_AD_RATE] * c[C_AD_RATE]
        l_d = c[C_L_D]
        l_q = c[C_L_Q]
        gain = c[C_AD_GAIN]
        if steady and abs(w_e) >= c[C_AD_PSI_W]:  # (AD5) psi observable: (AD3)
            y = u_q - s[S_AD_RS] * i_qm - l_q * di_q - w_e * l_d * i_dm
            s[S_AD_W2] += gain * (w_e * w_e - s[S_AD_W2])
            s[S_AD_WY] += gain * (w_e * y - s[S_AD_WY])
            psi0 = c[C_AD_PSI0]
            s[S_AD_PSI] = min(max(s[S_AD_WY] / s[S_AD_W2], AD_PSI_MIN * psi0), AD_PSI_MAX * psi0)
            seen_psi = 1.0
        i2 = i_dm * i_dm + i_qm * i_qm
        if steady and abs(w_e) <= c[C_AD_RS_W] and i2 >= c[C_AD_RS_I] * c[C_AD_RS_I]:  # (AD5) R_s: (AD4)
            y = (u_d * i_dm + u_q * i_qm - l_d * di_d * i_dm - l_q * di_q * i_qm
                 - w_e * (s[S_AD_PSI] * i_qm + (l_d - l_q) * i_dm * i_qm))
            s[S_AD_I4] += gain * (i2 * i2 - s[S_AD_I4])
            s[S_AD_I2Y] += gain * (i2 * y - s[S_AD_I2Y])
            rs0 = c[C_AD_RS0]
            s[S_AD_RS] = min(max(s[S_AD_I2Y] / s[S_AD_I4], AD_RS_MIN * rs0), AD_RS_MAX * rs0)
            seen_rs = 1.0
    s[S_AD_PRIMED_V] = 1.0
    s[S_AD_SEEN_PSI] = seen_psi
    s[S_AD_SEEN_RS] = seen_rs
    s[S_AD_THETA_PREV] = wrap_angle(theta)
    s[S_AD_ID_PREV] = i_d
    s[S_AD_IQ_PREV] = i_q
    s[S_AD_V_ALPHA] = s[S_V_ALPHA]
    s[S_AD_V_BETA] = s[S_V_BETA]
    if c[C_ADAPT] == ADAPT_USE:
        adapt_apply(s, c)
