"""The observers' kernels: the EKF5's time update (eqs 23-24, model A2-A6 and Jacobian A8-A32),
the EKF4 (the same without T_L), the stationary-frame EKF5 (the voltage turned into its frame at
mid-period; h = the inverse Park of its currents), the measurement update (eqs 25-27), the magnet
flux adaptation (``adapt_psi``) and the dispatch by observer (``observer_predict``,
``observer_correct``).

The vectors ``s`` and ``c`` are laid out by ``pmsm_ev.kernels.layout`` (``S_*``, ``C_*``).
"""

from __future__ import annotations

import math

from .jit import F as _F
from .jit import V as _V
from .jit import kernel
from .jit import sig as _sig
from .layout import (
    C_A_RD,
    C_A_RQ,
    C_C_MID,
    C_C_TDQ,
    C_C_TH,
    C_C_TL,
    C_C_TPSI,
    C_C_VD,
    C_C_VQ,
    C_C_WD,
    C_C_WPSI,
    C_C_WQ,
    C_DELAYED,
    C_DT,
    C_EKF_BILINEAR,
    C_N,
    C_OBSERVER,
    C_PSI_ADAPT,
    C_PSI_ADAPT_W,
    C_Q,
    C_R0,
    C_R1,
    OBS_EKF4,
    OBS_EKF5,
    OBS_EKF5AB,
    S_A,
    S_K,
    S_P,
    S_PHT,
    S_PSI_RATIO,
    S_STARTED,
    S_THETA_PRIOR,
    S_U_PREV_0,
    S_U_PREV_1,
    S_V_ALPHA,
    S_V_BETA,
    S_X,
)
from .transforms import park, wrap_angle


# -- observers, eqs 23-27 ------------------------------------------------------------------------
@kernel()
def ekf5_time_update(s, c, v_d, v_q, f03, f13, c_mid):
    """EKF5 time update (23)-(24): x^f = f(x^e), P^f = J_f P J_f^T + Q, J_f at x^e (A8-A32).

    J_f rows: r0 = [f00 f01 f02 f03 0], r1 = [f10 f11 f12 f13 0], r2 = [f20 f21 1 0 f24],
    r3 = [0 0 f32 1 0], r4 = [0 0 0 0 1]. f03, f13 (the voltage's dependence on theta) and
    c_mid (that of its angle on omega) are zero for the dq EKF5, whose voltage input does
    not depend on its state; see ``ekf5ab_predict``.
    """
    i_d = s[S_X]
    i_q = s[S_X + 1]
    w = s[S_X + 2]
    th = s[S_X + 3]
    t_l = s[S_X + 4]
    c_wq, c_wd, c_wpsi = c[C_C_WQ], c[C_C_WD], c[C_C_WPSI]
    c_tpsi, c_tdq, c_th = c[C_C_TPSI], c[C_C_TDQ], c[C_C_TH]
    if c[C_PSI_ADAPT] != 0.0:  # the adapted magnet flux (``adapt_psi``) in A3, A4 and their Jacobian
        c_wpsi = c_wpsi * s[S_PSI_RATIO]
        c_tpsi = c_tpsi * s[S_PSI_RATIO]
    f00, f01, f02 = c[C_A_RD], c_wq * w, c_wq * i_q + f03 * c_mid  # (A8-A10)
    f10, f11, f12 = -c_wd * w, c[C_A_RQ], -c_wd * i_d - c_wpsi + f13 * c_mid  # (A13-A15)
    f20, f21, f24 = c_tdq * i_q, c_tpsi + c_tdq * i_d, c[C_C_TL]  # (A18, A19, A22)
    f32 = c_th  # (A25)
    s[S_X] = c[C_A_RD] * i_d + c_wq * w * i_q + c[C_C_VD] * v_d  # (A2)
    s[S_X + 1] = c[C_A_RQ] * i_q - c_wd * w * i_d - c_wpsi * w + c[C_C_VQ] * v_q  # (A3)
    s[S_X + 2] = w + c_tpsi * i_q + c_tdq * i_d * i_q + c[C_C_TL] * t_l  # (A4)
    s[S_X + 3] = th + c_th * w  # (A5); T_L: (A6)
    propagate5(s, c, f00, f01, f02, f03, f10, f11, f12, f13, f20, f21, f24, f32)  # (24)


