"""The sensorless unit with injection as a state machine (``pmsm_ev.kernels.modes``): the transition table,
each transition called on its own, each detector, and property tests over event sequences. The kernels are
called as plain Python (``pmsm_ev.kernels`` is the source package; ``pmsm_ev.accel`` compiles a copy), on
the vectors of a ``ControlUnit`` built with ``low_speed = "injection"``."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from machine_support import reachable
from pmsm_ev import kernels as k
from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.params import ControllerParams, InjectionParams, ParameterError

INJECTION_MODES = (k.MODE_ACQUIRE, k.MODE_POLARITY, k.MODE_INJECTION, k.MODE_EKF)
EVENTS = (k.EV_ACQUIRED, k.EV_POLARITY_RIGHT, k.EV_POLARITY_FLIPPED, k.EV_POLARITY_UNRESOLVED, k.EV_FAST,
          k.EV_SLOW, k.EV_INJECTION_LOST, k.EV_DISAGREE, k.EV_EKF_LOST, k.EV_FLIPPED, k.EV_BLIND_STOP,
          k.EV_STILL_PARKED, k.EV_EMF_LOST, k.EV_CANNOT_SEE)


def _unit(**kw):
    """A unit with injection; its state and parameter vectors as plain lists (plain-Python kernels)."""
    u = ControlUnit("sensorless", injection=InjectionParams(low_speed="injection", **kw))
    return u, [float(x) for x in u._s], [float(x) for x in u._c]


def _go(s, c, mode, event):
    return k.transition(s, c, mode, event, 0.0, 0.0)


# -- the table ---------------------------------------------------------------------------------------
#: the strategy's rows of the unit's one table (``kernels.machine``, with the I-f strategy's): those of its events
ROWS = tuple(row for row in k.TRANSITIONS if row[1] in EVENTS)


def test_table_has_one_row_per_pair_and_known_modes_and_actions():
    pairs = [(row[0], row[1]) for row in k.TRANSITIONS]
    assert len(pairs) == len(set(pairs))
    assert len(ROWS) == 16
    actions = {getattr(k, n) for n in dir(k) if n.startswith("A_")}
    for mode, event, new, action in ROWS:
        # the one way out of the strategy: a unit that cannot see its motor's axis takes the I-f strategy's alignment
        assert mode in INJECTION_MODES and (new in INJECTION_MODES or (event, new) == (k.EV_CANNOT_SEE, k.MODE_ALIGN))
        assert event in EVENTS
        assert action in actions


def test_every_mode_is_reachable_from_the_acquisition():
    assert reachable(ROWS, k.MODE_ACQUIRE) == set(INJECTION_MODES) | {k.MODE_ALIGN}


def test_a_pair_not_in_the_table_changes_nothing():
    _, s, c = _unit()
    before = list(s)
    assert _go(s, c, k.MODE_ACQUIRE, k.EV_FAST) == k.MODE_ACQUIRE
    assert _go(s, c, k.MODE_EKF, k.EV_POLARITY_RIGHT) == k.MODE_EKF
    assert s == before


def test_the_unit_starts_in_the_acquisition_with_the_square_wave_armed():
    u, s, _ = _unit()
    assert u.mode == k.MODE_ACQUIRE
    assert s[k.S_INJ_SIGN] == 1.0 and s[k.S_INJ_SKIP] == 2.0


# -- each transition on its own ------------------------------------------------------------------------
def test_acquired_starts_the_polarity_test_with_its_sums_cleared():
    _, s, c = _unit()
    s[k.S_POL:k.S_POL + 4] = [1.0, 2.0, 3.0, 4.0]
    s[k.S_MODE_TIME] = 0.11
    assert _go(s, c, k.MODE_ACQUIRE, k.EV_ACQUIRED) == k.MODE_POLARITY
    assert s[k.S_POL:k.S_POL + 4] == [0.0] * 4 and s[k.S_MODE_TIME] == 0.0


def test_polarity_right_gives_torque_on_the_tracking_observer():
    _, s, c = _unit()
    s[k.S_TRK:k.S_TRK + 3] = [1.2, 0.0, 0.0]
    s[k.S_W_INT] = 7.0
    assert _go(s, c, k.MODE_POLARITY, k.EV_POLARITY_RIGHT) == k.MODE_INJECTION
    assert s[k.S_W_INT] == 0.0
    assert s[k.S_THETA_HAT] == pytest.approx(1.2)  # the EKF put on the tracking observer


def test_polarity_flipped_turns_the_frame_by_pi():
    _, s, c = _unit()
    s[k.S_TRK] = 0.4
    s[k.S_INT_D], s[k.S_INT_Q] = 1.5, -0.5
    assert _go(s, c, k.MODE_POLARITY, k.EV_POLARITY_FLIPPED) == k.MODE_INJECTION
    assert math.cos(s[k.S_TRK] - (0.4 + math.pi)) == pytest.approx(1.0)
    assert (s[k.S_INT_D], s[k.S_INT_Q]) == (-1.5, 0.5)
    assert s[k.S_THETA_HAT] == pytest.approx(s[k.S_TRK])


def test_an_unresolved_polarity_is_tried_again_once_then_latches_without_torque():
    _, s, c = _unit()
    assert _go(s, c, k.MODE_POLARITY, k.EV_POLARITY_UNRESOLVED) == k.MODE_ACQUIRE
    assert s[k.S_FAULT] == k.FAULT_NONE and s[k.S_POL_TRIES] == 1.0
    assert _go(s, c, k.MODE_POLARITY, k.EV_POLARITY_UNRESOLVED) == k.MODE_ACQUIRE
    assert s[k.S_FAULT] == k.FAULT_LATCHED
    s[k.S_MODE_TIME] = 10.0  # the acquisition is over, but no torque follows
    assert k.detect_acquired(s, c) == k.EV_NONE


def test_a_unit_that_cannot_see_takes_the_if_strategy_from_its_alignment_the_brake_let_go_after_the_ramp():
    """Row (MODE_ACQUIRE, EV_CANNOT_SEE, MODE_ALIGN, A_IF_FALLBACK): the I-f strategy for good (``S_IF_FALLBACK``),
    its state from its start (the alignment's clock, no fault, no episode), the park let go, the loops' integrators
    from 0, the EKF at rest with an unknown start's covariance; the identification kept. The brake holds the car
    until the alignment's vector has its current (``t_ramp``), then lets go."""
    u, s, c = _unit()
    s[k.S_ID_Y:k.S_ID_Y + 2] = [4300.0, 4220.0]
    s[k.S_ALIGN_CLOCK], s[k.S_EPISODE], s[k.S_PARKED] = 123.0, 1.0, 1.0
    s[k.S_INT_D], s[k.S_INT_Q], s[k.S_W_INT] = 1.5, -0.5, 7.0
    s[k.S_OMEGA_HAT], s[k.S_P + 12] = -7.5, 1e-6  # the speed the EKF made of the identification's square wave
    assert _go(s, c, k.MODE_ACQUIRE, k.EV_CANNOT_SEE) == k.MODE_ALIGN
    assert s[k.S_IF_FALLBACK] == 1.0 and s[k.S_PARKED] == 0.0
    assert [s[i] for i in (k.S_ALIGN_CLOCK, k.S_EPISODE, k.S_FAULT, k.S_INT_D, k.S_INT_Q, k.S_W_INT)] == [0.0] * 6
    assert s[k.S_ID_Y:k.S_ID_Y + 2] == [4300.0, 4220.0]
    assert s[k.S_OMEGA_HAT] == 0.0 and s[k.S_TL_HAT] == 0.0
    assert [s[k.S_P + 6 * i] for i in range(5)] == [c[k.C_P0 + i] for i in range(5)]
    assert _t_brake(u, s) == pytest.approx(c[k.C_HOLD_BRAKE])  # held, as it was through the acquisition
    for n in range(10):
        k.injection_unit_step(s, c, 0.0, 0.0, 0.0)
        assert s[k.S_MODE] == k.MODE_ALIGN and _t_brake(u, s) > 0.0, n  # held while the vector's current ramps up
    s[k.S_ALIGN_CLOCK] = round(c[k.C_T_RAMP] / c[k.C_DT]) - 1.0  # the ramp's last period
    k.injection_unit_step(s, c, 0.0, 0.0, 0.0)
    assert _t_brake(u, s) > 0.0
    k.injection_unit_step(s, c, 0.0, 0.0, 0.0)
    assert s[k.S_MODE] == k.MODE_ALIGN and s[k.S_HOLD] == 0.0 and _t_brake(u, s) == 0.0  # then let go


def test_a_latched_unit_that_cannot_see_stays_latched_in_the_if_strategy():
    """Two unresolved polarity tests latch the safe state; a fallback to the I-f strategy after them keeps it
    latched with the friction brake held and no voltage out, never a fresh start."""
    _, s, c = _unit()
    for _ in range(2):
        assert _go(s, c, k.MODE_ACQUIRE, k.EV_ACQUIRED) == k.MODE_POLARITY
        assert _go(s, c, k.MODE_POLARITY, k.EV_POLARITY_UNRESOLVED) == k.MODE_ACQUIRE
    assert s[k.S_FAULT] == k.FAULT_LATCHED
    assert _go(s, c, k.MODE_ACQUIRE, k.EV_CANNOT_SEE) == k.MODE_ALIGN
    assert s[k.S_IF_FALLBACK] == 1.0 and s[k.S_FAULT] == k.FAULT_LATCHED
    u = ControlUnit("sensorless", injection=InjectionParams(low_speed="injection"))
    for _ in range(3):  # the safe state asks the friction brake at every period (a car on a slope is held) and
        out = k.injection_unit_step(s, c, 5.0, -3.0, 50.0)  # puts no voltage out (the inverter's short circuit)
        assert s[k.S_FAULT] == k.FAULT_LATCHED and _t_brake(u, s) == pytest.approx(c[k.C_HOLD_BRAKE])
        assert out[:4] == (0.0, 0.0, 0.0, 0.0) and out[13] == k.FAULT_LATCHED


@pytest.mark.parametrize(("y", "blind", "acc", "held", "sees"), [
    ((4300.0, 4220.0), 1.0, 0.77, True, False),  # the design's corner motor: blind, its angle 0.77 rad rms
    ((4300.0, 4300.0), 1.0, 0.0, True, False),  # no saliency at all: no error signal
    ((4459.0, 3893.0), 1.0, 0.087, True, True),  # issue 47's motor A: blind by its saliency, its angle found at a stop
    ((4459.0, 3893.0), 0.0, 0.07, True, True),  # seeing
    ((0.0, 0.0), 1.0, 0.0, True, True),  # nothing identified (no current: an open phase): the polarity test latches
    ((4300.0, 4220.0), 1.0, 0.77, False, True),  # measured on a car the brake did not hold: it may have rolled
])
def test_cannot_see_is_a_blind_unit_whose_angle_the_injection_cannot_find(y, blind, acc, held, sees):
    _, s, c = _unit()
    s[k.S_ID_Y:k.S_ID_Y + 2] = list(y)
    s[k.S_ID_BLIND], s[k.S_ID_ACC] = blind, acc
    s[k.S_HOLD] = c[k.C_HOLD_BRAKE] if held else 0.0
    assert bool(k.cannot_see(s, c)) is not sees
    s[k.S_MODE_TIME] = 10.0  # the acquisition over
    s[k.S_GAIN_RATIO] = 1.0  # the sensors measured
    assert k.detect(s, c, k.MODE_ACQUIRE, 0.0) == (k.EV_ACQUIRED if sees else k.EV_CANNOT_SEE)


@pytest.mark.parametrize(("ratio", "parked", "omega_ref", "event"), [
    (0.0, 0.0, 0.0, k.EV_BLIND_STOP),  # the enable's acquisition, nothing asked: park and pool the answers
    (0.0, 1.0, 0.0, k.EV_STILL_PARKED),  # parked: again
    (0.0, 1.0, 5.0, k.EV_CANNOT_SEE),  # the driver asks to go: the I-f strategy now
    (1.01, 1.0, 0.0, k.EV_CANNOT_SEE),  # the sensors measured: judged
])
def test_a_unit_that_cannot_see_with_its_sensors_not_yet_measured_parks_while_nothing_is_asked(ratio, parked,
                                                                                              omega_ref, event):
    """``detect``: a blind unit whose angle accuracy is beyond ``inj_see_max`` parks instead of taking the I-f
    strategy for good while the driver asks for nothing and its sensors' relative gain is not yet measured (eq SG0
    measures it from the parked answers, ``gain_standstill_se`` > 0); with it 0 (the default) it is judged at once."""
    _, s, c = _unit(gain_standstill_se=0.005)
    s[k.S_ID_Y:k.S_ID_Y + 2] = [4300.0, 4220.0]
    s[k.S_ID_BLIND], s[k.S_ID_ACC], s[k.S_HOLD] = 1.0, 0.77, c[k.C_HOLD_BRAKE]
    s[k.S_GAIN_RATIO], s[k.S_PARKED], s[k.S_MODE_TIME] = ratio, parked, 10.0
    assert k.detect(s, c, k.MODE_ACQUIRE, omega_ref) == event
    _, s, c = _unit(gain_standstill_se=0.0)
    s[k.S_ID_Y:k.S_ID_Y + 2] = [4300.0, 4220.0]
    s[k.S_ID_BLIND], s[k.S_ID_ACC], s[k.S_HOLD] = 1.0, 0.77, c[k.C_HOLD_BRAKE]
    s[k.S_PARKED], s[k.S_MODE_TIME] = parked, 10.0
    assert k.detect(s, c, k.MODE_ACQUIRE, omega_ref) == k.EV_CANNOT_SEE


def test_the_enables_acquisition_parks_a_unit_that_cannot_see_yet():
    """Row (MODE_ACQUIRE, EV_BLIND_STOP, MODE_ACQUIRE, A_PARK): the car held on the brake, the acquisition afresh,
    parked (so that its answers are pooled: ``refining``)."""
    u, s, c = _unit()
    s[k.S_ID_Y:k.S_ID_Y + 2] = [4300.0, 4220.0]
    s[k.S_ID_BLIND], s[k.S_ID_DONE] = 1.0, 1.0
    s[k.S_ID_SUM:k.S_ID_SUM + 8] = [1.0] * 8
    s[k.S_MODE_TIME] = 10.0
    assert _go(s, c, k.MODE_ACQUIRE, k.EV_BLIND_STOP) == k.MODE_ACQUIRE
    assert s[k.S_PARKED] == 1.0 and s[k.S_HOLD] == c[k.C_HOLD_BRAKE] and s[k.S_MODE_TIME] == 0.0
    assert k.refining(s, c) and s[k.S_ID_SUM:k.S_ID_SUM + 8] == [1.0] * 8


def _t_brake(u, s):
    return k.unit_t_brake([float(x) for x in u.io], s)


@pytest.mark.parametrize("event", [k.EV_POLARITY_RIGHT, k.EV_POLARITY_FLIPPED])
def test_the_hill_hold_brakes_from_enable_and_lets_go_at_the_first_torque(event):
    u, s, c = _unit()
    hold = c[k.C_T_MAX] * u.params.n_g * u.params.eta  # the drive's own torque limit at the wheels
    assert c[k.C_HOLD_BRAKE] == pytest.approx(hold) and hold > 1000.0
    assert u.T_brake == pytest.approx(hold) and _t_brake(u, s) == pytest.approx(hold)
    assert _go(s, c, k.MODE_ACQUIRE, k.EV_ACQUIRED) == k.MODE_POLARITY
    assert _t_brake(u, s) == pytest.approx(hold)  # still no torque: still held
    assert _go(s, c, k.MODE_POLARITY, event) == k.MODE_INJECTION
    assert s[k.S_HOLD] == 0.0 and _t_brake(u, s) == 0.0  # the paper's reference: no friction brake after
    assert _go(s, c, k.MODE_INJECTION, k.EV_INJECTION_LOST) == k.MODE_ACQUIRE
    assert _t_brake(u, s) == 0.0  # a reacquisition, maybe under way: the hold is enable's only


def test_a_polarity_never_resolved_keeps_the_car_held():
    u, s, c = _unit()
    for _ in range(2):
        assert _go(s, c, k.MODE_POLARITY, k.EV_POLARITY_UNRESOLVED) == k.MODE_ACQUIRE
    assert s[k.S_FAULT] == k.FAULT_LATCHED and _t_brake(u, s) == pytest.approx(c[k.C_HOLD_BRAKE])


def test_no_hill_hold_when_off_or_on_the_if_strategy():
    u, s, _ = _unit(hold_brake=0.0)
    assert u.T_brake == 0.0 and _t_brake(u, s) == 0.0
    u_if = ControlUnit("sensorless", injection=InjectionParams(low_speed="if"))
    assert u_if.T_brake == 0.0 and u_if._s[k.S_HOLD] == 0.0


@pytest.mark.parametrize("mode", [k.MODE_POLARITY, k.MODE_INJECTION])
def test_a_lost_injection_reacquires_as_an_episode(mode):
    _, s, c = _unit()
    s[k.S_W_INT] = 3.0
    assert _go(s, c, mode, k.EV_INJECTION_LOST) == k.MODE_ACQUIRE
    assert s[k.S_EPISODE] > 0.0 and s[k.S_W_INT] == 0.0 and s[k.S_INJ_SKIP] == 2.0


def test_a_disagreeing_ekf_is_put_on_the_injection_as_an_episode():
    _, s, c = _unit()
    s[k.S_TRK:k.S_TRK + 3] = [0.3, 20.0, 5.0]
    s[k.S_OMEGA_HAT], s[k.S_THETA_HAT] = 19.0, 1.3
    assert _go(s, c, k.MODE_INJECTION, k.EV_DISAGREE) == k.MODE_INJECTION
    assert (s[k.S_OMEGA_HAT], s[k.S_THETA_HAT], s[k.S_TL_HAT]) == pytest.approx((20.0, 0.3, 5.0))
    assert s[k.S_EPISODE] > 0.0
    assert s[k.S_P + 18] == c[k.C_P0_ALIGNED + 3]  # the angle's variance of the restart


def test_a_flipped_tracking_observer_is_turned_onto_the_ekfs_polarity_as_an_episode():
    """EV_FLIPPED: the tracking observer turned by pi (the EKF's back-EMF sees the direction the injection cannot),
    what the current PIs hold in its frame with it; the EKF kept."""
    _, s, c = _unit()
    s[k.S_TRK:k.S_TRK + 3] = [0.3, 20.0, 5.0]
    s[k.S_OMEGA_HAT], s[k.S_THETA_HAT] = 19.0, 0.3 - math.pi + 0.1
    s[k.S_INT_Q] = 4.0
    assert _go(s, c, k.MODE_INJECTION, k.EV_FLIPPED) == k.MODE_INJECTION
    assert s[k.S_TRK] == pytest.approx(0.3 - math.pi) and s[k.S_INT_Q] == -4.0
    assert s[k.S_THETA_HAT] == pytest.approx(0.3 - math.pi + 0.1)
    assert s[k.S_EPISODE] > 0.0 and s[k.S_DISAGREE_V:k.S_DISAGREE_V + 2] == [1.0, 0.0]


def test_a_blind_unit_at_a_stop_parks_the_car_on_the_brake_and_finds_the_angle_afresh():
    """EV_BLIND_STOP: the friction brake asked for (the hill hold's), the acquisition from the start (its sums
    cleared, no current), no episode: the unit said it is blind, nothing was lost."""
    u, s, c = _unit()
    s[k.S_ACQ:k.S_ACQ + 4] = [1.0, 2.0, 3.0, 4.0]
    s[k.S_W_INT] = 9.0
    assert _go(s, c, k.MODE_INJECTION, k.EV_BLIND_STOP) == k.MODE_ACQUIRE
    assert s[k.S_PARKED] == 1.0 and s[k.S_HOLD] == c[k.C_HOLD_BRAKE] > 0.0
    assert s[k.S_ACQ:k.S_ACQ + 4] == [0.0] * 4 and s[k.S_W_INT] == 0.0 and s[k.S_EPISODE] == 0.0


def test_still_parked_acquires_again_and_the_first_torque_lets_go():
    _, s, c = _unit()
    s[k.S_PARKED], s[k.S_HOLD] = 1.0, c[k.C_HOLD_BRAKE]
    s[k.S_ACQ] = 5.0
    assert _go(s, c, k.MODE_ACQUIRE, k.EV_STILL_PARKED) == k.MODE_ACQUIRE
    assert s[k.S_ACQ] == 0.0 and s[k.S_PARKED] == 1.0 and s[k.S_HOLD] == c[k.C_HOLD_BRAKE]
    assert _go(s, c, k.MODE_POLARITY, k.EV_POLARITY_RIGHT) == k.MODE_INJECTION
    assert s[k.S_PARKED] == 0.0 and s[k.S_HOLD] == 0.0


def test_a_back_emf_the_frame_does_not_explain_stops_the_car_and_reacquires_as_an_episode():
    """EV_EMF_LOST: an episode, the friction brake asked for, the acquisition from the start (its sums cleared,
    no current), so that the angle is found on a car that stands again; the first torque lets go."""
    _, s, c = _unit()
    s[k.S_ACQ:k.S_ACQ + 4] = [1.0, 2.0, 3.0, 4.0]
    s[k.S_W_INT], s[k.S_INT_Q], s[k.S_EMF_T] = 9.0, 5.0, 0.01
    assert _go(s, c, k.MODE_INJECTION, k.EV_EMF_LOST) == k.MODE_ACQUIRE
    assert s[k.S_EPISODE] > 0.0 and s[k.S_PARKED] == 1.0 and s[k.S_HOLD] == c[k.C_HOLD_BRAKE] > 0.0
    assert s[k.S_ACQ:k.S_ACQ + 4] == [0.0] * 4 and s[k.S_W_INT] == 0.0 and s[k.S_INT_Q] == 0.0
    assert s[k.S_EMF_T] == 0.0
    assert _go(s, c, k.MODE_POLARITY, k.EV_POLARITY_RIGHT) == k.MODE_INJECTION
    assert s[k.S_PARKED] == 0.0 and s[k.S_HOLD] == 0.0


def _emf(s, c, omega_ctrl, e, omega, psi_share=1.0, i_q=100.0):
    """The integrators as the current loops settle them (eqs 10-11 at steady state, less the decoupling on the
    frame's speed, eqs 19-20) for a rotor at ``omega`` under a frame at ``omega_ctrl`` trailing it by ``e``, a
    magnet of ``psi_share`` of the model's, the current (0, i_q) in the frame."""
    n, psi, r = c[k.C_N], c[k.C_PSI], c[k.C_AD_RS0]
    s[k.S_OMEGA_CTRL], s[k.S_I_D], s[k.S_I_Q] = omega_ctrl, 0.0, i_q
    s[k.S_INT_D] = r * 0.0 - n * omega * psi_share * psi * math.sin(e)
    s[k.S_INT_Q] = r * i_q + n * omega * psi_share * psi * math.cos(e) - n * omega_ctrl * psi


@pytest.mark.parametrize(("omega_ctrl", "e", "omega", "psi_share", "event"), [
    (0.0, 0.0, 0.0, 1.0, k.EV_NONE),  # standing, locked
    (25.0, 0.1, 25.0, 0.85, k.EV_NONE),  # in the blend, locked, a magnet 15 % weak
    (0.0, 0.3, 12.0, 1.0, k.EV_NONE),  # a rotor creeping below the bound under a standing frame
    (-3.0, 1.0, 23.0, 0.87, k.EV_EMF_LOST),  # motor A without identification: the car rolls, the frame stands
    (-18.0, 0.0, 0.0, 1.0, k.EV_EMF_LOST),  # a frame spinning over a standing rotor
    (-12.0, 0.0, 0.0, 1.0, k.EV_NONE),  # ... slower than C_EMF_SPEED: not yet
    (20.0, math.pi, 20.0, 1.0, k.EV_EMF_LOST),  # the frame pi off at the rotor's speed
])
def test_the_back_emf_detector_sees_a_rotor_the_frame_does_not_follow(omega_ctrl, e, omega, psi_share, event):
    """Eqs LS1-LS2 on the integrators the loops settle at: no event while the frame follows the rotor (a magnet 15 %
    weaker than the model's included), EV_EMF_LOST after C_INJ_LOS_TIME (and the filter's settling) where the rotor
    turns under a frame that does not follow it, or the frame spins over a standing rotor."""
    _, s, c = _unit()
    s[k.S_MODE_TIME] = 1.0
    _emf(s, c, omega_ctrl, e, omega, psi_share)
    n = round(c[k.C_INJ_LOS_TIME] / c[k.C_DT])
    events = [k.detect_emf_lost(s, c) for _ in range(4 * n)]
    assert set(events) == ({k.EV_NONE, k.EV_EMF_LOST} if event == k.EV_EMF_LOST else {k.EV_NONE})


def test_the_back_emf_detector_waits_for_the_integrators_and_its_time():
    """No event within C_INJ_LOS_TIME of the mode's start (the integrators start from 0 with the torque), nor before
    the residual has stayed beyond its bound that long."""
    _, s, c = _unit()
    _emf(s, c, 0.0, 0.0, 40.0)
    n = round(c[k.C_INJ_LOS_TIME] / c[k.C_DT])
    s[k.S_MODE_TIME] = 0.0
    assert all(k.detect_emf_lost(s, c) == k.EV_NONE for _ in range(3 * n))  # the mode's clock does not run here
    s[k.S_MODE_TIME] = 1.0
    events = [k.detect_emf_lost(s, c) for _ in range(2 * n)]
    first = events.index(k.EV_EMF_LOST)
    assert first >= n - 1 and set(events[:first]) == {k.EV_NONE}


@pytest.mark.parametrize(("blind", "omega_ref", "omega", "t", "event"), [
    (1.0, 0.0, 2.0, 0.1, k.EV_BLIND_STOP),
    (0.0, 0.0, 2.0, 0.1, k.EV_NONE),  # it sees: the tracking observer holds the angle
    (1.0, 5.0, 2.0, 0.1, k.EV_NONE),  # the driver asks to move
    (1.0, 0.0, 20.0, 0.1, k.EV_NONE),  # still in the blend: the EKF sees
    (1.0, 0.0, 2.0, 0.01, k.EV_NONE),  # just back in injection
])
def test_blind_stop_only_for_a_blind_unit_asked_to_stand_below_the_blend(blind, omega_ref, omega, t, event):
    _, s, c = _unit()
    s[k.S_ID_BLIND], s[k.S_OMEGA_CTRL], s[k.S_MODE_TIME] = blind, omega, t
    assert k.detect_blind_stop(s, c, omega_ref) == event


@pytest.mark.parametrize(("y_d", "y_q", "blind", "ratio", "hold", "turns", "parks"), [
    (4460.0, 4000.0, 0.0, 0.0, 1.30, 200.0, True),  # 1.115, its sensors not yet measured
    (4460.0, 4000.0, 0.0, 1.01, 1.30, 200.0, True),  # measured: it still parks (little saliency to hold on)
    (4460.0, 3300.0, 0.0, 0.0, 1.30, 200.0, False),  # 1.35: it holds on the injection
    (4460.0, 4000.0, 0.0, 0.0, 0.0, 200.0, False),  # off
    (4460.0, 4000.0, 0.0, 0.0, 1.30, 0.0, True),  # the sensors never measured: as measured
    (0.0, 0.0, 0.0, 0.0, 1.30, 200.0, False),  # not identified
    (4460.0, 4300.0, 1.0, 1.01, 1.30, 200.0, True),  # blind, measured or not
    (4460.0, 3300.0, 1.0, 0.0, 0.0, 200.0, True),  # blind, the rule off
])
def test_a_unit_parks_when_blind_or_of_too_little_saliency_to_hold_the_car_on(y_d, y_q, blind, ratio, hold, turns,
                                                                             parks):
    _, s, c = _unit(saliency_hold=hold, gain_turns=turns)
    s[k.S_ID_Y_D], s[k.S_ID_Y_Q], s[k.S_ID_BLIND], s[k.S_GAIN_RATIO] = y_d, y_q, blind, ratio
    assert k.modes.parks(s, c) == parks
    s[k.S_OMEGA_CTRL], s[k.S_MODE_TIME] = 2.0, 0.1
    assert k.detect_blind_stop(s, c, 0.0) == (k.EV_BLIND_STOP if parks else k.EV_NONE)


def _balanced(s, c, g_a, g_b, periods, omega=50.0, amplitude=80.0, mode=None):
    """``periods`` control periods of balanced three-phase currents of ``amplitude`` [A] turning at the mechanical
    speed ``omega`` [rad/s] (the EKF's), read by sensors of gains g_a, g_b; the last corrected (i_a, i_b)."""
    s[k.S_MODE] = k.MODE_EKF if mode is None else mode
    s[k.S_OMEGA_HAT] = omega
    th = 0.0
    out = (0.0, 0.0)
    for _ in range(periods):
        i_a = amplitude * math.cos(th)
        i_b = amplitude * math.cos(th - 2.0 * math.pi / 3.0)
        m_a, m_b = g_a * i_a, g_b * i_b
        f_a, f_b = k.modes.balance_sensors(s, c, m_a, (m_a + 2.0 * m_b) / math.sqrt(3.0))
        out = (f_a, 0.5 * (math.sqrt(3.0) * f_b - f_a), i_a, i_b)
        th += c[k.C_N] * omega * c[k.C_DT]
    return out


def test_the_sensors_relative_gain_is_measured_over_its_turns_on_the_ekf_and_taken_out():
    _, s, c = _unit(gain_turns=20.0)
    per_turn = 2.0 * math.pi / (c[k.C_N] * 50.0 * c[k.C_DT])  # control periods an electrical turn at 50 rad/s
    _balanced(s, c, 1.02, 0.98, int(19.5 * per_turn))
    assert s[k.S_GAIN_RATIO] == 0.0  # not yet its turns: nothing taken out
    assert s[k.S_GAIN_TURNS] == pytest.approx(19.5, rel=1e-3)
    f_a, f_b, i_a, i_b = _balanced(s, c, 1.02, 0.98, int(2 * per_turn))
    assert s[k.S_GAIN_RATIO] == pytest.approx(1.02 / 0.98, rel=2e-3)  # (SG1): a part turn's share of 21
    assert f_b / f_a == pytest.approx(i_b / i_a, rel=3e-3)  # (SG2): the two phases read alike


@pytest.mark.parametrize("mode", [k.MODE_INJECTION, k.MODE_ACQUIRE, k.MODE_POLARITY])
def test_the_sensors_relative_gain_is_not_measured_with_the_square_wave_on(mode):
    _, s, c = _unit(gain_turns=10.0)
    _balanced(s, c, 1.02, 0.98, 20000, mode=mode)
    assert s[k.S_GAIN_SUM_A] == s[k.S_GAIN_TURNS] == s[k.S_GAIN_RATIO] == 0.0


def test_no_sensor_balance_where_its_turns_are_0():
    _, s, c = _unit(gain_turns=0.0)
    s[k.S_MODE] = k.MODE_EKF
    assert k.modes.balance_sensors(s, c, 3.0, 4.0) == (3.0, 4.0)
    assert s[k.S_GAIN_SUM_A] == 0.0


@pytest.mark.parametrize(("parked", "omega_ref", "event"), [
    (1.0, 0.0, k.EV_STILL_PARKED), (1.0, 3.0, k.EV_ACQUIRED), (0.0, 0.0, k.EV_ACQUIRED)])
def test_a_parked_acquisition_starts_again_until_the_driver_asks_to_move(parked, omega_ref, event):
    _, s, c = _unit()
    s[k.S_ID_DONE], s[k.S_PARKED] = 1.0, parked
    s[k.S_MODE_TIME] = 2 * c[k.C_ACQ_TIME] + c[k.C_ACQ_SETTLE] + 1e-9
    assert k.detect(s, c, k.MODE_ACQUIRE, omega_ref) == event


def test_fast_hands_over_to_the_ekf_alone():
    _, s, c = _unit()
    assert _go(s, c, k.MODE_INJECTION, k.EV_FAST) == k.MODE_EKF
    assert s[k.S_BLEND] == 1.0


def test_slow_turns_the_injection_on_with_the_tracking_observer_on_the_ekf():
    _, s, c = _unit()
    s[k.S_OMEGA_HAT], s[k.S_THETA_HAT], s[k.S_TL_HAT] = 22.0, -2.0, 12.0
    s[k.S_INJ_SIGN] = -1.0
    assert _go(s, c, k.MODE_EKF, k.EV_SLOW) == k.MODE_INJECTION
    assert s[k.S_TRK:k.S_TRK + 3] == [-2.0, 22.0, 12.0]
    assert s[k.S_INJ_SIGN] == 1.0 and s[k.S_INJ_SKIP] == 2.0


def test_a_lost_ekf_searches_again_from_an_unknown_start_as_an_episode():
    _, s, c = _unit()
    s[k.S_P:k.S_P + 25] = [0.0] * 25
    assert _go(s, c, k.MODE_EKF, k.EV_EKF_LOST) == k.MODE_EKF
    assert [s[k.S_P + 6 * i] for i in range(5)] == [c[k.C_P0 + i] for i in range(5)]
    assert s[k.S_EPISODE] > 0.0


# -- the detectors -------------------------------------------------------------------------------------
@pytest.mark.parametrize("identified", [False, True])
def test_acquired_only_at_the_end_of_the_acquisition(identified):
    """The acquisition ends after its two axes and the settling, plus the offset window, the identification on the d
    and the q axis and the R_s test's two levels at the first acquisition after enable (none after)."""
    _, s, c = _unit()
    if identified:
        s[k.S_ID_DONE] = 1.0
    end = 2 * c[k.C_ACQ_TIME] + c[k.C_ACQ_SETTLE] + (
        0.0 if identified else c[k.C_OFS_TIME] + 2 * c[k.C_ID_TIME] + 2 * c[k.C_RS_TIME])
    s[k.S_MODE_TIME] = end - 1e-9
    assert k.detect_acquired(s, c) == k.EV_NONE
    s[k.S_MODE_TIME] = end + 1e-12  # (the sum's rounding)
    assert k.detect_acquired(s, c) == k.EV_ACQUIRED


def test_the_identification_measures_on_the_found_d_axis_then_on_q():
    _, s, c = _unit()
    t0 = c[k.C_OFS_TIME]
    assert t0 > 0.0 and k.acquisition_phase(s, c, 0.0) == k.PHASE_OFFSET
    settled = 2 * c[k.C_ACQ_TIME] + c[k.C_ACQ_SETTLE]
    t_id = c[k.C_ID_TIME]
    assert t_id > 0.0
    t_rs = c[k.C_RS_TIME]
    phases = [k.acquisition_phase(s, c, t0 + t + 1e-12) for t in (0.0, c[k.C_ACQ_TIME], settled - 1e-9, settled,
                                                     settled + 0.5 * t_id, settled + t_id, settled + 1.5 * t_id,
                                                     settled + 2 * t_id, settled + 2 * t_id + t_rs,
                                                     settled + 2 * t_id + 2 * t_rs)]
    assert phases == [k.PHASE_AXIS0, k.PHASE_AXIS45, k.PHASE_SETTLE, k.PHASE_ID_D, k.PHASE_ID_D2, k.PHASE_ID_Q,
                      k.PHASE_ID_Q2, k.PHASE_RS1, k.PHASE_RS2, k.PHASE_OVER]


@pytest.mark.parametrize(("y_pos", "y_neg", "event"), [
    (5200.0, 4800.0, k.EV_POLARITY_RIGHT),  # + i_d saturates: the larger admittance
    (4800.0, 5200.0, k.EV_POLARITY_FLIPPED),
    (5000.0, 5001.0, k.EV_POLARITY_UNRESOLVED),  # a linear motor: no difference
])
def test_polarity_decided_by_the_larger_d_admittance(y_pos, y_neg, event):
    _, s, c = _unit()
    s[k.S_POL:k.S_POL + 4] = [100 * y_pos, 100 * y_neg, 100.0, 100.0]
    s[k.S_MODE_TIME] = 5 * c[k.C_POL_RAMP] + 2 * c[k.C_POL_HOLD]
    assert k.detect_polarity(s, c) == event
    s[k.S_MODE_TIME] -= 1e-3  # not before the test's end
    assert k.detect_polarity(s, c) == k.EV_NONE


def test_polarity_schedule_is_a_palindrome_whose_current_integrates_to_zero():
    """+i, -i, +i: the d current's integral and its first moment about the middle vanish (the torque an angle
    error leaks from it leaves the car's speed and displacement at zero); each sign measured only on its
    hold, after the current loop settled."""
    _, _, c = _unit()
    i, r, h = c[k.C_POL_I], c[k.C_POL_RAMP], c[k.C_POL_HOLD]
    end = 5 * r + 2 * h
    dt = 1e-6
    ts = [(j + 0.5) * dt for j in range(round(end / dt))]
    rows = [k.polarity_schedule(c, t) for t in ts]
    assert k.polarity_schedule(c, end - 1e-9)[2] == 0.0 and k.polarity_schedule(c, end)[2] == 1.0
    impulse = sum(row[0] for row in rows) * dt
    moment = sum((t - 0.5 * end) * row[0] for t, row in zip(ts, rows)) * dt
    assert abs(impulse) < 1e-6 * i * h and abs(moment) < 1e-6 * i * h * end
    for sign in (1.0, -1.0):
        measured = [row[0] for row in rows if row[1] == sign]
        assert measured and all(x == sign * i for x in measured)
    assert min(t for t, row in zip(ts, rows) if row[1] != 0.0) >= r + 0.25 * 0.5 * (h - r) - dt


def test_polarity_frame_holds_within_its_band_and_follows_beyond_it():
    _, s, c = _unit()
    band = c[k.C_POL_BAND]
    s[k.S_POL_AXIS] = math.pi - 0.5 * band  # next to the wrap
    s[k.S_TRK] = math.pi - 0.1 * band  # within the band: held
    assert k.polarity_frame(s, c) == math.pi - 0.5 * band
    s[k.S_TRK] = -math.pi + 2.0 * band  # 2.5 bands ahead, across the wrap: followed a band behind
    assert k.polarity_frame(s, c) == pytest.approx(-math.pi + band)
    s[k.S_TRK] = -math.pi + 1.5 * band  # within the band of where it is now: held there
    assert k.polarity_frame(s, c) == pytest.approx(-math.pi + band)


@pytest.mark.parametrize("limited", [1.0, 0.5, 0.0])
def test_the_injections_current_limit_rises_to_the_drives_with_the_blend(limited):
    """The speed PI's q current within C_INJ_I_MAX at rest (``limited`` 1), the drive's own limit with the EKF
    alone (0, bit for bit the plain speed loop's), in between in the blend."""
    _, s, c = _unit()
    c[k.C_REF_MODE] = 0.0
    lo, hi = c[k.C_INJ_I_MAX], c[k.C_I_Q_MAX]
    assert lo < hi
    s2 = list(s)
    _, i_q = k.foc_references(s, c, 1000.0, 0.0, limited)
    assert i_q == pytest.approx(hi - limited * (hi - lo))
    if limited == 0.0:
        assert i_q == k.speed_step(s2, c, 1000.0, 0.0) and s == s2


def test_the_injections_torque_limit_in_the_reference_generators_modes():
    """With the reference generator (the cycles' "fw"), the torque at rest within k_t C_INJ_I_MAX."""
    u = ControlUnit("sensorless", controller=ControllerParams(reference="fw", v_dc=360.0),
                    injection=InjectionParams(low_speed="injection"))
    s, c = [float(x) for x in u._s], [float(x) for x in u._c]
    assert c[k.C_REF_MODE] != 0.0
    i_d, i_q = k.foc_references(s, c, 1000.0, 0.0, 1.0)
    torque = k.model_torque(c, i_d, i_q)
    assert torque == pytest.approx(c[k.C_K_DQN] * c[k.C_PSI] * c[k.C_INJ_I_MAX], rel=1e-9)
    assert math.hypot(i_d, i_q) < c[k.C_INJ_I_MAX]


def test_speed_detector_has_its_hysteresis_and_no_transition_at_a_modes_start():
    _, s, c = _unit()
    hi, hyst = c[k.C_BLEND_HI], c[k.C_BLEND_HYST]
    assert k.detect_speed(s, c, k.MODE_INJECTION, 2 * hi) == k.EV_NONE  # the mode just began
    s[k.S_MODE_TIME] = c[k.C_INJ_LOS_TIME]
    assert k.detect_speed(s, c, k.MODE_INJECTION, hi - 0.01) == k.EV_NONE
    assert k.detect_speed(s, c, k.MODE_INJECTION, -hi) == k.EV_FAST
    assert k.detect_speed(s, c, k.MODE_EKF, hi - 0.5 * hyst) == k.EV_NONE
    assert k.detect_speed(s, c, k.MODE_EKF, hi - 1.01 * hyst) == k.EV_SLOW


def test_injection_lost_only_after_its_time():
    _, s, c = _unit()
    s[k.S_INJ_ERR_F] = 2.0 * c[k.C_INJ_LOS_ANGLE]
    n = round(c[k.C_INJ_LOS_TIME] / c[k.C_DT])
    assert all(k.detect_injection_lost(s, c) == k.EV_NONE for _ in range(n - 1))
    assert k.detect_injection_lost(s, c) == k.EV_INJECTION_LOST
    s[k.S_INJ_ERR_F] = 0.5 * c[k.C_INJ_LOS_ANGLE]  # back within: the timer from zero
    assert k.detect_injection_lost(s, c) == k.EV_NONE and s[k.S_INJ_LOS_T] == 0.0


def test_disagreement_counts_only_where_both_observers_are_evidence():
    """The injection's angle against the EKF's, filtered (``S_DISAGREE_F``), counts only in the blend's first
    quarter: at rest the EKF is no evidence, past it the square wave is at less than half its amplitude."""
    _, s, c = _unit()
    s[k.S_DISAGREE_F] = 2.0 * c[k.C_INJ_LOS_ANGLE]
    n = round(c[k.C_INJ_LOS_TIME] / c[k.C_DT])
    for w in (0.0, 0.3, 0.6):
        s[k.S_BLEND] = w
        assert all(k.detect_injection_lost(s, c) == k.EV_NONE for _ in range(2 * n))
    s[k.S_BLEND] = 0.2
    events = [k.detect_injection_lost(s, c) for _ in range(n)]
    assert events[-1] == k.EV_DISAGREE and set(events[:-1]) == {k.EV_NONE}


def test_a_disagreement_near_pi_is_a_flip_not_an_average_of_zero():
    """The disagreement filtered as a vector (``S_DISAGREE_V``): answers that alternate between +-(pi - 0.1), a
    tracking observer on the axis's other direction, average to pi, not to 0 (a filtered wrapped angle did), and
    beyond ``FLIP_ANGLE`` the detector says EV_FLIPPED (a plain disagreement beyond the loss angle, EV_DISAGREE)."""
    _, s, c = _unit()
    g = c[k.C_LOS_FILTER]
    for j in range(400):
        d = (math.pi - 0.1) * (1 if j % 2 else -1)
        s[k.S_DISAGREE_V] += g * (math.cos(d) - s[k.S_DISAGREE_V])
        s[k.S_DISAGREE_SIN] += g * (math.sin(d) - s[k.S_DISAGREE_SIN])
    s[k.S_DISAGREE_F] = math.atan2(s[k.S_DISAGREE_SIN], s[k.S_DISAGREE_V])
    assert abs(s[k.S_DISAGREE_F]) > k.FLIP_ANGLE
    s[k.S_BLEND] = 0.2
    n = round(c[k.C_INJ_LOS_TIME] / c[k.C_DT])
    assert [k.detect_injection_lost(s, c) for _ in range(n)][-1] == k.EV_FLIPPED
    s[k.S_DISAGREE_F] = 0.5 * (c[k.C_INJ_LOS_ANGLE] + k.FLIP_ANGLE)
    assert [k.detect_injection_lost(s, c) for _ in range(n)][-1] == k.EV_DISAGREE


def _identified(s, y_d=4460.0, y_q=3890.0):
    s[k.S_ID_Y:k.S_ID_Y + 2] = [y_d, y_q]
    s[k.S_ID_YE:k.S_ID_YE + 2] = [y_d, y_q]


@pytest.mark.parametrize(("e", "lost"), [(0.0, False), (0.3, False), (0.9, False), (1.2, True), (0.5 * math.pi, True)])
def test_the_d_admittance_sees_a_tracking_observer_off_the_axis(e, lost):
    """``axis_cosine``: (I1) adm = Y_s + Y_x cos 2e with the identified admittances gives cos 2e whatever the error
    signal says; held below ``C_AXIS_COS`` (60 deg) for the loss time in FOC on the injection, EV_INJECTION_LOST."""
    _, s, c = _unit()
    _identified(s)
    y_s, y_x = 0.5 * (4460.0 + 3890.0), 0.5 * (4460.0 - 3890.0)
    assert k.axis_cosine(s, y_s + y_x * math.cos(2 * e)) == pytest.approx(math.cos(2 * e))
    s[k.S_AXIS_F] = math.cos(2 * e)
    s[k.S_MODE] = k.MODE_INJECTION
    n = round(c[k.C_INJ_LOS_TIME] / c[k.C_DT])
    events = [k.detect_injection_lost(s, c) for _ in range(n)]
    assert events[-1] == (k.EV_INJECTION_LOST if lost else k.EV_NONE)


def test_the_axis_detector_waits_for_the_identification_and_foc_on_the_injection():
    _, s, c = _unit()
    s[k.S_AXIS_F] = -1.0
    s[k.S_MODE] = k.MODE_INJECTION
    assert not k.axis_lost(s, c)  # not identified: no admittances to judge by
    _identified(s)
    assert k.axis_lost(s, c)
    s[k.S_MODE] = k.MODE_POLARITY  # the polarity test's d current saturates the d axis
    assert not k.axis_lost(s, c)


def _sums(s, y_d, y_q, v_e, v, n=250):
    """The identification's sums of a motor with admittances y_d, y_q and a dead time that takes v_e [V] from each
    half-wave: a(V) = y (1 - v_e / V) at V and 2 V (the identification's: half ``C_INJ_V_MAX`` and all of it)."""
    for j, (y, amp) in enumerate(((y_d, v), (y_d, 2 * v), (y_q, v), (y_q, 2 * v))):
        s[k.S_ID_SUM + j] = n * y * (1.0 - v_e / amp)
        s[k.S_ID_N_D + j] = n


@pytest.mark.parametrize("v_e", [0.0, 5.0, 10.0])
def test_identify_cancels_the_dead_times_voltage_by_two_amplitudes(v_e):
    """(ID1): the admittances found whatever voltage the dead time takes; the amplitude that gives the data
    sheet's error signal as the square wave sees it (ID4: motor A of the issue, a third of the saliency, 2.7 times
    the voltage and the dead time's share on top), within its bounds, and the error signal's gain there."""
    _, s, c = _unit()
    y_d, y_q = 1 / 2.2425e-4, 1 / 2.5689e-4
    v = c[k.C_INJ_V]
    _sums(s, y_d, y_q, v_e, 0.5 * c[k.C_INJ_V_MAX])
    k.identify(s, c)
    assert s[k.S_ID_Y:k.S_ID_Y + 2] == pytest.approx([y_d, y_q], rel=1e-12)
    v_a = v * c[k.C_INJ_Y] / (0.5 * (y_d - y_q)) + v_e  # a(V) = y (1 - v_e / V): V_a Y_x - v_e Y_x = v C_INJ_Y
    assert v_a == pytest.approx(2.66 * v + v_e, rel=0.01) and s[k.S_INJ_VA] == pytest.approx(v_a)
    assert s[k.S_ID_YE] == pytest.approx(y_d * (1 - v_e / v_a), rel=1e-12)
    assert s[k.S_INJ_YX] == pytest.approx(0.5 * (y_d - y_q) * (1 - v_e / v_a), rel=1e-12)
    assert s[k.S_INJ_VA] * s[k.S_INJ_YX] == pytest.approx(v * c[k.C_INJ_Y], rel=1e-12)  # the design's signal
    assert s[k.S_ID_BLIND] == 0.0  # 1.146 >= 1.10


def test_identify_says_blind_below_the_least_saliency_and_bounds_the_amplitude():
    _, s, c = _unit()
    _sums(s, 4460.0, 4460.0 / 1.05, 0.0, c[k.C_INJ_V])
    k.identify(s, c)
    assert s[k.S_ID_BLIND] == 1.0 and s[k.S_INJ_VA] == c[k.C_INJ_V_MAX]
    _, s, c = _unit()
    _sums(s, 4460.0, 4460.0 / 2.0, 0.0, c[k.C_INJ_V])  # more salient than the data sheet: not below C_INJ_V
    k.identify(s, c)
    assert s[k.S_ID_BLIND] == 0.0 and s[k.S_INJ_VA] == c[k.C_INJ_V]


@pytest.mark.parametrize(("blind", "parked", "measures"), [(0.0, 0.0, False), (0.0, 1.0, False), (1.0, 0.0, False),
                                                            (1.0, 1.0, True)])
def test_only_a_parking_units_parked_acquisitions_measure_the_motor_again(blind, parked, measures):
    """``refining``: after the enable's identification only a unit that parks (here: blind) holding the car at a stop
    runs the identification's phases again (not the offset window or the R_s test), and its acquisition keeps the
    sums."""
    _, s, c = _unit()
    s[k.S_ID_DONE], s[k.S_ID_BLIND], s[k.S_PARKED] = 1.0, blind, parked
    assert bool(k.refining(s, c)) is measures
    assert k.identification_time(s, c) == (c[k.C_ID_TIME] if measures else 0.0)
    assert k.offset_time(s, c) == 0.0 and k.rs_test_time(s, c) == 0.0
    s[k.S_ID_SUM:k.S_ID_SUM + 8] = [1.0] * 8
    k.enter_acquire(s, c, 0.0, 0.0)
    assert s[k.S_ID_SUM:k.S_ID_SUM + 8] == [blind] * 8  # a blind unit's pooled, a seeing unit's cleared


@pytest.mark.parametrize(("parked", "trusted"), [(1.146, False), (1.25, True)])
def test_a_blind_unit_that_the_pooled_answers_find_salient_is_no_longer_blind(parked, trusted):
    """The enable's answers read a saliency below ``C_SALIENCY_MIN`` (blind); a parked acquisition's answers pooled
    with them (four times as many) give the saliency of all: still blind below ``C_SALIENCY_TRUST`` (issue 47's
    motor A, 1.146: pooled 1.128), trusted above it, the amplitude and the gain from all the answers."""
    _, s, c = _unit()
    y_d = 1 / 2.2425e-4
    _sums(s, y_d, y_d / 1.06, 0.0, 0.5 * c[k.C_INJ_V_MAX])
    k.identify(s, c)
    assert s[k.S_ID_BLIND] == 1.0
    s[k.S_ID_DONE] = 1.0
    enable = list(s[k.S_ID_SUM:k.S_ID_SUM + 8])
    _sums(s, y_d, y_d / parked, 0.0, 0.5 * c[k.C_INJ_V_MAX], n=1000)
    s[k.S_ID_SUM:k.S_ID_SUM + 8] = [a + b for a, b in zip(enable, s[k.S_ID_SUM:k.S_ID_SUM + 8])]
    k.identify(s, c)
    pooled = (0.2 / 1.06 + 0.8 / parked) * y_d
    assert c[k.C_SALIENCY_MIN] < y_d / pooled
    assert s[k.S_ID_BLIND] == (0.0 if trusted else 1.0) and s[k.S_ID_Y_Q] == pytest.approx(pooled, rel=1e-12)
    assert s[k.S_INJ_YX] == pytest.approx(0.5 * (y_d - pooled), rel=1e-12)


@pytest.mark.parametrize("v_dt", [0.0, 0.3])
def test_identify_rs_cancels_the_dead_times_voltage_by_two_levels(v_dt):
    """(ID2): the d command's mean R i + v_dt at the two levels gives R whatever the dead time's v_dt; a current
    that did not rise gives nothing."""
    _, s, c = _unit()
    r, i2, n = 0.0123, c[k.C_RS_I], 200
    s[k.S_RS_SUM:k.S_RS_SUM + 6] = [n * (r * 0.5 * i2 + v_dt), n * 0.5 * i2, n * (r * i2 + v_dt), n * i2, n, n]
    k.identify_rs(s, c)
    assert s[k.S_ID_RS] == pytest.approx(r, rel=1e-12)
    _, s, c = _unit()
    s[k.S_RS_SUM:k.S_RS_SUM + 6] = [n * v_dt, 0.0, n * v_dt, n * 0.1, n, n]  # an open phase: no current
    k.identify_rs(s, c)
    assert s[k.S_ID_RS] == 0.0


def test_identify_leaves_the_model_where_no_voltage_reached_the_motor():
    _, s, c = _unit()
    _sums(s, 0.0, 0.0, 0.0, c[k.C_INJ_V])
    k.identify(s, c)
    assert s[k.S_ID_Y] == 0.0 and s[k.S_INJ_YX] == 0.0 and s[k.S_INJ_VA] == 0.0
    assert k.error_gain(s, c) == c[k.C_INJ_Y]


def test_the_ekf_bound_grows_with_the_back_emf():
    """At speed a motor that is not the model's leaves a share of the back-EMF unexplained: the bound is
    C_EKF_LOS_I plus the current the back-EMF drives in a period."""
    _, s, c = _unit()
    n = round(c[k.C_EKF_LOS_TIME] / c[k.C_DT])
    s[k.S_OMEGA_HAT] = 1000.0
    s[k.S_RESID_F] = 0.99 * (c[k.C_EKF_LOS_I] + c[k.C_EKF_LOS_EMF] * 1000.0)
    assert all(k.detect_ekf_lost(s, c) == k.EV_NONE for _ in range(2 * n))
    s[k.S_RESID_F] = 1.01 * (c[k.C_EKF_LOS_I] + c[k.C_EKF_LOS_EMF] * 1000.0)
    assert [k.detect_ekf_lost(s, c) for _ in range(n)][-1] == k.EV_EKF_LOST


def test_ekf_lost_only_after_its_time():
    _, s, c = _unit()
    s[k.S_RESID_F] = 2.0 * c[k.C_EKF_LOS_I]
    n = round(c[k.C_EKF_LOS_TIME] / c[k.C_DT])
    events = [k.detect_ekf_lost(s, c) for _ in range(n)]
    assert events[-1] == k.EV_EKF_LOST and set(events[:-1]) == {k.EV_NONE}


# -- properties over event sequences ---------------------------------------------------------------------
@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(EVENTS), max_size=40))
def test_no_torque_before_a_polarity_test_decided(events):
    """Whatever the events, FOC (modes injection and EKF) is reached from enable only through a decided
    polarity test, and the mode stays one of the strategy's, but for the I-f strategy's alignment once the unit
    cannot see (EV_CANNOT_SEE), where the injection's events change nothing."""
    _, s, c = _unit()
    mode, decided = k.MODE_ACQUIRE, False
    for ev in events:
        new = _go(s, c, mode, ev)
        if k.MODE_ALIGN in (mode, new):
            assert new == k.MODE_ALIGN and (mode == k.MODE_ALIGN or (mode, ev) == (k.MODE_ACQUIRE, k.EV_CANNOT_SEE))
            mode = new
            continue
        assert new in INJECTION_MODES
        if mode == k.MODE_POLARITY and ev in (k.EV_POLARITY_RIGHT, k.EV_POLARITY_FLIPPED):
            decided = True
        if new == k.MODE_ACQUIRE:
            decided = False
        if new in (k.MODE_INJECTION, k.MODE_EKF):
            assert decided
        mode = new


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(EVENTS), max_size=40))
def test_the_fault_latches_only_on_unresolved_polarity_twice(events):
    """Transitions alone latch the fault only after two unresolved polarity tests (episodes latch through
    their age, in the step)."""
    _, s, c = _unit()
    mode, unresolved = k.MODE_ACQUIRE, 0
    for ev in events:
        if mode == k.MODE_POLARITY and ev == k.EV_POLARITY_UNRESOLVED:
            unresolved += 1
        mode = _go(s, c, mode, ev)
        assert (s[k.S_FAULT] == k.FAULT_LATCHED) == (unresolved >= 2)


