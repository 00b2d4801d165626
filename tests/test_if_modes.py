"""The sensorless unit's I-f strategy as a state machine (``pmsm_ev.kernels.startup``): its transition tables
(its rows of the unit's ``TRANSITIONS`` and the stand's ``STAND_TRANSITIONS``), each transition called on its own, each
detector, and property tests over event sequences. The kernels are called as plain Python
(``pmsm_ev.kernels`` is the source package; ``pmsm_ev.accel`` compiles a copy), on the vectors of a
``ControlUnit`` built with the I-f strategy (the default). The tests assert what a transition does to the
state and when a detector fires against its parameters, not the times a closed-loop run shows."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from machine_support import reachable
from pmsm_ev import kernels as k
from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.params import StartupParams

IF_MODES = (k.MODE_ALIGN, k.MODE_IF, k.MODE_EKF)
IF_EVENTS = (k.EV_RUNAWAY, k.EV_ALIGNED, k.EV_SLOWED, k.EV_SLIP_AT_SPEED, k.EV_SLIP, k.EV_LIMIT, k.EV_AGREED,
             k.EV_OVERDUE, k.EV_STALL_TURNING, k.EV_STALL, k.EV_STALL_LAST)
STAND_EVENTS = (k.EV_STANDS, k.EV_VECTOR_TURNS, k.EV_ROTOR_MOVES)
IF_ACTIONS = (k.A_CATCH, k.A_START_IF, k.A_HANDOVER_DOWN, k.A_FLYING, k.A_RELOCK, k.A_EPISODE, k.A_HANDOVER_UP,
              k.A_FORCED_UP, k.A_STALL_FOC, k.A_REALIGN, k.A_LATCH)
STAND_ACTIONS = (k.A_ANCHOR, k.A_RESTART_ON_ANCHOR, k.A_PUT_BACK)
#: the strategy's rows of the unit's one table (``kernels.machine``): those of its events
IF_ROWS = tuple(row for row in k.TRANSITIONS if row[1] in IF_EVENTS)
#: the events that begin (or continue) a loss-of-synchronism episode: all but the healthy handovers
TROUBLE = (k.EV_RUNAWAY, k.EV_SLIP_AT_SPEED, k.EV_SLIP, k.EV_LIMIT, k.EV_OVERDUE, k.EV_STALL_TURNING, k.EV_STALL,
           k.EV_STALL_LAST)


def _unit(**kw):
    """A unit with the I-f strategy; its state and parameter vectors as plain lists (plain-Python kernels)."""
    u = ControlUnit("sensorless", startup=StartupParams(**kw))
    return u, [float(x) for x in u._s], [float(x) for x in u._c]


def _go(s, c, mode, event, omega_ref=0.0, i_alpha=0.0, i_beta=0.0):
    return k.if_transition(s, c, mode, event, i_alpha, i_beta, omega_ref)


def _periods(c, duration):
    return round(duration / c[k.C_DT])


def _first(events):
    """The index of the first event and that event, of a detector called once a period."""
    j = next(j for j, ev in enumerate(events) if ev != k.EV_NONE)
    return j, events[j]


# -- the tables ----------------------------------------------------------------------------------------
def test_table_has_one_row_per_pair_and_known_modes_events_and_actions():
    pairs = [(row[0], row[1]) for row in k.TRANSITIONS]
    assert len(pairs) == len(set(pairs))  # over both strategies' rows
    assert len(IF_ROWS) == 11
    for mode, event, new, action in IF_ROWS:
        assert mode in IF_MODES and new in IF_MODES
        assert event in IF_EVENTS and action in IF_ACTIONS
    assert {row[1] for row in IF_ROWS} == set(IF_EVENTS)  # every event has its row
    for state, event, new, action in k.STAND_TRANSITIONS:
        assert {state, new} <= {k.STAND_FREE, k.STAND_HELD}
        assert event in STAND_EVENTS and action in STAND_ACTIONS


def test_codes_are_distinct_from_the_injection_strategys():
    """A row says which strategy it is of: events and actions of the two strategies do not share codes."""
    injection_events = {row[1] for row in k.TRANSITIONS if row not in IF_ROWS}
    injection_actions = {row[3] for row in k.TRANSITIONS if row not in IF_ROWS}
    assert injection_events == {k.EV_ACQUIRED, k.EV_POLARITY_RIGHT, k.EV_POLARITY_FLIPPED, k.EV_POLARITY_UNRESOLVED,
                                k.EV_FAST, k.EV_SLOW, k.EV_INJECTION_LOST, k.EV_DISAGREE, k.EV_EKF_LOST, k.EV_FLIPPED,
                                k.EV_BLIND_STOP, k.EV_STILL_PARKED, k.EV_EMF_LOST, k.EV_CANNOT_SEE}
    assert not injection_events & (set(IF_EVENTS) | set(STAND_EVENTS))
    assert not injection_actions & (set(IF_ACTIONS) | set(STAND_ACTIONS))
    assert k.EV_NONE not in set(IF_EVENTS) | set(STAND_EVENTS)


def test_every_mode_is_reachable_from_the_alignment_and_every_mode_can_leave():
    assert reachable(IF_ROWS, k.MODE_ALIGN) == set(IF_MODES)
    assert all(any(row[0] == m and row[2] != m for row in IF_ROWS) for m in IF_MODES)


def test_a_pair_not_in_the_table_or_no_event_changes_nothing():
    _, s, c = _unit()
    before = list(s)
    assert _go(s, c, k.MODE_ALIGN, k.EV_AGREED) == k.MODE_ALIGN
    assert _go(s, c, k.MODE_EKF, k.EV_STALL) == k.MODE_EKF
    assert _go(s, c, k.MODE_IF, k.EV_ALIGNED) == k.MODE_IF
    assert _go(s, c, k.MODE_IF, k.EV_NONE) == k.MODE_IF
    k.stand_transition(s, c, k.EV_VECTOR_TURNS, 0.0, 0.0)  # not standing: nothing to end
    assert s == before


def test_the_unit_starts_aligning_with_no_stand_and_no_fault():
    u, s, _ = _unit()
    assert u.mode == k.MODE_ALIGN
    assert s[k.S_ANCHORED] == k.STAND_FREE and s[k.S_FAULT] == k.FAULT_NONE and s[k.S_EPISODE] == 0.0


# -- each transition on its own ----------------------------------------------------------------------------
def test_runaway_hands_the_rotor_to_i_f_on_the_ekf_at_the_limit_as_a_new_episode():
    _, s, c = _unit()
    s[k.S_OMEGA_HAT], s[k.S_THETA_HAT], s[k.S_TL_HAT] = 8.0, 1.0, 40.0  # rolling forwards under a load
    s[k.S_RUNAWAY_T] = 0.02
    s[k.S_EPISODE] = 0.5  # an episode running (a realignment's): its age starts again
    assert _go(s, c, k.MODE_ALIGN, k.EV_RUNAWAY) == k.MODE_IF
    assert s[k.S_PHI] == pytest.approx(1.0 + c[k.C_E_MAX])  # ahead of the rotor against the load
    assert s[k.S_OMEGA_IF] == 8.0 and s[k.S_I_MAG] == s[k.S_I_TGT] == c[k.C_I_Q_MAX]
    assert s[k.S_EPISODE] == c[k.C_DT] and s[k.S_RUNAWAY_T] == 0.0 and s[k.S_SLIP] == 0.0


@pytest.mark.parametrize(("load", "omega_hat", "omega_ref", "sign"), [
    (40.0, 0.0, 0.0, 1.0),  # a load to hold: ahead
    (-40.0, 0.0, 0.0, -1.0),  # a load pulling forwards: behind
    (0.0, 0.0, 10.0, 1.0),  # no load, the reference ahead: ahead
    (10.0, 20.0, 0.0, -1.0),  # a rotor running ahead of the reference more than the load holds it: behind
])
def test_relock_leads_the_rotor_in_the_direction_of_the_torque_needed(load, omega_hat, omega_ref, sign):
    """The torque needed: the load plus J (omega_ref - omega_hat) / relock_time (10 N m against
    0.526 * 20 / 0.5 = 21 N m in the last case)."""
    _, s, c = _unit()
    s[k.S_OMEGA_HAT], s[k.S_THETA_HAT], s[k.S_TL_HAT] = omega_hat, -0.4, load
    k.relock(s, c, omega_hat, omega_ref)
    assert k.wrap_angle(s[k.S_PHI] + 0.4) == pytest.approx(sign * c[k.C_E_MAX])


def test_aligned_restarts_the_ekf_on_the_vector_at_rest():
    _, s, c = _unit()
    s[k.S_PHI], s[k.S_I_MAG] = 0.02, 60.0
    s[k.S_OMEGA_HAT], s[k.S_THETA_HAT], s[k.S_TL_HAT] = 3.0, 2.0, 17.0
    assert _go(s, c, k.MODE_ALIGN, k.EV_ALIGNED, i_alpha=60.0) == k.MODE_IF
    assert (s[k.S_OMEGA_HAT], s[k.S_THETA_HAT], s[k.S_TL_HAT]) == (0.0, 0.02, 0.0)
    assert [s[k.S_P + 6 * i] for i in range(5)] == [c[k.C_P0_ALIGNED + i] for i in range(5)]
    assert s[k.S_OMEGA_IF] == 0.0 and s[k.S_I_TGT] == max(c[k.C_I_IF], 60.0)
    assert s[k.S_TRUST_OFF] == 0.0  # the rotor's place on the vector: on it
    assert s[k.S_EPISODE] == 0.0


def test_slowed_leaves_the_vector_where_the_current_is():
    """Handover down: the torque continuous (the vector on the present current), the current rising to the
    margin over it, the I-f speed from the EKF's."""
    _, s, c = _unit()
    s[k.S_OMEGA_HAT] = 15.0
    assert _go(s, c, k.MODE_EKF, k.EV_SLOWED, i_alpha=30.0, i_beta=40.0) == k.MODE_IF
    assert s[k.S_PHI] == math.atan2(40.0, 30.0) and s[k.S_I_MAG] == 50.0
    assert s[k.S_I_TGT] == max(c[k.C_IF_MARGIN] * 50.0, c[k.C_I_IF])
    assert s[k.S_OMEGA_IF] == 15.0 and s[k.S_SLIP] == 0.0 and s[k.S_AGREE] == 0.0
    assert s[k.S_EPISODE] == 0.0