@kernel()
def propagate5(s, c, f00, f01, f02, f03, f10, f11, f12, f13, f20, f21, f24, f32):
    """P^f = J_f P J_f^T + Q (24) for the EKF5's J_f (rows as in ``ekf5_time_update``), and the prior
    angle kept."""
    for j in range(5):  # A = J_f P, column by column
        p0 = s[S_P + j]
        p1 = s[S_P + 5 + j]
        p2 = s[S_P + 10 + j]
        p3 = s[S_P + 15 + j]
        p4 = s[S_P + 20 + j]
        s[S_A + j] = f00 * p0 + f01 * p1 + f02 * p2 + f03 * p3
        s[S_A + 5 + j] = f10 * p0 + f11 * p1 + f12 * p2 + f13 * p3
        s[S_A + 10 + j] = f20 * p0 + f21 * p1 + p2 + f24 * p4
        s[S_A + 15 + j] = f32 * p2 + p3
        s[S_A + 20 + j] = p4
    for i in range(5):  # P^f = A J_f^T + Q: column k of A J_f^T is A (row k of J_f)
        a0 = s[S_A + 5 * i]
        a1 = s[S_A + 5 * i + 1]
        a2 = s[S_A + 5 * i + 2]
        a3 = s[S_A + 5 * i + 3]
        a4 = s[S_A + 5 * i + 4]
        r = S_P + 5 * i
        s[r] = f00 * a0 + f01 * a1 + f02 * a2 + f03 * a3
        s[r + 1] = f10 * a0 + f11 * a1 + f12 * a2 + f13 * a3
        s[r + 2] = f20 * a0 + f21 * a1 + a2 + f24 * a4
        s[r + 3] = f32 * a2 + a3
        s[r + 4] = a4
        s[r + i] += c[C_Q + i]
    s[S_THETA_PRIOR] = s[S_X + 3]


@kernel()
def bilinear_currents(c, i_d, i_q, w, u_d, u_q, c_wpsi):
    """Tustin's step of the current model (A2-A3 as the trapezoidal rule, ``EkfParams.discretisation``
    "bilinear"): with di/dt = A i + b (eqs 10-11, A's entries the constants of A8-A15 over dt),
    (I - A dt/2) i' = (I + A dt/2) i + b dt, b dt = (dt/L_d u_d, dt/L_q u_q - N psi dt/L_q w).
    Returns i_d', i_q', the Jacobian entries d i'/d(i_d, i_q, omega_m) at the voltage held
    (g00, g01, g02, g10, g11, g12) and (I - A dt/2)^-1 (m00, m01, m10, m11), which maps a
    derivative of b dt onto one of i'."""
    r_d = 1.0 - c[C_A_RD]  # R_s dt / L_d
    r_q = 1.0 - c[C_A_RQ]
    a01 = c[C_C_WQ] * w
    a10 = -c[C_C_WD] * w
    det = (1.0 + 0.5 * r_d) * (1.0 + 0.5 * r_q) - 0.25 * a01 * a10
    m00 = (1.0 + 0.5 * r_q) / det
    m01 = 0.5 * a01 / det
    m10 = 0.5 * a10 / det
    m11 = (1.0 + 0.5 * r_d) / det
    rhs0 = (1.0 - 0.5 * r_d) * i_d + 0.5 * a01 * i_q + c[C_C_VD] * u_d
    rhs1 = 0.5 * a10 * i_d + (1.0 - 0.5 * r_q) * i_q + c[C_C_VQ] * u_q - c_wpsi * w
    x0 = m00 * rhs0 + m01 * rhs1
    x1 = m10 * rhs0 + m11 * rhs1
    g00 = m00 * (1.0 - 0.5 * r_d) + m01 * 0.5 * a10  # (I - A dt/2)^-1 (I + A dt/2)
    g01 = m00 * 0.5 * a01 + m01 * (1.0 - 0.5 * r_q)
    g10 = m10 * (1.0 - 0.5 * r_d) + m11 * 0.5 * a10
    g11 = m10 * 0.5 * a01 + m11 * (1.0 - 0.5 * r_q)
    h0 = 0.5 * c[C_C_WQ] * (i_q + x1)  # d/d omega of (I + A dt/2) i + b dt - (I - A dt/2) i'
    h1 = -0.5 * c[C_C_WD] * (i_d + x0) - c_wpsi
    return (x0, x1, g00, g01, m00 * h0 + m01 * h1, g10, g11, m10 * h0 + m11 * h1, m00, m01, m10, m11)


