"""The sensorless unit's I-f strategy (``InjectionParams.low_speed`` = "if"): alignment, I-f drive (eq 12
sizes the vector's current, eq 13 turns it), handover to and from FOC (eqs 14-20) on the stationary-frame
EKF5 (eqs 23-27), the load-angle guard, the stand, and the loss-of-synchronism detection and recovery
(docs/sensorless.md): a state machine in the form of ``kernels.modes``' (``kernels.machine``): modes,
detectors that return events, the I-f rows of the unit's one ordered table ``machine.TRANSITIONS`` (and
the stand's, ``STAND_TRANSITIONS``), entry actions; ``sensorless_step`` is one control period.

The vectors ``s`` and ``c`` are laid out by ``pmsm_ev.kernels.layout`` (``S_*``, ``C_*``).
"""

from __future__ import annotations

import math

from .adaptation import adapt_period
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
    C_ADAPT,
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
    C_GUARD_BAND,
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
    C_RELOCK_TIME,
    C_SIN_E,
    C_SLIP_FILTER,
    C_SLIP_TIME,
    C_SLIP_TOL,
    C_SOFT_GUARD,
    C_STALL_TIME,
    C_STILL,
    C_STILL_TIME,
    C_T_HOLD,
    C_T_RAMP,
    C_T_SETTLE,
    C_T_SWEEP,
    C_TRUST_MOVE,
    C_W_DOWN,
    C_W_UP,
    FAULT_LATCHED,
    FAULT_NONE,
    FAULT_RECOVERING,
    MODE_ALIGN,
    MODE_EKF,
    MODE_IF,
    S_AGREE,
    S_ALIGN_CLOCK,
    S_ALIGN_SPEED,
    S_ANCHOR,
    S_ANCHOR_REL,
    S_ANCHOR_TL,
    S_ANCHORED,
    S_EPISODE,
    S_FAULT,
    S_GUARD,
    S_I_D_HAT,
    S_I_DL,
    S_I_MAG,
    S_I_Q_HAT,
    S_I_QL,
    S_I_TGT,
    S_IF_DUE,
    S_INSYNC,
    S_INT_D,
    S_INT_Q,
    S_LOS,
    S_MODE,
    S_OMEGA_CTRL,
    S_OMEGA_HAT,
    S_OMEGA_IF,
    S_P,
    S_PHI,
    S_REALIGN,
    S_RUNAWAY_T,
    S_SLIP,
    S_STILL_OUT,
    S_T_FF,
    S_THETA_CTRL,
    S_THETA_HAT,
    S_THETA_PRIOR,
    S_TL_HAT,
    S_TRUST_OFF,
    S_TRUST_TL,
    S_V_ALPHA,
    S_V_BETA,
    S_V_Q,
    S_W_INT,
)
from .machine import (
    A_ANCHOR,
    A_CATCH,
    A_FLYING,
    A_FORCED_UP,
    A_HANDOVER_DOWN,
    A_HANDOVER_UP,
    A_LATCH,
    A_REALIGN,
    A_RELOCK,
    A_RESTART_ON_ANCHOR,
    A_STALL_FOC,
    A_START_IF,
    EV_AGREED,
    EV_ALIGNED,
    EV_LIMIT,
    EV_NONE,
    EV_OVERDUE,
    EV_ROTOR_MOVES,
    EV_RUNAWAY,
    EV_SLIP,
    EV_SLIP_AT_SPEED,
    EV_SLOWED,
    EV_STALL,
    EV_STALL_LAST,
    EV_STALL_TURNING,
    EV_STANDS,
    EV_VECTOR_TURNS,
    STAND_FREE,
    STAND_TABLE,
    TRANSITION_TABLE,
    lookup,
)
from .observers import adapt_psi, ekf5ab_period
from .transforms import park, wrap_angle

#: the I-f strategy's state slots, zeroed where a unit with injection that cannot see its motor's axis takes it for good
#: (``kernels.modes.fall_back_to_if``); a reset zeroes them with every slot (their declared reset value)
IF_STATE = (S_MODE, S_ALIGN_CLOCK, S_PHI, S_I_MAG, S_I_TGT, S_OMEGA_IF, S_AGREE, S_SLIP, S_GUARD, S_LOS, S_EPISODE,
            S_INSYNC, S_FAULT, S_THETA_CTRL, S_OMEGA_CTRL, S_ANCHOR, S_ANCHORED, S_ANCHOR_TL, S_STILL_OUT, S_IF_DUE,
            S_REALIGN, S_TRUST_OFF, S_TRUST_TL, S_ANCHOR_REL, S_RUNAWAY_T, S_ALIGN_SPEED)


#: the least current [A] the vector's damping gain k / sqrt(i) is taken at (``damping_gain``): the gain, placed for
#: the swing of a rotor held by psi i, stays finite while the vector's current ramps up from 0
DAMP_I_MIN = 1.0