def test_a_slip_at_speed_is_a_flying_handover_seated_on_the_load():
    _, s, c = _unit()
    s[k.S_OMEGA_HAT], s[k.S_TL_HAT] = 50.0, 30.0
    s[k.S_IF_DUE] = 0.5
    assert _go(s, c, k.MODE_IF, k.EV_SLIP_AT_SPEED, omega_ref=60.0) == k.MODE_EKF
    i_load = 30.0 / (c[k.C_N] * c[k.C_PSI])  # T_L_hat / (N psi): the present current says nothing of the load
    assert s[k.S_W_INT] == pytest.approx(i_load - c[k.C_KP_W] * (60.0 - 50.0))
    assert s[k.S_EPISODE] == c[k.C_DT] and s[k.S_IF_DUE] == 0.0


def test_a_slip_at_low_speed_puts_the_vector_back_on_the_rotor():
    _, s, c = _unit()
    s[k.S_OMEGA_HAT], s[k.S_THETA_HAT], s[k.S_TL_HAT] = 5.0, 0.7, 20.0
    assert _go(s, c, k.MODE_IF, k.EV_SLIP, omega_ref=5.0) == k.MODE_IF
    assert s[k.S_PHI] == pytest.approx(0.7 + c[k.C_E_MAX]) and s[k.S_I_MAG] == c[k.C_I_Q_MAX]
    assert s[k.S_OMEGA_IF] == 5.0 and s[k.S_EPISODE] == c[k.C_DT]