# -- bad input ------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("kw", "names"), [
    ({"low_speed": "hfi"}, "low_speed"),
    ({"low_speed": "injection", "inj_frequency": 6000.0}, "inj_frequency"),
    ({"low_speed": "injection", "inj_frequency": 3000.0}, "inj_frequency"),
    ({"low_speed": "injection", "inj_voltage": 0.0}, "inj_voltage"),
    ({"low_speed": "injection", "inj_voltage": -5.0}, "inj_voltage"),
    ({"low_speed": "injection", "inj_voltage": 150.0}, "inj_voltage"),
    ({"low_speed": "injection", "inj_blend_low": 40.0}, "inj_blend_low"),
    ({"low_speed": "injection", "hold_brake": -1.0}, "hold_brake"),
    ({"low_speed": "injection", "id_time": 0.001}, "id_time"),
    ({"low_speed": "injection", "id_time": -0.05}, "id_time"),
    ({"low_speed": "injection", "saliency_min": 0.9}, "saliency_min"),
    ({"low_speed": "injection", "saliency_trust": 1.05}, "saliency_trust"),
    ({"low_speed": "injection", "inj_axis_cos": 1.0}, "inj_axis_cos"),
    ({"low_speed": "injection", "inj_voltage_max": 20.0}, "inj_voltage_max"),
    ({"low_speed": "injection", "inj_voltage_max": 120.0}, "inj_voltage_max"),
    ({"low_speed": "injection", "rs_time": 0.001}, "rs_time"),
    ({"low_speed": "injection", "rs_current": 0.0}, "rs_current"),
    ({"low_speed": "injection", "emf_slip_speed": 0.0}, "emf_slip_speed"),
    ({"low_speed": "injection", "emf_slip_rel": -0.1}, "emf_slip_rel"),
    ({"low_speed": "injection", "inj_see_max": 0.1}, "inj_see_max"),
    ({"low_speed": "injection", "inj_see_max": 1.0}, "inj_see_max"),
    ({"low_speed": "injection", "saliency_hold": 0.9}, "saliency_hold"),
    ({"low_speed": "injection", "gain_turns": 5.0}, "gain_turns"),
    ({"low_speed": "injection", "gain_turns": -1.0}, "gain_turns"),
])
def test_bad_injection_parameters_are_refused_by_name(kw, names):
    with pytest.raises(ParameterError, match=names) as err:
        ControlUnit("sensorless", injection=InjectionParams(**kw))
    assert "\n" not in str(err.value)