@kernel()
def damping_gain(s, c):
    """The vector's damping gain [rad per rad/s]: k = 2 zeta sqrt(J / (psi i)) at the vector's current i
    (``S_I_MAG``, at least ``DAMP_I_MIN``), ``C_IF_DAMP`` / sqrt(i) (docs/sensorless.md)."""
    return c[C_IF_DAMP] / math.sqrt(max(s[S_I_MAG], DAMP_I_MIN))


@kernel()
def fault_output(s):
    """The unit's ``fault`` output: ``FAULT_LATCHED`` in the safe state, else ``FAULT_RECOVERING`` during an episode,
    else ``FAULT_NONE`` (both strategies)."""
    return s[S_FAULT] if s[S_FAULT] == FAULT_LATCHED else (FAULT_RECOVERING if s[S_EPISODE] > 0.0 else FAULT_NONE)


@kernel()
def enter_if_strategy(s):
    """The I-f strategy from its start (``IF_STATE`` zeroed): the alignment (``MODE_ALIGN``) from its clock's 0."""
    for slot in IF_STATE:
        s[slot] = 0.0

# -- the I-f strategy's physics: the handovers' seating, the EKF's restart, the vector's sizing ----


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
    s[S_TRUST_OFF] = wrap_angle(s[S_THETA_HAT] - s[S_PHI])
    s[S_TRUST_TL] = s[S_TL_HAT]


@kernel()
def restart_ekf_on(s, c, theta, omega, t_l, p0):
    """The EKF put on an angle, speed and load, its covariance diagonal from ``p0`` (a ``C_*`` slot of 5
    entries); its currents kept."""
    s[S_OMEGA_HAT] = omega
    s[S_THETA_HAT] = theta
    s[S_TL_HAT] = t_l
    for k in range(25):
        s[S_P + k] = 0.0
    for k in range(5):
        s[S_P + 6 * k] = c[p0 + k]


@kernel()
def model_torque(c, i_d, i_q):
    """Eq 12 with the controller's motor model, times k_dq [N m]."""
    return c[C_K_DQN] * i_q * (c[C_PSI] + (c[C_L_D] - c[C_L_Q]) * i_d)


@kernel()
def restart_ekf(s, c, theta, i_d, i_q):
    """The EKF restarted at a known angle from standstill: x = [i_d, i_q, 0, theta, 0], P = the
    restart's P0 (``C_P0_ALIGNED``); the rotor's place on the I-f vector (``S_TRUST_OFF``) is where
    it was restarted, its load 0 (``trust_rotor``)."""
    s[S_I_D_HAT] = i_d
    s[S_I_Q_HAT] = i_q
    restart_ekf_on(s, c, theta, 0.0, 0.0, C_P0_ALIGNED)
    s[S_THETA_PRIOR] = theta
    trust_rotor(s)


