"""The sensorless unit's kernels: alignment, I-f drive (eq 12 sizes the vector's current, eq 13
turns it), handover to and from FOC (eqs 14-20) on the stationary-frame EKF5 (eqs 23-27), the
load-angle guard and the loss-of-synchronism detection and recovery: ``sensorless_step``, one
control period (docs/sensorless.md).

The vectors ``s`` and ``c`` are laid out by ``pmsm_ev.kernels.layout`` (``S_*``, ``C_*``).
"""

from __future__ import annotations

import math

from .control import (
    current_step,
    generate_references,
    modulate,
    speed_feedforward,
    speed_step,
    store_command,
    torque_speed_step,
)
from .jit import F as _F
from .jit import V as _V
from .jit import kernel
from .jit import sig as _sig
from .layout import (
    C_ADVANCE,
    C_AGREE_TIME,
    C_AGREE_TOL,
    C_ALIGN_DAMP,
    C_ALIGN_SLIP,
    C_ALIGN_SLIP_TIME,
    C_ANCHOR_SPEED,
    C_CC_HS,
    C_CC_PRED,
    C_DT,
    C_E_GUARD,
    C_E_MAX,
    C_FAULT_TIME,
    C_FF,
    C_GUARD,
    C_HALF_PERIOD_N,
    C_I_ALIGN,
    C_I_D_REF,
    C_I_IF,
    C_I_Q_MAX,
    C_I_RATE,
    C_I_RATE_LOAD,
    C_IF_ACCEL,
    C_IF_DAMP,
    C_IF_DEADLINE,
    C_IF_MARGIN,
    C_J_IF,
    C_K_DQN,
    C_K_T,
    C_KP_ID,
    C_KP_IQ,
    C_KP_W,
    C_L_D,
    C_L_Q,
    C_N,
    C_P0_ALIGNED,
    C_PAPER_SIGNS,
    C_PSI,
    C_PSI_ADAPT,
    C_REALIGN_MAX,
    C_RECOVER_TIME,
    C_REF_MODE,
    C_SIN_E,
    C_SLIP_FILTER,
    C_SLIP_TIME,
    C_SLIP_TOL,
    C_STALL_TIME,
    C_STILL,
    C_T_HOLD,
    C_T_RAMP,
    C_T_SETTLE,
    C_T_SWEEP,
    C_W_DOWN,
    C_W_UP,
    FAULT_LATCHED,
    FAULT_NONE,
    FAULT_RECOVERING,
    MODE_ALIGN,
    MODE_EKF,
    MODE_IF,
    S_AGREE,
    S_ANCHOR,
    S_ANCHOR_REL,
    S_ANCHOR_TL,
    S_ANCHORED,
    S_CLOCK,
    S_EPISODE,
    S_FAULT,
    S_GUARD,
    S_I_DL,
    S_I_MAG,
    S_I_QL,
    S_I_TGT,
    S_IF_DUE,
    S_INSYNC,
    S_INT_D,
    S_INT_Q,
    S_LOS,
    S_MODE,
    S_OMEGA_CTRL,
    S_OMEGA_IF,
    S_P,
    S_PHI,
    S_REALIGN,
    S_SLIP,
    S_STILL_OUT,
    S_T_FF,
    S_THETA_CTRL,
    S_THETA_PRIOR,
    S_TRUST_OFF,
    S_TRUST_TL,
    S_V_ALPHA,
    S_V_BETA,
    S_V_Q,
    S_W_INT,
    S_X,
)
from .observers import adapt_psi, ekf5ab_period
from .transforms import park, wrap_angle

# -- the sensorless unit: alignment, I-f, handover to and from the stationary-frame EKF5 --------
_HALF_PI = 0.5 * math.pi


