"""The sensorless unit's state machines: the modes' events, entry actions and transition table of both
strategies at and near zero speed, and its lookup.

Each strategy (``kernels.startup``: alignment, I-f and handover, ``low_speed`` = "if"; ``kernels.modes``:
injection) is written the same way:

* **modes** (``MODE_*`` in ``kernels.layout``, the unit's ``S_MODE``), each with its own control;
* **detectors**: small functions, one purpose and (where it needs time) one timer each, that return an
  **event** (``EV_*``; ``EV_NONE`` for none);
* **one ordered transition table**, ``TRANSITIONS``, of both strategies' rows (mode, event, next mode, entry
  action), looked up by ``lookup``, the first match taken; a pair not in the table changes nothing (the I-f
  strategy's stand, a second machine beside its modes, has its own three rows, ``STAND_TRANSITIONS``);
* **entry actions** (``A_*``): what a transition does to the state, each a small function, run by the
  strategy's ``enter`` (``modes.enter``, ``startup.enter_if``; the stand's in
  ``startup.stand_transition``).

Event and action codes are distinct across the strategies, so that a row says which strategy it is of. Modes,
events, actions and the stand's states are named integers, each declared once (the modes in ``kernels.layout``, the
rest here); the state vector holds a mode or an event as its float (``S_MODE``, ``S_EVENT``, ``S_ANCHORED``: exact for
these small integers), and the compiled table as floats (``jit.table``), which compare equal to them.
"""

from __future__ import annotations

from .jit import kernel
from .jit import table as _table
from .layout import (
    MODE_ACQUIRE,
    MODE_ALIGN,
    MODE_EKF,
    MODE_IF,
    MODE_INJECTION,
    MODE_POLARITY,
)

EV_NONE = 0  #: no event this period

# == the injection strategy (``kernels.modes``) ==================================================
# -- events: what a detector saw this period (``S_EVENT``) ------------------------------------
EV_ACQUIRED = 1  #: the acquisition and the tracking observer's settling are over
EV_POLARITY_RIGHT = 2  #: the polarity test found the tracking observer's direction right
EV_POLARITY_FLIPPED = 3  #: ... found it pi off
EV_POLARITY_UNRESOLVED = 4  #: ... could not tell (the answers at +-i differ by less than C_POL_CONTRAST)
EV_FAST = 5  #: the speed reached C_BLEND_HI: the EKF alone
EV_SLOW = 6  #: the speed fell below C_BLEND_HI - C_BLEND_HYST: the injection back on
EV_INJECTION_LOST = 7  #: the tracking observer's angle error stayed beyond C_INJ_LOS_ANGLE
EV_DISAGREE = 8  #: in the blend, the EKF's angle stayed that far from the tracking observer's
EV_EKF_LOST = 9  #: the EKF's current innovation stayed beyond C_EKF_LOS_I
EV_FLIPPED = 10  #: in the blend, the EKF's angle stayed more than pi/2 from the tracking observer's: a pi slip
#: a blind unit (its saliency below C_SALIENCY_MIN) at a stop: park the car, find the angle afresh (also at the enable's
#: acquisition, where it cannot see with its sensors' relative gain not yet measured)
EV_BLIND_STOP = 25
EV_STILL_PARKED = 26  #: an acquisition over while parked and the reference still 0: another one
EV_EMF_LOST = 27  #: the current loops carry a back-EMF the frame's speed does not explain (eqs LS1-LS2)
EV_CANNOT_SEE = 28  #: the identification over, blind and the angle accuracy beyond C_ANGLE_MAX (``cannot_see``)
EVENT_NAMES = ("none", "acquired", "polarity right", "polarity flipped", "polarity unresolved", "fast", "slow",
               "injection lost", "disagree", "EKF lost", "flipped")

# -- entry actions --------------------------------------------------------------------------------
A_ACQUIRE = 0  #: start the acquisition afresh (``enter_acquire``)
A_POLARITY = 1  #: start the polarity test (``enter_polarity``)
A_TORQUE = 2  #: FOC on the injection, the speed loop from rest (``enter_torque``)
A_FLIP_TORQUE = 3  #: the tracking observer turned by pi, then as A_TORQUE (``flip_frame``)
A_RETRY = 4  #: count an unresolved test; the second latches the fault; then as A_ACQUIRE
A_EKF_ALONE = 5  #: the injection off: the blend at the EKF alone, the detectors cleared (``modes.enter``)
A_INJECTION_ON = 6  #: the injection on again, the tracking observer on the EKF (``modes.enter``)
A_REACQUIRE = 7  #: an episode; then as A_ACQUIRE
A_RESEAT = 8  #: an episode; the EKF put on the tracking observer (``reseat``)
A_RESTART_EKF = 9  #: an episode; the EKF's covariance back to an unknown start's (``restart_ekf_search``)
A_REPOLARIZE = 10  #: an episode; the tracking observer turned by pi onto the EKF's polarity (``flip_frame``)
A_PARK = 25  #: the friction brake held, the acquisition afresh (``park_car``)
A_REACQUIRE_PARKED = 26  #: an episode; then as A_PARK: the car stopped on the brake while the angle is found
A_IF_FALLBACK = 27  #: the I-f strategy for good, from its alignment, the brake released (``fall_back_to_if``)