@kernel()
def ekf5_time_update_bilinear(s, c, u_d, u_q, du_th_d, du_th_q, du_w_d, du_w_q):
    """The EKF5's time update with Tustin's step of A2-A3 (``bilinear_currents``) for the input
    voltage (u_d, u_q), whose derivatives by theta and omega_m are du_th, du_w; A4-A6 as printed."""
    i_d = s[S_X]
    i_q = s[S_X + 1]
    w = s[S_X + 2]
    th = s[S_X + 3]
    t_l = s[S_X + 4]
    c_wpsi, c_tpsi, c_tdq, c_th = c[C_C_WPSI], c[C_C_TPSI], c[C_C_TDQ], c[C_C_TH]
    if c[C_PSI_ADAPT] != 0.0:
        c_wpsi = c_wpsi * s[S_PSI_RATIO]
        c_tpsi = c_tpsi * s[S_PSI_RATIO]
    x0, x1, f00, f01, f02, f10, f11, f12, m00, m01, m10, m11 = bilinear_currents(c, i_d, i_q, w, u_d, u_q, c_wpsi)
    vd = c[C_C_VD]
    vq = c[C_C_VQ]
    f03 = m00 * vd * du_th_d + m01 * vq * du_th_q
    f13 = m10 * vd * du_th_d + m11 * vq * du_th_q
    f02 += m00 * vd * du_w_d + m01 * vq * du_w_q
    f12 += m10 * vd * du_w_d + m11 * vq * du_w_q
    f20, f21, f24 = c_tdq * i_q, c_tpsi + c_tdq * i_d, c[C_C_TL]  # (A18, A19, A22)
    s[S_X] = x0
    s[S_X + 1] = x1
    s[S_X + 2] = w + c_tpsi * i_q + c_tdq * i_d * i_q + c[C_C_TL] * t_l  # (A4)
    s[S_X + 3] = th + c_th * w  # (A5); T_L: (A6)
    propagate5(s, c, f00, f01, f02, f03, f10, f11, f12, f13, f20, f21, f24, c_th)


@kernel()
def adapt_psi(s, c):
    """Adapt the stationary-frame EKF5's magnet flux (after its measurement update; on while
    |omega_hat| > ``C_PSI_ADAPT_W``). The estimated angle tracks the rotor, so over time it turns
    at the true electrical speed; with a wrong psi the model's back-EMF omega_hat psi_hat can match
    the currents only with a wrong omega_hat, and the Kalman gain then corrects the angle by the
    difference at every step: corr = theta_post - theta_prior has the mean N (omega - omega_hat) dt.
    The law d(psi_hat/psi)/dt = -gain corr / (N dt |omega_hat|) sign(omega_hat) raises psi_hat while
    omega_hat runs ahead of the angle's rate (psi_hat too small) and settles where the two agree;
    psi_hat/psi is kept within 0.5 .. 1.5."""
    w = s[S_X + 2]
    if abs(w) <= c[C_PSI_ADAPT_W]:
        return
    corr = wrap_angle(s[S_X + 3] - s[S_THETA_PRIOR])
    rate = -c[C_PSI_ADAPT] * corr / (c[C_N] * c[C_DT] * w)  # the sign of omega_hat via the division
    s[S_PSI_RATIO] = min(max(s[S_PSI_RATIO] + rate * c[C_DT], 0.5), 1.5)