def test_a_limit_is_an_episode_and_nothing_else():
    _, s, c = _unit()
    s[k.S_EPISODE], s[k.S_INSYNC] = 0.4, 0.3  # an episode running: its age kept
    before = list(s)
    assert _go(s, c, k.MODE_IF, k.EV_LIMIT) == k.MODE_IF
    assert s[k.S_EPISODE] == 0.4 and s[k.S_INSYNC] == 0.0
    assert [a for j, a in enumerate(s) if j != k.S_INSYNC] == [a for j, a in enumerate(before) if j != k.S_INSYNC]


def test_agreed_hands_over_bumplessly_without_an_episode():
    """FOC seated on the present torque (eq 12 with i_d at its reference), the due timer and the
    realignments cleared."""
    _, s, c = _unit()
    s[k.S_OMEGA_HAT], s[k.S_THETA_HAT] = 40.0, 0.0
    s[k.S_REALIGN], s[k.S_IF_DUE], s[k.S_AGREE] = 1.0, 0.8, 0.3
    assert _go(s, c, k.MODE_IF, k.EV_AGREED, omega_ref=40.0, i_alpha=0.0, i_beta=50.0) == k.MODE_EKF
    assert s[k.S_W_INT] == pytest.approx(50.0)  # i_d = 0 already: the same q current
    assert (s[k.S_REALIGN], s[k.S_IF_DUE], s[k.S_AGREE], s[k.S_EPISODE]) == (0.0, 0.0, 0.0, 0.0)