@kernel()
def seat_current_pis(s, c, theta, turn, i_dref, i_qref, i_d, i_q, omega_est):
    """Set the current PIs' integrators and decoupling filters so that ``current_step`` in the
    frame at ``theta`` (with these references, currents and speed) first returns the voltage
    held now, turned on by ``turn`` [rad] (the angle a rotor-synchronous vector turns in a
    period): a change of frame without a voltage jump. The filters start at the references,
    so that only the integrators carry the change (bumpless transfer). With the high-speed current
    control (``current_step_hs``) the same for its decoupling on the predicted current and its ZOH
    gain."""
    v_d, v_q = park(s[S_V_ALPHA], s[S_V_BETA], theta - turn)
    s[S_I_DL] = i_dref
    s[S_I_QL] = i_qref
    w_e = c[C_N] * omega_est
    if c[C_CC_HS] != 0.0:
        half_arc = c[C_HALF_PERIOD_N] * omega_est
        if abs(half_arc) > 1e-6:  # the command before the ZOH gain sin(a)/a (``modulate``)
            v_d *= half_arc / math.sin(half_arc)
            v_q *= half_arc / math.sin(half_arc)
        k = c[C_CC_PRED]
        s[S_INT_D] = v_d + w_e * c[C_L_Q] * (i_q + k * (i_qref - i_q)) - c[C_KP_ID] * (i_dref - i_d)
        s[S_INT_Q] = (v_q - w_e * (c[C_L_D] * (i_d + k * (i_dref - i_d)) + c[C_PSI])
                      - c[C_KP_IQ] * (i_qref - i_q))
        return
    s[S_INT_D] = v_d + w_e * c[C_L_Q] * i_qref - c[C_KP_ID] * (i_dref - i_d)  # (15), (19)
    back_emf = w_e * c[C_L_D] * i_dref + w_e * c[C_PSI]
    if c[C_PAPER_SIGNS] != 0.0:
        s[S_INT_Q] = v_q + back_emf - c[C_KP_IQ] * (i_qref - i_q)  # (16), (20) as printed
    else:
        s[S_INT_Q] = v_q - back_emf - c[C_KP_IQ] * (i_qref - i_q)  # (16), (20)


@kernel()
def trust_rotor(s):
    """Keep the EKF's angle less the I-f vector's (``S_TRUST_OFF``: the rotor's place on the vector) and
    its load (``S_TRUST_TL``): what a stand is anchored on (``C_ANCHOR_SPEED``)."""
    s[S_TRUST_OFF] = wrap_angle(s[S_X + 3] - s[S_PHI])
    s[S_TRUST_TL] = s[S_X + 4]


@kernel()
def restart_ekf(s, c, theta, i_d, i_q):
    """The EKF restarted at a known angle from standstill: x = [i_d, i_q, 0, theta, 0], P = the
    restart's P0 (``C_P0_ALIGNED``); the rotor's place on the I-f vector (``S_TRUST_OFF``) is where
    it was restarted, its load 0 (``trust_rotor``)."""
    s[S_X] = i_d
    s[S_X + 1] = i_q
    s[S_X + 2] = 0.0
    s[S_X + 3] = theta
    s[S_X + 4] = 0.0
    for i in range(25):
        s[S_P + i] = 0.0
    for i in range(5):
        s[S_P + 6 * i] = c[C_P0_ALIGNED + i]
    s[S_THETA_PRIOR] = theta
    trust_rotor(s)


@kernel()
def seat_foc(s, c, omega_ref, omega_hat, i_alpha, i_beta, on_load):
    """Hand the drive to FOC on the EKF (mode EKF), seated on the present state: the speed PI's
    integral so that (14) returns the q current that gives the present torque once i_d is at its
    reference (eq 12: the I-f vector's d current adds a reluctance torque N (L_d - L_q) i_d i_q that
    FOC's i_d = 0 takes away; with the reference generator, ``C_REF_MODE`` != 0: the present torque
    over k_t, the generator's references for it), or with ``on_load`` the current of the load the EKF sees,
    T_L_hat / (N psi), after a loss of synchronism, when the present current says nothing of the
    load; the current PIs on the voltage held, turned by one period of the I-f vector's rotation
    (``seat_current_pis``)."""
    theta = s[S_X + 3]
    i_d, i_q = park(i_alpha, i_beta, theta)
    if c[C_REF_MODE] != 0.0:  # the reference generator's modes: (14) returns the present torque / k_t,
        # which the generator turns into its references (the current PIs seated on them)
        t_seat = s[S_X + 4] if on_load else c[C_K_DQN] * i_q * (c[C_PSI] + (c[C_L_D] - c[C_L_Q]) * i_d)
        t_pi = t_seat - s[S_T_FF] if c[C_FF] != 0.0 else t_seat  # the feedforward's share is its own
        s[S_W_INT] = t_pi / c[C_K_T] - c[C_KP_W] * (omega_ref - omega_hat)
        i_dref, i_seat = generate_references(s, c, t_seat, omega_hat)
    elif on_load:
        i_dref = c[C_I_D_REF]
        i_seat = s[S_X + 4] / (c[C_N] * c[C_PSI])
        s[S_W_INT] = i_seat - c[C_KP_W] * (omega_ref - omega_hat)  # (14) returns i_seat now
    else:  # N i_q (psi + (L_d - L_q) i_d) = N i_seat (psi + (L_d - L_q) i_dref)
        i_dref = c[C_I_D_REF]
        i_seat = i_q * (c[C_PSI] + (c[C_L_D] - c[C_L_Q]) * i_d) / (c[C_PSI] + (c[C_L_D] - c[C_L_Q]) * c[C_I_D_REF])
        s[S_W_INT] = i_seat - c[C_KP_W] * (omega_ref - omega_hat)  # (14) returns i_seat now
    seat_current_pis(s, c, theta + c[C_ADVANCE] * omega_hat, c[C_N] * s[S_OMEGA_IF] * c[C_DT],
                     i_dref, i_seat, i_d, i_q, omega_hat)
    s[S_AGREE] = 0.0


