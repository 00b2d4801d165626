"""The sensorless unit with injection at and near zero speed (``InjectionParams.low_speed`` =
"injection"): a state machine of modes, events and one transition table (docs/sensorless.md,
"Closed loop at zero speed").

Modes (``S_MODE``):

* ``MODE_ACQUIRE``: the square wave on, no current: the rotor's axis from the answers on two axes 45
  deg apart (``C_ACQ_TIME`` each), then the tracking observer settles (``C_ACQ_SETTLE``); at the first
  acquisition after enable the unit then measures its motor (``identify``: the d admittance on the found
  d axis, then on the q axis, ``C_ID_TIME`` each), so that the injection's error signal has the motor's
  gain, not the data sheet's;
* ``MODE_POLARITY``: d current pulses of +- ``C_POL_I`` (no torque on the d axis): the sign whose d
  admittance is the larger is the magnet's direction (its saturation);
* ``MODE_INJECTION``: FOC (eqs 14-20) on the tracking observer's angle and speed, the EKF's blended in
  with the speed (``blend_weight``), the square wave fading out with the same weight;
* ``MODE_EKF``: FOC on the stationary-frame EKF5 alone (eqs 23-27), no injection.

Each period the detectors (small functions, each of one purpose and timer) return at most one event
(``EV_*``, by priority); ``transition`` looks the (mode, event) pair up in ``TRANSITIONS``, the one
ordered table, and runs the row's entry action. A pair not in the table changes nothing. The mechanism
is the I-f strategy's too (``kernels.machine``).

A detector that does not judge the estimate by itself (``detect_emf_lost``): the current PIs' integrators carry,
at steady state, the voltage the motor needs less the decoupling and back-EMF terms the controller adds on the
frame's speed omega_hat (eqs 19-20); less the resistance's drop, what is left is the back-EMF the frame's speed does
not explain. A rotor turning at omega under a frame off it by e leaves N omega psi (sin e, cos e) - N omega_hat psi
(0, 1) there; as a speed

    r = |(I_d - R i_d, I_q - R i_q)| / (N psi)                                                        (LS1)

(I_d, I_q the integrators, i_d, i_q the currents in the frame, R the identified R_s, psi the model's), and the
frame has lost the rotor where, filtered as the other detectors (``C_LOS_FILTER``), for ``C_INJ_LOS_TIME``

    r_f > C_EMF_SPEED + C_EMF_REL w_f,   w = |(I_d - R i_d, I_q - R i_q + N omega_hat psi)| / (N psi)    (LS2)

w the rotor's speed the current loops see (all the back-EMF they carry, the frame's feed-forward's with it): the
share of it a magnet that is not the model's leaves unexplained. A frame that spins over a standing rotor leaves
r = |omega_hat|, w = 0; a rotor turning under a standing frame r = w = |omega|.

It sees a rotor that turns under a frame that stands or turns otherwise, whatever the injection's error signal or
the EKF (fed by the injection at low speed) say.

The fault output, as the I-f strategy's: a loss of synchronism begins an episode (``FAULT_RECOVERING``),
which ends after ``C_RECOVER_TIME`` without trouble, or latches the safe state after ``C_FAULT_TIME``:
stop and hold, closed loop at zero speed (the reference taken as 0). A polarity left unresolved twice
latches it too, without torque: no torque is given on an unknown polarity.
"""

from __future__ import annotations

import math

from .adaptation import adapt_period, model_apply
from .control import (
    current_step,
    modulate,
    speed_feedforward,
    speed_pi,
    store_command,
    torque_speed_step_within,
)
from .injection import (
    SKIP_HALF_WAVES,
    angle_error,
    blend_weight,
    blended_frame,
    cross_offset,
    demodulate,
    error_gain,
    fundamental,
    injection_share,
    injection_voltage,
    seat_tracker,
    seed_fundamental,
    start_injection,
    track,
)
from .jit import F as _F
from .jit import V as _V
from .jit import kernel
from .jit import sig as _sig
from .layout import (
    C_ACQ_SETTLE,
    C_ACQ_TIME,
    C_AD_RS0,
    C_ADAPT,
    C_ADVANCE,
    C_ANGLE_MAX,
    C_AXIS_COS,
    C_BLEND_HI,
    C_BLEND_HYST,
    C_BLEND_LO,
    C_DELAYED,
    C_DT,
    C_EKF_LOS_EMF,
    C_EKF_LOS_I,
    C_EKF_LOS_TIME,
    C_EMF_REL,
    C_EMF_SPEED,
    C_FF,
    C_GAIN_SE,
    C_GAIN_TURNS,
    C_HOLD_BRAKE,
    C_I_D_REF,
    C_I_Q_MAX,
    C_ID_TIME,
    C_INJ_I_MAX,
    C_INJ_LOS_ANGLE,
    C_INJ_LOS_TIME,
    C_INJ_M,
    C_INJ_V,
    C_INJ_V_MAX,
    C_INJ_Y,
    C_K_T,
    C_LOS_FILTER,
    C_MODEL_SRC,
    C_N,
    C_OFS_TIME,
    C_P0,
    C_P0_ALIGNED,
    C_POL_BAND,
    C_POL_CONTRAST,
    C_POL_HOLD,
    C_POL_I,
    C_POL_RAMP,
    C_PSI,
    C_REF_MODE,
    C_RS_I,
    C_RS_TIME,
    C_SALIENCY_HOLD,
    C_SALIENCY_MIN,
    C_SALIENCY_TRUST,
    C_SEE_MAX,
    C_T_MAX,
    C_T_RAMP,
    C_TRK_L1,
    FAULT_LATCHED,
    FAULT_NONE,
    MODE_ACQUIRE,
    MODE_EKF,
    MODE_INJECTION,
    MODE_POLARITY,
    MODEL_IDENTIFIED,
    S_ACQ,
    S_ACQ_N0,
    S_ACQ_N45,
    S_ACQ_SIN0,
    S_ACQ_SIN45,
    S_ALIGN_CLOCK,
    S_AXIS_F,
    S_BLEND,
    S_CROSS,
    S_DISAGREE_COS,
    S_DISAGREE_F,
    S_DISAGREE_SIN,
    S_EKF_LOS_T,
    S_EMF_F,
    S_EMF_SEEN,
    S_EMF_T,
    S_EVENT,
    S_FAULT,
    S_GAIN_RATIO,
    S_GAIN_SUM_A,
    S_GAIN_SUM_B,
    S_GAIN_TURNS,
    S_HOLD,
    S_I_D,
    S_I_D_HAT,
    S_I_DL,
    S_I_Q,
    S_I_Q_HAT,
    S_I_QL,
    S_ID_A_D,
    S_ID_A_D2,
    S_ID_A_Q,
    S_ID_A_Q2,
    S_ID_ACC,
    S_ID_BLIND,
    S_ID_D_SQ,
    S_ID_D_SUM,
    S_ID_DONE,
    S_ID_N_D,
    S_ID_N_D2,
    S_ID_N_Q,
    S_ID_N_Q2,
    S_ID_NOISE,
    S_ID_NOISE_F,
    S_ID_OFS_ALPHA,
    S_ID_OFS_BETA,
    S_ID_RS,
    S_ID_SUM,
    S_ID_Y_D,
    S_ID_Y_Q,
    S_ID_YE_D,
    S_ID_YE_Q,
    S_IF_FALLBACK,
    S_INJ_ADM,
    S_INJ_AXIS,
    S_INJ_ERR,
    S_INJ_ERR_F,
    S_INJ_LOS_T,
    S_INJ_NEW,
    S_INJ_SKIP,
    S_INJ_VA,
    S_INJ_YX,
    S_INT_D,
    S_INT_Q,
    S_MODE,
    S_MODE_TIME,
    S_OFS_ALPHA,
    S_OFS_BETA,
    S_OFS_N,
    S_OFS_SUM,
    S_OMEGA_CTRL,
    S_OMEGA_HAT,
    S_PARKED,
    S_POL,
    S_POL_AXIS,
    S_POL_N_NEG,
    S_POL_N_POS,
    S_POL_TRIES,
    S_POL_Y_NEG,
    S_POL_Y_POS,
    S_RESID_F,
    S_RS_I1,
    S_RS_I2,
    S_RS_N1,
    S_RS_N2,
    S_RS_SUM,
    S_RS_V1,
    S_RS_V2,
    S_THETA_CTRL,
    S_THETA_HAT,
    S_TL_HAT,
    S_TRK_OMEGA,
    S_TRK_THETA,
    S_TRK_TL,
    S_U_PREV_ALPHA,
    S_U_PREV_BETA,
    S_V_ALPHA,
    S_V_BETA,
    S_V_D,
    S_V_FUND_ALPHA,
    S_V_FUND_BETA,
    S_V_OUT_ALPHA,
    S_V_OUT_BETA,
    S_W_INT,
)
from .machine import (
    A_ACQUIRE,
    A_EKF_ALONE,
    A_FLIP_TORQUE,
    A_IF_FALLBACK,
    A_INJECTION_ON,
    A_PARK,
    A_POLARITY,
    A_REACQUIRE,
    A_REACQUIRE_PARKED,
    A_REPOLARIZE,
    A_RESEAT,
    A_RESTART_EKF,
    A_RETRY,
    A_TORQUE,
    EV_ACQUIRED,
    EV_BLIND_STOP,
    EV_CANNOT_SEE,
    EV_DISAGREE,
    EV_EKF_LOST,
    EV_EMF_LOST,
    EV_FAST,
    EV_FLIPPED,
    EV_INJECTION_LOST,
    EV_NONE,
    EV_POLARITY_FLIPPED,
    EV_POLARITY_RIGHT,
    EV_POLARITY_UNRESOLVED,
    EV_SLOW,
    EV_STILL_PARKED,
    MODE_ALIGN,
    next_mode,
)
from .observers import ekf5ab_period, ekf5ab_period_on
from .startup import (
    age_episode,
    begin_episode,
    enter_if_strategy,
    fault_output,
    model_torque,
    restart_ekf_on,
    sensorless_step,
)
from .transforms import park, wrap_angle