def test_overdue_forces_the_handover_as_an_episode():
    _, s, c = _unit()
    s[k.S_OMEGA_HAT], s[k.S_TL_HAT] = 40.0, 10.0
    s[k.S_REALIGN], s[k.S_IF_DUE] = 1.0, 1.0
    assert _go(s, c, k.MODE_IF, k.EV_OVERDUE, omega_ref=60.0) == k.MODE_EKF
    assert s[k.S_REALIGN] == 0.0 and s[k.S_EPISODE] == c[k.C_DT]
    assert s[k.S_IF_DUE] == 1.0  # kept: a handover down while the reference asks for FOC is forced again


def test_a_stall_with_the_rotor_turning_gets_foc_and_counts_a_realignment():
    _, s, c = _unit()
    s[k.S_OMEGA_HAT] = 25.0
    s[k.S_IF_DUE] = 3.0
    assert _go(s, c, k.MODE_IF, k.EV_STALL_TURNING, omega_ref=100.0) == k.MODE_EKF
    assert s[k.S_REALIGN] == 1.0 and s[k.S_IF_DUE] == 0.0 and s[k.S_EPISODE] == c[k.C_DT]


def test_a_stall_realigns_from_standstill_with_everything_of_i_f_cleared():
    _, s, c = _unit()
    for slot, value in ((k.S_ALIGN_CLOCK, 4e4), (k.S_I_MAG, 400.0), (k.S_I_TGT, 400.0), (k.S_OMEGA_IF, 3.0),
                        (k.S_SLIP, 2.0), (k.S_ALIGN_SPEED, 1.0), (k.S_AGREE, 0.1), (k.S_GUARD, k.GUARD_HARD),
                        (k.S_LOS, 0.05), (k.S_RUNAWAY_T, 0.01), (k.S_ANCHORED, k.STAND_HELD), (k.S_INT_D, 5.0),
                        (k.S_INT_Q, -5.0), (k.S_IF_DUE, 3.0)):
        s[slot] = value
    assert _go(s, c, k.MODE_IF, k.EV_STALL, omega_ref=100.0) == k.MODE_ALIGN
    for slot in (k.S_ALIGN_CLOCK, k.S_I_MAG, k.S_I_TGT, k.S_OMEGA_IF, k.S_SLIP, k.S_ALIGN_SPEED, k.S_AGREE, k.S_GUARD,
                 k.S_LOS, k.S_RUNAWAY_T, k.S_INT_D, k.S_INT_Q, k.S_IF_DUE):
        assert s[slot] == 0.0
    assert s[k.S_ANCHORED] == k.STAND_FREE and s[k.S_REALIGN] == 1.0 and s[k.S_EPISODE] == c[k.C_DT]


def test_a_stall_with_no_realignment_left_latches_the_safe_state():
    _, s, c = _unit()
    s[k.S_REALIGN] = c[k.C_REALIGN_MAX]
    assert _go(s, c, k.MODE_IF, k.EV_STALL_LAST) == k.MODE_IF
    assert s[k.S_FAULT] == k.FAULT_LATCHED and s[k.S_EPISODE] > 0.0