def test_lower_frequencies_are_whole_half_waves():
    u, _, c = _unit(inj_frequency=2500.0)
    assert c[k.C_INJ_M] == 2.0


def test_an_identification_that_sees_no_current_gives_no_torque_and_latches_the_safe_state():
    """No current answers the square wave (an open phase, a DC link at 0): nothing is identified (the model's gain
    and amplitude stay), the polarity test cannot decide, and after the second try the fault latches (output
    fault 2) in the acquisition, with no current asked for: never torque on a guess."""
    u, _, _ = _unit()
    for _ in range(round(1.2 / u.dt)):
        out = u.step(0.0, 0.0, 50.0)
    s = u._s
    assert u.L_d_id == 0.0 and u.L_q_id == 0.0 and u.R_s_id == 0.0 and s[k.S_INJ_VA] == 0.0
    assert out[13] == k.FAULT_LATCHED and out[12] == k.MODE_ACQUIRE
    assert out[6] == 0.0 and u.T_brake > 0.0  # no q current asked for; the hill hold keeps the car


def test_the_angle_accuracy_follows_eq_id3():
    """(ID3) on Table I's motor at a stop: sigma = 1 A, 30 V, Y_x = 751 1/H, a = 50 rad/s: 0.052 rad (measured from
    24 start angles: 0.05 rad rms); a third of the saliency's Y_x at three times the voltage gives the same."""
    _, s, c = _unit()
    acc = k.angle_accuracy(c, 1.0, 30.0, 751.0)
    assert acc == pytest.approx(0.052, abs=0.001)
    assert k.angle_accuracy(c, 1.0, 90.0, 751.0 / 3) == pytest.approx(acc, rel=1e-12)
    assert k.angle_accuracy(c, 2.0, 30.0, 751.0) == pytest.approx(2 * acc, rel=1e-12)