@kernel()
def ekf5_predict(s, c, v_d, v_q):
    """The paper's EKF5 time update (eqs 23-24, A2-A32) with the dq voltage command of the period;
    with ``C_EKF_BILINEAR`` Tustin's step (``bilinear_currents``), the command taken as the held
    voltage (the vector at mid-period, with the angle advance of half a period)."""
    if c[C_EKF_BILINEAR] != 0.0:
        ekf5_time_update_bilinear(s, c, v_d, v_q, 0.0, 0.0, 0.0, 0.0)
        return
    ekf5_time_update(s, c, v_d, v_q, 0.0, 0.0, 0.0)


@kernel()
def ekf5ab_predict(s, c, v_alpha, v_beta):
    """Stationary-frame EKF5 time update with the alpha-beta vector the inverter held over
    the period, turned into the filter's own frame at mid-period,
    (v_d, v_q) = Park(v_alpha, v_beta, theta + N omega dt / 2), then A2-A6 as the EKF5.
    The angle thus enters J_f through the voltage: d v_d/d theta = v_q, d v_q/d theta = -v_d
    (f03, f13), and via the mid-period angle also d/d omega (c_mid). x0 is the estimate at
    the first sample, so the first call (the period before it) is no time update; see
    ``pmsm_ev.observers.Ekf5AlphaBeta``."""
    if s[S_STARTED] == 0.0:
        s[S_STARTED] = 1.0
        return
    c_mid = c[C_C_MID]
    v_d, v_q = park(v_alpha, v_beta, s[S_X + 3] + c_mid * s[S_X + 2])
    if c[C_EKF_BILINEAR] != 0.0:  # Tustin's step; d v / d theta = (v_q, -v_d), d v / d omega = c_mid of that
        ekf5_time_update_bilinear(s, c, v_d, v_q, v_q, -v_d, c_mid * v_q, -c_mid * v_d)
        return
    ekf5_time_update(s, c, v_d, v_q, c[C_C_VD] * v_q, -c[C_C_VQ] * v_d, c_mid)


@kernel()
def ekf4_predict(s, c, v_d, v_q):
    """EKF4 time update (eqs 23-24): the EKF5 model (A2, A3, A5) without T_L, omega a random walk (dw/dt = 0).

    J_f rows: r0 = [f00 f01 f02 0], r1 = [f10 f11 f12 0], r2 = [0 0 1 0], r3 = [0 0 f32 1].
    """
    i_d = s[S_X]
    i_q = s[S_X + 1]
    w = s[S_X + 2]
    th = s[S_X + 3]
    c_wq, c_wd, c_wpsi, c_th = c[C_C_WQ], c[C_C_WD], c[C_C_WPSI], c[C_C_TH]
    f32 = c_th
    if c[C_EKF_BILINEAR] != 0.0:  # Tustin's step, the command taken as the vector at mid-period
        x0, x1, f00, f01, f02, f10, f11, f12, _, _, _, _ = bilinear_currents(c, i_d, i_q, w, v_d, v_q, c_wpsi)
        s[S_X] = x0
        s[S_X + 1] = x1
    else:
        f00, f01, f02 = c[C_A_RD], c_wq * w, c_wq * i_q
        f10, f11, f12 = -c_wd * w, c[C_A_RQ], -c_wd * i_d - c_wpsi
        s[S_X] = c[C_A_RD] * i_d + c_wq * w * i_q + c[C_C_VD] * v_d  # (A2)
        s[S_X + 1] = c[C_A_RQ] * i_q - c_wd * w * i_d - c_wpsi * w + c[C_C_VQ] * v_q  # (A3)
    s[S_X + 3] = th + c_th * w  # (A5)
    for j in range(4):
        p0 = s[S_P + j]
        p1 = s[S_P + 4 + j]
        p2 = s[S_P + 8 + j]
        p3 = s[S_P + 12 + j]
        s[S_A + j] = f00 * p0 + f01 * p1 + f02 * p2
        s[S_A + 4 + j] = f10 * p0 + f11 * p1 + f12 * p2
        s[S_A + 8 + j] = p2
        s[S_A + 12 + j] = f32 * p2 + p3
    for i in range(4):
        a0 = s[S_A + 4 * i]
        a1 = s[S_A + 4 * i + 1]
        a2 = s[S_A + 4 * i + 2]
        a3 = s[S_A + 4 * i + 3]
        r = S_P + 4 * i
        s[r] = f00 * a0 + f01 * a1 + f02 * a2
        s[r + 1] = f10 * a0 + f11 * a1 + f12 * a2
        s[r + 2] = a2
        s[r + 3] = f32 * a2 + a3
        s[r + i] += c[C_Q + i]
    s[S_THETA_PRIOR] = s[S_X + 3]