def test_a_stand_is_anchored_on_the_trusted_place_and_load():
    _, s, c = _unit()
    s[k.S_PHI], s[k.S_TRUST_OFF], s[k.S_TRUST_TL] = 3.0, 0.5, 12.0
    k.stand_transition(s, c, k.EV_STANDS, 0.0, 0.0)
    assert s[k.S_ANCHORED] == k.STAND_HELD
    assert s[k.S_ANCHOR] == pytest.approx(k.wrap_angle(3.5)) and s[k.S_ANCHOR_REL] == 0.5
    assert s[k.S_ANCHOR_TL] == 12.0


@pytest.mark.parametrize("event", [k.EV_VECTOR_TURNS, k.EV_ROTOR_MOVES])
def test_a_stand_ends_with_the_ekf_on_the_vector_as_it_is_now(event):
    """The vector may have turned since the stand began: the EKF goes to its angle now plus the anchor's offset,
    on the stand's load; restarted at rest where the vector starts to turn, its speed kept where the rotor
    moves (the EKF sees that motion)."""
    _, s, c = _unit()
    s[k.S_ANCHORED] = k.STAND_HELD
    s[k.S_PHI], s[k.S_ANCHOR_REL], s[k.S_ANCHOR_TL] = 1.0, -0.3, 25.0
    s[k.S_OMEGA_HAT], s[k.S_THETA_HAT], s[k.S_TL_HAT] = 0.7, 2.5, 60.0
    k.stand_transition(s, c, event, 0.0, 0.0)
    assert s[k.S_ANCHORED] == k.STAND_FREE
    assert s[k.S_THETA_HAT] == pytest.approx(0.7) and s[k.S_TL_HAT] == 25.0
    assert s[k.S_OMEGA_HAT] == (0.0 if event == k.EV_VECTOR_TURNS else 0.7)
    assert s[k.S_TRUST_OFF] == pytest.approx(-0.3) and s[k.S_TRUST_TL] == 25.0


# -- the detectors ---------------------------------------------------------------------------------------
def test_the_alignment_ends_at_its_schedules_end():
    _, s, c = _unit()
    end = StartupParams().align_time
    assert k.detect_alignment_end(s, c, end - 1e-9) == k.EV_NONE
    assert k.detect_alignment_end(s, c, end) == k.EV_ALIGNED


def test_runaway_only_after_its_time_and_never_with_align_slip_zero():
    _, s, c = _unit()
    s[k.S_OMEGA_HAT] = -1.5 * c[k.C_ALIGN_SLIP]
    n = _periods(c, c[k.C_ALIGN_SLIP_TIME])
    events = [k.detect_alignment_end(s, c, 0.1) for _ in range(n + 1)]
    assert set(events[:n - 1]) == {k.EV_NONE} and events[-1] == k.EV_RUNAWAY
    s[k.S_OMEGA_HAT] = 0.5 * c[k.C_ALIGN_SLIP]  # the alignment's own swing: the timer from zero
    assert k.detect_alignment_end(s, c, 0.1) == k.EV_NONE and s[k.S_RUNAWAY_T] == 0.0
    _, s, c = _unit(align_slip=0.0)
    s[k.S_OMEGA_HAT] = 100.0
    assert all(k.detect_alignment_end(s, c, 0.1) == k.EV_NONE for _ in range(2 * n))


def test_slowed_below_omega_down_only():
    _, s, c = _unit()
    s[k.S_OMEGA_HAT] = -c[k.C_W_DOWN]
    assert k.detect_slowed(s, c) == k.EV_NONE
    s[k.S_OMEGA_HAT] = 0.99 * c[k.C_W_DOWN]
    assert k.detect_slowed(s, c) == k.EV_SLOWED


