"""The controller's kernels: the speed PI (eq 14), the current PIs (eqs 15-16) with the
decoupling filters and terms (eqs 17-20), the dead-time compensation, and ``control_step``, one
control period of the units with an observer (or the sensored baseline): the observer's time and
measurement updates (eqs 23-27, ``pmsm_ev.kernels.observers``), eqs 14-20, the inverse Park to the
voltage held (see ``pmsm_ev.control_unit``).

The vectors ``s`` and ``c`` are laid out by ``pmsm_ev.kernels.layout`` (``S_*``, ``C_*``).
"""

from __future__ import annotations

import math

from .adaptation import adapt_period
from .jit import F as _F
from .jit import V as _V
from .jit import kernel
from .jit import sig as _sig
from .layout import (
    C_ADAPT,
    C_ADVANCE,
    C_BAT_LINK,
    C_BRAKE_GAIN,
    C_CC_HS,
    C_CC_PRED,
    C_DELAYED,
    C_DT,
    C_DTC_I0,
    C_DTC_V,
    C_ESTIMATED,
    C_FF,
    C_FF_T0,
    C_FF_T1,
    C_FF_T2,
    C_FW_MARGIN,
    C_HALF_PERIOD_N,
    C_I_D_REF,
    C_I_MAX,
    C_I_Q_MAX,
    C_J_FF,
    C_K_DQN,
    C_K_T,
    C_KI_ID,
    C_KI_IQ,
    C_KI_W,
    C_KP_ID,
    C_KP_IQ,
    C_KP_W,
    C_L_D,
    C_L_Q,
    C_N,
    C_OBSERVER,
    C_P_CHG,
    C_P_DIS,
    C_P_REGEN,
    C_PAPER_SIGNS,
    C_PSI,
    C_PSI_ADAPT,
    C_REF_MODE,
    C_T_D,
    C_T_MAX,
    C_U_FW,
    C_U_MAX,
    C_ZOH,
    OBS_EKF5AB,
    S_FF_PRIMED,
    S_I_D,
    S_I_DL,
    S_I_DREF,
    S_I_Q,
    S_I_QL,
    S_I_QREF,
    S_INT_D,
    S_INT_Q,
    S_REGION,
    S_SAT,
    S_T_AVAIL,
    S_T_BRAKE,
    S_T_FF,
    S_T_REF,
    S_THETA_PRIOR,
    S_U_PREV_0,
    S_U_PREV_1,
    S_V_ALPHA,
    S_V_BETA,
    S_V_D,
    S_V_OUT_ALPHA,
    S_V_OUT_BETA,
    S_V_Q,
    S_W_INT,
    S_W_REF_PREV,
    S_X,
)
from .observers import adapt_psi, observer_correct, observer_predict
from .plant import dead_time_error
from .references import envelope, friction_brake, references_within, regen_limit
from .transforms import inverse_park, park


# -- controller, eqs 14-20 -----------------------------------------------------------------------
@kernel()
def speed_pi(s, c, omega_ref, omega_est, limit):
    """Speed PI, eq 14, its output [A] limited to +-``limit``, with conditional integration."""
    e = omega_ref - omega_est
    unsat = c[C_KP_W] * e + s[S_W_INT]  # (14)
    out = min(max(unsat, -limit), limit)
    # anti-windup: integrate unless the output is clamped and e pushes further out
    if out == unsat or (unsat > limit) != (e > 0):
        s[S_W_INT] += c[C_KI_W] * e * c[C_DT]
    return out


@kernel()
def speed_pi_between(s, c, omega_ref, omega_est, lo, hi):
    """Speed PI, eq 14, its output [A] limited to [``lo``, ``hi``] (lo <= 0 <= hi), with conditional
    integration: ``speed_pi`` with the clamp moved by a feedforward's share of it."""
    e = omega_ref - omega_est
    unsat = c[C_KP_W] * e + s[S_W_INT]  # (14)
    out = min(max(unsat, lo), hi)
    # anti-windup: integrate unless the output is clamped and e pushes further out
    if out == unsat or (unsat > hi and e < 0) or (unsat < lo and e > 0):
        s[S_W_INT] += c[C_KI_W] * e * c[C_DT]
    return out