# == the I-f strategy (``kernels.startup``) ======================================================
# Modes (``S_MODE``): MODE_ALIGN (the alignment's schedule, ``align_schedule``), MODE_IF (the vector
# turned, ``turn_vector``), MODE_EKF (FOC on the EKF). The stand is a second, smaller machine beside
# them (``S_ANCHORED``: STAND_FREE, STAND_HELD): the car standing on the I-f vector, whose angle and load
# the guard and the sizing then take from when the EKF last saw the rotor turn. The safe state is the
# fault latched (``S_FAULT``) over the modes, as in the injection strategy: the reference taken as 0.

# -- events (``EV_*``; ``EV_NONE``, 0, none): distinct from the injection strategy's (1 .. 10, 25 .. 28) --
EV_RUNAWAY = 11  #: alignment: |omega_hat| above C_ALIGN_SLIP for C_ALIGN_SLIP_TIME (a load beyond the vector)
EV_ALIGNED = 12  #: alignment: its schedule is over, the magnet on the vector
EV_SLOWED = 13  #: EKF: |omega_hat| below C_W_DOWN (no back-EMF to see the angle by much longer)
EV_SLIP_AT_SPEED = 14  #: I-f: out of step for C_SLIP_TIME, the rotor at C_W_DOWN or faster (the EKF sees it)
EV_SLIP = 15  #: I-f: out of step for C_SLIP_TIME, slower
EV_LIMIT = 16  #: I-f: the guard holding the vector at the current limit, the rotor off the reference, that long
EV_AGREED = 17  #: I-f: omega_hat within C_AGREE_TOL of the I-f speed above C_W_UP for C_AGREE_TIME
EV_OVERDUE = 18  #: I-f: C_IF_DEADLINE with |omega_ref| above C_W_UP, the rotor turning with the vector
EV_STALL_TURNING = 19  #: I-f: C_STALL_TIME so, the rotor turning the vector's way at C_W_DOWN or faster
EV_STALL = 20  #: ... the rotor slower: it stands or swings
EV_STALL_LAST = 21  #: ... with no realignment left (C_REALIGN_MAX)
EV_STANDS = 22  #: the stand: the car stands on the I-f vector (``car_stands``)
EV_VECTOR_TURNS = 23  #: the stand ends, the rotor still: the vector starts to turn (a restart)
EV_ROTOR_MOVES = 24  #: the stand ends, the rotor moving: a load that changed pushes it
IF_EVENT_NAMES = {EV_RUNAWAY: "runaway", EV_ALIGNED: "aligned", EV_SLOWED: "slowed", EV_SLIP_AT_SPEED:
                  "slip at speed", EV_SLIP: "slip", EV_LIMIT: "limit", EV_AGREED: "agreed", EV_OVERDUE: "overdue",
                  EV_STALL_TURNING: "stall, turning", EV_STALL: "stall", EV_STALL_LAST: "stall, none left",
                  EV_STANDS: "stands", EV_VECTOR_TURNS: "vector turns", EV_ROTOR_MOVES: "rotor moves"}

# -- entry actions (``A_*``): distinct from the injection strategy's (0 .. 10, 25 .. 27) ------------
A_CATCH = 11  #: a new episode, I-f on the EKF's angle at the current limit (``catch_runaway``)
A_START_IF = 12  #: the EKF restarted on the aligned vector, at rest (``start_if``)
A_HANDOVER_DOWN = 13  #: the vector left where the current is (``hand_down``)
A_FLYING = 14  #: an episode, FOC on the EKF seated on its load (``seat_foc``)
A_RELOCK = 15  #: an episode, the vector put back on the rotor (``relock``)
A_EPISODE = 16  #: an episode, nothing more to give (it runs on to the fault unless it ends)
A_HANDOVER_UP = 17  #: FOC on the EKF seated on the present torque (``seat_foc``), the realignments counted from 0
A_FORCED_UP = 18  #: an episode, FOC on the EKF seated on its load, the realignments counted from 0
A_STALL_FOC = 19  #: an episode, a realignment counted, FOC on the EKF seated on its load
A_REALIGN = 20  #: an episode, a realignment counted, the alignment from standstill (``realign``)
A_LATCH = 21  #: an episode, the fault latched (the safe state)
A_ANCHOR = 22  #: the stand anchored on the trusted angle and load (``anchor``)
A_RESTART_ON_ANCHOR = 23  #: the EKF restarted at rest on the anchor, on the vector as it is now (``release``)
A_PUT_BACK = 24  #: the EKF's angle and load put back on the anchor (``release``)