@pytest.mark.parametrize(("omega_hat", "event"), [(40.0, k.EV_SLIP_AT_SPEED), (5.0, k.EV_SLIP)])
def test_a_slip_after_slip_time_by_the_rotors_speed(omega_hat, event):
    _, s, c = _unit()
    s[k.S_OMEGA_IF] = 30.0
    s[k.S_SLIP] = 1.01 * (c[k.C_SLIP_TOL] + c[k.C_AGREE_TOL] * 30.0)
    assert k.slipping(s, c)
    n = _periods(c, c[k.C_SLIP_TIME])
    events = [k.detect_trouble(s, c, True, False, omega_hat) for _ in range(n + 1)]
    assert _first(events) in ((n - 1, event), (n, event))  # in the slip_time-th period (within the sum's rounding)
    assert s[k.S_LOS] < 2.0 * c[k.C_DT]  # the timer from zero once fired
    s[k.S_SLIP] = 0.99 * (c[k.C_SLIP_TOL] + c[k.C_AGREE_TOL] * 30.0)  # a locked vector's swing
    assert not k.slipping(s, c)


def test_the_limit_is_the_guard_at_the_current_limit_with_the_rotor_off_the_reference():
    _, s, c = _unit()
    s[k.S_GUARD], s[k.S_I_MAG] = k.GUARD_HARD, c[k.C_I_Q_MAX]
    bound = c[k.C_SLIP_TOL] + c[k.C_AGREE_TOL] * 20.0
    assert k.at_limit(s, c, 20.0, 20.0 - 1.01 * bound)
    assert not k.at_limit(s, c, 20.0, 20.0 - 0.99 * bound)
    s[k.S_I_MAG] = 0.99 * c[k.C_I_Q_MAX]  # current left to give
    assert not k.at_limit(s, c, 20.0, -50.0)
    n = _periods(c, c[k.C_SLIP_TIME])
    assert _first([k.detect_trouble(s, c, False, True, 0.0) for _ in range(n + 1)]) in ((n - 1, k.EV_LIMIT),
                                                                                      (n, k.EV_LIMIT))


def test_agreement_above_omega_up_for_agree_time():
    _, s, c = _unit()
    n = _periods(c, c[k.C_AGREE_TIME])
    s[k.S_OMEGA_IF] = 0.9 * c[k.C_W_UP]  # below omega_up: never
    assert all(k.detect_agreed(s, c, s[k.S_OMEGA_IF]) == k.EV_NONE for _ in range(2 * n))
    s[k.S_OMEGA_IF] = 40.0
    off = 1.01 * c[k.C_AGREE_TOL] * 40.0
    assert all(k.detect_agreed(s, c, 40.0 + off) == k.EV_NONE for _ in range(2 * n))
    events = [k.detect_agreed(s, c, 40.0 - 0.5 * off) for _ in range(n + 1)]
    assert set(events[:n - 1]) == {k.EV_NONE} and events[-1] == k.EV_AGREED


def test_the_handover_due_is_overdue_after_if_deadline_and_a_stall_after_stall_time():
    _, s, c = _unit()
    s[k.S_OMEGA_IF] = 40.0
    dl, stall = _periods(c, c[k.C_IF_DEADLINE]), _periods(c, c[k.C_STALL_TIME])
    events = [k.detect_due(s, c, 100.0, 38.0, False) for _ in range(dl + 1)]
    assert set(events[:dl - 1]) == {k.EV_NONE} and events[-1] == k.EV_OVERDUE
    # slipping, or the rotor not turning with the vector: not forced, and at stall_time a stall
    for omega_hat, slip, stalled in ((38.0, True, k.EV_STALL_TURNING), (-38.0, False, k.EV_STALL),
                                     (5.0, False, k.EV_STALL)):
        s[k.S_IF_DUE] = 0.0
        events = [k.detect_due(s, c, 100.0, omega_hat, slip) for _ in range(stall + 1)]
        assert set(events[:stall - 1]) == {k.EV_NONE} and events[-1] == stalled
    s[k.S_REALIGN] = c[k.C_REALIGN_MAX]
    assert k.detect_due(s, c, 100.0, 5.0, False) == k.EV_STALL_LAST
    s[k.S_FAULT] = k.FAULT_LATCHED  # the safe state: never due
    assert k.detect_due(s, c, 100.0, 5.0, False) == k.EV_NONE and s[k.S_IF_DUE] == 0.0