# -- the schedules of the acquisition and the polarity test ----------------------------------------
#: the acquisition's phases (``acquisition_phase``): on the first axis, on the axis 45 deg ahead, the tracking
#: observer settling, the identification on the found d axis at the square wave's amplitude and at twice it, on
#: the q axis at both, the R_s test's d current at its lower and its upper level, over
(PHASE_AXIS0, PHASE_AXIS45, PHASE_SETTLE, PHASE_ID_D, PHASE_ID_D2, PHASE_ID_Q, PHASE_ID_Q2, PHASE_RS1, PHASE_RS2,
 PHASE_OVER) = range(10)
#: ... and before them all, at the first acquisition after enable, the offset window: no voltage, no current
PHASE_OFFSET = 10
#: eq ID3's noise factor of the tracking observer (I3, three poles at -a): its angle's answer H(s) = (3 a s^2 + 3 a^2 s
#: + a^3) / (s + a)^3 to the error signal's noise has (1 / pi) int_0^inf |H(j w)|^2 dw = 33 a / 16
TRACK_NOISE = 33.0 / 16.0
#: the injection's angle and the EKF's are of opposite polarities where they differ by more than this [rad]:
#: half a turn of the electrical angle's two candidates 0 and pi (the tracking observer sees the axis, not its
#: direction; the EKF's back-EMF sees the direction)
FLIP_ANGLE = 0.5 * math.pi
#: the acquisition's second axis, this far ahead of the first [rad]: the answers' sin 2e on the first and on it
#: (-cos 2e there) give the axis's angle 2e by atan2 whatever its quadrant
AXIS_AHEAD = 0.25 * math.pi
#: the polarity test's tries: the second left unresolved latches the fault (a direction the test cannot tell at
#: two acquisitions' angles in a row is not one the injection can drive on)
POL_TRIES = 2.0
#: each hold of the polarity test is measured after this share of it: the current loop settles in its first quarter
POL_SETTLE_SHARE = 0.25
#: the blend's weight up to which the injection's angle and the EKF's are judged against each other
#: (``detect_injection_lost``): its first quarter, where the square wave is at half its amplitude or more
#: (``injection_share``) and the injection's angle still worth the EKF's
DISAGREE_BLEND = 0.25
#: a loss detector's timer has run its time once within this share of a period of it (``timed_out``): the sum of the
#: periods' dt rounds, and a timer must not miss its time by one period for it
TIMER_SLACK = 0.5
#: the identification's lower amplitude: this share of ``C_INJ_V_MAX``, the higher all of it (ID1: the two amplitudes
#: V and 2 V cancel the dead time's voltage)
ID_LOWER_SHARE = 0.5
#: the R_s test gives nothing where the current rose by less than half the levels' difference (``C_RS_I`` / 2):
#: this share of ``C_RS_I`` (a current that does not follow its reference: an open phase, no DC link)
RS_RISE_MIN = 0.25


@kernel()
def parks(s, c):
    """True where the unit holds the car on the friction brake at its stops and finds the angle afresh for each
    restart (``park_car``, ``detect_blind_stop``): a blind unit (``S_ID_BLIND``), and a seeing one whose identified
    saliency is below ``C_SALIENCY_HOLD``: too little to hold a car on a slope on the injection's angle (the phase
    sensors' mismatch turns the axis by more at a lower saliency until it is measured, and a car that creeps under
    the hold moves the rotor faster than a weak error signal pulls the tracking observer: the low-saliency corner's
    motor of 1.085, read 1.13, its sensors measured, slipped a turn at its first hold on a 1.9 % slope). Off where
    ``C_SALIENCY_HOLD`` is 0 (a blind unit parks whatever)."""
    if s[S_ID_BLIND] != 0.0:
        return True
    if c[C_SALIENCY_HOLD] == 0.0:
        return False
    return s[S_ID_Y_Q] > 0.0 and s[S_ID_Y_D] < c[C_SALIENCY_HOLD] * s[S_ID_Y_Q]


@kernel()
def pools(s, c):
    """True where the unit keeps its identification's answers from acquisition to acquisition (``enter_acquire``)
    and adds its parked acquisitions' (``refining``): a blind unit (``S_ID_BLIND``), and, with the sensors' relative
    gain measured at standstill (``C_GAIN_SE`` > 0, eq SG0), a unit that parks (``parks``) until it is."""
    if s[S_ID_BLIND] != 0.0:
        return True
    return c[C_GAIN_SE] != 0.0 and c[C_GAIN_TURNS] != 0.0 and s[S_GAIN_RATIO] == 0.0 and parks(s, c)


@kernel()
def refining(s, c):
    """True where a unit that pools its answers (``pools``) holds the car at a stop (``S_PARKED``): its acquisitions
    measure the motor again and pool their answers with the enable's, so that the saliency a blind unit judged itself
    blind by is measured from more answers at every stop, at the rotor angles the stops give: the sensors' noise (at
    1.5 A the enable's 0.5 s read a motor of saliency 1.10 from 4.5 % low to 12.9 % high over 16 rotor angles,
    ``pmsm_cosim.app.identification_study``) falls as one over the root of the stops' time and the phase sensors'
    gain mismatch (up to 2 |g_a - g_b| / sqrt 3 of it, as cos 2 theta) averages out over their angles; and, where it
    is on, the mismatch itself from the answers' antisymmetric part (``standstill_gain``, eq SG0). A blind unit the
    pooled answers find above ``C_SALIENCY_TRUST`` is no longer blind and drives on the injection from its next
    restart; a unit that does not pool is not measured again (its detectors watch it)."""
    return s[S_PARKED] != 0.0 and pools(s, c)


@kernel()
def balance_sensors(s, c, i_alpha, i_beta):
    """The phase sensors' relative gain, measured on the EKF and taken out of the measurements [A]. Two sensors of
    gains g_a, g_b (the third phase their sum's negative) read i_alpha = g_a i_a and phase b as g_b i_b; a balanced
    three-phase current has equal squares on every phase over whole electrical turns, so over the turns the EKF
    drives (the square wave off: the motor's currents alone)

        g_a / g_b = sqrt(sum i_alpha^2 / sum i_b^2),   i_b = (sqrt 3 i_beta - i_alpha) / 2            (SG1)

    and, once the sums span ``C_GAIN_TURNS`` electrical turns (their part turns at either end a share of one over
    them), phase b is read as (g_a / g_b) i_b from then on, the two sensors alike:

        i_beta <- (i_alpha + 2 (g_a / g_b) i_b) / sqrt 3                                              (SG2)

    A common gain scales every current alike (the loops take it out); a mismatch reads, in the injection's
    answers, as a saliency fixed to the stator, (g_a - g_b) / sqrt 3 of the mean admittance, which turns the
    axis a motor of little saliency is found on (``C_SALIENCY_HOLD``). The sums go on after: the ratio follows the
    sensors as they warm. The noise's squares add alike to both sums (the sensors' noise is alike)."""
    if c[C_GAIN_TURNS] == 0.0:
        return i_alpha, i_beta
    i_b = 0.5 * (math.sqrt(3.0) * i_beta - i_alpha)
    if s[S_MODE] == MODE_EKF:
        s[S_GAIN_SUM_A] += i_alpha * i_alpha
        s[S_GAIN_SUM_B] += i_b * i_b
        s[S_GAIN_TURNS] += abs(c[C_N] * s[S_OMEGA_HAT]) * c[C_DT] / (2.0 * math.pi)
        if s[S_GAIN_TURNS] >= c[C_GAIN_TURNS] and s[S_GAIN_SUM_B] > 0.0:  # (SG1)
            s[S_GAIN_RATIO] = math.sqrt(s[S_GAIN_SUM_A] / s[S_GAIN_SUM_B])
    r = s[S_GAIN_RATIO]
    if r == 0.0:
        return i_alpha, i_beta
    return i_alpha, (i_alpha + 2.0 * r * i_b) / math.sqrt(3.0)  # (SG2)


@kernel()
def standstill_gain(s, c):
    """(SG0) The phase sensors' relative gain at standstill, from the identification's cross answers pooled since
    enable. The sensors read M i, M = [[g_a, 0], [(g_a - g_b) / sqrt 3, g_b]] in alpha-beta, whose antisymmetric
    part is a turn by (g_a - g_b) / (2 sqrt 3); the rotor's admittance Y is symmetric, so that the answers M Y have
    an antisymmetric part Y_s (g_a - g_b) / (2 sqrt 3) (to first order in the mismatch and in Y_x / Y_s), the same
    on every axis: the cross answer on the found d axis less the one on the q axis as the d one is taken
    (``cross_admittance``'s b_d and -b_q), (b_d + b_q) / 2 by (ID1). With y_s = (y_d + y_q) / 2 (the common gain
    in it too):

        x = (g_a - g_b) / g = 2 sqrt 3 (b_d + b_q) / (2 y_s),   g_a / g_b = (1 + x / 2) / (1 - x / 2)    (SG0)

    taken into ``S_GAIN_RATIO`` (read by ``balance_sensors``, SG2) once x's standard error, from the answers'
    scatter, is at most ``C_GAIN_SE``, and only while no ratio is taken yet; the pooled sums then start afresh (the
    answers after it are balanced, those before it not). A low-saliency motor of seed 6464 (1.098, gains 0.981 /
    1.014: g_a / g_b 0.9675) parked from enable took 0.9679 after 4.6 s."""
    if c[C_GAIN_SE] == 0.0 or c[C_GAIN_TURNS] == 0.0 or s[S_GAIN_RATIO] != 0.0:
        return
    if not (s[S_ID_Y_D] > 0.0 and s[S_ID_Y_Q] > 0.0):
        return
    b = 0.0
    var = 0.0
    for j in range(4):
        if s[S_ID_N_D + j] < 2.0:
            return
        b_j, var_j = cross_answer(s, c, j)
        w = -0.5 if j % 2 == 0 else 1.0  # (ID1): 2 b(2 V) - b(V), halved over the two axes
        b += w * b_j
        var += w * w * var_j
    k = 2.0 * math.sqrt(3.0) / (0.5 * (s[S_ID_Y_D] + s[S_ID_Y_Q]))
    x = k * b
    if k * math.sqrt(var) <= c[C_GAIN_SE] and abs(x) < 2.0:
        s[S_GAIN_RATIO] = (1.0 + 0.5 * x) / (1.0 - 0.5 * x)  # (SG0)
        for j in range(8):  # the answers from here on are balanced: a parking unit pools them afresh
            s[S_ID_SUM + j] = 0.0
            s[S_ID_NOISE + j] = 0.0