@kernel()
def vector_torque(c, i, sin_e, cos_e):
    """Eq 12 for a current vector of magnitude ``i`` leading the rotor's d axis by e:
    T_e = N (psi i sin e + (L_d - L_q) i^2 sin e cos e) [N m] (the controller's motor model); with
    L_q > L_d the reluctance term takes torque below e = 90 deg and adds it above."""
    return c[C_N] * i * sin_e * (c[C_PSI] + (c[C_L_D] - c[C_L_Q]) * i * cos_e)


@kernel()
def vector_current(c, torque, sin_e, cos_e):
    """The least magnitude whose vector at the load angle e gives ``torque`` [A] (``vector_torque``
    solved for i, the smaller root); inf if no current does."""
    a = (c[C_L_Q] - c[C_L_D]) * cos_e  # N sin e (psi i - a i^2) = torque
    t = abs(torque) / (c[C_N] * sin_e)
    if abs(a) < 1e-12:
        return t / c[C_PSI]
    disc = c[C_PSI] * c[C_PSI] - 4.0 * a * t
    if disc < 0.0:
        return math.inf
    return 2.0 * t / (c[C_PSI] + math.sqrt(disc))  # = (psi - sqrt(disc)) / (2 a), without cancellation


@kernel()
def if_vector_step(s, c, omega_ref, t_l):
    """I-f: turn the vector and size its current from the torque it can give (eq 12 with the rotor
    lagging the vector by the load angle e, ``vector_torque``; docs/sensorless.md).

    The I-f speed follows ``omega_ref`` with at most ``C_IF_ACCEL`` and at most what the vector's
    torque at the design load angle ``C_E_MAX`` leaves over the load the EKF sees,
    J dw/dt = T_e(i, e_max) - T_L_hat (never forced to turn against the reference by it: a load
    beyond the vector is the guard's, ``sync_guard``; at the current limit, the torque at 90 deg,
    the reserve spent). The target current is at least what the
    acceleration asked for and that load need at e_max, and ``C_IF_MARGIN`` times the load's
    current; it never falls in I-f. The magnitude ramps at ``C_I_RATE``, at ``C_I_RATE_LOAD``
    while the guard holds the vector back (the load exceeds the vector). ``t_l``: the load [N m]."""
    dt = c[C_DT]
    sin_e = c[C_SIN_E]
    cos_e = math.cos(c[C_E_MAX])
    j = c[C_J_IF]
    if s[S_I_MAG] < c[C_I_Q_MAX]:
        t_cap = vector_torque(c, s[S_I_MAG], sin_e, cos_e)
    else:  # at the current limit the reserve is spent: the torque at 90 deg (up to the soft guard)
        t_cap = c[C_N] * c[C_PSI] * s[S_I_MAG]
    step = c[C_IF_ACCEL] * dt
    hi = min(step, max((t_cap - t_l) / j * dt, 0.0))
    lo = max(-step, min((-t_cap - t_l) / j * dt, 0.0))
    w_if = s[S_OMEGA_IF]
    want = min(max(omega_ref - w_if, -step), step)  # the step the reference asks for
    s[S_OMEGA_IF] = w_if + min(max(want, lo), hi)
    s[S_PHI] = wrap_angle(s[S_PHI] + c[C_N] * s[S_OMEGA_IF] * dt)  # (13)
    need = vector_current(c, t_l + j * want / dt, sin_e, cos_e)
    load_current = c[C_IF_MARGIN] * abs(t_l) / (c[C_N] * c[C_PSI])  # eq 12 with i_d = 0, times the margin
    s[S_I_TGT] = min(max(s[S_I_TGT], need, load_current), c[C_I_Q_MAX])
    rate = (c[C_I_RATE_LOAD] if s[S_GUARD] != 0.0 else c[C_I_RATE]) * dt
    s[S_I_MAG] += min(max(s[S_I_TGT] - s[S_I_MAG], -rate), rate)