def test_the_handover_due_counts_only_above_omega_up_and_zero_turns_it_off():
    _, s, c = _unit(if_deadline=0.0, stall_time=0.0)
    s[k.S_OMEGA_IF] = 40.0
    assert all(k.detect_due(s, c, 100.0, 5.0, False) == k.EV_NONE for _ in range(_periods(c, 4.0)))
    k.detect_due(s, c, 0.9 * c[k.C_W_UP], 5.0, False)
    assert s[k.S_IF_DUE] == 0.0


def test_a_stand_begins_with_vector_and_rotor_still_and_ends_past_its_noise():
    _, s, c = _unit()
    s[k.S_MODE] = k.MODE_IF
    s[k.S_OMEGA_IF], s[k.S_OMEGA_HAT] = 0.5 * c[k.C_STILL], -0.5 * c[k.C_STILL]
    assert k.detect_stand(s, c) == k.EV_STANDS
    s[k.S_MODE] = k.MODE_EKF  # only in I-f
    assert k.detect_stand(s, c) == k.EV_NONE
    s[k.S_MODE], s[k.S_ANCHORED] = k.MODE_IF, k.STAND_HELD
    s[k.S_OMEGA_HAT] = 2.0 * c[k.C_STILL]  # the EKF's speed noise: less than still_time above still_speed
    s[k.S_STILL_OUT] = 0.99 * c[k.C_STILL_TIME]
    assert k.detect_stand(s, c) == k.EV_NONE
    s[k.S_STILL_OUT] = c[k.C_STILL_TIME]  # a motion
    assert k.detect_stand(s, c) == k.EV_ROTOR_MOVES
    s[k.S_OMEGA_HAT], s[k.S_OMEGA_IF] = 0.0, 2.0 * c[k.C_STILL]  # the vector turns, the rotor still
    assert k.detect_stand(s, c) == k.EV_VECTOR_TURNS


def test_the_ekf_is_believed_where_it_has_something_to_say():
    _, s, c = _unit()
    s[k.S_PHI], s[k.S_TRUST_OFF] = 1.0, -0.2
    s[k.S_THETA_HAT] = 1.0 - 0.2 + 0.99 * c[k.C_TRUST_MOVE]  # at low speed, moved less than trust_move: not
    assert not k.ekf_believed(s, c)
    s[k.S_THETA_HAT] = 1.0 - 0.2 + 1.01 * c[k.C_TRUST_MOVE]  # moved more: a load that changed
    assert k.ekf_believed(s, c)
    s[k.S_THETA_HAT] = 0.8
    s[k.S_OMEGA_HAT] = c[k.C_ANCHOR_SPEED]  # turning fast enough for its back-EMF
    assert k.ekf_believed(s, c)
    s[k.S_OMEGA_HAT] = 0.0
    s[k.S_GUARD] = k.GUARD_SOFT
    assert k.ekf_believed(s, c)


def test_the_guard_holds_speed_beyond_its_soft_angle_and_angle_beyond_its_hard_one():
    _, s, c = _unit()
    soft, hard, band = c[k.C_SOFT_GUARD], c[k.C_E_GUARD], c[k.C_GUARD_BAND]
    s[k.S_PHI], s[k.S_OMEGA_IF] = 0.5 * (soft + hard), 20.0  # between the limits, turning faster than the rotor
    k.sync_guard(s, c, 10.0, 0.0, 0.0)
    assert s[k.S_GUARD] == k.GUARD_SOFT and s[k.S_OMEGA_IF] == 10.0
    s[k.S_PHI] = soft - 0.5 * band  # back within the band: still held
    k.sync_guard(s, c, 10.0, 0.0, 0.0)
    assert s[k.S_GUARD] == k.GUARD_SOFT
    s[k.S_PHI] = soft - 1.5 * band  # beyond it: let go
    k.sync_guard(s, c, 10.0, 0.0, 0.0)
    assert s[k.S_GUARD] == 0.0
    s[k.S_PHI], s[k.S_OMEGA_IF] = -(hard + 0.2), -5.0  # trailing past the hard limit: held there
    k.sync_guard(s, c, 2.0, 0.0, 0.0)
    assert s[k.S_GUARD] == k.GUARD_HARD and s[k.S_PHI] == pytest.approx(-hard) and s[k.S_OMEGA_IF] == 2.0