@kernel()
def ekf_update(s, n, s00, s01, s11, y0, y1):
    """Eqs 25-27 from P H^T (at ``S_PHT``), S = H P H^T + R and the innovation y."""
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det  # S^-1
    for i in range(n):  # (25): K = P H^T S^-1; (26)
        a = s[S_PHT + 2 * i]
        b = s[S_PHT + 2 * i + 1]
        k0 = a * i00 + b * i01
        k1 = a * i01 + b * i11
        s[S_K + 2 * i] = k0
        s[S_K + 2 * i + 1] = k1
        s[S_X + i] += k0 * y0 + k1 * y1
    # (27): P - K (P H^T)^T, symmetric by construction; computed on the upper half
    for i in range(n):
        k0 = s[S_K + 2 * i]
        k1 = s[S_K + 2 * i + 1]
        for j in range(i, n):
            v = s[S_P + n * i + j] - k0 * s[S_PHT + 2 * j] - k1 * s[S_PHT + 2 * j + 1]
            s[S_P + n * i + j] = v
            s[S_P + n * j + i] = v
    s[S_X + 3] = wrap_angle(s[S_X + 3])


@kernel()
def ekf_correct_dq(s, c, n, i_d, i_q):
    """Eqs 25-27 with z = [i_d, i_q], h(x) = [x0, x1], J_h = [I_2 0] (A33)."""
    for i in range(n):
        s[S_PHT + 2 * i] = s[S_P + n * i]
        s[S_PHT + 2 * i + 1] = s[S_P + n * i + 1]
    ekf_update(s, n, s[S_P] + c[C_R0], s[S_P + 1], s[S_P + n + 1] + c[C_R1], i_d - s[S_X], i_q - s[S_X + 1])


@kernel()
def ekf5ab_correct(s, c, i_alpha, i_beta):
    """Eqs 25-27 with z = [i_alpha, i_beta], h(x) = inverse Park of (i_d, i_q) at theta.

    J_h rows: [c, -s, 0, h03, 0], [s, c, 0, h13, 0].
    """
    th = s[S_X + 3]
    ekf5ab_correct_at(s, c, i_alpha, i_beta, math.cos(th), math.sin(th))