#: the guard: beyond this lead of the vector over the EKF's angle [rad] the vector turns no faster than
#: the rotor away from it (90 deg: past it, more lead gives more torque only through the reluctance term)
_SOFT_GUARD = 0.5 * math.pi
#: the EKF is believed at low speed once it says the rotor has moved on the I-f vector by more than this
#: since it was last believed [rad] (``trust_rotor``) [chosen: 30 deg]: a load that changed (a grade
#: step under a creeping car moves the rotor that far on the vector within ~20 ms, and the EKF sees the
#: motion); the drift of a mismatched EKF at a restart stays below it in most cases, and where it does
#: not the current sized on its load stays below the limit (the cycle Monte-Carlo's sample 0017:
#: 100 % in the band with 30 deg, 0.3 rad and 60 deg alike). At 60 deg the matrix's creep5 rolled back
#: 6.3 cm, at 30 deg 5.1 cm, before the anchoring 3.4 cm
_TRUST_MOVE = math.radians(30.0)
#: it counts as holding the vector until the vector is back by this much [rad]: 3 deg, so that a vector
#: held there and turning with the rotor does not flicker in and out
_GUARD_BAND = math.radians(3.0)
#: ``S_GUARD`` values: the soft limit holds the vector's speed, the hard one its angle
GUARD_SOFT, GUARD_HARD = 1.0, 2.0


@kernel()
def sync_guard(s, c, omega_hat, lag, theta):
    """Keep the applied I-f vector (``S_PHI`` less ``lag``, the damping's pull-back) within
    +-``C_E_GUARD`` of the rotor's angle ``theta`` (electrical: the EKF's, or while the car stands
    the one it had when the stand began): a vector that would lead (or trail) the
    rotor by more is held there and turns at the rotor's speed, so the rotor cannot fall out of
    step while the EKF holds its angle (``GUARD_HARD``). Beyond ``_SOFT_GUARD`` its speed is held to
    the rotor's (``GUARD_SOFT``): the lead stops growing before the EKF, whose load state lags a
    sudden load, shows the rotor slowing. ``S_GUARD`` is released once the vector is back within
    ``_SOFT_GUARD`` by ``_GUARD_BAND``."""
    e = wrap_angle(s[S_PHI] - lag - theta)
    e_max = c[C_E_GUARD]
    if e > e_max or e < -e_max:
        s[S_PHI] = wrap_angle(theta + lag + (e_max if e > 0.0 else -e_max))
        s[S_OMEGA_IF] = omega_hat
        s[S_GUARD] = GUARD_HARD
    elif (e > _SOFT_GUARD and s[S_OMEGA_IF] > omega_hat) or (e < -_SOFT_GUARD and s[S_OMEGA_IF] < omega_hat):
        s[S_OMEGA_IF] = omega_hat
        s[S_GUARD] = GUARD_SOFT
    elif abs(e) < _SOFT_GUARD - _GUARD_BAND:
        s[S_GUARD] = 0.0


@kernel()
def relock(s, c, omega_hat, omega_ref):
    """Recovery at low speed (a loss of synchronism, or a rotor running away under the alignment):
    the vector put on the EKF's angle, leading it by the design load angle in the direction of the
    torque needed to hold the load the EKF sees and to bring the speed to the reference within
    ``_RELOCK_TIME``, turning at the EKF's speed, its current set to the limit at once; the rotor's
    place on it trusted (``trust_rotor``)."""
    push = s[S_X + 4] + c[C_J_IF] * (omega_ref - omega_hat) / _RELOCK_TIME
    s[S_PHI] = wrap_angle(s[S_X + 3] + (c[C_E_MAX] if push >= 0.0 else -c[C_E_MAX]))
    s[S_OMEGA_IF] = omega_hat
    s[S_I_TGT] = c[C_I_Q_MAX]
    s[S_I_MAG] = c[C_I_Q_MAX]  # at once: the rotor is running away (the current PIs follow in ~5 ms)
    s[S_SLIP] = 0.0
    trust_rotor(s)  # the EKF holds the angle: the rotor's motion has shown it


@kernel()
def begin_episode(s, c):
    """Out of synchronism this period: a loss-of-synchronism episode begins, or the one running goes on
    (its age kept, ``C_FAULT_TIME``), and the time in synchronism that would end it starts again."""
    s[S_INSYNC] = 0.0
    if s[S_EPISODE] == 0.0:
        s[S_EPISODE] = c[C_DT]


@kernel()
def age_episode(s, c, trouble):
    """A loss-of-synchronism episode's clock: it ends after ``C_RECOVER_TIME`` without ``trouble`` (a
    detector's timer running), or latches the fault at ``C_FAULT_TIME``."""
    if s[S_EPISODE] > 0.0:
        dt = c[C_DT]
        s[S_EPISODE] += dt
        s[S_INSYNC] = 0.0 if trouble else s[S_INSYNC] + dt
        if s[S_INSYNC] >= c[C_RECOVER_TIME]:
            s[S_EPISODE] = 0.0
        elif s[S_EPISODE] >= c[C_FAULT_TIME]:
            s[S_FAULT] = FAULT_LATCHED


#: the time in which a relocked vector's torque is meant to bring the speed to the reference [s]
_RELOCK_TIME = 0.5