@kernel()
def speed_feedforward(s, c, omega_ref):
    """The speed loop's feedforward of this period, ``S_T_FF`` [N m] (``ControllerParams.speed_feedforward``,
    docs/cycles.md): the torque the reference itself needs, so that the PI (eq 14) only corrects what
    the model misses (a two-degree-of-freedom speed controller). The acceleration term J omega_ref' on
    the speed PI's own inertia ``C_J_FF`` (J_m + J_load = J_eq, eq 9's left side), with the reference's
    slope over the last period (omega_ref - omega_ref_prev) / dt (0 in the first period: no history);
    and the road load at the reference's speed, sign(omega_ref) (T0 + T1 |omega_ref| + T2 omega_ref^2)
    (coast-down coefficients at the shaft, ``C_FF_T0..2``: eqs 3-4's rolling and drag; 0 at a stand).
    Called every period, whatever the mode, so that the slope is always the last period's."""
    if s[S_FF_PRIMED] != 0.0:
        a_ref = (omega_ref - s[S_W_REF_PREV]) / c[C_DT]
    else:
        a_ref = 0.0
        s[S_FF_PRIMED] = 1.0
    s[S_W_REF_PREV] = omega_ref
    w = abs(omega_ref)
    road = c[C_FF_T0] + (c[C_FF_T1] + c[C_FF_T2] * w) * w
    if omega_ref < 0.0:
        road = -road
    elif omega_ref == 0.0:
        road = 0.0
    s[S_T_FF] = c[C_J_FF] * a_ref + road


@kernel(_sig(_F, _V, _V, _F, _F))
def speed_step(s, c, omega_ref, omega_est):
    """Speed PI, eq 14, i_qref limited to +-i_q_max, with conditional integration: ``speed_pi`` at
    ``C_I_Q_MAX``, written out as it was so that the paper's per-step path makes no extra call
    (tests/test_references.py checks that the two agree bit for bit)."""
    i_q_max = c[C_I_Q_MAX]
    e = omega_ref - omega_est
    unsat = c[C_KP_W] * e + s[S_W_INT]  # (14)
    i_qref = min(max(unsat, -i_q_max), i_q_max)
    # anti-windup: integrate unless the output is clamped and e pushes further out
    if i_qref == unsat or (unsat > i_q_max) != (e > 0):
        s[S_W_INT] += c[C_KI_W] * e * c[C_DT]
    return i_qref