@kernel()
def identification_time(s, c):
    """The identification's time on each axis [s]: ``C_ID_TIME`` in the first acquisition after enable and in every
    parked acquisition of a blind unit (``refining``), 0 in the others (a reacquisition, which may find the car
    rolling, does not measure again)."""
    return c[C_ID_TIME] if s[S_ID_DONE] == 0.0 or refining(s, c) else 0.0


@kernel()
def offset_time(s, c):
    """The offset window's time [s]: ``C_OFS_TIME`` in the first acquisition after enable, 0 after."""
    return c[C_OFS_TIME] if s[S_ID_DONE] == 0.0 else 0.0


@kernel()
def rs_test_time(s, c):
    """The R_s test's time at each level [s]: ``C_RS_TIME`` in the first acquisition after enable, 0 after."""
    return c[C_RS_TIME] if s[S_ID_DONE] == 0.0 else 0.0


@kernel()
def acquisition_phase(s, c, t):
    """The acquisition's phase (``PHASE_*``) at the time ``t`` [s] in it: on the first axis, on the axis 45 deg
    ahead (``C_ACQ_TIME`` each), the tracking observer settling (``C_ACQ_SETTLE``), the identification on the
    found d axis and on the q axis (``identification_time`` each, half of it at half ``C_INJ_V_MAX``, half at all
    of it), the R_s test's two levels, over; at the first acquisition after enable all of them after the offset
    window (``offset_time``: ``PHASE_OFFSET``)."""
    t = t - offset_time(s, c)
    if t < 0.0:
        return PHASE_OFFSET
    half = 0.5 * identification_time(s, c)
    t_settled = 2.0 * c[C_ACQ_TIME] + c[C_ACQ_SETTLE]
    if t < c[C_ACQ_TIME]:
        return PHASE_AXIS0
    if t < 2.0 * c[C_ACQ_TIME]:
        return PHASE_AXIS45
    if t < t_settled:
        return PHASE_SETTLE
    for j in range(4):
        if t < t_settled + (j + 1) * half:
            return PHASE_ID_D + j
    t_rs = rs_test_time(s, c)
    if t < t_settled + 4.0 * half + t_rs:
        return PHASE_RS1
    if t < t_settled + 4.0 * half + 2.0 * t_rs:
        return PHASE_RS2
    return PHASE_OVER


@kernel()
def rs_level_time(s, c, t):
    """The time [s] since the R_s test's present level began (``t`` the time in the acquisition, in
    ``PHASE_RS1`` or ``PHASE_RS2``)."""
    t_rs1 = offset_time(s, c) + 2.0 * c[C_ACQ_TIME] + c[C_ACQ_SETTLE] + 2.0 * identification_time(s, c)
    return t - t_rs1 - (rs_test_time(s, c) if acquisition_phase(s, c, t) == PHASE_RS2 else 0.0)


@kernel()
def identify_rs(s, c):
    """R_s from the R_s test: the d current held at two levels on the found d axis at standstill (no back-EMF, no
    change of flux: the d voltage is R_s i_d plus the inverter's dead-time voltage, about the same at both levels
    where the current keeps its sign), the d PI's integral (its steady voltage, without the proportional part's
    noise) over the current:

        R_s = (v_2 - v_1) / (i_2 - i_1)                                                         (ID2)

    the difference cancelling the dead-time voltage. Nothing where a level brought no sample or the current did
    not rise by half the levels' difference (``S_ID_RS`` stays 0)."""
    n1 = s[S_RS_N1]
    n2 = s[S_RS_N2]
    if n1 < 1.0 or n2 < 1.0:
        return
    di = s[S_RS_I2] / n2 - s[S_RS_I1] / n1
    if not di > RS_RISE_MIN * c[C_RS_I]:
        return
    r = (s[S_RS_V2] / n2 - s[S_RS_V1] / n1) / di  # (ID2)
    if r > 0.0:
        s[S_ID_RS] = r


@kernel()
def phase_starts(s, c, t, phase):
    """True in the first period of the acquisition's ``phase`` (the time ``t`` [s] in the acquisition)."""
    return acquisition_phase(s, c, t - c[C_DT]) != phase


@kernel()
def identify(s, c):
    """The motor identified from the acquisition's identification phases: the mean d admittance a of the answers
    on the found d axis and on the q axis, each at the square wave's amplitude V and at 2 V. (I1) at e = 0 and at
    e = 90 deg gives Y_s + Y_x = 1/L_d and Y_s - Y_x = 1/L_q, the incremental admittances at zero current; the
    inverter's dead time takes a voltage of about constant size from each half-wave (the ripple crosses zero in
    its middle, whatever its amplitude), so that a(V) = y (1 - V_e / V), and the difference of the two amplitudes
    cancels it (as the two levels of a DC test cancel the dead time's voltage in R_s):

        y = (2 V a(2 V) - V a(V)) / (2 V - V) = 2 a(2 V) - a(V)                                   (ID1)

    ``S_ID_BLIND`` says whether the saliency L_q / L_d = y_d / y_q is below ``C_SALIENCY_MIN`` (in a blind unit's
    parked acquisitions, ``refining``: below ``C_SALIENCY_TRUST``). The square wave's
    amplitude from then on (``S_INJ_VA``) gives the error signal the current per unit of sin 2e the data sheet's
    motor gives at ``C_INJ_V`` without dead time, C_INJ_V C_INJ_Y, as the square wave sees it: the error signal's
    gain at V is E(V) = Y_x - B / V with (ID1)'s dead-time share B = V ((y_d - a_d(V)) - (y_q - a_q(V))) / 2, so

        V_a E(V_a) = C_INJ_V C_INJ_Y,   V_a = (C_INJ_V C_INJ_Y + B) / Y_x                          (ID4)

    within [C_INJ_V, C_INJ_V_MAX] (the angle's noise at a stop, eq ID3, then the design's whatever the dead time
    takes; sized on Y_x alone, a motor whose answers lose a quarter to the dead time at 30 V kept three quarters
    of the design's signal and was found blind by ID3 at 1.5 A). The admittances as the square wave sees them at
    V_a ((ID1) solved for a(V_a)), ``S_ID_YE``, give the error signal's gain (``S_INJ_YX``, ``error_gain``) and
    the axis's cos 2e (``axis_cosine``). Nothing is identified where an amplitude on an axis
    brought no answer or an admittance that is not positive (no voltage reached the motor): the model's gain
    and amplitude stay."""
    for j in range(4):
        if s[S_ID_N_D + j] < 1.0:
            return
    v = identification_amplitude(c, 0)  # the lower amplitude
    a_d = s[S_ID_A_D] / s[S_ID_N_D]
    a_q = s[S_ID_A_Q] / s[S_ID_N_Q]
    y_d = 2.0 * s[S_ID_A_D2] / s[S_ID_N_D2] - a_d  # (ID1)
    y_q = 2.0 * s[S_ID_A_Q2] / s[S_ID_N_Q2] - a_q
    # the found axis off the d axis by e: the d admittances read Y_s +- Y_x cos 2e and the cross ones +-Y_x sin 2e (I1);
    # the saliency from both, whatever e (ID5)
    b_v, var_v, b_y, var_y = cross_admittance(s, c)
    e = 0.5 * math.atan2(b_y, 0.5 * (y_d - y_q))  # the found axis's error, from the answers of the whole identification
    a_d, a_q = on_axis_admittances(a_d, a_q, b_v, var_v)
    y_d, y_q = on_axis_admittances(y_d, y_q, b_y, var_y)
    if not (y_d > 0.0 and y_q > 0.0 and a_d > 0.0 and a_q > 0.0):
        return
    if s[S_ID_DONE] == 0.0:  # the enable's answers, all on this acquisition's axis: the tracking observer put on the
        # axis they give (their 240 ms against the acquisition's 80), and the polarity test's frame with it (ID5)
        seat_tracker(s, wrap_angle(s[S_TRK_THETA] + e), 0.0, 0.0)
        s[S_POL_AXIS] = s[S_TRK_THETA]
    s[S_ID_Y_D] = y_d
    s[S_ID_Y_Q] = y_q
    identify_noise(s)
    # a blind unit's pooled answers must show more to be trusted (a seeing unit's pooled answers the same least)
    limit = c[C_SALIENCY_TRUST] if s[S_ID_DONE] != 0.0 and s[S_ID_BLIND] != 0.0 else c[C_SALIENCY_MIN]
    s[S_ID_BLIND] = 1.0 if y_d < limit * y_q else 0.0
    if y_d > y_q:
        b = 0.5 * v * ((y_d - a_d) - (y_q - a_q))  # the dead time's share of the error signal's gain, times V
        v_a = min(max((c[C_INJ_V] * c[C_INJ_Y] + b) / (0.5 * (y_d - y_q)), c[C_INJ_V]), c[C_INJ_V_MAX])  # (ID4)
        s[S_INJ_VA] = v_a
        e_d = y_d - v * (y_d - a_d) / v_a  # a(V_a) of (ID1)
        e_q = y_q - v * (y_q - a_q) / v_a
        s[S_ID_YE_D] = e_d
        s[S_ID_YE_Q] = e_q
        if e_d > e_q:
            s[S_INJ_YX] = 0.5 * (e_d - e_q)
            s[S_ID_ACC] = angle_accuracy(c, s[S_ID_NOISE_F], v_a, s[S_INJ_YX])
            if s[S_ID_ACC] > c[C_ANGLE_MAX]:  # too noisy an angle for the injection to hold the car on
                s[S_ID_BLIND] = 1.0
        else:  # no error signal at the amplitude the square wave will have
            s[S_ID_BLIND] = 1.0