@pytest.mark.parametrize(("y_q", "parked", "measures"), [(3000.0, 1.0, True), (3000.0, 0.0, False),
                                                          (2500.0, 1.0, False)])
def test_a_seeing_unit_of_little_saliency_measures_again_while_parked(y_q, parked, measures):
    """``refining``: with the sensors' relative gain measured at standstill (``gain_standstill_se`` > 0), a seeing
    unit that parks (its saliency below ``saliency_hold``) pools its parked acquisitions' answers too (eq SG0 needs
    them) until the ratio is measured; a unit salient enough to hold the car on the injection does not park, is not
    measured again, and its next acquisition clears the sums. Off (the default), only a blind unit pools."""
    _, s, c = _unit(gain_standstill_se=0.005)
    s[k.S_ID_DONE], s[k.S_ID_Y_D], s[k.S_ID_Y_Q] = 1.0, 1.15 * 3000.0, y_q
    s[k.S_PARKED] = parked
    assert bool(k.refining(s, c)) is measures
    s[k.S_ID_SUM:k.S_ID_SUM + 8] = [1.0] * 8
    k.enter_acquire(s, c, 0.0, 0.0)
    assert s[k.S_ID_SUM:k.S_ID_SUM + 8] == [1.0 if y_q == 3000.0 else 0.0] * 8
    s[k.S_GAIN_RATIO] = 1.01  # measured: no more
    assert not k.refining(s, c)
    _, s, c = _unit()
    s[k.S_ID_DONE], s[k.S_ID_Y_D], s[k.S_ID_Y_Q], s[k.S_PARKED] = 1.0, 1.15 * 3000.0, y_q, parked
    assert not k.refining(s, c)