@kernel()
def current_step_hs(s, c, i_dref, i_qref, i_d, i_q, omega_est):
    """The high-speed current control (``ControllerParams.current_control = "high_speed"``,
    docs/speed-range.md): the PIs (15-16) on the errors; the decoupling and back-EMF terms of eqs
    19-20 on the current predicted at the middle of the period the voltage is applied over,
    x = i + C_CC_PRED (i_ref - i) (the closed loop's first-order response); under the voltage limit
    only the PI part u is shortened, v = f + lam u with |v| = u_max (f, the operating point's own
    voltage, here on the measured current, keeps its dq angle; if |f| alone exceeds u_max, the whole vector
    is scaled, as in ``current_step``, so that the PIs still turn it; within the rest the d PI
    part comes first, the field-weakening current, and the q part gets what is left), and the integrators
    are updated with the realisable reference error (u_lim - I) / K_p, the error the limited
    voltage realises (Harnefors' anti-windup), not held. The filters of eqs 17-18 run on, unused."""
    dt = c[C_DT]
    e_d = i_dref - i_d
    e_q = i_qref - i_q
    kp_d = c[C_KP_ID]
    kp_q = c[C_KP_IQ]
    u_d = kp_d * e_d + s[S_INT_D]  # (15)
    u_q = kp_q * e_q + s[S_INT_Q]  # (16)
    w_e = c[C_N] * omega_est
    k = c[C_CC_PRED]
    f_d = -w_e * c[C_L_Q] * (i_q + k * e_q)  # (19) on the predicted current
    f_q = w_e * (c[C_L_D] * (i_d + k * e_d) + c[C_PSI])  # (20), the signs that cancel (11)
    s[S_I_DL] += dt / c[C_T_D] * (i_dref - s[S_I_DL])  # (17)
    s[S_I_QL] += dt / c[C_T_D] * (i_qref - s[S_I_QL])  # (18)
    u_max = c[C_U_MAX]
    v_d = f_d + u_d
    v_q = f_q + u_q
    if v_d * v_d + v_q * v_q > u_max * u_max:  # priority: f, then the d PI part, then the q PI part
        s[S_SAT] = 1.0
        # limited, the loop does not follow its design: f on the measured current
        f_d = -w_e * c[C_L_Q] * i_q
        f_q = w_e * (c[C_L_D] * i_d + c[C_PSI])
        f2 = f_d * f_d + f_q * f_q
        if f2 >= u_max * u_max:  # the present current's own voltage is beyond the limit: the whole vector
            scale = u_max / math.sqrt(v_d * v_d + v_q * v_q)  # scaled, so that the PIs still turn it
            v_d *= scale
            v_q *= scale
            r_d = v_d - f_d  # the PI part it realises
            r_q = v_q - f_q
        elif (f_d + u_d) * (f_d + u_d) + f_q * f_q > u_max * u_max:  # the d part shortened, no q part
            r_d = extension(f_d, f_q, u_d, 0.0, u_max) * u_d
            r_q = 0.0
            v_d = f_d + r_d
            v_q = f_q
        else:  # the d part whole, the q part shortened
            r_d = u_d
            r_q = extension(f_d + u_d, f_q, 0.0, u_q, u_max) * u_q
            v_d = f_d + r_d
            v_q = f_q + r_q
        s[S_INT_D] += c[C_KI_ID] * dt * (r_d - s[S_INT_D]) / kp_d  # the realisable reference
        s[S_INT_Q] += c[C_KI_IQ] * dt * (r_q - s[S_INT_Q]) / kp_q
    else:
        s[S_SAT] = 0.0
        s[S_INT_D] += c[C_KI_ID] * e_d * dt
        s[S_INT_Q] += c[C_KI_IQ] * e_q * dt
    return v_d, v_q


@kernel()
def extension(f_d, f_q, u_d, u_q, u_max):
    """The lam in [0, 1] with |f + lam u| = u_max, for |f| < u_max < |f + u|."""
    a = u_d * u_d + u_q * u_q
    b = f_d * u_d + f_q * u_q
    return (math.sqrt(b * b + a * (u_max * u_max - f_d * f_d - f_q * f_q)) - b) / a

@kernel()
def generate_references(s, c, t_dem, omega_est):
    """The reference generator on a torque demand ``t_dem`` [N m] at the speed ``omega_est``
    (``pmsm_ev.kernels.references``): a braking demand limited to the regenerative power
    (``regen_limit``), the rest of it the friction brake's (``friction_brake``); returns
    (i_dref, i_qref) and keeps them, the torque given, the brake's demand, the region and the torque
    available in the state (``S_I_DREF`` .. ``S_T_AVAIL``)."""
    t_env, lam, d_top, region_top = envelope(omega_est, c[C_K_DQN], c[C_PSI], c[C_L_D], c[C_L_Q], c[C_N],
                                             c[C_I_MAX], c[C_U_FW])
    return references_of(s, c, t_dem, omega_est, t_env, lam, d_top, region_top)


@kernel()
def unit_dc_link(c, v_dc, p_charge, p_discharge):
    """The control unit on a measured DC link (the controller's inputs; a battery's, ``pmsm_ev.kernels.battery_step``):
    with ``v_dc`` > 0 [V] the voltage limit of the current control becomes v_dc / sqrt 3 and that of the field
    weakening ``C_FW_MARGIN`` of it, so that the references follow the battery's sag; the battery's charge acceptance
    ``p_charge`` and discharge power ``p_discharge`` [W] bound the torque's power at the shaft
    (``battery_power_limit``). ``v_dc`` <= 0 (unconnected): nothing changes (the parameters' constant link)."""
    if v_dc > 0.0:
        c[C_BAT_LINK] = 1.0
        c[C_U_MAX] = v_dc / math.sqrt(3.0)
        c[C_U_FW] = c[C_FW_MARGIN] * c[C_U_MAX]
        c[C_P_CHG] = p_charge
        c[C_P_DIS] = p_discharge


