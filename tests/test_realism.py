"""Sensor and inverter realism of the plant (all off by default)."""

import math

import numpy as np
import pytest

from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.params import ControllerParams, ParameterError, PlantParams, VehicleParams
from pmsm_ev.plant import Plant, gaussian_pair

LOCKED = VehicleParams(m_v=1e15)  # rotor held: the true currents are known exactly


def measure_errors(plant_params, n=4000, v=(2.0, 1.0)):
    """Measured minus true phase currents (a, b) over n steps."""
    p = Plant(vehicle=LOCKED, plant=plant_params)
    err_a, err_b = [], []
    for _ in range(n):
        p.step(*v, 0.0, 1e-4)
        true_a, true_b = p.i_alpha_true, p.i_beta_true
        # phase errors from the alpha-beta errors (two-sensor inverse Clarke)
        da, db = p.i_alpha - true_a, p.i_beta - true_b
        err_a.append(da)
        err_b.append(-0.5 * da + 0.5 * math.sqrt(3) * db)
    return np.array(err_a), np.array(err_b), p


@pytest.mark.parametrize("sigma", [0.1, 1.0])
def test_noise_statistics_match_sigma(sigma):
    ea, eb, _ = measure_errors(PlantParams(sensor_noise=sigma, sensor_seed=7), n=20000)
    for e in (ea, eb):
        assert abs(np.std(e) / sigma - 1.0) < 0.05
        assert abs(np.mean(e)) < 4 * sigma / math.sqrt(len(e))
    assert abs(np.corrcoef(ea, eb)[0, 1]) < 0.05  # the two phases are independent


def test_same_seed_same_noise_other_seed_differs():
    a1, _, _ = measure_errors(PlantParams(sensor_noise=0.5, sensor_seed=3), n=500)
    a2, _, _ = measure_errors(PlantParams(sensor_noise=0.5, sensor_seed=3), n=500)
    a3, _, _ = measure_errors(PlantParams(sensor_noise=0.5, sensor_seed=4), n=500)
    assert np.array_equal(a1, a2)
    assert not np.allclose(a1, a3)


def test_gaussian_pair_is_standard_normal():
    x = np.array([gaussian_pair(11, n) for n in range(20000)]).ravel()
    assert abs(np.mean(x)) < 0.03 and abs(np.std(x) - 1.0) < 0.02


def test_offset_and_gain_error():
    ea, eb, p = measure_errors(PlantParams(sensor_offset_a=0.3, sensor_gain_b=1.02), n=3000)
    i_b_true = -0.5 * p.i_alpha_true + 0.5 * math.sqrt(3) * p.i_beta_true
    assert ea[-1] == pytest.approx(0.3, abs=1e-9)
    assert eb[-1] == pytest.approx(0.02 * i_b_true, rel=1e-6)


def test_quantisation_steps_are_the_lsb():
    bits, rng = 12, 500.0
    lsb = 2 * rng / 2**bits
    p = Plant(vehicle=LOCKED, plant=PlantParams(adc_bits=bits, adc_range=rng))
    for _ in range(3000):
        p.step(3.0, -1.0, 0.0, 1e-4)
        a = p.i_alpha
        b = -0.5 * p.i_alpha + 0.5 * math.sqrt(3) * p.i_beta
        for x in (a, b):
            assert abs(x / lsb - round(x / lsb)) < 1e-6  # a whole number of LSBs
        assert abs(a - p.i_alpha_true) <= 0.5 * lsb + 1e-9


def test_inverter_limits_the_voltage_vector():
    v_dc = 100.0
    p = Plant(plant=PlantParams(v_dc=v_dc, omega_m0=100.0))
    for k in range(200):
        th = 0.3 * k
        p.step(300.0 * math.cos(th), 300.0 * math.sin(th), 0.0, 1e-4)
        assert math.hypot(p.v_alpha_applied, p.v_beta_applied) <= v_dc / math.sqrt(3) * (1 + 1e-12)


def test_closed_loop_antiwindup_under_inverter_limit():
    """A DC link too small for 200 rad/s: voltage stays limited, integrators stay bounded."""
    v_dc = 80.0
    plant = Plant(plant=PlantParams(v_dc=v_dc, omega_m0=150.0, i_q0=20.0))
    ctrl = ControlUnit("sensored", controller=ControllerParams(u_max=v_dc / math.sqrt(3)))
    for _ in range(20000):  # 2 s asking for 200 rad/s
        ctrl.step(plant.i_alpha, plant.i_beta, 200.0, plant.theta_e, plant.omega_m)
        plant.step(ctrl.v_alpha, ctrl.v_beta, 0.0, 1e-4)
        assert math.hypot(plant.v_alpha_applied, plant.v_beta_applied) <= v_dc / math.sqrt(3) * (1 + 1e-12)
    assert ctrl.current.saturated
    assert abs(ctrl.current.int_q) < v_dc and abs(ctrl.current.int_d) < v_dc
    assert abs(ctrl.speed.integral) <= ControllerParams().i_q_max + 1.0


def test_one_step_actuation_delay():
    p0 = Plant(plant=PlantParams(omega_m0=100.0))
    p1 = Plant(plant=PlantParams(omega_m0=100.0, inverter_delay=1))
    p1.step(10.0, 5.0, 0.0, 1e-4)  # received now, applied next step
    assert (p1.v_alpha_applied, p1.v_beta_applied) == (0.0, 0.0)
    p0.step(0.0, 0.0, 0.0, 1e-4)
    p0.step(10.0, 5.0, 0.0, 1e-4)
    p1.step(0.0, 0.0, 0.0, 1e-4)
    assert (p1.v_alpha_applied, p1.v_beta_applied) == (10.0, 5.0)
    assert p1.get_state()[:4] == p0.get_state()[:4]


def test_state_restore_continues_the_noise_sequence():
    p = Plant(plant=PlantParams(sensor_noise=1.0, omega_m0=50.0))
    for _ in range(10):
        p.step(1.0, 1.0, 0.0, 1e-4)
    saved = p.get_state()
    p.step(1.0, 1.0, 0.0, 1e-4)
    expected = (p.i_alpha, p.i_beta)
    p.set_state(saved)
    p.step(1.0, 1.0, 0.0, 1e-4)
    assert (p.i_alpha, p.i_beta) == expected


@pytest.mark.parametrize("bad", [dict(sensor_noise=-1.0), dict(adc_bits=-1), dict(adc_range=0.0),
                                 dict(v_dc=-5.0), dict(inverter_delay=2), dict(sensor_gain_a=0.0)])
def test_rejects_nonphysical_realism(bad):
    with pytest.raises(ParameterError):
        Plant(plant=PlantParams(**bad))