def _cross_sums(s, c, anti, spread, n=400.0):
    """The identification's cross answers (``S_ID_D_SUM``, ``S_ID_D_SQ``) with an antisymmetric part ``anti`` [1/H]
    alone, (b_d + b_q) / 2 = anti on both amplitudes (no dead time), each answer scattered by +-``spread`` [1/H]."""
    for j in range(4):
        scale = 2.0 * c[k.C_INJ_M] * c[k.C_DT] * k.identification_amplitude(c, j)  # an answer [A] per [1/H]
        mean, sd = anti * scale, spread * scale
        s[k.S_ID_N_D + j] = n
        s[k.S_ID_D_SUM + j] = n * mean
        s[k.S_ID_D_SQ + j] = n * (mean * mean + sd * sd)


def test_the_sensors_relative_gain_at_standstill_from_the_answers_antisymmetric_part():
    """(SG0) The antisymmetric part of the answers, Y_s (g_a - g_b) / (2 sqrt 3), gives the ratio once its standard
    error is within ``gain_standstill_se``; the pooled sums then start afresh. Too scattered answers, a ratio already
    measured, or the measurement off take nothing."""
    y_d, y_q = 4400.0, 4000.0
    x = 0.033  # (g_a - g_b) / g
    anti = 0.5 * (y_d + y_q) * x / (2.0 * math.sqrt(3.0))
    _, s, c = _unit(gain_standstill_se=0.005)
    s[k.S_ID_Y_D], s[k.S_ID_Y_Q] = y_d, y_q
    _cross_sums(s, c, anti, spread=50.0)
    k.standstill_gain(s, c)
    assert s[k.S_GAIN_RATIO] == pytest.approx((1 + x / 2) / (1 - x / 2), rel=1e-12)
    assert s[k.S_ID_SUM:k.S_ID_SUM + 8] == [0.0] * 8 and s[k.S_ID_NOISE:k.S_ID_NOISE + 8] == [0.0] * 8
    _, s, c = _unit(gain_standstill_se=0.005)
    s[k.S_ID_Y_D], s[k.S_ID_Y_Q] = y_d, y_q
    _cross_sums(s, c, anti, spread=2000.0)  # a standard error of about 0.13: not yet
    k.standstill_gain(s, c)
    assert s[k.S_GAIN_RATIO] == 0.0 and s[k.S_ID_N_D] == 400.0
    for kw, ratio in (({"gain_standstill_se": 0.005}, 1.01), ({}, 0.0),
                      ({"gain_standstill_se": 0.005, "gain_turns": 0.0}, 0.0)):
        _, s, c = _unit(**kw)
        s[k.S_ID_Y_D], s[k.S_ID_Y_Q], s[k.S_GAIN_RATIO] = y_d, y_q, ratio
        _cross_sums(s, c, anti, spread=50.0)
        k.standstill_gain(s, c)
        assert s[k.S_GAIN_RATIO] == ratio