@kernel()
def battery_power_limit(t, omega, p_charge, p_discharge):
    """The torque ``t`` [N m] at the speed ``omega`` held within the battery's powers at the shaft: a braking torque
    (t omega < 0) to ``p_charge`` / |omega| (what the battery accepts: the rest is the friction brake's), a motoring
    one to ``p_discharge`` / |omega|. The motor's and the inverter's losses lie between the shaft and the battery:
    braking, the battery gets less than the shaft's power (the bound holds), motoring it gives more (by the losses)."""
    p = t * omega
    if p < 0.0:
        cap = p_charge / abs(omega)
        return -cap if t < -cap else (cap if t > cap else t)
    if p > 0.0:
        cap = p_discharge / abs(omega)
        return -cap if t < -cap else (cap if t > cap else t)
    return t


@kernel()
def references_of(s, c, t_dem, omega_est, t_env, lam, d_top, region_top):
    """``generate_references`` on the limits ``envelope`` gives at ``omega_est`` (and the battery's powers,
    ``battery_power_limit``, on a measured DC link)."""
    t_motor = regen_limit(t_dem, omega_est, c[C_P_REGEN])
    if c[C_BAT_LINK] != 0.0:
        t_motor = battery_power_limit(t_motor, omega_est, c[C_P_CHG], c[C_P_DIS])
    i_dref, i_qref, t_given, t_avail, region = references_within(
        t_motor, c[C_K_DQN], c[C_PSI], c[C_L_D], c[C_L_Q], c[C_I_MAX], c[C_T_MAX], t_env, lam, d_top, region_top)
    s[S_I_DREF] = i_dref
    s[S_T_REF] = t_given
    s[S_T_BRAKE] = friction_brake(t_dem, t_given, omega_est, c[C_BRAKE_GAIN])
    s[S_REGION] = region
    s[S_T_AVAIL] = t_avail
    return i_dref, i_qref


@kernel()
def torque_speed_step(s, c, omega_ref, omega_est):
    """The speed loop of the reference generator's modes (``C_REF_MODE`` != 0): the speed PI (eq 14,
    the same gains) commands the torque T = k_t x its output (k_t = k_dq N psi, ``C_K_T``: the loop gain
    of the paper's mode), plus with ``C_FF`` the feedforward ``S_T_FF`` (``speed_feedforward``); its clamp
    and conditional integration at the torque available at the present speed (``envelope``, within T_max:
    no windup where field weakening gives less than asked); the generator turns T into (i_dref, i_qref)
    (``generate_references``)."""
    return torque_speed_step_within(s, c, omega_ref, omega_est, c[C_T_MAX])


@kernel()
def torque_speed_step_within(s, c, omega_ref, omega_est, t_limit):
    """``torque_speed_step`` with its torque held within ``t_limit`` [N m] too (below T_max: a mode whose
    observer cannot carry the drive's whole current)."""
    k_t = c[C_K_T]
    t_env, lam, d_top, region_top = envelope(omega_est, c[C_K_DQN], c[C_PSI], c[C_L_D], c[C_L_Q], c[C_N],
                                             c[C_I_MAX], c[C_U_FW])
    t_cap = min(t_env, c[C_T_MAX], t_limit)
    if c[C_FF] != 0.0:  # the feedforward (``speed_feedforward``, this period's) plus the PI on what is left
        t_ff = min(max(s[S_T_FF], -t_cap), t_cap)
        u = speed_pi_between(s, c, omega_ref, omega_est, (-t_cap - t_ff) / k_t, (t_cap - t_ff) / k_t)  # (14)
        return references_of(s, c, k_t * u + t_ff, omega_est, t_env, lam, d_top, region_top)
    u = speed_pi(s, c, omega_ref, omega_est, t_cap / k_t)  # (14)
    return references_of(s, c, k_t * u, omega_est, t_env, lam, d_top, region_top)


