"""Sensor and inverter realism of the plant (all off by default)."""

import math

import numpy as np
import pytest

from pmsm_cosim.app.reference import run_reference
from pmsm_cosim.engine.recording import read_results
from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.params import (
    ControllerParams,
    DriveParams,
    EkfParams,
    MotorParams,
    ParameterError,
    PlantParams,
    ScenarioParams,
    VehicleParams,
)
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


def test_the_compiled_noise_is_the_plain_python_noise_bit_for_bit():
    """The kernel gaussian_pair compiled (uint64 arithmetic) and as plain Python (masked integers):
    the same pair for seeds and sample numbers over the whole 64-bit range (a uint64 times an integer
    literal is an int64 in numba, whose shifts keep the sign: that would change every sample)."""
    from pmsm_ev import accel
    from pmsm_ev.kernels import plant as plain

    if not accel.compiled():
        pytest.skip(f"the kernels are not compiled here: {accel.describe()}")
    compiled = accel.direct(accel.kernels().gaussian_pair)
    rng = np.random.default_rng(5)
    seeds = [0, 1, 2**63 - 1, 2**63, 2**64 - 1] + [int(x) for x in rng.integers(0, 2**63, 40)]
    samples = [0, 1, 17, 2**31, 2**62 + 3, 2**63 - 1, 2**64 - 1] + [int(x) for x in rng.integers(0, 2**62, 40)]
    for seed in seeds:
        for n in samples:
            assert compiled(seed, n) == plain.gaussian_pair(seed, n), (seed, n)
    assert gaussian_pair(-1, 5) == plain.gaussian_pair(2**64 - 1, 5)  # any integer seed: its low 64 bits


def test_the_compiled_measurement_is_the_plain_python_one_bit_for_bit():
    """The kernel measured_currents (sensors, noise, the ADC, Clarke) compiled and as plain Python: the same
    pair, ADC ties at half an LSB included (numba's round, like Python's, rounds half to even), clipping at
    the range, with and without noise."""
    from pmsm_ev import accel
    from pmsm_ev.kernels import plant as plain

    if not accel.compiled():
        pytest.skip(f"the kernels are not compiled here: {accel.describe()}")
    compiled = accel.direct(accel.kernels().measured_currents)
    rng = np.random.default_rng(9)
    lsb = 2 * 400.0 / 2**12
    currents = [(0.0, 0.0), (0.5 * lsb, 0.0), (1.5 * lsb, 2.5 * lsb), (-2.5 * lsb, 0.5 * lsb), (900.0, -900.0)]
    currents += [tuple(float(x) for x in rng.uniform(-450, 450, 2)) for _ in range(300)]
    options = [(1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 400.0), (1.01, 0.3, 0.98, -0.2, 1.0, 0.0, 400.0),
               (1.0, 0.0, 1.0, 0.0, 0.0, lsb, 400.0), (1.0, 0.1, 1.0, 0.0, 2.0, lsb, 400.0)]
    for k, (i_alpha, i_beta) in enumerate(currents):
        for args in options:
            assert compiled(i_alpha, i_beta, 7, k, *args) == plain.measured_currents(i_alpha, i_beta, 7, k, *args)


