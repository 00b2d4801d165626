"""The speed loop's feedforward (``ControllerParams.speed_feedforward``, ``kernels.speed_feedforward``,
docs/cycles.md): its torque is J_eq x the reference's slope plus the level road's load at the reference
speed; in a closed loop (Plant + sensored ControlUnit, reference 'fw') it takes the soft speed PI's lag
out of a drive cycle's ramps and its roll-back out of the end of a stop; bad settings are one line."""

from __future__ import annotations

import math

import pytest

from pmsm_ev import kernels as k
from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.params import (
    ControllerParams,
    DriveParams,
    MotorParams,
    ParameterError,
    PlantParams,
    VehicleParams,
    equivalent_inertia,
    road_load_coefficients,
)
from pmsm_ev.plant import Plant
from pmsm_ev.vehicle import load_torque

FF = ControllerParams(reference="fw", v_dc=360.0, P_regen_max=50e3, speed_feedforward="inertia+road")


def test_road_load_coefficients_are_eqs_3_4_at_the_shaft():
    """T0 + T1 w + T2 w^2 is the plant's own level-road load (eqs 2-4 through eq 9) at any forward speed,
    the head wind's (v + v_a)^2 included: 17.19 N m at the top speed."""
    v = VehicleParams()
    t0, t1, t2 = road_load_coefficients(v)
    for w in (10.0, 200.0, 800.0, 1550.0):  # (above 10 rad/s the plant's smooth sign of rolling is 1)
        assert t0 + t1 * w + t2 * w * w == pytest.approx(load_torque(w, 0.0, v), rel=1e-6)
    assert (t0, t1, t2) == (FF.ff_T0, FF.ff_T1, FF.ff_T2)
    assert t0 + t1 * 1550.0 + t2 * 1550.0**2 == pytest.approx(17.19, abs=0.01)


def test_the_feedforward_is_the_references_acceleration_and_road_load():
    """Kernel figures: a reference rising at 50 rad/s^2 gives J_eq x 50 plus the road load at the reference;
    none in the first period (no slope yet); at a stand (reference 0) no road load; a falling one brakes."""
    dt = 1e-4
    unit = ControlUnit("sensored", controller=FF, dt=dt)
    s = unit._s
    j_eq = equivalent_inertia(MotorParams(), VehicleParams())
    t0, t1, t2 = road_load_coefficients(VehicleParams())
    ref = 100.0
    unit.step(0.0, 0.0, ref, 0.0, ref)
    assert s[k.S_T_FF] == pytest.approx(t0 + t1 * ref + t2 * ref * ref, rel=1e-12)  # first period: no slope
    for _ in range(10):
        ref += 50.0 * dt
        unit.step(0.0, 0.0, ref, 0.0, ref)
    assert s[k.S_T_FF] == pytest.approx(j_eq * 50.0 + t0 + t1 * ref + t2 * ref * ref, rel=1e-9)
    unit.step(0.0, 0.0, 0.0, 0.0, 0.0)  # a jump to 0: a braking spike, clamped by the envelope downstream
    assert s[k.S_T_FF] == pytest.approx(j_eq * -ref / dt, rel=1e-9)
    unit.step(0.0, 0.0, 0.0, 0.0, 0.0)
    assert s[k.S_T_FF] == 0.0  # standing: no slope, no road load
    inertia = ControlUnit("sensored", controller=ControllerParams(reference="fw", v_dc=360.0,
                                                                  speed_feedforward="inertia"), dt=dt)
    inertia.step(0.0, 0.0, 300.0, 0.0, 300.0)
    inertia.step(0.0, 0.0, 300.0 + 20.0 * dt, 0.0, 300.0)
    assert inertia._s[k.S_T_FF] == pytest.approx(j_eq * 20.0, rel=1e-6)
    off = ControlUnit("sensored", controller=ControllerParams(reference="fw", v_dc=360.0), dt=dt)
    assert off._c[k.C_FF] == 0.0 and off._c[k.C_J_FF] == 0.0


def _follow(controller: ControllerParams, profile, t_end: float, dt: float = 1e-4):
    """Plant + sensored ControlUnit on the reference profile(t): the largest lag |w_ref - w| [rad/s] after
    the first second, and the lowest speed after the reference reached zero [rad/s]."""
    plant = Plant(plant=PlantParams(v_dc=360.0))
    unit = ControlUnit("sensored", controller=controller, dt=dt)
    worst, lowest = 0.0, math.inf
    for n in range(int(round(t_end / dt))):
        t = n * dt
        ref = profile(t)
        out = unit.step(plant.i_alpha, plant.i_beta, ref, plant.theta_e, plant.omega_m)
        plant.step(out[0], out[1], 0.0, dt, unit.T_brake)
        if t > 1.0:
            worst = max(worst, abs(ref - plant.omega_m))
        if ref == 0.0 and t > 2.0:
            lowest = min(lowest, plant.omega_m)
    return worst, lowest


def _cycle_like(t: float) -> float:
    """A drive cycle's shape at the motor: 0.5 s standing, up at 60 rad/s^2 (1.4 m/s^2 at the wheels) to 600
    rad/s (51 km/h) at 10.5 s, held, from 17 s down at 50 rad/s^2 to a stop at 29 s."""
    if t < 0.5:
        return 0.0
    if t < 10.5:
        return 60.0 * (t - 0.5)
    if t < 17.0:
        return 600.0
    return max(600.0 - 50.0 * (t - 17.0), 0.0)


def test_the_feedforward_takes_the_lag_and_the_roll_back_out():
    """The soft speed PI (omega_n 2 rad/s) alone lags a 60 rad/s^2 ramp by 12 rad/s (1 km/h: its double
    integrator follows a ramp without a steady error, but only after a transient of ~1 s at each change of
    slope) and, its integral carrying the braking torque, rolls the car back after the stop; with the
    feedforward the lag is a small fraction of that and the car stands. Printed: both."""
    plain = ControllerParams(reference="fw", v_dc=360.0, P_regen_max=50e3)
    lag_pi, low_pi = _follow(plain, _cycle_like, 32.0)
    lag_ff, low_ff = _follow(FF, _cycle_like, 32.0)
    kmh = VehicleParams().r_w / VehicleParams().n_g * 3.6  # km/h per rad/s at the motor
    print(f"\nlargest lag: PI alone {lag_pi:.2f} rad/s ({lag_pi * kmh:.2f} km/h), with the feedforward "
          f"{lag_ff:.2f} rad/s ({lag_ff * kmh:.2f} km/h); lowest speed after the stop: {low_pi:.2f} against "
          f"{low_ff:.2f} rad/s")
    assert lag_pi * kmh > 0.8
    assert lag_ff < lag_pi / 20.0 and lag_ff < 0.5
    assert low_pi < -3.0 and low_ff > -0.1


@pytest.mark.parametrize(("change", "message"), [
    ({"speed_feedforward": "full"}, "speed_feedforward must be one of"),
    ({"reference": "paper", "speed_feedforward": "inertia"}, "needs reference 'mtpa' or 'fw'"),
    ({"ff_T0": -1.0}, "ff_T0 must be >= 0"),
    ({"ff_T2": math.nan}, "ff_T2 must be >= 0"),
])
def test_bad_feedforward_settings_get_one_line(change, message):
    params = dict(reference="fw", v_dc=360.0, speed_feedforward="inertia+road") | change
    with pytest.raises(ParameterError, match=message) as err:
        DriveParams(controller=ControllerParams(**params)).validate()
    assert "\n" not in str(err.value)