@kernel(_sig(f"UniTuple({_F}, 2)", _V, _V, _F, _F, _F, _F, _F))
def current_step(s, c, i_dref, i_qref, i_d, i_q, omega_est):
    """Current PIs (15-16), decoupling filters (17-18) and terms (19-20); the voltage
    vector limited to u_max, the integrators held while it is limited. With ``C_CC_HS`` the
    high-speed current control instead (``current_step_hs``)."""
    if c[C_CC_HS] != 0.0:
        return current_step_hs(s, c, i_dref, i_qref, i_d, i_q, omega_est)
    dt = c[C_DT]
    e_d = i_dref - i_d
    e_q = i_qref - i_q
    u_d = c[C_KP_ID] * e_d + s[S_INT_D]  # (15)
    u_q = c[C_KP_IQ] * e_q + s[S_INT_Q]  # (16)
    w_e = c[C_N] * omega_est
    v_d = u_d - w_e * c[C_L_Q] * s[S_I_QL]  # (19)
    if c[C_PAPER_SIGNS] != 0.0:
        v_q = u_q - w_e * c[C_L_D] * s[S_I_DL] - w_e * c[C_PSI]  # (20) as printed
    else:
        v_q = u_q + w_e * c[C_L_D] * s[S_I_DL] + w_e * c[C_PSI]  # (20) corrected to cancel (11)
    s[S_I_DL] += dt / c[C_T_D] * (i_dref - s[S_I_DL])  # (17)
    s[S_I_QL] += dt / c[C_T_D] * (i_qref - s[S_I_QL])  # (18)
    u_max = c[C_U_MAX]
    mag = math.sqrt(v_d * v_d + v_q * v_q)
    if mag > u_max:
        s[S_SAT] = 1.0
        if mag == math.inf:  # the squares overflowed (|v| > 1e154 V): the length of the
            big = max(abs(v_d), abs(v_q))  # scaled vector; NaN if a component is infinite
            mag = big * math.sqrt((v_d / big) * (v_d / big) + (v_q / big) * (v_q / big))
        scale = u_max / mag
        v_d *= scale
        v_q *= scale
    else:
        s[S_SAT] = 0.0
        s[S_INT_D] += c[C_KI_ID] * e_d * dt
        s[S_INT_Q] += c[C_KI_IQ] * e_q * dt
    return v_d, v_q


@kernel()
def modulate(c, v_d, v_q, theta, omega, zoh):
    """The vector to hold over the period: the inverse Park of (v_d, v_q) at the control angle
    ``theta`` advanced by ``C_ADVANCE`` omega (``angle_advance`` periods), times the ZOH gain: with the
    high-speed current control sin(a)/a, else with ``zoh`` and ``C_ZOH`` a/sin(a) (a = omega_e dt / 2,
    ``zoh_compensation``), else 1."""
    half_arc = c[C_HALF_PERIOD_N] * omega  # a = omega_e dt / 2
    if c[C_CC_HS] != 0.0:
        gain = math.sin(half_arc) / half_arc if abs(half_arc) > 1e-6 else 1.0
    else:
        gain = half_arc / math.sin(half_arc) if zoh and c[C_ZOH] != 0.0 and abs(half_arc) > 1e-6 else 1.0
    return inverse_park(gain * v_d, gain * v_q, theta + c[C_ADVANCE] * omega)


@kernel()
def dead_time_compensated(c, v_alpha, v_beta, i_alpha, i_beta):
    """The voltage sent to the inverter with dead-time compensation: the command minus the
    error ``dead_time_error`` expects for the measured currents, so that the applied voltage
    is the command again. The observers keep the command (``S_V_ALPHA``, ``S_V_BETA``) as
    their voltage input: the compensation's aim is that the motor sees it."""
    e_alpha, e_beta = dead_time_error(i_alpha, i_beta, c[C_DTC_V], c[C_DTC_I0])
    return v_alpha - e_alpha, v_beta - e_beta


@kernel()
def compensate_dead_time(s, c, v_alpha, v_beta, i_alpha, i_beta):
    """``dead_time_compensated``, the result also kept in ``S_V_OUT_ALPHA``, ``S_V_OUT_BETA``."""
    v_alpha, v_beta = dead_time_compensated(c, v_alpha, v_beta, i_alpha, i_beta)
    s[S_V_OUT_ALPHA] = v_alpha
    s[S_V_OUT_BETA] = v_beta
    return v_alpha, v_beta


