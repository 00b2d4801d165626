"""The sensorless unit never stays in I-f while the reference asks for FOC's speed range
(``StartupParams.if_deadline``, ``stall_time``, ``realign_max``; docs/sensorless.md, "Handover deadline and
stall"). The case is the one the Monte-Carlo on WLTC found: the plant's L_q 19 % below the EKF's and a large
I-f vector (400 A, as after a stop whose braking or load estimate raised it). The EKF's speed then swings
about the I-f speed by +-10 rad/s, the handover's agreement never lasts ``agree_time``, and the vector pulls
out of step at 90 rad/s: the car stands with the vector swinging at 400 A and, before these detectors,
nothing said so (no episode, no fault)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app.cli import main
from pmsm_cosim.engine.recording import read_results
from pmsm_ev import kernels as _k
from pmsm_ev.params import ParameterError, StartupParams

#: a large I-f vector on a plant whose L_q is 19 % below the unit's model (0.29 mH)
MISMATCH = ("ctrl.i_if=400", "plant.L_q=0.000234")


@pytest.fixture(scope="module")
def fmus():
    return project_fmus()


def _run(tmp_path, name, stop, *sets):
    out = tmp_path / name
    argv = ["run", "wltc3b-if", "--stop-time", str(stop), "--no-figures", "--quiet", "--out", str(out)]
    assert main(argv + ["--set", *MISMATCH, *sets]) == 0
    return read_results(out), json.loads((out / "metrics.json").read_text())


def _due(r) -> float:
    """The time of the first handover up after |omega_ref| passed omega_up, less that time [s]."""
    t, m, w = r["time"], r["mode"], np.abs(r["omega_ref"])
    up = int(np.argmax((m[1:] == _k.MODE_EKF) & (m[:-1] == _k.MODE_IF))) + 1
    start = up
    while start > 0 and w[start - 1] > StartupParams().omega_up and m[start - 1] == _k.MODE_IF:
        start -= 1
    return float(t[up] - t[start])


def _due_from(r, after: float) -> float:
    """The time after ``after`` [s] from which the unit is in I-f with |omega_ref| above omega_up (the
    handover up's due timer runs from there) [s]."""
    t, m, w = r["time"], r["mode"], np.abs(r["omega_ref"])
    return float(t[int(np.argmax((t > after) & (m == _k.MODE_IF) & (w > StartupParams().omega_up)))])


def test_without_the_deadline_the_unit_stays_in_i_f_and_says_nothing(fmus, tmp_path):
    """The defect, kept reproducible: deadlines off, the launch at 13 s never hands over, the rotor pulls
    out and stands while the reference climbs to 45 km/h, and no episode is reported."""
    r, m = _run(tmp_path, "off", 25, "ctrl.if_deadline=0", "ctrl.stall_time=0")
    after = r["time"] > 13.0
    assert np.all(r["mode"][after] == _k.MODE_IF)
    assert m["trace"]["inside_share"] < 0.7
    assert abs(r["omega_m"][-1]) < 3.0 and r["omega_ref"][-1] > 300.0  # stands, the reference at 300 rad/s
    assert m["synchronism"]["episodes"] == 0 and not m["synchronism"]["fault_latched"]


def test_an_overdue_handover_is_forced_and_the_car_follows_the_trace(fmus, tmp_path):
    """With the defaults the handover comes if_deadline (1 s) after |omega_ref| passed omega_up (a healthy
    launch takes agree_time, 0.3 s), as an episode that ends in synchronism; the car stays in the band."""
    r, m = _run(tmp_path, "on", 25)
    assert _due(r) == pytest.approx(StartupParams().if_deadline, abs=0.051)
    assert m["trace"]["inside_share"] == 1.0
    s = m["synchronism"]
    assert s["episodes"] == 1 and not s["fault_latched"]
    assert s["t_first_episode"] == pytest.approx(_due_from(r, 13.0) + StartupParams().if_deadline, abs=0.051)
    assert r["fault"][-1] == _k.FAULT_NONE and r["mode"][-1] == _k.MODE_EKF
    assert np.max(np.abs(r["omega_m"] - r["omega_hat"])[r["time"] > 16.0]) < 5.0


@pytest.mark.parametrize("sets, reaction", [
    ((), _k.MODE_ALIGN),
    # the same case nudged (a 380 A vector instead of 400 A): its swing then has the rotor turning the vector's way
    # when the stall is detected, not standing
    (("ctrl.i_if=380",), _k.MODE_EKF),
])  # (which reaction a run shows is the detector's, tests/test_if_modes.py: EV_STALL_TURNING or EV_STALL)
def test_a_stalled_rotor_is_realigned_or_handed_to_foc_and_drives_on(fmus, tmp_path, sets, reaction):
    """The forced handover off: the rotor pulls out and swings on the 400 A vector; stall_time (3 s) after
    |omega_ref| passed omega_up the unit reacts (an episode): a rotor that stands is aligned again from
    standstill, starts in I-f and hands over; one that turns the vector's way at omega_down or faster gets FOC
    on the EKF at once. Which one depends on the swing's phase at that moment; either way the car is back in
    the band within 7 s of the stall."""
    st = StartupParams()
    r, m = _run(tmp_path, "stall", 30, "ctrl.if_deadline=0", *sets)
    changes = m["sensorless"]["mode_changes"]
    t_stall, to = next((t, b) for t, a, b in changes if a == _k.MODE_IF and t > 13.0)
    assert t_stall == pytest.approx(_due_from(r, 13.0) + st.stall_time, abs=0.051) and to == reaction
    t_up = next(t for t, a, b in changes if t >= t_stall and b == _k.MODE_EKF)
    assert t_up - t_stall < (st.align_time + 1.5 if reaction == _k.MODE_ALIGN else 0.051)
    s = m["synchronism"]
    assert s["episodes"] == 1 and s["t_first_episode"] == pytest.approx(t_stall, abs=0.051)
    assert not s["fault_latched"] and r["fault"][-1] == _k.FAULT_NONE
    late = r["time"] > t_stall + 7.0
    assert np.max(np.abs(r["omega_m"] - r["omega_ref"])[late]) < 20.0  # 20 rad/s = 1.7 km/h


def test_a_stall_with_no_realignment_left_latches_the_safe_state(fmus, tmp_path):
    """realign_max = 0 (and the 380 A vector, whose rotor turns at the stall): the stall latches the fault at once:
    the reference taken as 0, the vector brought to rest and held at the current limit; once it is held the car
    does not move. How fast the rotor turns at the latch is the swing's phase at that moment, so the stop is
    bounded by that speed: the vector ramps down at the I-f ramp (if_accel), at least half of it while the
    guard keeps it with the rotor."""
    st = StartupParams()
    r, m = _run(tmp_path, "latched", 22, "ctrl.if_deadline=0", "ctrl.realign_max=0", "ctrl.i_if=380")
    t = r["time"]
    s = m["synchronism"]
    assert s["fault_latched"]
    assert s["t_fault"] == pytest.approx(_due_from(r, 13.0) + st.stall_time, abs=0.051)
    after = t > s["t_fault"]
    assert np.all(r["fault"][after] == _k.FAULT_LATCHED) and np.all(r["mode"][after] == _k.MODE_IF)
    # the vector at rest from t_held to the end, reached within the ramp's time from the rotor's speed
    turning = np.flatnonzero(r["omega_ctrl"] != 0.0)
    t_held = t[turning[-1] + 1]
    w_latch = np.max(np.abs(r["omega_m"][after & (t < s["t_fault"] + 0.5)]))
    assert t_held - s["t_fault"] < w_latch / (0.5 * st.if_accel) + 0.5 and t[-1] - t_held > 3.0
    held = t > t_held + 0.5  # the rotor's swing on the held vector settled
    assert np.all(np.abs(r["omega_m"][held]) < 3.0) and np.ptp(r["x_vehicle"][held]) < 0.01


@pytest.mark.parametrize("changes, message", [
    ({"stall_time": 1.0}, r"stall_time must be > if_deadline or 0 \(got 1.0 <= 1.0 s\)"),
    ({"realign_max": 1.5}, r"realign_max must be a whole number \(got 1.5\)"),
    ({"if_deadline": -1.0}, r"if_deadline must be finite and >= 0 \(got -1.0\)"),
])
def test_the_deadline_parameters_are_checked(changes, message):
    with pytest.raises(ParameterError, match=message):
        StartupParams(**changes).validate()