# -- properties over event sequences ---------------------------------------------------------------------
@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(IF_EVENTS), max_size=40))
def test_modes_stay_the_strategys_and_every_trouble_is_an_episode(events):
    """Whatever the events: the mode stays one of the strategy's; every transition on a trouble event leaves
    an episode running, the healthy ones (aligned, slowed, agreed) begin none; FOC is reached from I-f only,
    the alignment again only by a stall."""
    _, s, c = _unit()
    mode = k.MODE_ALIGN
    for ev in events:
        episode = s[k.S_EPISODE]
        new = _go(s, c, mode, ev, omega_ref=10.0)
        assert new in IF_MODES
        taken = any(row[0] == mode and row[1] == ev for row in IF_ROWS)
        if taken and ev in TROUBLE:
            assert s[k.S_EPISODE] > 0.0
        elif taken:
            assert s[k.S_EPISODE] == episode
        if new == k.MODE_EKF and mode != k.MODE_EKF:
            assert mode == k.MODE_IF
        if new == k.MODE_ALIGN and mode != k.MODE_ALIGN:
            assert ev == k.EV_STALL
        mode = new


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(IF_EVENTS), max_size=40))
def test_realignments_count_stalls_since_the_last_handover_and_only_the_last_stall_latches(events):
    """``S_REALIGN`` counts the stalls (realigned or handed to FOC) since the last handover up (agreed or
    forced); the fault latches on the transition of a stall with none left, and on no other (episodes latch
    through their age, in the step)."""
    _, s, c = _unit()
    mode, stalls, latched = k.MODE_ALIGN, 0, False
    for ev in events:
        taken = any(row[0] == mode and row[1] == ev for row in IF_ROWS)
        mode = _go(s, c, mode, ev, omega_ref=10.0)
        if taken and ev in (k.EV_AGREED, k.EV_OVERDUE):
            stalls = 0
        elif taken and ev in (k.EV_STALL, k.EV_STALL_TURNING):
            stalls += 1
        latched = latched or (taken and ev == k.EV_STALL_LAST)
        assert s[k.S_REALIGN] == stalls
        assert (s[k.S_FAULT] == k.FAULT_LATCHED) == latched


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.floats(0.0, 3.0), st.floats(-0.2, 0.2)), max_size=40))
def test_the_stand_alternates_and_always_leaves_the_ekf_on_the_anchor(periods):
    """The stand's detector and transitions over a sequence of periods (the vector turning or not, the EKF's
    speed, a drift of its angle): stands and ends alternate, and each end puts the EKF on the vector's angle
    plus the anchor's offset, on the anchor's load."""
    _, s, c = _unit()
    s[k.S_MODE] = k.MODE_IF
    s[k.S_TRUST_OFF], s[k.S_TRUST_TL] = 0.1, 15.0
    last = None
    for turning, omega_hat, drift in periods:
        s[k.S_OMEGA_IF] = 2.0 if turning else 0.0
        s[k.S_PHI] = k.wrap_angle(s[k.S_PHI] + 0.01 * s[k.S_OMEGA_IF])
        s[k.S_OMEGA_HAT] = omega_hat
        s[k.S_THETA_HAT] = k.wrap_angle(s[k.S_THETA_HAT] + drift)
        s[k.S_STILL_OUT] = s[k.S_STILL_OUT] + c[k.C_DT] if omega_hat >= c[k.C_STILL] else 0.0
        ev = k.detect_stand(s, c)
        k.stand_transition(s, c, ev, 0.0, 0.0)
        if ev != k.EV_NONE:
            assert last is None or (ev == k.EV_STANDS) != (last == k.EV_STANDS)
            last = ev
        if ev in (k.EV_VECTOR_TURNS, k.EV_ROTOR_MOVES):
            assert math.cos(s[k.S_THETA_HAT] - s[k.S_PHI] - s[k.S_ANCHOR_REL]) == pytest.approx(1.0)
            assert s[k.S_TL_HAT] == s[k.S_ANCHOR_TL]
        assert s[k.S_ANCHORED] == (k.STAND_HELD if last == k.EV_STANDS else k.STAND_FREE)