def test_the_step_with_its_measurement_is_the_two_kernels_one_after_the_other():
    """plant_step_measured (the plant's per-step path with sensors) is plant_step then measured_currents of
    its clean currents, bit for bit: compiled against the two compiled kernels and against the plain Python
    ones, over a drive whose speed needs several RK4 sub-steps, the energies included; and a Plant stepped
    with sensors gives the sensors' reading of its own clean currents."""
    from pmsm_ev import accel
    from pmsm_ev.kernels import plant as plain

    k = accel.kernels()
    plant = Plant(plant=PlantParams(sensor_noise=1.0, sensor_offset_a=0.2, sensor_gain_b=1.01, adc_bits=12))
    pp = plant._pp
    sensor = plant._sensor_args
    assert sensor[5] > 0  # the ADC's step
    fused, step, measured = (accel.direct(k.plant_step_measured), accel.direct(k.plant_step),
                             accel.direct(k.measured_currents))
    rng = np.random.default_rng(3)
    for n in range(200):
        x = tuple(float(v) for v in rng.uniform([-300, -300, -1600, -3.2], [300, 300, 1600, 3.2]))
        u = tuple(float(v) for v in rng.uniform(-250, 250, 2))
        e1, e2, e3 = (plant.energy.copy(), plant.energy.copy(), list(plant.energy)) if accel.compiled() else (
            list(plant.energy), list(plant.energy), list(plant.energy))
        out = fused(*x, *u, 0.02, 1e-4, pp, e1, 11, n, *sensor)
        two = step(*x, *u, 0.02, 1e-4, pp, e2)
        assert out == two + measured(two[4], two[5], 11, n, *sensor)
        plain_pp = list(pp)
        two_plain = plain.plant_step(*x, *u, 0.02, 1e-4, plain_pp, e3)
        assert out == two_plain + plain.measured_currents(two_plain[4], two_plain[5], 11, n, *sensor)
        assert list(e1) == list(e2) == e3
    for _ in range(5):
        out = plant.step(120.0, -80.0, 0.0, 1e-4)
        assert (out[4], out[5]) == plant._measure(plant.i_alpha_true, plant.i_beta_true, plant.samples - 1)
        assert out[4] != plant.i_alpha_true


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
    dq = ("i_d", "i_q", "omega_m", "theta_e")
    assert [p1.get_state()[k] for k in dq] == [p0.get_state()[k] for k in dq]


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


# -- unknown initial angle: the stationary-frame EKF5 at 200 rad/s ----------------------
#
# A flying start: the plant turns at 200 rad/s (omega_e dt = 4 * 200 * 1e-4 = 0.08 rad per
# period) with its rotor at THETA0, the observer knows the speed but guesses the angle
# wrong. A row of results.csv at t_k holds the control unit's outputs computed at t_{k-1}
# (the results contract), so theta_hat there is the estimate of theta(t_{k-1}); it is
# propagated one period, + N omega_hat dt, to compare it with theta_e(t_k). Without that,
# every observer shows a -omega_e dt = -0.08 rad "error" that is only the row's timing.

W0 = 200.0  # [rad/s]
THETA0 = 1.0  # true electrical angle at t = 0 [rad]
N_POLE_PAIRS = MotorParams().N
#: bound on the steady angle error at 200 rad/s [rad]. The EKF5ab's model is the forward-
#: Euler step of eqs 10-13 with the held stationary-frame voltage turned into its frame at
#: mid-period; against the sampled drive its residual is of order (omega_e dt)^2 = 0.0064
#: times a small factor (measured -1.5e-4 rad, shrinking 4x per halved dt). 5e-4 rad is
#: 1/160 of omega_e dt: any one-period timing mismatch (0.08 rad) fails it by far.
STEADY_BOUND = 5.0e-4
#: bound after recovery with sigma = 0.1 A current noise [rad] (measured 6.3e-4 rad)
NOISY_BOUND = 2.0e-3


def flying_start(out_dir, angle_error, angle_source="estimated", stop_time=1.2, dt=1e-4, **plant):
    """Reference run of the EKF5ab from a 200 rad/s flying start; (results, angle error)."""
    params = DriveParams(plant=PlantParams(omega_m0=W0, theta_e0=THETA0, **plant),
                         ekf=EkfParams(x0_omega=W0, x0_theta=THETA0 + angle_error),
                         scenario=ScenarioParams(startup_time=0.0), dt=dt)  # omega_ref = 200 from t = 0
    run_reference(out_dir, scenario=1, stop_time=stop_time, observer="ekf5ab", angle_source=angle_source,
                  params=params, output_interval=1e-3)  # scenario 1 is level for 50 s
    r = read_results(out_dir)
    err = r["theta_hat"] + N_POLE_PAIRS * r["omega_hat"] * dt - r["theta_e"]
    return r, (err + math.pi) % (2 * math.pi) - math.pi