@kernel()
def ekf5ab_correct_at(s, c, i_alpha, i_beta, cs, sn):
    """``ekf5ab_correct`` with cos and sin of the prior angle given (``cs``, ``sn``)."""
    xd = s[S_X]
    xq = s[S_X + 1]
    h03 = -sn * xd - cs * xq
    h13 = cs * xd - sn * xq
    for i in range(5):
        r = S_P + 5 * i
        s[S_PHT + 2 * i] = cs * s[r] - sn * s[r + 1] + h03 * s[r + 3]
        s[S_PHT + 2 * i + 1] = sn * s[r] + cs * s[r + 1] + h13 * s[r + 3]
    s00 = cs * s[S_PHT] - sn * s[S_PHT + 2] + h03 * s[S_PHT + 6] + c[C_R0]
    s01 = cs * s[S_PHT + 1] - sn * s[S_PHT + 3] + h03 * s[S_PHT + 7]
    s11 = sn * s[S_PHT + 1] + cs * s[S_PHT + 3] + h13 * s[S_PHT + 7] + c[C_R1]
    ekf_update(s, 5, s00, s01, s11, i_alpha - (cs * xd - sn * xq), i_beta - (sn * xd + cs * xq))


@kernel(_sig("none", _V, _V, _F, _F))
def observer_predict(s, c, u0, u1):
    """The time update (eqs 23-24) of the observer ``C_OBSERVER`` (none for the sensored baseline) with
    the voltage of the period: (v_d, v_q), or (v_alpha, v_beta) for the stationary-frame EKF5."""
    kind = c[C_OBSERVER]
    if kind == OBS_EKF5:
        ekf5_predict(s, c, u0, u1)
    elif kind == OBS_EKF4:
        ekf4_predict(s, c, u0, u1)
    elif kind == OBS_EKF5AB:
        ekf5ab_predict(s, c, u0, u1)


@kernel(_sig("none", _V, _V, _F, _F, _F, _F, _F, _F))
def observer_correct(s, c, i_alpha, i_beta, i_d, i_q, theta_meas, omega_meas):
    """The measurement update (eqs 25-27) of the observer ``C_OBSERVER``; the sensored baseline takes
    the measured currents, speed and angle."""
    kind = c[C_OBSERVER]
    if kind == OBS_EKF5:
        ekf_correct_dq(s, c, 5, i_d, i_q)
    elif kind == OBS_EKF4:
        ekf_correct_dq(s, c, 4, i_d, i_q)
    elif kind == OBS_EKF5AB:
        ekf5ab_correct(s, c, i_alpha, i_beta)
    else:
        s[S_X] = i_d
        s[S_X + 1] = i_q
        s[S_X + 2] = omega_meas
        s[S_X + 3] = theta_meas
        s[S_THETA_PRIOR] = theta_meas


@kernel()
def ekf5ab_period(s, c, i_alpha, i_beta):
    """The stationary-frame EKF5's control period in the sensorless unit: the time update (eqs 23-24) with
    the vector held over the last period (with ``C_DELAYED``, the one of a period earlier, the held one
    kept for the next), the measurement update (eqs 25-27) with the measured currents. Returns the
    magnitude of the innovation, the currents less the predicted ones before the update [A]."""
    return ekf5ab_period_on(s, c, i_alpha, i_beta, s[S_V_ALPHA], s[S_V_BETA])


@kernel()
def ekf5ab_period_on(s, c, i_alpha, i_beta, u_alpha, u_beta):
    """``ekf5ab_period`` with the vector held over the last period given, ``u_alpha``, ``u_beta`` [V] (with
    ``C_DELAYED`` kept for the next period, the one of a period earlier used)."""
    if c[C_DELAYED] != 0.0:
        ekf5ab_predict(s, c, s[S_U_PREV_0], s[S_U_PREV_1])
        s[S_U_PREV_0] = u_alpha
        s[S_U_PREV_1] = u_beta
    else:
        ekf5ab_predict(s, c, u_alpha, u_beta)
    th = s[S_X + 3]
    cs, sn = math.cos(th), math.sin(th)
    y0 = i_alpha - (cs * s[S_X] - sn * s[S_X + 1])
    y1 = i_beta - (sn * s[S_X] + cs * s[S_X + 1])
    ekf5ab_correct_at(s, c, i_alpha, i_beta, cs, sn)  # (25)-(27)
    return math.sqrt(y0 * y0 + y1 * y1)