# -- the control unit ----------------------------------------------------------------------------
@kernel()
def store_command(s, c, i_alpha, i_beta, i_d, i_q, i_qref, v_d, v_q, v_alpha, v_beta):
    """End of a control period, every unit alike: keep the period's currents, references and
    command in the state; return the vector sent to the inverter (the command, plus the dead
    time's expected loss with dead-time compensation on)."""
    s[S_I_D] = i_d
    s[S_I_Q] = i_q
    s[S_I_QREF] = i_qref
    s[S_V_D] = v_d
    s[S_V_Q] = v_q
    s[S_V_ALPHA] = v_alpha
    s[S_V_BETA] = v_beta
    if c[C_DTC_V] != 0.0:
        return compensate_dead_time(s, c, v_alpha, v_beta, i_alpha, i_beta)
    return v_alpha, v_beta


@kernel(_sig(f"UniTuple({_F}, 12)", _V, _V, _F, _F, _F, _F, _F))
def control_step(s, c, i_alpha, i_beta, omega_ref, theta_meas, omega_meas):
    """One control period (see ``pmsm_ev.control_unit``): the observer's eqs 23-27, eqs 14-20; returns
    (v_alpha, v_beta, v_d, v_q, i_d, i_q, i_qref, i_d_hat, i_q_hat, omega_hat, theta_hat, T_L_hat)."""
    # (23)-(24) with the voltage applied over the last period: the last command, or with a
    # one-period actuation delay, the command before it; the dq command, or for the
    # stationary-frame EKF5 the alpha-beta vector sent to the inverter
    if c[C_OBSERVER] == OBS_EKF5AB:
        u0 = s[S_V_ALPHA]
        u1 = s[S_V_BETA]
    else:
        u0 = s[S_V_D]
        u1 = s[S_V_Q]
    if c[C_DELAYED] != 0.0:
        observer_predict(s, c, s[S_U_PREV_0], s[S_U_PREV_1])
        s[S_U_PREV_0] = u0
        s[S_U_PREV_1] = u1
    else:
        observer_predict(s, c, u0, u1)
    estimated = c[C_ESTIMATED] != 0.0
    theta_frame = s[S_THETA_PRIOR] if estimated else theta_meas
    i_d, i_q = park(i_alpha, i_beta, theta_frame)
    observer_correct(s, c, i_alpha, i_beta, i_d, i_q, theta_meas, omega_meas)  # (25)-(27)
    if c[C_PSI_ADAPT] != 0.0:
        adapt_psi(s, c)
    if estimated:
        theta_ctrl = s[S_X + 3]
        i_d, i_q = park(i_alpha, i_beta, theta_ctrl)
    else:
        theta_ctrl = theta_meas
    omega_hat = s[S_X + 2]
    if c[C_REF_MODE] != 0.0:  # the reference generator: MTPA, field weakening, limits, regen
        if c[C_FF] != 0.0:
            speed_feedforward(s, c, omega_ref)
        i_dref, i_qref = torque_speed_step(s, c, omega_ref, omega_hat)
    else:  # the paper's: i_d = i_d_ref, i_q from the speed PI
        i_dref = c[C_I_D_REF]
        i_qref = speed_step(s, c, omega_ref, omega_hat)  # (14)
    v_d, v_q = current_step(s, c, i_dref, i_qref, i_d, i_q, omega_hat)  # (15)-(20)
    v_alpha, v_beta = modulate(c, v_d, v_q, theta_ctrl, omega_hat, True)
    v_alpha, v_beta = store_command(s, c, i_alpha, i_beta, i_d, i_q, i_qref, v_d, v_q, v_alpha, v_beta)
    if c[C_ADAPT] != 0.0:  # psi and R_s over the period just gone (AD1-AD6)
        adapt_period(s, c, i_alpha, i_beta, theta_ctrl, omega_hat, 1.0)
    return (v_alpha, v_beta, v_d, v_q, i_d, i_q, i_qref,
            s[S_X], s[S_X + 1], s[S_X + 2], s[S_X + 3], s[S_X + 4])