@kernel()
def cross_answer(s, c, j):
    """The mean cross answer of the identification's phase ``PHASE_ID_D + j`` (the q part of its second differences,
    ``S_ID_NOISE``) as an admittance [1/H], and its variance [1/H^2] (0 with fewer than two answers): over 2 m dt V,
    the answer's [A] per [1/H] at the phase's amplitude V."""
    n = s[S_ID_N_D + j]
    scale = 2.0 * c[C_INJ_M] * c[C_DT] * identification_amplitude(c, j)  # 2 m dt V: the answer's [A] per [1/H]
    b = s[S_ID_D_SUM + j] / n / scale
    var = 0.0
    if n > 1.0:
        var = max(s[S_ID_D_SQ + j] - s[S_ID_D_SUM + j] * s[S_ID_D_SUM + j] / n, 0.0) / ((n - 1.0) * n)
        var /= scale * scale
    return b, var


@kernel()
def cross_admittance(s, c):
    """Y_x sin 2e from the identification's cross answers (``cross_answer``) [1/H], with its variance [1/H^2]: at the
    lower amplitude, then by (ID1). On the q axis (90 deg on) the cross answer is -Y_x sin 2e, so (b_d - b_q) / 2."""
    b_v = b_y = var_v = var_y = 0.0
    for j in range(4):
        b, var = cross_answer(s, c, j)
        sign = 1.0 if j < 2 else -1.0  # (b_d - b_q) / 2
        if j % 2 == 0:  # the lower amplitude: its own, and -1 of it in (ID1)
            b_v += 0.5 * sign * b
            var_v += 0.25 * var
            b_y -= 0.5 * sign * b
            var_y += 0.25 * var
        else:  # the higher: 2 of it in (ID1)
            b_y += sign * b
            var_y += var
    return b_v, var_v, b_y, var_y


@kernel()
def on_axis_admittances(a_d, a_q, b, var):
    """The admittances on the d and q axes from those read on an axis off by e, a_d, a_q = Y_s +- Y_x cos 2e, and the
    cross one b = Y_x sin 2e (variance ``var``): Y_s +- Y_x, Y_x^2 = ((a_d - a_q) / 2)^2 + b^2 - var (the noise's
    share of b^2 taken out; at least 0)                                                              (ID5)
    [1/H]."""
    y_s = 0.5 * (a_d + a_q)
    x = 0.5 * (a_d - a_q)
    y_x = math.sqrt(max(x * x + b * b - var, 0.0))
    return y_s + y_x, y_s - y_x


@kernel()
def identify_noise(s):
    """The current measurement's noise floor from the identification's answers: the q part of each answer's second
    difference D (I2), its sign the half-wave's, scatters about its phase's mean by the sensors' noise n alone, D =
    n_k - 2 n_(k-1) + n_(k-2) of variance 6 sigma_q^2 (sigma_q the noise along the answer's q direction). The found
    d axis's phases see it along q, the q axis's along d: over the two, sigma_q^2 = (sigma_alpha^2 + sigma_beta^2) /
    2 = 4/3 sigma^2 with two phase sensors of sigma each (i_alpha = i_a, i_beta = (i_a + 2 i_b) / sqrt 3). So sigma =
    sqrt(v / 8), v the four phases' pooled variance; ``S_ID_NOISE_F`` [A]."""
    ss = 0.0
    dof = 0.0
    for j in range(4):
        n = s[S_ID_N_D + j]
        if n > 1.0:
            ss += s[S_ID_D_SQ + j] - s[S_ID_D_SUM + j] * s[S_ID_D_SUM + j] / n
            dof += n - 1.0
    if dof > 0.0:
        s[S_ID_NOISE_F] = math.sqrt(max(ss, 0.0) / dof / 8.0)


@kernel()
def angle_accuracy(c, sigma, v_a, y_x):
    """The rms angle error [rad] the tracking observer keeps at a stop on the injection's answers, from the noise
    floor ``sigma`` [A] (a phase sensor's), the square wave's amplitude ``v_a`` [V] and the error signal's gain
    ``y_x`` [1/H] (I1):

        sigma_theta = sigma_q / (V_a Y_x) sqrt(33 a / (16 m dt)),   sigma_q = sqrt(4/3) sigma          (ID3)

    An answer's error signal is D_q / (2 m dt V_a Y_x) = sin 2e, the angle e half its asin; the noise of the answers,
    their sign the half-wave's, is (1 + z^-1)^2 on white noise of sigma_q (``identify_noise``), 4 sigma_q at the
    observer's low frequencies, so e's noise is sigma_q / (m dt V_a Y_x) an answer, white at the answers' period m dt;
    the observer (I3, three poles at -a, a = l1 / 3) passes (1 / pi) int |H|^2 dw = 33 a / 16 of it
    (``TRACK_NOISE``). Table I's motor, sigma = 1 A, 30 V, a = 50 rad/s: 0.052 rad (measured from 24 start angles:
    0.05 rad rms)."""
    if not (y_x > 0.0 and v_a > 0.0):
        return 0.0
    m_dt = c[C_INJ_M] * c[C_DT]
    a = c[C_TRK_L1] / 3.0
    return math.sqrt(4.0 / 3.0) * sigma / (v_a * y_x) * math.sqrt(TRACK_NOISE * a / m_dt)


@kernel()
def identification_amplitude(c, j):
    """The square wave's amplitude [V] in the identification's phase ``PHASE_ID_D + j``: half ``C_INJ_V_MAX`` and all
    of it on the found d axis, then on the q axis (ID1: the largest the voltage limit leaves, so that the dead
    time's voltage and the sensors' noise take the least share)."""
    return c[C_INJ_V_MAX] * (1.0 if j % 2 == 1 else ID_LOWER_SHARE)


@kernel()
def injection_amplitude(s, c):
    """The square wave's full amplitude [V]: the identification's (``S_INJ_VA``) once it has run, else
    ``C_INJ_V``."""
    return s[S_INJ_VA] if s[S_INJ_VA] > 0.0 else c[C_INJ_V]


@kernel()
def axis_cosine(s, adm):
    """cos 2e of the tracking observer's axis error e from a d admittance ``adm`` [1/H] at the square wave's full
    amplitude and the identified admittances as it sees them (``S_ID_YE``): (I1) adm = Y_s + Y_x cos 2e, clipped
    to +-1; 1 where the motor is not identified. Independent of the error signal sin 2e: a tracking observer
    pulled 45 deg or more off the axis shows cos 2e <= 0 whatever its own error signal says."""
    y_d = s[S_ID_YE_D]
    y_q = s[S_ID_YE_Q]
    if not (y_d > y_q and y_q > 0.0):
        return 1.0
    x = (adm - 0.5 * (y_d + y_q)) / (0.5 * (y_d - y_q))
    return min(max(x, -1.0), 1.0)


@kernel()
def polarity_schedule(c, t):
    """The polarity test at the time ``t`` [s] in it: (d current reference [A], which sign is measured
    now: +1, -1 or 0, over: 1.0 once done). +i, -i, +i joined by ramps, a palindrome whose current integrates
    to zero (each hold at +i (h - r) / 2, the one at -i h, h = ``C_POL_HOLD``, r = ``C_POL_RAMP``): the
    torque that an angle error e leaks from the d current (i sin e on q, times the magnet's flux) pushes the
    car forth, back and forth, so that its speed and its displacement both come back to zero (a plain +i, -i
    pair leaves a displacement of the order of i sin e h^2 / J). Each hold is measured in its last three
    quarters (the current loop settles in its first)."""
    i = c[C_POL_I]
    r = c[C_POL_RAMP]
    h = c[C_POL_HOLD]
    h_plus = 0.5 * (h - r)  # each hold at +i
    t1 = r + h_plus  # the first hold at +i ends
    t2 = t1 + 2.0 * r  # the ramp to -i ends
    t3 = t2 + h  # the hold at -i ends
    t4 = t3 + 2.0 * r  # the ramp back to +i ends
    t5 = t4 + h_plus  # the second hold at +i ends
    if t < r:
        return i * t / r, 0.0, 0.0
    if t < t1:
        return i, 1.0 if t >= r + POL_SETTLE_SHARE * h_plus else 0.0, 0.0
    if t < t2:
        return i - i * (t - t1) / r, 0.0, 0.0
    if t < t3:
        return -i, -1.0 if t >= t2 + POL_SETTLE_SHARE * h else 0.0, 0.0
    if t < t4:
        return -i + i * (t - t3) / r, 0.0, 0.0
    if t < t5:
        return i, 1.0 if t >= t4 + POL_SETTLE_SHARE * h_plus else 0.0, 0.0
    if t < t5 + r:
        return i - i * (t - t5) / r, 0.0, 0.0
    return 0.0, 0.0, 1.0


# -- detectors: each returns an event or EV_NONE ---------------------------------------------------
@kernel()
def detect_acquired(s, c):
    """EV_ACQUIRED once the acquisition is over (none while the fault is latched: a polarity left
    unresolved stops the unit here)."""
    if s[S_FAULT] == FAULT_LATCHED and s[S_POL_TRIES] >= POL_TRIES:
        return EV_NONE
    return EV_ACQUIRED if acquisition_phase(s, c, s[S_MODE_TIME]) == PHASE_OVER else EV_NONE


@kernel()
def cannot_see(s, c):
    """True where the identification found the motor (both admittances) but its angle accuracy at a stop (eq ID3,
    ``S_ID_ACC``) is beyond ``C_SEE_MAX``, or there is no error signal at all (no saliency: ``S_ID_ACC`` 0): the
    injection cannot find the axis the acquisition and the polarity test need (the design's corner motor, saliency
    1.06 at 1.5 A: 0.77 rad, its polarity test unresolved twice, the fault latched at enable), where a motor blind
    by its saliency alone (``C_SALIENCY_MIN``) with an accurate angle is still found at every stop (``park_car``).
    Only on a car the brake held through the identification (``S_HOLD``: the hill hold at enable, a parked stop):
    a rotor rolling under it turns the axes it measures on and reads no saliency whatever the motor's."""
    if not (s[S_ID_Y_D] > 0.0 and s[S_ID_Y_Q] > 0.0 and s[S_ID_BLIND] != 0.0 and s[S_HOLD] > 0.0):
        return False
    return not (0.0 < s[S_ID_ACC] <= c[C_SEE_MAX])