@kernel()
def seat_foc(s, c, omega_ref, omega_hat, i_alpha, i_beta, on_load):
    """Hand the drive to FOC on the EKF (mode EKF), seated on the present state: the speed PI's
    integral so that (14) returns the q current that gives the present torque once i_d is at its
    reference (eq 12: the I-f vector's d current adds a reluctance torque N (L_d - L_q) i_d i_q that
    FOC's i_d = 0 takes away; with the reference generator, ``C_REF_MODE`` != 0: the present torque
    over k_t, the generator's references for it), or with ``on_load`` the current of the load the EKF sees,
    T_L_hat / k_t (k_t = k_dq N psi), after a loss of synchronism, when the present current says nothing of the
    load; the current PIs on the voltage held, turned by one period of the I-f vector's rotation
    (``seat_current_pis``)."""
    theta = s[S_THETA_HAT]
    i_d, i_q = park(i_alpha, i_beta, theta)
    if c[C_REF_MODE] != 0.0:  # the reference generator's modes: (14) returns the present torque / k_t,
        # which the generator turns into its references (the current PIs seated on them)
        t_seat = s[S_TL_HAT] if on_load else model_torque(c, i_d, i_q)
        t_pi = t_seat - s[S_T_FF] if c[C_FF] != 0.0 else t_seat  # the feedforward's share is its own
        s[S_W_INT] = t_pi / c[C_K_T] - c[C_KP_W] * (omega_ref - omega_hat)
        i_dref, i_seat = generate_references(s, c, t_seat, omega_hat)
    elif on_load:
        i_dref = c[C_I_D_REF]
        i_seat = s[S_TL_HAT] / c[C_K_T]
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
    T_e = k_dq N (psi i sin e + (L_d - L_q) i^2 sin e cos e) [N m] (the controller's motor model, k_dq the
    dq convention's factor, ``MotorParams.k_dq``); with L_q > L_d the reluctance term takes torque below
    e = 90 deg and adds it above."""
    return c[C_K_DQN] * i * sin_e * (c[C_PSI] + (c[C_L_D] - c[C_L_Q]) * i * cos_e)


@kernel()
def vector_current(c, torque, sin_e, cos_e):
    """The least magnitude whose vector at the load angle e gives ``torque`` [A] (``vector_torque``
    solved for i, the smaller root); inf if no current does."""
    a = (c[C_L_Q] - c[C_L_D]) * cos_e  # k_dq N sin e (psi i - a i^2) = torque
    t = abs(torque) / (c[C_K_DQN] * sin_e)
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
        t_cap = c[C_K_T] * s[S_I_MAG]
    step = c[C_IF_ACCEL] * dt
    hi = min(step, max((t_cap - t_l) / j * dt, 0.0))
    lo = max(-step, min((-t_cap - t_l) / j * dt, 0.0))
    w_if = s[S_OMEGA_IF]
    want = min(max(omega_ref - w_if, -step), step)  # the step the reference asks for
    s[S_OMEGA_IF] = w_if + min(max(want, lo), hi)
    s[S_PHI] = wrap_angle(s[S_PHI] + c[C_N] * s[S_OMEGA_IF] * dt)  # (13)
    need = vector_current(c, t_l + j * want / dt, sin_e, cos_e)
    load_current = c[C_IF_MARGIN] * abs(t_l) / c[C_K_T]  # eq 12 with i_d = 0, times the margin
    s[S_I_TGT] = min(max(s[S_I_TGT], need, load_current), c[C_I_Q_MAX])
    rate = (c[C_I_RATE_LOAD] if s[S_GUARD] != 0.0 else c[C_I_RATE]) * dt
    s[S_I_MAG] += min(max(s[S_I_TGT] - s[S_I_MAG], -rate), rate)


#: ``S_GUARD`` values: the soft limit holds the vector's speed, the hard one its angle
GUARD_SOFT, GUARD_HARD = 1.0, 2.0


@kernel()
def sync_guard(s, c, omega_hat, lag, theta):
    """Keep the applied I-f vector (``S_PHI`` less ``lag``, the damping's pull-back) within
    +-``C_E_GUARD`` of the rotor's angle ``theta`` (electrical: the EKF's, or while the car stands
    the one it had when the stand began): a vector that would lead (or trail) the
    rotor by more is held there and turns at the rotor's speed, so the rotor cannot fall out of
    step while the EKF holds its angle (``GUARD_HARD``). Beyond ``C_SOFT_GUARD`` its speed is held to
    the rotor's (``GUARD_SOFT``): the lead stops growing before the EKF, whose load state lags a
    sudden load, shows the rotor slowing. ``S_GUARD`` is released once the vector is back within
    ``C_SOFT_GUARD`` by ``C_GUARD_BAND``."""
    e = wrap_angle(s[S_PHI] - lag - theta)
    e_max = c[C_E_GUARD]
    soft = c[C_SOFT_GUARD]
    if e > e_max or e < -e_max:
        s[S_PHI] = wrap_angle(theta + lag + (e_max if e > 0.0 else -e_max))
        s[S_OMEGA_IF] = omega_hat
        s[S_GUARD] = GUARD_HARD
    elif (e > soft and s[S_OMEGA_IF] > omega_hat) or (e < -soft and s[S_OMEGA_IF] < omega_hat):
        s[S_OMEGA_IF] = omega_hat
        s[S_GUARD] = GUARD_SOFT
    elif abs(e) < soft - c[C_GUARD_BAND]:
        s[S_GUARD] = 0.0


@kernel()
def relock(s, c, omega_hat, omega_ref):
    """Recovery at low speed (a loss of synchronism, or a rotor running away under the alignment):
    the vector put on the EKF's angle, leading it by the design load angle in the direction of the
    torque needed to hold the load the EKF sees and to bring the speed to the reference within
    ``C_RELOCK_TIME``, turning at the EKF's speed, its current set to the limit at once; the rotor's
    place on it trusted (``trust_rotor``)."""
    push = s[S_TL_HAT] + c[C_J_IF] * (omega_ref - omega_hat) / c[C_RELOCK_TIME]
    s[S_PHI] = wrap_angle(s[S_THETA_HAT] + (c[C_E_MAX] if push >= 0.0 else -c[C_E_MAX]))
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


# == the I-f strategy as a state machine (``kernels.machine``: its codes and tables) ===============
# -- detectors: each returns an event or EV_NONE -------------------------------------------------
@kernel()
def car_stands(s, c):
    """The car stands on the I-f vector: in I-f (the last period's mode), the vector's speed below
    ``C_STILL`` (a back-EMF of 0.18 V at 0.5 rad/s: none to see the angle by), and the EKF's too, or, while a
    stand lasts, above it for less than ``C_STILL_TIME`` (``S_STILL_OUT``: its noise, not a motion)."""
    return (s[S_MODE] == MODE_IF and abs(s[S_OMEGA_IF]) < c[C_STILL]
            and (abs(s[S_OMEGA_HAT]) < c[C_STILL] or (s[S_ANCHORED] != 0.0 and s[S_STILL_OUT] < c[C_STILL_TIME])))


@kernel()
def detect_stand(s, c):
    """EV_STANDS when the car begins to stand (``car_stands``); when a stand ends, EV_VECTOR_TURNS with the
    EKF's speed below ``C_STILL`` (the vector has begun to turn: a restart), else EV_ROTOR_MOVES."""
    stands = car_stands(s, c)
    if s[S_ANCHORED] == STAND_FREE:
        return EV_STANDS if stands else EV_NONE
    if stands:
        return EV_NONE
    return EV_VECTOR_TURNS if abs(s[S_OMEGA_HAT]) < c[C_STILL] else EV_ROTOR_MOVES


@kernel()
def ekf_believed(s, c):
    """In I-f, outside a stand: the EKF is believed on the rotor's place on the vector and on the load
    (``trust_rotor``) where it sees the rotor turn (``C_ANCHOR_SPEED``), or the guard holds the vector, or it
    says that the vector leads (or trails) the rotor by more than the design load angle, or that the rotor
    has moved on the vector by more than ``C_TRUST_MOVE`` since it was last believed (a load that changed:
    the EKF saw the motion). Else, at low speed, not: with a mismatched motor model its angle and load
    drift there with the current (the resistance's error), and an I-f current sized on that load would
    feed the drift (docs/sensorless.md)."""
    lead = wrap_angle(s[S_PHI] - s[S_THETA_HAT])
    return (abs(s[S_OMEGA_HAT]) >= c[C_ANCHOR_SPEED] or s[S_GUARD] != 0.0 or abs(lead) > c[C_E_MAX]
            or abs(wrap_angle(lead + s[S_TRUST_OFF])) > c[C_TRUST_MOVE])


@kernel()
def alignment_over(c, t):
    """The alignment's schedule is over at the time ``t`` [s] in it: ramp, hold, sweep and settle."""
    t_hold = c[C_T_RAMP] + c[C_T_HOLD]
    t_sweep = t_hold + c[C_T_SWEEP]
    return t >= t_sweep + c[C_T_SETTLE]


@kernel()
def detect_alignment_end(s, c, t):
    """EV_RUNAWAY once the EKF has seen the rotor turn faster than ``C_ALIGN_SLIP`` for
    ``C_ALIGN_SLIP_TIME`` (its timer ``S_RUNAWAY_T``): a load beyond the vector, faster than the alignment's
    own swing; else EV_ALIGNED at the end of the schedule."""
    dt = c[C_DT]
    runaway = c[C_ALIGN_SLIP] > 0.0 and abs(s[S_OMEGA_HAT]) > c[C_ALIGN_SLIP]
    s[S_RUNAWAY_T] = s[S_RUNAWAY_T] + dt if runaway else 0.0
    if s[S_RUNAWAY_T] >= c[C_ALIGN_SLIP_TIME]:
        return EV_RUNAWAY
    return EV_ALIGNED if alignment_over(c, t) else EV_NONE


@kernel()
def detect_slowed(s, c):
    """EV_SLOWED on FOC below |omega_hat| = ``C_W_DOWN`` (the hysteresis against ``C_W_UP``)."""
    return EV_SLOWED if abs(s[S_OMEGA_HAT]) < c[C_W_DOWN] else EV_NONE


@kernel()
def slipping(s, c):
    """The rotor out of step with the I-f vector: |omega_hat - omega_if| (filtered, ``S_SLIP``) beyond
    ``C_SLIP_TOL`` + ``C_AGREE_TOL`` |omega_if| (a locked vector's swing stays within +-3 rad/s)."""
    return abs(s[S_SLIP]) > c[C_SLIP_TOL] + c[C_AGREE_TOL] * abs(s[S_OMEGA_IF])


@kernel()
def at_limit(s, c, omega_ref, omega_hat):
    """A limit reached: the guard holding the vector with the current at ``C_I_Q_MAX`` while the rotor is as
    far from the reference as a slip (a load beyond what the drive gives)."""
    return (s[S_GUARD] != 0.0 and s[S_I_MAG] >= c[C_I_Q_MAX] and abs(omega_ref - omega_hat)
            > c[C_SLIP_TOL] + c[C_AGREE_TOL] * abs(omega_ref))


@kernel()
def detect_trouble(s, c, slip, limit, omega_hat):
    """In trouble (``slip``: ``slipping``; ``limit``: ``at_limit``) for ``C_SLIP_TIME`` (its timer ``S_LOS``):
    EV_SLIP_AT_SPEED where the rotor slips at ``C_W_DOWN`` or faster, EV_SLIP slower, EV_LIMIT at the limit
    without a slip."""
    dt = c[C_DT]
    s[S_LOS] = s[S_LOS] + dt if (slip or limit) else 0.0
    if s[S_LOS] >= c[C_SLIP_TIME]:
        s[S_LOS] = 0.0
        if not slip:
            return EV_LIMIT
        return EV_SLIP_AT_SPEED if abs(omega_hat) >= c[C_W_DOWN] else EV_SLIP
    return EV_NONE


@kernel()
def detect_agreed(s, c, omega_hat):
    """EV_AGREED once the EKF's speed has agreed with the I-f speed, above ``C_W_UP``, to within
    ``C_AGREE_TOL`` for ``C_AGREE_TIME`` (its timer ``S_AGREE``): the back-EMF shows the angle, the handover up."""
    w_if = s[S_OMEGA_IF]
    if abs(w_if) > c[C_W_UP] and abs(omega_hat - w_if) < c[C_AGREE_TOL] * abs(w_if):
        s[S_AGREE] += c[C_DT]
    else:
        s[S_AGREE] = 0.0
    return EV_AGREED if s[S_AGREE] >= c[C_AGREE_TIME] else EV_NONE


@kernel()
def detect_due(s, c, omega_ref, omega_hat, slip):
    """The handover up due: its timer ``S_IF_DUE`` counts the time in I-f with |omega_ref| above ``C_W_UP``
    (the reference asks for FOC's speed range; not in the safe state), which a healthy launch ends
    ``C_AGREE_TIME`` after the reference passes ``C_W_UP``. After ``C_IF_DEADLINE``, EV_OVERDUE where the
    rotor turns with the vector (the I-f speed above ``C_W_UP``, the EKF's of the same sign at ``C_W_DOWN``
    or faster, not ``slip``); after ``C_STALL_TIME``, a stall: EV_STALL_TURNING where the rotor turns the
    vector's way at ``C_W_DOWN`` or faster, EV_STALL where not, EV_STALL_LAST with no realignment left
    (``C_REALIGN_MAX``). 0 turns either off."""
    if s[S_FAULT] != FAULT_LATCHED and abs(omega_ref) > c[C_W_UP]:
        s[S_IF_DUE] += c[C_DT]
    else:
        s[S_IF_DUE] = 0.0
    w_if = s[S_OMEGA_IF]
    turning = abs(omega_hat) >= c[C_W_DOWN] and omega_hat * w_if > 0.0
    if 0.0 < c[C_IF_DEADLINE] <= s[S_IF_DUE] and not slip and abs(w_if) > c[C_W_UP] and turning:
        return EV_OVERDUE
    if 0.0 < c[C_STALL_TIME] <= s[S_IF_DUE]:
        if s[S_REALIGN] >= c[C_REALIGN_MAX]:
            return EV_STALL_LAST
        return EV_STALL_TURNING if turning else EV_STALL
    return EV_NONE


# -- entry actions -------------------------------------------------------------------------------
@kernel()
def catch_runaway(s, c, omega_ref):
    """The rotor runs away under the alignment's vector (a car parked on a slope). Its motion has shown the
    EKF the angle (back-EMF): the EKF is kept (not restarted) and I-f takes over on its angle, the vector put
    ahead of the rotor against the load at the current limit (``relock``), as a new loss-of-synchronism
    episode (one still running from a realignment is not continued: its age starts again)."""
    relock(s, c, s[S_OMEGA_HAT], omega_ref)
    s[S_RUNAWAY_T] = 0.0
    s[S_EPISODE] = c[C_DT]
    s[S_INSYNC] = 0.0
    s[S_AGREE] = 0.0


@kernel()
def start_if(s, c, i_alpha, i_beta):
    """Aligned: the magnet is on the vector; the EKF restarts there, at rest (``restart_ekf``); I-f from
    rest, its current at least ``C_I_IF``."""
    i_d, i_q = park(i_alpha, i_beta, s[S_PHI])
    restart_ekf(s, c, s[S_PHI], i_d, i_q)
    s[S_OMEGA_IF] = 0.0
    s[S_SLIP] = 0.0
    s[S_I_TGT] = max(c[C_I_IF], s[S_I_MAG])


@kernel()
def hand_down(s, c, i_alpha, i_beta):
    """Handover down: the vector stays where the current is, its magnitude ramps up to ``C_IF_MARGIN`` times
    it (at least ``C_I_IF``), the I-f speed starts at the EKF's; the current PIs seated on the voltage held
    (``seat_current_pis``); FOC's angle is the rotor's place on the vector (``trust_rotor``)."""
    dt = c[C_DT]
    omega_hat = s[S_OMEGA_HAT]
    i_mag = math.sqrt(i_alpha * i_alpha + i_beta * i_beta)
    s[S_PHI] = math.atan2(i_beta, i_alpha)
    s[S_I_MAG] = i_mag
    s[S_I_TGT] = max(c[C_IF_MARGIN] * i_mag, c[C_I_IF])
    s[S_OMEGA_IF] = omega_hat
    s[S_AGREE] = 0.0
    s[S_SLIP] = 0.0
    seat_current_pis(s, c, s[S_PHI] + c[C_ADVANCE] * omega_hat, c[C_N] * omega_hat * dt,
                     i_mag, 0.0, i_mag, 0.0, 0.0)
    trust_rotor(s)


@kernel()
def realign(s):
    """The alignment from standstill again: its clock from the next period, the vector off, the I-f
    detectors' timers and filters, the stand and the current PIs' integrators cleared."""
    s[S_ALIGN_CLOCK] = 0.0
    s[S_I_MAG] = 0.0
    s[S_I_TGT] = 0.0
    s[S_OMEGA_IF] = 0.0
    s[S_SLIP] = 0.0
    s[S_ALIGN_SPEED] = 0.0
    s[S_AGREE] = 0.0
    s[S_GUARD] = 0.0
    s[S_LOS] = 0.0
    s[S_RUNAWAY_T] = 0.0
    s[S_ANCHORED] = float(STAND_FREE)
    s[S_INT_D] = 0.0
    s[S_INT_Q] = 0.0


@kernel()
def enter_if(s, c, action, i_alpha, i_beta, omega_ref):
    """Run an entry action of the I-f strategy (``A_*``). The handover up's due timer (``S_IF_DUE``) is
    cleared where the handover comes by agreement, by a slip at speed or by a stall; a forced handover
    keeps it (a handover down while the reference still asks for FOC's range is forced again at once)."""
    if action == A_CATCH:
        catch_runaway(s, c, omega_ref)
    elif action == A_START_IF:
        start_if(s, c, i_alpha, i_beta)
    elif action == A_HANDOVER_DOWN:
        hand_down(s, c, i_alpha, i_beta)
    elif action == A_HANDOVER_UP:
        seat_foc(s, c, omega_ref, s[S_OMEGA_HAT], i_alpha, i_beta, False)
        s[S_REALIGN] = 0.0
        s[S_IF_DUE] = 0.0
    elif action == A_FORCED_UP:
        seat_foc(s, c, omega_ref, s[S_OMEGA_HAT], i_alpha, i_beta, True)
        s[S_REALIGN] = 0.0
        begin_episode(s, c)
    else:  # a loss of synchronism, a limit or a stall: an episode
        if action == A_STALL_FOC or action == A_REALIGN or action == A_LATCH:
            s[S_IF_DUE] = 0.0
        begin_episode(s, c)
        if action == A_FLYING:
            seat_foc(s, c, omega_ref, s[S_OMEGA_HAT], i_alpha, i_beta, True)
            s[S_IF_DUE] = 0.0
        elif action == A_RELOCK:
            relock(s, c, s[S_OMEGA_HAT], omega_ref)
        elif action == A_STALL_FOC:
            s[S_REALIGN] += 1.0
            seat_foc(s, c, omega_ref, s[S_OMEGA_HAT], i_alpha, i_beta, True)
        elif action == A_REALIGN:
            s[S_REALIGN] += 1.0
            realign(s)
        elif action == A_LATCH:
            s[S_FAULT] = FAULT_LATCHED


@kernel()
def if_transition(s, c, mode, event, i_alpha, i_beta, omega_ref):
    """Take the table's (``TRANSITIONS``) transition for (mode, event), if any: the entry action run. Returns the mode
    (``S_MODE`` is written at the end of the period: ``sensorless_step`` reads the last period's)."""
    if event == EV_NONE:
        return mode
    new, action = lookup(TRANSITION_TABLE, mode, event)
    if action < 0.0:
        return mode
    enter_if(s, c, action, i_alpha, i_beta, omega_ref)
    return new


@kernel()
def anchor(s):
    """The stand begins: anchored on the rotor's place on the vector and the load of when the EKF was last
    believed (``trust_rotor``): the rotor is held by the vector, so its angle is the vector's plus that
    offset."""
    s[S_ANCHOR_REL] = s[S_TRUST_OFF]
    s[S_ANCHOR] = wrap_angle(s[S_PHI] + s[S_TRUST_OFF])
    s[S_ANCHOR_TL] = s[S_TRUST_TL]


@kernel()
def release(s, c, restart, i_alpha, i_beta):
    """The stand ends; the rotor has turned with the vector since it began: the EKF put on the vector's angle
    now plus the anchor's offset, on the stand's load; with ``restart`` (the vector starts to turn) restarted
    there at rest, as after the alignment, else (the rotor moves: the EKF sees it) its angle set there."""
    theta = wrap_angle(s[S_PHI] + s[S_ANCHOR_REL])
    if restart:
        i_d, i_q = park(i_alpha, i_beta, theta)
        restart_ekf(s, c, theta, i_d, i_q)
    else:
        s[S_THETA_HAT] = theta
    s[S_TL_HAT] = s[S_ANCHOR_TL]
    trust_rotor(s)


@kernel()
def stand_transition(s, c, event, i_alpha, i_beta):
    """Take ``STAND_TRANSITIONS``' transition for (``S_ANCHORED``, event), if any."""
    if event == EV_NONE:
        return
    new, action = lookup(STAND_TABLE, s[S_ANCHORED], event)
    if action < 0.0:
        return
    s[S_ANCHORED] = new
    if action == A_ANCHOR:
        anchor(s)
    else:
        release(s, c, action == A_RESTART_ON_ANCHOR, i_alpha, i_beta)


# -- the modes' control --------------------------------------------------------------------------
#: the alignment's first axis [rad]: +90 deg, whose unstable point (-90 deg) the sweep to 0 deg then
#: carries the rotor away from (docs/sensorless.md, "Alignment")
_HALF_PI = 0.5 * math.pi


@kernel()
def align_schedule(s, c, t):
    """The alignment's vector at the time ``t`` [s] in it (``C_T_RAMP`` .. ``C_T_SETTLE``): its current ramped
    up on +90 deg, held, swept to 0 deg, held."""
    t_hold = c[C_T_RAMP] + c[C_T_HOLD]
    t_sweep = t_hold + c[C_T_SWEEP]
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


@kernel()
def turn_vector(s, c, omega_ref, omega_hat):
    """I-f, every period but the one the vector was placed in: the vector turned and sized
    (``if_vector_step``) for the load the EKF had when it was last believed (the stand's while the car
    stands); the damping's input omega_hat - omega_if filtered (``S_SLIP``); the guard (``sync_guard``) on
    the EKF's angle (the stand's anchor while the car stands), on with ``C_GUARD``, while an episode lasts
    and in the safe state."""
    if s[S_FAULT] == FAULT_LATCHED:
        s[S_I_TGT] = c[C_I_Q_MAX]
    anchored = s[S_ANCHORED] != STAND_FREE
    if_vector_step(s, c, omega_ref, s[S_ANCHOR_TL] if anchored else s[S_TRUST_TL])
    s[S_SLIP] += c[C_SLIP_FILTER] * (omega_hat - s[S_OMEGA_IF] - s[S_SLIP])
    if c[C_GUARD] != 0.0 or s[S_EPISODE] > 0.0 or s[S_FAULT] == FAULT_LATCHED:
        sync_guard(s, c, omega_hat, damping_gain(s, c) * s[S_SLIP],
                   s[S_ANCHOR] if anchored else s[S_THETA_HAT])


@kernel(_sig(f"UniTuple({_F}, 16)", _V, _V, _F, _F, _F))
def sensorless_step(s, c, i_alpha, i_beta, omega_ref):
    """One control period of the sensorless unit with the I-f strategy (``pmsm_ev.control_unit``, observer
    "sensorless", ``C_LOW_SPEED`` = I-f): never reads the rotor angle or speed. Returns ``control_step``'s
    outputs, the mode (``MODE_ALIGN``, ``MODE_IF``, ``MODE_EKF``), the fault (``FAULT_*``) and the control
    frame's angle [rad] and speed [rad/s].

    1. The stationary-frame EKF5 (eqs 23-27 with h = inverse Park) in every mode.
    2. The stand (``STAND_TRANSITIONS``): a car standing on the I-f vector is anchored (``anchor``), and the
       EKF put back on the anchor when the stand ends (``release``); outside a stand, in I-f, the EKF believed
       where it has something to say (``ekf_believed``, ``trust_rotor``).
    3. The modes' detectors, in order, each in the mode the one before left, with ``TRANSITIONS``: in
       alignment ``detect_alignment_end`` (else the schedule, ``align_schedule``); on FOC ``detect_slowed``; in
       I-f (after ``turn_vector``, but in the period the vector was placed) ``detect_trouble``, then
       ``detect_agreed``, then ``detect_due``.
    4. The episode's clock (``age_episode``): trouble is the trouble timer running or an episode's event.
    5. The mode's control: FOC (eqs 14-20) on the EKF's angle and speed; in alignment and I-f the current PIs
       in the vector's frame (reference on its d axis, no decoupling: the back-EMF is small there and the
       integrators carry it), the vector pulled back by the damping (I-f: on ``S_SLIP``; alignment: on the
       back-EMF of its q axis, ``S_ALIGN_SPEED``).
    In the safe state (the fault latched) the reference is taken as 0: stop and hold.
    """
    dt = c[C_DT]
    ekf5ab_period(s, c, i_alpha, i_beta)  # (23)-(27)
    # the rotor's speed above C_STILL, how long (the stand's end)
    s[S_STILL_OUT] = s[S_STILL_OUT] + c[C_DT] if abs(s[S_OMEGA_HAT]) >= c[C_STILL] else 0.0
    event = detect_stand(s, c)
    if event != EV_NONE:
        stand_transition(s, c, event, i_alpha, i_beta)
    elif s[S_ANCHORED] == STAND_FREE and s[S_MODE] == MODE_IF and ekf_believed(s, c):
        trust_rotor(s)
    if c[C_PSI_ADAPT] != 0.0 and s[S_MODE] == MODE_EKF:
        adapt_psi(s, c)
    if s[S_FAULT] == FAULT_LATCHED:  # the safe state: stop and hold
        omega_ref = 0.0
    if c[C_FF] != 0.0:  # the speed loop's feedforward, its slope kept up in every mode
        speed_feedforward(s, c, omega_ref)
    t = s[S_ALIGN_CLOCK] * dt  # the alignment's clock
    s[S_ALIGN_CLOCK] += 1.0
    last = s[S_MODE]
    mode = last
    trouble = False  # this period, in I-f: out of step, or a limit reached (the episode's clock)
    slip = False
    # the detectors in their order, each in the mode the one before left (the table's comment); the
    # transitions taken in one place (one inlined copy of the entry actions: the step stays small)
    for stage in range(4):
        event = EV_NONE
        if stage == 0:  # the mode's own: the alignment's end (else its schedule), FOC's handover down
            if mode == MODE_ALIGN:
                event = detect_alignment_end(s, c, t)
                if event == EV_NONE:
                    align_schedule(s, c, t)
            elif mode == MODE_EKF:
                event = detect_slowed(s, c)
        elif mode != MODE_IF:
            break
        elif stage == 1:  # I-f: the vector turned (not in the period it was placed), then in trouble?
            omega_hat = s[S_OMEGA_HAT]
            if last == MODE_IF:
                turn_vector(s, c, omega_ref, omega_hat)
            slip = slipping(s, c)
            event = detect_trouble(s, c, slip, at_limit(s, c, omega_ref, omega_hat), omega_hat)
            trouble = s[S_LOS] > 0.0 or event != EV_NONE
        elif stage == 2:
            event = detect_agreed(s, c, s[S_OMEGA_HAT])
        else:
            event = detect_due(s, c, omega_ref, s[S_OMEGA_HAT], slip)
            trouble = trouble or event != EV_NONE
        if event != EV_NONE:
            mode = if_transition(s, c, mode, event, i_alpha, i_beta, omega_ref)
    age_episode(s, c, trouble)  # a loss-of-synchronism episode: recovered, or the fault latched
    s[S_MODE] = mode
    if mode == MODE_EKF:
        omega_hat = s[S_OMEGA_HAT]
        theta_ctrl = s[S_THETA_HAT]
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
            theta_ctrl -= damping_gain(s, c) * s[S_SLIP]
        elif c[C_ALIGN_DAMP] != 0.0:  # alignment: the same damping on the speed the back-EMF shows
            # on the vector's q axis, v_q / (N psi) = omega_m cos(e) (e the vector's lead; the EKF's
            # angle is unknown here), less the sweep's own speed: the torque it adds is
            # -N psi i k omega_m cos^2(e), a damping whatever the angle (docs/sensorless.md)
            s[S_ALIGN_SPEED] += c[C_SLIP_FILTER] * (s[S_V_Q] / (c[C_N] * c[C_PSI]) - omega_ctrl - s[S_ALIGN_SPEED])
            theta_ctrl -= damping_gain(s, c) * s[S_ALIGN_SPEED]
        else:
            s[S_ALIGN_SPEED] = 0.0
        i_d, i_q = park(i_alpha, i_beta, theta_ctrl)
        i_qref = 0.0
        v_d, v_q = current_step(s, c, s[S_I_MAG], 0.0, i_d, i_q, 0.0)  # (15)-(16), no decoupling
    s[S_THETA_CTRL] = theta_ctrl
    s[S_OMEGA_CTRL] = omega_ctrl
    fault = fault_output(s)
    v_alpha, v_beta = modulate(c, v_d, v_q, theta_ctrl, omega_ctrl, False)
    v_alpha, v_beta = store_command(s, c, i_alpha, i_beta, i_d, i_q, i_qref, v_d, v_q, v_alpha, v_beta)
    if c[C_ADAPT] != 0.0:  # psi and R_s over the period just gone (AD1-AD6), in FOC on the EKF only
        adapt_period(s, c, i_alpha, i_beta, theta_ctrl, omega_ctrl, 1.0 if mode == MODE_EKF else 0.0)
    return (v_alpha, v_beta, v_d, v_q, i_d, i_q, i_qref,
            s[S_I_D_HAT], s[S_I_Q_HAT], s[S_OMEGA_HAT], s[S_THETA_HAT], s[S_TL_HAT], mode, fault, theta_ctrl,
            omega_ctrl)