@kernel(_sig(f"UniTuple({_F}, 16)", _V, _V, _F, _F, _F))
def sensorless_step(s, c, i_alpha, i_beta, omega_ref):
    """One control period of the sensorless unit (``pmsm_ev.control_unit``, observer
    "sensorless"): never reads the rotor angle or speed. Returns ``control_step``'s outputs,
    the mode (``MODE_ALIGN``, ``MODE_IF``, ``MODE_EKF``), the fault (``FAULT_*``) and the control
    frame's angle [rad] and speed [rad/s].

    1. The stationary-frame EKF5 (eqs 23-27 with h = inverse Park) runs in every mode.
    2. Alignment (``C_T_RAMP`` .. ``C_T_SETTLE``): the current vector ramped up on +90 deg,
       held, swept to 0 deg, held (damped on the back-EMF); then the EKF restarts at the aligned
       angle, at rest. The speed reference is not read. A rotor that runs away under the vector
       (|omega_hat| > ``C_ALIGN_SLIP`` for ``C_ALIGN_SLIP_TIME``: a load beyond it) ends the alignment: I-f on the EKF's
       angle (``relock``), as a loss-of-synchronism episode.
    3. I-f: the vector turns at the I-f speed (the reference, slew-limited by what the vector's
       torque allows: ``if_vector_step``), within the guard angle of the EKF's angle
       (``sync_guard``); handover up once omega_hat agrees with the I-f speed.
    4. EKF: FOC (eqs 14-20) on the EKF's angle and speed; back to I-f at low speed.
    5. Loss of synchronism (I-f): |omega_hat - omega_if| (filtered) above ``C_SLIP_TOL`` +
       ``C_AGREE_TOL`` |omega_if| for ``C_SLIP_TIME`` (or a limit reached: the guard holding the
       vector with the current at ``C_I_Q_MAX`` and the rotor as far from the reference, that long:
       an episode, nothing more to give); recovery:
       a flying handover to FOC when |omega_hat| >= ``C_W_DOWN``, else ``relock``; the guard is on
       while an episode lasts (also when ``C_GUARD`` is off) and in the safe state. An episode
       ends after ``C_RECOVER_TIME`` in synchronism; one older than ``C_FAULT_TIME`` latches the
       fault: the safe state is a stop and hold (the reference taken as 0, the I-f current at the limit).
    6. Handover deadline and stall (I-f with |omega_ref| above ``C_W_UP``, ``S_IF_DUE``): after
       ``C_IF_DEADLINE`` the handover up is forced if the rotor turns with the vector (FOC on the EKF, an
       episode); after ``C_STALL_TIME`` the rotor is aligned again from standstill (an episode), at most
       ``C_REALIGN_MAX`` times without a handover up in between, then the fault latches.
    In alignment and I-f the current PIs work in the vector's frame (reference on its d
    axis, no decoupling: the back-EMF is small there and the integrators carry it).
    """
    dt = c[C_DT]
    ekf5ab_period(s, c, i_alpha, i_beta)  # (23)-(27)
    # the rotor's speed above C_STILL counts only once it lasts (the EKF's speed noise at a stand with
    # 1 A of sensor noise crosses 0.5 rad/s for a few periods at a time)
    s[S_STILL_OUT] = s[S_STILL_OUT] + c[C_DT] if abs(s[S_X + 2]) >= c[C_STILL] else 0.0
    if (s[S_MODE] == MODE_IF and abs(s[S_OMEGA_IF]) < c[C_STILL]
            and (abs(s[S_X + 2]) < c[C_STILL] or (s[S_ANCHORED] != 0.0 and s[S_STILL_OUT] < 0.5 * c[C_SLIP_TIME]))):
        # the car stands on the I-f vector: no back-EMF shows the angle, and the EKF's (and with it its
        # load) drifts with the sensors' noise and offsets; the rotor is held, so the guard and the I-f
        # sizing take the angle and the load of when the EKF last saw it turn (at C_ANCHOR_SPEED or
        # faster: the rotor's place on the vector, ``trust_rotor``), and the EKF is put back there,
        # on the vector as it is then, when the stand ends
        if s[S_ANCHORED] == 0.0:
            s[S_ANCHOR_REL] = s[S_TRUST_OFF]
            s[S_ANCHOR] = wrap_angle(s[S_PHI] + s[S_TRUST_OFF])
            s[S_ANCHOR_TL] = s[S_TRUST_TL]
            s[S_ANCHORED] = 1.0
    elif s[S_ANCHORED] != 0.0:  # the stand ends; the rotor has turned with the vector since it began
        theta = wrap_angle(s[S_PHI] + s[S_ANCHOR_REL])
        if abs(s[S_X + 2]) < c[C_STILL]:  # the vector starts to turn (a restart): the EKF restarted
            i_d, i_q = park(i_alpha, i_beta, theta)  # there, at rest (as after the alignment), on the
            restart_ekf(s, c, theta, i_d, i_q)  # stand's load
        else:  # the rotor moves (a load that changed): the EKF, which sees it, put back on that angle
            s[S_X + 3] = theta
        s[S_X + 4] = s[S_ANCHOR_TL]
        s[S_ANCHORED] = 0.0
        trust_rotor(s)
    elif s[S_MODE] == MODE_IF:
        # the EKF believed on the rotor's place on the vector and on the load where it sees the rotor turn
        # (C_ANCHOR_SPEED), or the guard holds the vector, or it says that the vector leads (or trails) the
        # rotor by more than the design load angle or that the rotor has moved on the vector by more than
        # _TRUST_MOVE since it was last believed (a load that changed: the EKF saw the motion). Else, at low speed, not:
        # with a mismatched motor model its angle and load drift there with the current (the resistance's
        # error), and an I-f current sized on that load would feed the drift (docs/sensorless.md)
        lead = wrap_angle(s[S_PHI] - s[S_X + 3])
        if (abs(s[S_X + 2]) >= c[C_ANCHOR_SPEED] or s[S_GUARD] != 0.0 or abs(lead) > c[C_E_MAX]
                or abs(wrap_angle(lead + s[S_TRUST_OFF])) > _TRUST_MOVE):
            trust_rotor(s)
    if c[C_PSI_ADAPT] != 0.0 and s[S_MODE] == MODE_EKF:
        adapt_psi(s, c)
    if s[S_FAULT] == FAULT_LATCHED:  # the safe state: stop and hold
        omega_ref = 0.0
    if c[C_FF] != 0.0:  # the speed loop's feedforward, its slope kept up in every mode
        speed_feedforward(s, c, omega_ref)
    t = s[S_CLOCK] * dt
    s[S_CLOCK] += 1.0
    mode = s[S_MODE]
    omega_hat = s[S_X + 2]
    if mode == MODE_ALIGN:  # how long the EKF has seen the rotor turn faster than C_ALIGN_SLIP
        s[S_LOS] = s[S_LOS] + dt if (c[C_ALIGN_SLIP] > 0.0 and abs(omega_hat) > c[C_ALIGN_SLIP]) else 0.0
    if mode == MODE_ALIGN and s[S_LOS] >= c[C_ALIGN_SLIP_TIME]:
        # the rotor runs away under the alignment's vector, faster than the alignment's own swing: a
        # load beyond the vector (a car parked on a slope). Its motion has shown the EKF the angle
        # (back-EMF): the EKF is kept (not restarted) and I-f takes over on its angle, the vector put
        # ahead of the rotor against the load at the current limit, as a loss-of-synchronism episode
        s[S_OMEGA_IF] = omega_hat
        relock(s, c, omega_hat, omega_ref)
        s[S_LOS] = 0.0
        s[S_EPISODE] = dt
        s[S_INSYNC] = 0.0
        s[S_AGREE] = 0.0
        mode = MODE_IF
    elif mode == MODE_ALIGN:
        t_hold = c[C_T_RAMP] + c[C_T_HOLD]
        t_sweep = t_hold + c[C_T_SWEEP]
        if t < t_sweep + c[C_T_SETTLE]:
            s[S_I_MAG] = c[C_I_ALIGN] * min(t / c[C_T_RAMP], 1.0) if c[C_T_RAMP] > 0.0 else c[C_I_ALIGN]
            if t < t_hold:
                s[S_PHI] = _HALF_PI
                s[S_OMEGA_IF] = 0.0
            elif t < t_sweep:
                s[S_PHI] = _HALF_PI * (1.0 - (t - t_hold) / c[C_T_SWEEP])
                s[S_OMEGA_IF] = -_HALF_PI / (c[C_T_SWEEP] * c[C_N])  # the sweep's speed [rad/s]
            else:
                s[S_PHI] = 0.0
                s[S_OMEGA_IF] = 0.0
        else:  # aligned: the magnet is on the vector; the EKF restarts there, at rest
            i_d, i_q = park(i_alpha, i_beta, s[S_PHI])
            restart_ekf(s, c, s[S_PHI], i_d, i_q)
            omega_hat = 0.0
            s[S_OMEGA_IF] = 0.0
            s[S_SLIP] = 0.0
            s[S_I_TGT] = max(c[C_I_IF], s[S_I_MAG])
            mode = MODE_IF
    elif mode == MODE_EKF and abs(omega_hat) < c[C_W_DOWN]:
        # handover down: the vector stays where the current is, its magnitude ramps up
        i_mag = math.sqrt(i_alpha * i_alpha + i_beta * i_beta)
        s[S_PHI] = math.atan2(i_beta, i_alpha)
        s[S_I_MAG] = i_mag
        s[S_I_TGT] = max(c[C_IF_MARGIN] * i_mag, c[C_I_IF])
        s[S_OMEGA_IF] = omega_hat
        s[S_AGREE] = 0.0
        s[S_SLIP] = 0.0
        seat_current_pis(s, c, s[S_PHI] + c[C_ADVANCE] * omega_hat, c[C_N] * omega_hat * dt,
                         i_mag, 0.0, i_mag, 0.0, 0.0)
        trust_rotor(s)  # FOC's angle: the rotor's place on the vector
        mode = MODE_IF
    trouble = False  # this period, in I-f: out of step, or a limit reached (the episode's clock)
    if mode == MODE_IF:
        if t > 0.0 and s[S_MODE] == MODE_IF:  # turn the vector (not in the period it was placed)
            if s[S_FAULT] == FAULT_LATCHED:
                s[S_I_TGT] = c[C_I_Q_MAX]
            anchored = s[S_ANCHORED] != 0.0
            # sized for the load the EKF had when it was last believed (``trust_rotor``, above), the stand's
            # while the car stands
            if_vector_step(s, c, omega_ref, s[S_ANCHOR_TL] if anchored else s[S_TRUST_TL])
            # the damping's input, omega_hat - omega_if low-pass filtered (see below)
            s[S_SLIP] += c[C_SLIP_FILTER] * (omega_hat - s[S_OMEGA_IF] - s[S_SLIP])
            if c[C_GUARD] != 0.0 or s[S_EPISODE] > 0.0 or s[S_FAULT] == FAULT_LATCHED:  # on while recovering
                sync_guard(s, c, omega_hat, c[C_IF_DAMP] / math.sqrt(max(s[S_I_MAG], 1.0)) * s[S_SLIP],
                           s[S_ANCHOR] if anchored else s[S_X + 3])
        w_if = s[S_OMEGA_IF]
        slipping = abs(s[S_SLIP]) > c[C_SLIP_TOL] + c[C_AGREE_TOL] * abs(w_if)
        # in trouble: out of step, or a limit reached: the guard holding the vector at the current
        # limit while the rotor does not follow the reference (a load beyond what the drive gives)
        trouble = slipping or (s[S_GUARD] != 0.0 and s[S_I_MAG] >= c[C_I_Q_MAX] and abs(omega_ref - omega_hat)
                               > c[C_SLIP_TOL] + c[C_AGREE_TOL] * abs(omega_ref))
        s[S_LOS] = s[S_LOS] + dt if trouble else 0.0
        if s[S_LOS] >= c[C_SLIP_TIME]:
            s[S_LOS] = 0.0
            begin_episode(s, c)
            # at the limit (not slipping) there is nothing more to give: the episode runs on to the fault
            if slipping and abs(omega_hat) >= c[C_W_DOWN]:  # loss of synchronism, the rotor turns and the
                seat_foc(s, c, omega_ref, omega_hat, i_alpha, i_beta, True)  # EKF holds its angle: flying handover
                mode = MODE_EKF
            elif slipping:  # at low speed: the vector put back on the rotor
                relock(s, c, omega_hat, omega_ref)
            w_if = s[S_OMEGA_IF]
        if mode == MODE_IF:
            if abs(w_if) > c[C_W_UP] and abs(omega_hat - w_if) < c[C_AGREE_TOL] * abs(w_if):
                s[S_AGREE] += dt
            else:
                s[S_AGREE] = 0.0
            if s[S_AGREE] >= c[C_AGREE_TIME]:  # handover up: FOC on the EKF, seated on the present state
                seat_foc(s, c, omega_ref, omega_hat, i_alpha, i_beta, False)
                s[S_REALIGN] = 0.0
                mode = MODE_EKF
        if mode == MODE_IF and s[S_FAULT] != FAULT_LATCHED and abs(omega_ref) > c[C_W_UP]:
            s[S_IF_DUE] += dt  # the reference asks for FOC's speed range, the unit is still in I-f
        else:
            s[S_IF_DUE] = 0.0
        if (0.0 < c[C_IF_DEADLINE] <= s[S_IF_DUE] and not slipping and abs(w_if) > c[C_W_UP]
                and abs(omega_hat) >= c[C_W_DOWN] and omega_hat * w_if > 0.0):
            # the handover up overdue (the EKF's speed swings about the I-f speed and never agrees for
            # C_AGREE_TIME): forced, FOC on the EKF, which holds the angle at this speed (back-EMF), an episode
            seat_foc(s, c, omega_ref, omega_hat, i_alpha, i_beta, True)
            s[S_REALIGN] = 0.0
            trouble = True
            begin_episode(s, c)
            mode = MODE_EKF
        elif 0.0 < c[C_STALL_TIME] <= s[S_IF_DUE]:
            # stalled (a limit reached): the rotor does not follow the vector; at a stand no back-EMF shows
            # its angle, so it is aligned again from standstill, an episode; realign_max times at most
            # without a handover up in between, then the fault latches (the safe state). A rotor that
            # turns the vector's way at |omega_hat| >= C_W_DOWN at that moment (a 400 A vector's swing
            # catches it again and again) shows the EKF its angle: FOC on the EKF instead (as after a
            # loss of synchronism at speed), counted as a realignment
            s[S_IF_DUE] = 0.0
            trouble = True
            begin_episode(s, c)
            if s[S_REALIGN] < c[C_REALIGN_MAX] and abs(omega_hat) >= c[C_W_DOWN] and omega_hat * w_if > 0.0:
                s[S_REALIGN] += 1.0
                seat_foc(s, c, omega_ref, omega_hat, i_alpha, i_beta, True)
                mode = MODE_EKF
            elif s[S_REALIGN] < c[C_REALIGN_MAX]:
                s[S_REALIGN] += 1.0
                s[S_CLOCK] = 0.0  # the alignment's clock: it starts with the next period
                s[S_I_MAG] = 0.0
                s[S_I_TGT] = 0.0
                s[S_OMEGA_IF] = 0.0
                s[S_SLIP] = 0.0
                s[S_AGREE] = 0.0
                s[S_GUARD] = 0.0
                s[S_LOS] = 0.0
                s[S_ANCHORED] = 0.0
                s[S_INT_D] = 0.0
                s[S_INT_Q] = 0.0
                mode = MODE_ALIGN
            else:
                s[S_FAULT] = FAULT_LATCHED
    age_episode(s, c, trouble)  # a loss-of-synchronism episode: recovered, or the fault latched
    s[S_MODE] = mode
    if mode == MODE_EKF:
        theta_ctrl = s[S_X + 3]
        omega_ctrl = omega_hat
        i_d, i_q = park(i_alpha, i_beta, theta_ctrl)
        if c[C_REF_MODE] != 0.0:  # the reference generator: MTPA, field weakening, limits, regen
            i_dref, i_qref = torque_speed_step(s, c, omega_ref, omega_hat)
        else:
            i_dref = c[C_I_D_REF]
            i_qref = speed_step(s, c, omega_ref, omega_hat)  # (14)
        v_d, v_q = current_step(s, c, i_dref, i_qref, i_d, i_q, omega_hat)  # (15)-(20)
    else:
        theta_ctrl = s[S_PHI]
        omega_ctrl = s[S_OMEGA_IF]
        if mode == MODE_IF:  # damp the rotor's swing on the vector: pull the vector back by
            # k (omega_hat - omega_if), filtered (updated with the vector's turn, above; 0 in the period
            # it is placed), k = 2 zeta sqrt(J / (psi i)) (docs/sensorless.md)
            theta_ctrl -= c[C_IF_DAMP] / math.sqrt(max(s[S_I_MAG], 1.0)) * s[S_SLIP]
        elif c[C_ALIGN_DAMP] != 0.0:  # alignment: the same damping on the speed the back-EMF shows
            # on the vector's q axis, v_q / (N psi) = omega_m cos(e) (e the vector's lead; the EKF's
            # angle is unknown here), less the sweep's own speed: the torque it adds is
            # -N psi i k omega_m cos^2(e), a damping whatever the angle (docs/sensorless.md)
            s[S_SLIP] += c[C_SLIP_FILTER] * (s[S_V_Q] / (c[C_N] * c[C_PSI]) - omega_ctrl - s[S_SLIP])
            theta_ctrl -= c[C_IF_DAMP] / math.sqrt(max(s[S_I_MAG], 1.0)) * s[S_SLIP]
        else:
            s[S_SLIP] = 0.0
        i_d, i_q = park(i_alpha, i_beta, theta_ctrl)
        i_qref = 0.0
        v_d, v_q = current_step(s, c, s[S_I_MAG], 0.0, i_d, i_q, 0.0)  # (15)-(16), no decoupling
    s[S_THETA_CTRL] = theta_ctrl
    s[S_OMEGA_CTRL] = omega_ctrl
    fault = s[S_FAULT] if s[S_FAULT] == FAULT_LATCHED else (FAULT_RECOVERING if s[S_EPISODE] > 0.0 else FAULT_NONE)
    v_alpha, v_beta = modulate(c, v_d, v_q, theta_ctrl, omega_ctrl, False)
    v_alpha, v_beta = store_command(s, c, i_alpha, i_beta, i_d, i_q, i_qref, v_d, v_q, v_alpha, v_beta)
    return (v_alpha, v_beta, v_d, v_q, i_d, i_q, i_qref,
            s[S_X], s[S_X + 1], s[S_X + 2], s[S_X + 3], s[S_X + 4], mode, fault, theta_ctrl, omega_ctrl)