@kernel()
def sensors_balanced(s, c):
    """True where the phase sensors' relative gain is measured (``S_GAIN_RATIO``, eqs SG0, SG1) or never will be at
    standstill (``C_GAIN_SE`` or ``C_GAIN_TURNS`` 0)."""
    return s[S_GAIN_RATIO] != 0.0 or c[C_GAIN_SE] == 0.0 or c[C_GAIN_TURNS] == 0.0


@kernel()
def detect_polarity(s, c):
    """At the end of the polarity test: EV_POLARITY_RIGHT where the d admittance at +i exceeds that at -i
    by at least ``C_POL_CONTRAST`` of their mean (a positive d current saturates the d axis),
    EV_POLARITY_FLIPPED where the opposite, else EV_POLARITY_UNRESOLVED."""
    _, _, done = polarity_schedule(c, s[S_MODE_TIME])
    if done == 0.0:
        return EV_NONE
    if s[S_POL_N_POS] < 1.0 or s[S_POL_N_NEG] < 1.0:
        return EV_POLARITY_UNRESOLVED
    y_pos = s[S_POL_Y_POS] / s[S_POL_N_POS]
    y_neg = s[S_POL_Y_NEG] / s[S_POL_N_NEG]
    contrast = (y_pos - y_neg) / (0.5 * (abs(y_pos) + abs(y_neg)) + 1e-300)
    if contrast >= c[C_POL_CONTRAST]:
        return EV_POLARITY_RIGHT
    if contrast <= -c[C_POL_CONTRAST]:
        return EV_POLARITY_FLIPPED
    return EV_POLARITY_UNRESOLVED


@kernel()
def axis_lost(s, c):
    """The tracking observer has left the rotor's axis by the d admittance (``axis_cosine``, filtered:
    ``S_AXIS_F``): cos 2e below ``C_AXIS_COS``, in FOC on the injection once the motor is identified. It does not
    judge the observer by its own error signal, whose gain a mismatched motor changes and which points back to
    the axis only within 45 deg."""
    return s[S_MODE] == MODE_INJECTION and s[S_ID_Y_D] > 0.0 and s[S_AXIS_F] < c[C_AXIS_COS]


@kernel()
def timed_out(s, c, timer, trouble, time):
    """A loss detector's timer (the slot ``timer``): it counts the time ``trouble`` has held (0 where it does not);
    True, the timer back at 0, once it has counted ``time`` [s] less ``TIMER_SLACK`` of a period (the rounding of
    the sum of dt's)."""
    s[timer] = s[timer] + c[C_DT] if trouble else 0.0
    if s[timer] < time - TIMER_SLACK * c[C_DT]:
        return False
    s[timer] = 0.0
    return True


@kernel()
def detect_injection_lost(s, c):
    """EV_INJECTION_LOST when the tracking observer's filtered angle error has stayed beyond
    ``C_INJ_LOS_ANGLE`` for ``C_INJ_LOS_TIME`` (its timer ``S_INJ_LOS_T``), or the d admittance has shown its
    axis lost that long (``axis_lost``): the injection no longer sees the axis it tracks (the saliency gone, or
    the rotor slipped faster than the observer follows); in the blend's first quarter (the square wave at half
    its amplitude or more: ``injection_share``), where the injection's angle and the EKF's (plus the
    cross-saturation's offset), both against the tracking observer, filtered as a vector (``S_DISAGREE_V``: no
    wrap at +-pi), have stayed that far apart: EV_FLIPPED beyond ``FLIP_ANGLE`` (the tracking observer on the
    axis's other direction, which the injection cannot see and the back-EMF can), else EV_DISAGREE."""
    w = s[S_BLEND]
    far = abs(s[S_INJ_ERR_F]) > c[C_INJ_LOS_ANGLE] or axis_lost(s, c)
    apart = 0.0 < w <= DISAGREE_BLEND and abs(s[S_DISAGREE_F]) > c[C_INJ_LOS_ANGLE]
    if not timed_out(s, c, S_INJ_LOS_T, far or apart, c[C_INJ_LOS_TIME]):
        return EV_NONE
    if far:
        return EV_INJECTION_LOST
    return EV_FLIPPED if abs(s[S_DISAGREE_F]) > FLIP_ANGLE else EV_DISAGREE


@kernel()
def detect_ekf_lost(s, c):
    """EV_EKF_LOST when the EKF's filtered current innovation has stayed beyond ``C_EKF_LOS_I`` plus the
    current the back-EMF drives in a period (``C_EKF_LOS_EMF`` |omega_hat|) for ``C_EKF_LOS_TIME`` (its timer
    ``S_EKF_LOS_T``): its angle or speed has left the rotor's. A motor that is not the model's (hot: R_s up,
    psi down) leaves a share of the back-EMF unexplained that grows with the speed; an EKF that has lost the
    angle leaves more than all of it."""
    bound = c[C_EKF_LOS_I] + c[C_EKF_LOS_EMF] * abs(s[S_OMEGA_HAT])
    return EV_EKF_LOST if timed_out(s, c, S_EKF_LOS_T, s[S_RESID_F] > bound, c[C_EKF_LOS_TIME]) else EV_NONE


@kernel()
def emf_residual(s, c):
    """The back-EMF the current PIs' integrators carry beyond what the frame's speed explains, as a speed [rad/s]
    (eq LS1), and the rotor's speed the current loops see, the magnitude of all the back-EMF they carry (that and
    the frame's own, N omega_hat psi on q) as a speed [rad/s]: the integrators and the currents of the last period
    in the control frame, less the resistance's drop on the identified R_s (the model's where none), over N psi."""
    r_s = s[S_ID_RS] if s[S_ID_RS] > 0.0 else c[C_AD_RS0]
    k = 1.0 / (c[C_N] * c[C_PSI])
    r_d = k * (s[S_INT_D] - r_s * s[S_I_D])
    r_q = k * (s[S_INT_Q] - r_s * s[S_I_Q])
    seen_q = r_q + s[S_OMEGA_CTRL]
    return math.sqrt(r_d * r_d + r_q * r_q), math.sqrt(r_d * r_d + seen_q * seen_q)


@kernel()
def detect_emf_lost(s, c):
    """EV_EMF_LOST in FOC on the injection (the blend included), ``C_INJ_LOS_TIME`` after the mode's start (the
    integrators start from 0 with the torque), when the filtered unexplained back-EMF (eq LS1, ``S_EMF_F``) has
    stayed beyond ``C_EMF_SPEED`` plus ``C_EMF_REL`` times the rotor's speed the current loops see (eq LS2,
    ``S_EMF_SEEN``, filtered the same way) for ``C_INJ_LOS_TIME`` (its
    timer ``S_EMF_T``): the rotor turns under a frame that does not follow it. It does not read the injection's
    error signal nor the EKF, which at low speed is put on the tracking observer."""
    r, seen = emf_residual(s, c)
    s[S_EMF_F] += c[C_LOS_FILTER] * (r - s[S_EMF_F])
    s[S_EMF_SEEN] += c[C_LOS_FILTER] * (seen - s[S_EMF_SEEN])
    if s[S_MODE_TIME] < c[C_INJ_LOS_TIME]:
        s[S_EMF_T] = 0.0
        return EV_NONE
    bound = c[C_EMF_SPEED] + c[C_EMF_REL] * s[S_EMF_SEEN]
    return EV_EMF_LOST if timed_out(s, c, S_EMF_T, s[S_EMF_F] > bound, c[C_INJ_LOS_TIME]) else EV_NONE


@kernel()
def detect_blind_stop(s, c, omega_ref):
    """EV_BLIND_STOP in FOC on the injection when the unit parks at its stops (``parks``: blind, ``S_ID_BLIND``, the
    identified saliency below ``C_SALIENCY_MIN``; or below ``C_SALIENCY_HOLD``), the driver asks for a stop (the
    reference 0) and the car is below the blend (``C_BLEND_LO``: the injection alone carries the angle),
    ``C_INJ_LOS_TIME`` after the mode's start: a tracking observer on so weak an error signal drifts while the car
    stands, so the car is held on the friction brake and the angle found afresh for the restart (``park_car``)."""
    if not parks(s, c) or omega_ref != 0.0 or s[S_MODE_TIME] < c[C_INJ_LOS_TIME]:
        return EV_NONE
    return EV_BLIND_STOP if abs(s[S_OMEGA_CTRL]) < c[C_BLEND_LO] else EV_NONE


@kernel()
def detect_speed(s, c, mode, omega):
    """EV_FAST in injection at |omega| >= ``C_BLEND_HI``; EV_SLOW on the EKF below ``C_BLEND_HI`` less
    ``C_BLEND_HYST``; neither within ``C_INJ_LOS_TIME`` of the mode's start (a speed that jumps, as an
    observer's after a restart, does not switch the injection on and off every period)."""
    if s[S_MODE_TIME] < c[C_INJ_LOS_TIME]:
        return EV_NONE
    if mode == MODE_INJECTION and abs(omega) >= c[C_BLEND_HI]:
        return EV_FAST
    if mode == MODE_EKF and abs(omega) < c[C_BLEND_HI] - c[C_BLEND_HYST]:
        return EV_SLOW
    return EV_NONE