#: the transition table of both strategies: (mode, event, next mode, entry action), looked up in order, the
#: first match taken (``lookup``). The strategies' events are distinct, so that their rows never meet, also
#: in the mode they share (MODE_EKF). Each row is tested on its own (tests/test_modes.py, tests/test_if_modes.py).
#: The I-f strategy's detectors run in a period in this order, each in the mode the one before left: the
#: alignment's (its runaway before its end), FOC's, then in I-f trouble, agreement, the handover due
#: (``startup.sensorless_step``); the injection strategy's give one event a period (``modes.detect``)
TRANSITIONS = (
    # the injection strategy
    (MODE_ACQUIRE, EV_ACQUIRED, MODE_POLARITY, A_POLARITY),
    (MODE_ACQUIRE, EV_CANNOT_SEE, MODE_ALIGN, A_IF_FALLBACK),
    (MODE_ACQUIRE, EV_BLIND_STOP, MODE_ACQUIRE, A_PARK),
    (MODE_POLARITY, EV_POLARITY_RIGHT, MODE_INJECTION, A_TORQUE),
    (MODE_POLARITY, EV_POLARITY_FLIPPED, MODE_INJECTION, A_FLIP_TORQUE),
    (MODE_POLARITY, EV_POLARITY_UNRESOLVED, MODE_ACQUIRE, A_RETRY),
    (MODE_POLARITY, EV_INJECTION_LOST, MODE_ACQUIRE, A_REACQUIRE),
    (MODE_INJECTION, EV_INJECTION_LOST, MODE_ACQUIRE, A_REACQUIRE),
    (MODE_INJECTION, EV_DISAGREE, MODE_INJECTION, A_RESEAT),
    (MODE_INJECTION, EV_FLIPPED, MODE_INJECTION, A_REPOLARIZE),
    (MODE_INJECTION, EV_BLIND_STOP, MODE_ACQUIRE, A_PARK),
    (MODE_ACQUIRE, EV_STILL_PARKED, MODE_ACQUIRE, A_ACQUIRE),
    (MODE_INJECTION, EV_EMF_LOST, MODE_ACQUIRE, A_REACQUIRE_PARKED),
    (MODE_INJECTION, EV_FAST, MODE_EKF, A_EKF_ALONE),
    (MODE_EKF, EV_EKF_LOST, MODE_EKF, A_RESTART_EKF),
    (MODE_EKF, EV_SLOW, MODE_INJECTION, A_INJECTION_ON),
    # the I-f strategy
    (MODE_ALIGN, EV_RUNAWAY, MODE_IF, A_CATCH),
    (MODE_ALIGN, EV_ALIGNED, MODE_IF, A_START_IF),
    (MODE_EKF, EV_SLOWED, MODE_IF, A_HANDOVER_DOWN),
    (MODE_IF, EV_SLIP_AT_SPEED, MODE_EKF, A_FLYING),
    (MODE_IF, EV_SLIP, MODE_IF, A_RELOCK),
    (MODE_IF, EV_LIMIT, MODE_IF, A_EPISODE),
    (MODE_IF, EV_AGREED, MODE_EKF, A_HANDOVER_UP),
    (MODE_IF, EV_OVERDUE, MODE_EKF, A_FORCED_UP),
    (MODE_IF, EV_STALL_TURNING, MODE_EKF, A_STALL_FOC),
    (MODE_IF, EV_STALL, MODE_ALIGN, A_REALIGN),
    (MODE_IF, EV_STALL_LAST, MODE_IF, A_LATCH),
)

#: the stand's states (``S_ANCHORED``)
STAND_FREE, STAND_HELD = 0, 1
#: the stand's transition table (as ``TRANSITIONS``, on ``S_ANCHORED``); its detector runs first in a
#: period, before the modes' (``detect_stand``)
STAND_TRANSITIONS = (
    (STAND_FREE, EV_STANDS, STAND_HELD, A_ANCHOR),
    (STAND_HELD, EV_VECTOR_TURNS, STAND_FREE, A_RESTART_ON_ANCHOR),
    (STAND_HELD, EV_ROTOR_MOVES, STAND_FREE, A_PUT_BACK),
)



#: the tables as ``lookup`` reads them (``jit.table``)
TRANSITION_TABLE = _table(TRANSITIONS)
STAND_TABLE = _table(STAND_TRANSITIONS)


@kernel()
def lookup(table, mode, event):
    """The row of ``table`` for (mode, event): (next mode, entry action) as floats (as the state holds a mode), or
    (mode, -1.0) where none."""
    for i in range(len(table)):
        row = table[i]
        if row[0] == mode and row[1] == event:
            return float(row[2]), float(row[3])
    return mode, -1.0


@kernel()
def next_mode(mode, event):
    """The table's row for (mode, event): (next mode, entry action), or (mode, -1.0) where none."""
    return lookup(TRANSITION_TABLE, mode, event)