@pytest.mark.parametrize("angle_source", ["estimated", "measured"])
@pytest.mark.parametrize("angle_error", [0.5, -0.5])
def test_ekf5ab_recovers_initial_angle_error_at_200_rad_s(tmp_path, angle_error, angle_source):
    """+-0.5 rad wrong at a 200 rad/s flying start: below STEADY_BOUND from 0.1 s to the end
    (1.2 s), i.e. recovered well within 1 s and staying there; the drive keeps its speed."""
    r, err = flying_start(tmp_path, angle_error, angle_source)
    t = r["time"]
    assert r["theta_hat"][0] - r["theta_e"][0] == pytest.approx(angle_error)  # the guess at t = 0
    assert np.max(np.abs(err[t >= 0.1])) < STEADY_BOUND
    assert np.max(np.abs(r["omega_m"] - W0)) < 2.0  # no loss of control during the recovery
    assert abs(r["omega_hat"][-1] - r["omega_m"][-1]) < 0.1


def test_ekf5ab_steady_angle_error_is_a_dt_squared_residual(tmp_path):
    """Steady angle error at 200 rad/s, no initial error: within STEADY_BOUND, and it shrinks
    like dt^2 (ratio > 3 when dt halves; a timing mismatch would be O(dt), ratio 2). The
    recorded theta_hat - theta_e without the one-period propagation is -omega_e dt."""
    means = []
    for dt in (1e-4, 5e-5):
        r, err = flying_start(tmp_path / str(dt), 0.0, stop_time=0.6, dt=dt)
        late = r["time"] >= 0.3
        assert np.max(np.abs(err[late])) < STEADY_BOUND
        means.append(np.mean(err[late]))
        recorded = (r["theta_hat"] - r["theta_e"] + math.pi) % (2 * math.pi) - math.pi
        omega_e_dt = N_POLE_PAIRS * W0 * dt
        assert np.mean(recorded[late]) == pytest.approx(-omega_e_dt, abs=STEADY_BOUND)
    assert means[0] / means[1] > 3.0


@pytest.mark.parametrize("angle_error", [0.5, -0.5])
def test_ekf5ab_recovers_initial_angle_under_current_noise(tmp_path, angle_error):
    """The same, sensorless, with sigma = 0.1 A white noise on each phase current."""
    r, err = flying_start(tmp_path, angle_error, sensor_noise=0.1, sensor_seed=5)
    t = r["time"]
    assert np.max(np.abs(err[t >= 0.1])) < NOISY_BOUND
    assert abs(np.mean(err[t >= 0.5])) < STEADY_BOUND  # the noise adds no bias
    assert np.max(np.abs(r["omega_m"] - W0)) < 2.0


def test_ekf5ab_with_compensated_actuation_delay(tmp_path):
    """A one-period inverter delay the controller compensates (delay_compensation = 1,
    angle_advance = 1.5): the observer is given the voltage the inverter applied, so the
    recovery and the steady error are those without delay. Uncompensated, the observer
    steps its model with the wrong period's voltage: a one-period error, ~omega_e dt."""
    comp = DriveParams(plant=PlantParams(omega_m0=W0, theta_e0=THETA0, inverter_delay=1),
                       controller=ControllerParams(delay_compensation=1, angle_advance=1.5),
                       ekf=EkfParams(x0_omega=W0, x0_theta=THETA0 + 0.5), scenario=ScenarioParams(startup_time=0.0))
    for sub, params in (("comp", comp), ("uncomp", DriveParams(
            plant=comp.plant, ekf=comp.ekf, scenario=comp.scenario))):
        run_reference(tmp_path / sub, scenario=1, stop_time=0.6, observer="ekf5ab", angle_source="estimated",
                      params=params, output_interval=1e-3)
    errors = {}
    for sub in ("comp", "uncomp"):
        r = read_results(tmp_path / sub)
        e = r["theta_hat"] + N_POLE_PAIRS * r["omega_hat"] * 1e-4 - r["theta_e"]
        errors[sub] = ((e + math.pi) % (2 * math.pi) - math.pi)[r["time"] >= 0.1]
    assert np.max(np.abs(errors["comp"])) < STEADY_BOUND
    assert np.mean(errors["uncomp"]) == pytest.approx(N_POLE_PAIRS * W0 * 1e-4, rel=0.1)