@kernel()
def detect(s, c, mode, omega_ref):
    """This period's event, by priority: a loss of synchronism first, then the mode's own (``omega_ref`` [rad/s]:
    the speed reference of the period). A parked acquisition (``S_PARKED``) that is over with the reference still
    0 gives EV_STILL_PARKED: the angle is found again, not held by the tracking observer. A unit that cannot see
    (``cannot_see``) takes the I-f strategy for good, but while the driver asks for nothing and its sensors' relative
    gain is not yet measured (``sensors_balanced``) it parks instead (EV_BLIND_STOP at the enable's acquisition,
    EV_STILL_PARKED at a parked one) and pools its answers: their mismatch reads as a saliency fixed to the stator,
    which at one rotor angle can lower the saliency read below what the motor has (a motor of 1.098 with sensors 3.3 %
    apart read 1.03 at a stop, its accuracy beyond ``C_SEE_MAX``), and it is measured from the same answers within
    seconds (eq SG0)."""
    if mode == MODE_ACQUIRE:
        ev = detect_acquired(s, c)
        if ev == EV_ACQUIRED and cannot_see(s, c):
            if omega_ref == 0.0 and not sensors_balanced(s, c):  # judged again once they are: parked meanwhile
                return EV_STILL_PARKED if s[S_PARKED] != 0.0 else EV_BLIND_STOP
            return EV_CANNOT_SEE
        return EV_STILL_PARKED if ev == EV_ACQUIRED and s[S_PARKED] != 0.0 and omega_ref == 0.0 else ev
    if mode == MODE_POLARITY:
        ev = detect_injection_lost(s, c)
        return ev if ev == EV_INJECTION_LOST else detect_polarity(s, c)
    if mode == MODE_INJECTION:
        ev = detect_injection_lost(s, c)
        ev_emf = detect_emf_lost(s, c)
        if ev == EV_NONE:
            ev = ev_emf
        if ev == EV_NONE:
            ev = detect_blind_stop(s, c, omega_ref)
        return ev if ev != EV_NONE else detect_speed(s, c, mode, s[S_OMEGA_CTRL])
    ev = detect_ekf_lost(s, c)
    return ev if ev != EV_NONE else detect_speed(s, c, mode, s[S_OMEGA_HAT])


# -- entry actions -------------------------------------------------------------------------------
@kernel()
def clear_detectors(s):
    """The detectors' timers and filters from zero."""
    s[S_INJ_ERR_F] = 0.0
    s[S_DISAGREE_F] = 0.0
    s[S_DISAGREE_COS] = 1.0
    s[S_DISAGREE_SIN] = 0.0
    s[S_AXIS_F] = 1.0
    s[S_INJ_LOS_T] = 0.0
    s[S_EKF_LOS_T] = 0.0
    s[S_EMF_T] = 0.0


@kernel()
def enter_acquire(s, c, i_alpha, i_beta):
    """The acquisition from the start: the square wave afresh, the sums cleared (the identification's sums of a unit
    that parks kept: ``refining``), no current (the PIs' integrators and the speed loop's at 0), the tracking
    observer at rest on its angle, the EKF's weight 0."""
    start_injection(s)
    seed_fundamental(s, c, i_alpha, i_beta)
    for k in range(4):
        s[S_ACQ + k] = 0.0
    if not pools(s, c):
        for k in range(8):
            s[S_ID_SUM + k] = 0.0
            s[S_ID_NOISE + k] = 0.0
    for k in range(3):
        s[S_OFS_SUM + k] = 0.0
    for k in range(6):
        s[S_RS_SUM + k] = 0.0
    s[S_INT_D] = 0.0
    s[S_INT_Q] = 0.0
    s[S_I_DL] = 0.0
    s[S_I_QL] = 0.0
    s[S_W_INT] = 0.0
    seat_tracker(s, s[S_TRK_THETA], 0.0, 0.0)
    s[S_BLEND] = 0.0
    clear_detectors(s)


@kernel()
def enter_polarity(s):
    """The polarity test's sums cleared (its frame is the acquisition's, ``collect``)."""
    for k in range(4):
        s[S_POL + k] = 0.0


@kernel()
def polarity_frame(s, c):
    """The polarity test's frame [rad]: held while the tracking observer stays within ``C_POL_BAND`` of it (a
    standing rotor: the observer's noise is not followed, so the d current leaks no torque from it), else
    moved to that far behind the observer (a rotor that turns)."""
    d = wrap_angle(s[S_TRK_THETA] - s[S_POL_AXIS])
    band = c[C_POL_BAND]
    if d > band:
        s[S_POL_AXIS] = wrap_angle(s[S_TRK_THETA] - band)
    elif d < -band:
        s[S_POL_AXIS] = wrap_angle(s[S_TRK_THETA] + band)
    return s[S_POL_AXIS]


@kernel()
def enter_torque(s, c):
    """FOC on the injection: the speed loop's integral from 0 (the car is at rest, no torque yet), the EKF
    put on the tracking observer; the hill hold of enable (or a blind unit's park) released (``S_HOLD``)."""
    s[S_W_INT] = 0.0
    s[S_HOLD] = 0.0
    s[S_PARKED] = 0.0
    trust_injection(s, c)
    clear_detectors(s)


@kernel()
def flip_frame(s):
    """The tracking observer's angle turned by pi; what the current PIs hold in its frame changes sign."""
    s[S_TRK_THETA] = wrap_angle(s[S_TRK_THETA] + math.pi)
    s[S_INT_D] = -s[S_INT_D]
    s[S_INT_Q] = -s[S_INT_Q]
    s[S_I_DL] = -s[S_I_DL]
    s[S_I_QL] = -s[S_I_QL]


@kernel()
def trust_injection(s, c):
    """The EKF put on the tracking observer (its angle less the cross-saturation's offset), with the
    restart's covariance (``C_P0_ALIGNED``)."""
    restart_ekf_on(s, c, wrap_angle(s[S_TRK_THETA] - s[S_CROSS]), s[S_TRK_OMEGA], s[S_TRK_TL], C_P0_ALIGNED)


@kernel()
def feed_ekf(s, phi):
    """Below the blend (the EKF's weight 0, ``MODE_INJECTION``) the EKF is fed by the injection: its speed, angle and
    load put on the tracking observer's (the angle less the cross-saturation's offset ``phi`` [rad]) every period, so
    that it carries the injection's estimate, from which its own back-EMF takes over as the weight rises (``S_X``'s
    second job, declared with it in the layout); its currents are its own."""
    s[S_OMEGA_HAT] = s[S_TRK_OMEGA]
    s[S_THETA_HAT] = wrap_angle(s[S_TRK_THETA] - phi)
    s[S_TL_HAT] = s[S_TRK_TL]


@kernel()
def trust_ekf(s):
    """The tracking observer put on the EKF (its angle plus the cross-saturation's offset)."""
    seat_tracker(s, wrap_angle(s[S_THETA_HAT] + s[S_CROSS]), s[S_OMEGA_HAT], s[S_TL_HAT])


@kernel()
def reseat(s, c):
    """The two observers disagree in the blend's lower half, where the injection's answer is the stronger
    evidence (the back-EMF is at most half the frame's, and weak at that speed against a mismatched
    resistance): the EKF put on the tracking observer (``trust_injection``)."""
    trust_injection(s, c)


@kernel()
def restart_ekf_search(s, c):
    """The EKF's covariance back to an unknown start's (``C_P0``): it searches the rotor again from its
    back-EMF, its estimate kept as the start."""
    restart_ekf_on(s, c, s[S_THETA_HAT], s[S_OMEGA_HAT], s[S_TL_HAT], C_P0)
    s[S_RESID_F] = 0.0


@kernel()
def park_car(s, c, i_alpha, i_beta):
    """A blind unit at a stop: the friction brake asked for (``S_HOLD`` = ``C_HOLD_BRAKE``, as the hill hold at
    enable), the acquisition afresh with the identification's phases (``refining``; not the offset window or the R_s
    test: they ran at enable); the first torque releases both."""
    s[S_PARKED] = 1.0
    s[S_HOLD] = c[C_HOLD_BRAKE]
    enter_acquire(s, c, i_alpha, i_beta)


@kernel()
def fall_back_to_if(s, c):
    """A unit that cannot see its motor's axis (``cannot_see``) takes the I-f strategy for good (``S_IF_FALLBACK``:
    ``injection_unit_step`` runs ``sensorless_step`` from the next period): the alignment from its start, the brake
    held until the alignment's vector has its current (``C_T_RAMP``: let go at once, a car on a slope rolled back
    under the ramping vector, 110 mm at the wide design's corner, and turned the rotor past it), then released (the
    alignment turns the rotor onto the vector; the I-f strategy holds the car on its vector, its stand), the
    current loops' and the speed loop's integrators from 0, the EKF at rest with an unknown start's
    covariance (``C_P0``) as at enable: the speed it made of the identification's square wave (up to 7.5 rad/s on
    the wide design's corner) would read to the alignment as a rotor pushed off its vector (``align_slip``) and
    put the I-f vector at the current limit; the identification's outputs stay, and a latched fault stays latched."""
    latched = s[S_FAULT] == FAULT_LATCHED
    restart_ekf_on(s, c, s[S_THETA_HAT], 0.0, 0.0, C_P0)
    s[S_IF_FALLBACK] = 1.0
    s[S_PARKED] = 0.0
    s[S_INT_D] = 0.0
    s[S_INT_Q] = 0.0
    s[S_W_INT] = 0.0
    enter_if_strategy(s)
    if latched:  # the safe state is for good: the I-f strategy's holds the car at the current limit
        s[S_FAULT] = FAULT_LATCHED


@kernel()
def enter(s, c, action, i_alpha, i_beta):
    """Run an entry action (``A_*``)."""
    if action == A_ACQUIRE:
        enter_acquire(s, c, i_alpha, i_beta)
    elif action == A_POLARITY:
        enter_polarity(s)
    elif action == A_TORQUE:
        enter_torque(s, c)
    elif action == A_FLIP_TORQUE:
        flip_frame(s)
        enter_torque(s, c)
    elif action == A_RETRY:
        s[S_POL_TRIES] += 1.0
        if s[S_POL_TRIES] >= POL_TRIES:
            s[S_FAULT] = FAULT_LATCHED
        enter_acquire(s, c, i_alpha, i_beta)
    elif action == A_EKF_ALONE:
        s[S_BLEND] = 1.0
        clear_detectors(s)
    elif action == A_INJECTION_ON:
        start_injection(s)
        seed_fundamental(s, c, i_alpha, i_beta)
        trust_ekf(s)
        clear_detectors(s)
    elif action == A_REACQUIRE:
        begin_episode(s, c)
        enter_acquire(s, c, i_alpha, i_beta)
    elif action == A_RESEAT:
        begin_episode(s, c)
        reseat(s, c)
        clear_detectors(s)
    elif action == A_RESTART_EKF:
        begin_episode(s, c)
        restart_ekf_search(s, c)
        clear_detectors(s)
    elif action == A_PARK:
        park_car(s, c, i_alpha, i_beta)
    elif action == A_REACQUIRE_PARKED:
        begin_episode(s, c)
        park_car(s, c, i_alpha, i_beta)
    elif action == A_IF_FALLBACK:
        fall_back_to_if(s, c)
    elif action == A_REPOLARIZE:
        begin_episode(s, c)
        flip_frame(s)
        clear_detectors(s)