@pytest.mark.parametrize(("g_a", "g_b", "theta"), [(0.981, 1.014, 0.7), (1.014, 0.981, 2.1)])
def test_a_parked_unit_of_little_saliency_measures_its_sensors_at_standstill(g_a, g_b, theta):
    """A motor of saliency 1.098 (the low-saliency corner's, seed 6464), sensors 3.3 % apart, 1.5 A of noise, an
    inverter without dead time, its car held at a stop from enable, SG0 on: the parked acquisitions pool their
    answers and SG0 takes the relative gain within 1 % of the sensors' before 8 s (two rotor angles, both signs of
    the mismatch). With 2 us of dead time compensated it is biased by up to 3 % (``gain_standstill_se``: off by
    default)."""
    from dataclasses import replace

    from pmsm_ev.params import MotorParams, PlantParams
    from pmsm_ev.plant import Plant

    motor = replace(MotorParams(), L_d=2.3216e-4, L_q=2.5483e-4, R_s=0.0104, psi=0.0822)
    plant = Plant(motor=motor, plant=PlantParams(flux_model="algebraic", sensor_noise=1.5, sensor_seed=765252,
                                                 flux_q_current=337.8, flux_d_current=207.5, dead_time=0.0,
                                                 v_dc=360.0, sensor_gain_a=g_a, sensor_gain_b=g_b))
    plant.theta_e = theta
    unit = ControlUnit("sensorless", controller=ControllerParams(dead_time_comp=0.0, v_dc=360.0),
                       injection=InjectionParams(low_speed="injection", gain_standstill_se=0.005))
    i_a = i_b = 0.0
    for _ in range(80000):
        out = unit.step(i_a, i_b, 0.0)
        r = plant.step(out[0], out[1], 0.0, 1e-4, unit.T_brake)
        i_a, i_b = r[4], r[5]
        if unit._s[k.S_GAIN_RATIO] != 0.0:
            break
    assert unit._s[k.S_GAIN_RATIO] == pytest.approx(g_a / g_b, rel=0.01)
    assert abs(plant.x_vehicle) < 1e-3  # held on the brake