@kernel()
def transition(s, c, mode, event, i_alpha, i_beta):
    """Take the table's transition for (mode, event), if any: the entry action run, the mode's clock
    restarted. Returns the mode."""
    new, action = next_mode(mode, event)
    if action < 0.0:
        return mode
    enter(s, c, action, i_alpha, i_beta)
    s[S_MODE_TIME] = 0.0
    return new


# -- the step ------------------------------------------------------------------------------------
@kernel()
def collect(s, c, mode, t, phase, answer, i_d):
    """The measurements of the acquisition and of the polarity test: the answers' sin 2e summed on each of
    the acquisition's axes (and, as it ends, the tracking observer put on the axis they give: 2e =
    atan2(sin 2e, -(-cos 2e)), and the polarity test's frame with it), the d admittances summed on the found d
    axis and on the q axis in the identification (and, as it ends, the motor identified: ``identify``), the d
    admittances summed at each sign of the polarity test."""
    dt = c[C_DT]
    if mode == MODE_ACQUIRE:
        if answer and phase < 2:
            s[S_ACQ_SIN0 + phase] += s[S_INJ_ERR]
            s[S_ACQ_N0 + phase] += 1.0
        starts = phase_starts(s, c, t, phase)
        if (phase == PHASE_RS1 or phase == PHASE_RS2) and rs_level_time(s, c, t) >= 0.5 * c[C_RS_TIME]:
            j = phase - PHASE_RS1  # the level's second half: the current settled
            s[S_RS_V1 + 2 * j] += s[S_V_D]  # the last period's d command and the d current it was computed on
            s[S_RS_I1 + 2 * j] += s[S_I_D]
            s[S_RS_N1 + j] += 1.0
        if answer and PHASE_ID_D <= phase <= PHASE_ID_Q2 and not starts:
            j = phase - PHASE_ID_D
            s[S_ID_A_D + j] += s[S_INJ_ADM]
            s[S_ID_N_D + j] += 1.0
            # the answer's q second difference [A], its sign the half-wave's (``identify_noise``)
            x = s[S_INJ_ERR] * error_gain(s, c) * 2.0 * c[C_INJ_M] * dt * identification_amplitude(c, j)
            s[S_ID_D_SUM + j] += x
            s[S_ID_D_SQ + j] += x * x
        if starts and PHASE_ID_D2 <= phase <= PHASE_RS1 and identification_time(s, c) > 0.0:
            s[S_INJ_SKIP] = SKIP_HALF_WAVES  # the amplitude steps, the axis jumps by 90 deg (to q, back to d)
        if starts and phase == PHASE_OVER and (s[S_ID_DONE] == 0.0 or refining(s, c)):
            if identification_time(s, c) > 0.0:
                s[S_INJ_SKIP] = SKIP_HALF_WAVES
                identify(s, c)  # a parking unit's parked acquisitions: from the answers pooled since enable
                standstill_gain(s, c)
            if s[S_ID_DONE] == 0.0:
                identify_rs(s, c)
            s[S_ID_DONE] = 1.0
            if c[C_MODEL_SRC] == MODEL_IDENTIFIED:  # the controller's model from what was measured (AD7)
                model_apply(s, c)
        if starts and phase == PHASE_AXIS0:  # the square wave begins after the offset window
            s[S_INJ_SKIP] = SKIP_HALF_WAVES
        elif starts and phase == PHASE_AXIS45:  # the axis jumps by 45 deg: two answers straddle it
            s[S_INJ_SKIP] = SKIP_HALF_WAVES
        elif starts and phase == PHASE_SETTLE:  # the axis found: sin 2e and -cos 2e
            e = 0.0
            if s[S_ACQ_N0] > 0.0 and s[S_ACQ_N45] > 0.0:
                e = 0.5 * math.atan2(s[S_ACQ_SIN0] / s[S_ACQ_N0], -s[S_ACQ_SIN45] / s[S_ACQ_N45])
            seat_tracker(s, wrap_angle(s[S_TRK_THETA] + e), 0.0, 0.0)
            s[S_POL_AXIS] = s[S_TRK_THETA]  # the polarity test's frame: the acquisition's average, not the settling's
            s[S_INJ_SKIP] = SKIP_HALF_WAVES
    elif mode == MODE_POLARITY and answer:
        _, sign, _ = polarity_schedule(c, t)
        if sign > 0.0:
            s[S_POL_Y_POS] += s[S_INJ_ADM]
            s[S_POL_N_POS] += 1.0
        elif sign < 0.0:
            s[S_POL_Y_NEG] += s[S_INJ_ADM]
            s[S_POL_N_NEG] += 1.0


@kernel()
def foc_references(s, c, omega_ref, omega, limited):
    """The current references of FOC (eq 14, or the reference generator's) at the speed ``omega``; with
    ``limited`` (0 .. 1) of the way from the drive's own limit down to the injection's ``C_INJ_I_MAX`` (its
    torque k_t C_INJ_I_MAX in the reference generator's modes)."""
    if c[C_REF_MODE] != 0.0:
        t_max = c[C_T_MAX]
        return torque_speed_step_within(s, c, omega_ref, omega,
                                        t_max - limited * max(0.0, t_max - c[C_K_T] * c[C_INJ_I_MAX]))
    i_max = c[C_I_Q_MAX]
    return c[C_I_D_REF], speed_pi(s, c, omega_ref, omega, i_max - limited * max(0.0, i_max - c[C_INJ_I_MAX]))


@kernel(_sig(f"UniTuple({_F}, 16)", _V, _V, _F, _F, _F))
def injection_unit_step(s, c, i_alpha, i_beta, omega_ref):
    """One control period of the sensorless unit with injection (observer "sensorless", ``C_LOW_SPEED`` =
    injection; the module's doc): never reads the rotor's angle or speed. Returns ``sensorless_step``'s
    outputs: ``control_step``'s, the mode, the fault, the control frame's angle [rad] and speed [rad/s].

    1. The stationary-frame EKF5 (eqs 23-27) in every mode; its current innovation measured.
    2. The injection's answer (``demodulate``), the fundamental currents, the tracking observer.
    3. The detectors' event, the table's transition.
    4. The mode's control: in acquisition and polarity the current PIs on the fundamental in the
       tracking observer's frame with the schedule's references; in injection FOC on the blended frame;
       on the EKF FOC on its angle and speed; the square wave added on its axis.
    """
    dt = c[C_DT]
    i_alpha -= s[S_ID_OFS_ALPHA]  # the sensors' offsets measured at enable (0 before)
    i_beta -= s[S_ID_OFS_BETA]
    i_alpha, i_beta = balance_sensors(s, c, i_alpha, i_beta)  # (SG1-SG2)
    if s[S_IF_FALLBACK] != 0.0:  # a unit that cannot see its motor's axis: the I-f strategy (``fall_back_to_if``)
        if s[S_FAULT] == FAULT_LATCHED:  # the safe state: the friction brake holds the car, as at enable
            s[S_HOLD] = c[C_HOLD_BRAKE]
        elif s[S_HOLD] > 0.0 and (s[S_MODE] != MODE_ALIGN or s[S_ALIGN_CLOCK] * dt >= c[C_T_RAMP]):
            s[S_HOLD] = 0.0  # the brake let go once the alignment's vector has its current
        out = sensorless_step(s, c, i_alpha, i_beta, omega_ref)
        if s[S_FAULT] != FAULT_LATCHED:
            return out
        # latched, the brake holding: no voltage (the windings shorted through the inverter, its active short
        # circuit), where the I-f strategy's own safe state turns its vector at the current limit over the held rotor
        return (0.0, 0.0, 0.0, 0.0, out[4], out[5], out[6], out[7], out[8], out[9], out[10], out[11], out[12],
                out[13], out[14], out[15])
    mode = s[S_MODE]
    t = s[S_MODE_TIME]
    f_alpha, f_beta = fundamental(s, c, i_alpha, i_beta)
    if mode == MODE_EKF:
        innovation = ekf5ab_period(s, c, i_alpha, i_beta)  # (23)-(27)
    else:  # the last period had the square wave: the EKF on the fundamental, as a back-EMF observer (INJ5)
        innovation = ekf5ab_period_on(s, c, f_alpha, f_beta, s[S_V_FUND_ALPHA], s[S_V_FUND_BETA])
    s[S_RESID_F] += c[C_LOS_FILTER] * (innovation - s[S_RESID_F])
    # the injection's answer on the axis of the last period, the tracking observer
    demodulate(s, c, i_alpha, i_beta, s[S_INJ_AXIS])
    f_d, f_q = park(f_alpha, f_beta, s[S_TRK_THETA])
    injecting = mode != MODE_EKF
    phase = acquisition_phase(s, c, t) if mode == MODE_ACQUIRE else PHASE_OVER
    answer = injecting and s[S_INJ_NEW] != 0.0
    share = injection_share(s[S_BLEND]) if mode == MODE_INJECTION else 1.0
    e_ekf = wrap_angle(s[S_THETA_HAT] + s[S_CROSS] - s[S_TRK_THETA]) if share < 1.0 else 0.0
    # the answers on the found axis correct the tracking observer; through the identification and the R_s test it is
    # held where the settling left it, at rest (no torque is given, the car is held: ``hold_brake``), so that the
    # axes measured are the found ones (an observer left to run on a speed the settling had not yet taken out, or
    # corrected by the weak error signal of a motor with little saliency, drifted 0.5 rad on motor A of issue 47)
    held = mode == MODE_ACQUIRE and (PHASE_ID_D <= phase <= PHASE_RS2 or phase == PHASE_OFFSET)
    # a blind unit's polarity test on a car the brake holds: the rotor stands, and the error signal of a motor with
    # little saliency, with the test's d current saturating the d axis, drifted the observer 0.9 rad off the axis
    # the acquisition found (a restart 80 deg off, the torque on the d axis)
    held = held or (mode == MODE_POLARITY and parks(s, c) and s[S_HOLD] > 0.0)
    on_axis = answer and phase >= PHASE_SETTLE and not held
    if held:
        seat_tracker(s, s[S_TRK_THETA], 0.0, 0.0)
    else:
        track(s, c, model_torque(c, f_d, f_q), share, on_axis, e_ekf)
    if on_axis and share > 0.0:
        e_inj = angle_error(s[S_INJ_ERR])
        gain = c[C_LOS_FILTER] * c[C_INJ_M]
        s[S_INJ_ERR_F] += gain * (e_inj - s[S_INJ_ERR_F])
        s[S_DISAGREE_COS] += gain * (math.cos(e_inj - e_ekf) - s[S_DISAGREE_COS])
        s[S_DISAGREE_SIN] += gain * (math.sin(e_inj - e_ekf) - s[S_DISAGREE_SIN])
        s[S_DISAGREE_F] = math.atan2(s[S_DISAGREE_SIN], s[S_DISAGREE_COS])
        if mode == MODE_INJECTION and share == 1.0:  # (at the full amplitude, not in the polarity test: its d
            # current saturates the d axis)
            s[S_AXIS_F] += gain * (axis_cosine(s, s[S_INJ_ADM]) - s[S_AXIS_F])
    collect(s, c, mode, t, phase, answer, f_d)
    if phase == PHASE_OFFSET:  # no voltage, no current: the sensors' mean is their offset
        s[S_OFS_ALPHA] += i_alpha
        s[S_OFS_BETA] += i_beta
        s[S_OFS_N] += 1.0
    elif mode == MODE_ACQUIRE and s[S_OFS_N] > 0.0:  # the window over: subtracted from the next period on
        s[S_ID_OFS_ALPHA] = s[S_OFS_ALPHA] / s[S_OFS_N]
        s[S_ID_OFS_BETA] = s[S_OFS_BETA] / s[S_OFS_N]
        s[S_OFS_N] = 0.0
    # the event and the transition
    event = detect(s, c, mode, omega_ref)
    s[S_EVENT] = float(event)  # (the state holds the code as its float)
    if event != EV_NONE:
        mode = transition(s, c, mode, event, i_alpha, i_beta)
        t = s[S_MODE_TIME]
    if s[S_IF_FALLBACK] != 0.0:  # taken this period: no voltage in it, the I-f strategy's alignment from the next
        s[S_MODE] = mode
        s[S_MODE_TIME] = 0.0
        # the EKF from here on the measured currents, the square wave's ripple in them: its currents put on them, and
        # the vector it takes as applied the one the inverter applies (with the actuation delay the last command,
        # the square wave in it; then this period's, none): fed the square wave's 90 V that never came, or the
        # fundamental against the ripple, its speed ran to 2000 rad/s from the unknown start's covariance
        s[S_I_D_HAT], s[S_I_Q_HAT] = park(i_alpha, i_beta, s[S_THETA_HAT])
        if c[C_DELAYED] != 0.0:
            s[S_U_PREV_ALPHA] = s[S_V_ALPHA]
            s[S_U_PREV_BETA] = s[S_V_BETA]
        s[S_V_OUT_ALPHA] = s[S_V_OUT_BETA] = 0.0
        s[S_V_ALPHA] = s[S_V_BETA] = 0.0
        s[S_V_FUND_ALPHA] = s[S_V_FUND_BETA] = 0.0
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, s[S_I_D_HAT], s[S_I_Q_HAT], s[S_OMEGA_HAT], s[S_THETA_HAT],
                s[S_TL_HAT], mode, FAULT_NONE, 0.0, 0.0)
    age_episode(s, c, s[S_INJ_LOS_T] > 0.0 or s[S_EKF_LOS_T] > 0.0 or s[S_EMF_T] > 0.0)
    if s[S_FAULT] == FAULT_LATCHED:  # the safe state: stop and hold
        omega_ref = 0.0
    if c[C_FF] != 0.0:  # the speed loop's feedforward, its slope kept up in every mode
        speed_feedforward(s, c, omega_ref)
    # the mode's control
    offset = 0.0
    amplitude = injection_amplitude(s, c)
    i_qref = 0.0
    if mode == MODE_ACQUIRE or mode == MODE_POLARITY:  # no torque: the current PIs alone, frame at rest
        theta = s[S_TRK_THETA]
        omega_ctrl = 0.0
        i_dref = 0.0
        if mode == MODE_ACQUIRE and acquisition_phase(s, c, t) == PHASE_AXIS45:
            offset = AXIS_AHEAD
        elif mode == MODE_ACQUIRE and PHASE_ID_D <= acquisition_phase(s, c, t) <= PHASE_ID_Q2:
            j = acquisition_phase(s, c, t) - PHASE_ID_D  # (ID1): V, 2 V on d, then on q
            offset = 0.5 * math.pi if j >= 2 else 0.0
            amplitude = identification_amplitude(c, j)
        elif mode == MODE_ACQUIRE and PHASE_RS1 <= acquisition_phase(s, c, t) <= PHASE_RS2:
            # (ID2): the two levels on the polarity test's frame (held where the acquisition put it: the
            # observer's noise leaks no torque)
            i_dref = c[C_RS_I] * (0.5 if acquisition_phase(s, c, t) == PHASE_RS1 else 1.0)
            theta = polarity_frame(s, c)
            offset = wrap_angle(s[S_TRK_THETA] - theta)
        elif mode == MODE_ACQUIRE and acquisition_phase(s, c, t) == PHASE_OFFSET:
            amplitude = 0.0  # the inverter's gates off (below: no voltage, no compensation)
        elif mode == MODE_POLARITY:
            i_dref, _, _ = polarity_schedule(c, t)
            theta = polarity_frame(s, c)
            offset = wrap_angle(s[S_TRK_THETA] - theta)  # the square wave stays on the tracking observer's axis
        s[S_CROSS] = 0.0
        i_d, i_q = park(f_alpha, f_beta, theta)
        if amplitude == 0.0:
            v_d = v_q = 0.0
        else:
            v_d, v_q = current_step(s, c, i_dref, 0.0, i_d, i_q, 0.0)
    elif mode == MODE_INJECTION:  # FOC on the tracking observer, the EKF blended in with the speed
        w = blend_weight(c, s[S_OMEGA_CTRL])
        s[S_BLEND] = w
        phi = cross_offset(c, f_q)  # the injection's axis less the d axis (f_q: in the injection's frame)
        s[S_CROSS] = phi
        if w == 0.0:
            feed_ekf(s, phi)
        theta, omega_ctrl = blended_frame(s, s[S_THETA_HAT], s[S_OMEGA_HAT], phi)
        offset = wrap_angle(s[S_TRK_THETA] - theta)  # the square wave stays on the injection's axis
        amplitude = injection_amplitude(s, c) * injection_share(w)
        i_dref, i_qref = foc_references(s, c, omega_ref, omega_ctrl, 1.0 - w)  # within the injection's limit
        i_d, i_q = park(f_alpha, f_beta, theta)
        v_d, v_q = current_step(s, c, i_dref, i_qref, i_d, i_q, omega_ctrl)  # (15)-(20)
    else:  # the EKF alone, the tracking observer kept on it
        s[S_BLEND] = 1.0
        theta = s[S_THETA_HAT]
        omega_ctrl = s[S_OMEGA_HAT]
        i_d, i_q = park(i_alpha, i_beta, theta)
        s[S_CROSS] = cross_offset(c, i_q)
        trust_ekf(s)
        amplitude = 0.0
        i_dref, i_qref = foc_references(s, c, omega_ref, omega_ctrl, 0.0)
        v_d, v_q = current_step(s, c, i_dref, i_qref, i_d, i_q, omega_ctrl)  # (15)-(20)
    v_alpha, v_beta = modulate(c, v_d, v_q, theta, omega_ctrl, False)
    s[S_V_FUND_ALPHA] = v_alpha  # without the square wave: the EKF's input in the next period while injecting
    s[S_V_FUND_BETA] = v_beta
    axis = theta + offset + c[C_ADVANCE] * omega_ctrl
    s[S_INJ_AXIS] = axis
    if mode != MODE_EKF:  # the square wave on its axis
        v_h = injection_voltage(s, c, amplitude)
        v_alpha += v_h * math.cos(axis)
        v_beta += v_h * math.sin(axis)
    s[S_MODE] = mode
    s[S_MODE_TIME] = t + dt
    s[S_THETA_CTRL] = theta
    s[S_OMEGA_CTRL] = omega_ctrl
    fault = fault_output(s)
    v_alpha, v_beta = store_command(s, c, i_alpha, i_beta, i_d, i_q, i_qref, v_d, v_q, v_alpha, v_beta)
    if phase == PHASE_OFFSET:  # the gates off: nothing reaches the winding, the dead time's compensation neither
        v_alpha = v_beta = 0.0
        s[S_V_OUT_ALPHA] = 0.0
        s[S_V_OUT_BETA] = 0.0
    if c[C_ADAPT] != 0.0:  # psi and R_s over the period just gone (AD1-AD6), on the found axis in every mode
        adapt_period(s, c, i_alpha, i_beta, theta, omega_ctrl, 1.0)
    return (v_alpha, v_beta, v_d, v_q, i_d, i_q, i_qref,
            s[S_I_D_HAT], s[S_I_Q_HAT], s[S_OMEGA_HAT], s[S_THETA_HAT], s[S_TL_HAT], mode, fault, theta, omega_ctrl)
