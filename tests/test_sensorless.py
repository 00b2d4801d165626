"""The truly sensorless unit from standstill (observer "sensorless", FocSensorless.fmu):
alignment, I-f start, handover to the stationary-frame EKF5 and back, stop and restart on a
slope; never reading the rotor angle or speed.

Short runs of the monolithic loop (Plant + ControlUnit, compiled kernels: ~0.5 s per 20 s
of drive) and one co-simulation against it.
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from fmpy_process import simulate_fmu
from orchestrator_support import project_fmus
from pmsm_cosim.app.drive import load_system
from pmsm_cosim.app.reference import run_reference
from pmsm_cosim.engine.master import Master
from pmsm_cosim.engine.recording import read_results
from pmsm_cosim.engine.system import read_toml
from pmsm_ev import kernels as _k
from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.params import (
    SENSORLESS_EKF,
    EkfParams,
    MotorParams,
    ParameterError,
    PlantParams,
    StartupParams,
    VehicleParams,
    equivalent_inertia,
)
from pmsm_ev.plant import Plant
from pmsm_ev.results import ALL_COLUMNS, SENSORLESS_COLUMNS
from pmsm_ev.scenarios import (
    HILL_START_DEG,
    HILL_START_OMEGA_REF,
    HILL_START_STOP_TIME,
    SENSORLESS_START_DELAY,
    Profile,
    hill_start_route,
    speed_reference,
)

DT = 1e-4
ALIGN, IF, EKF = _k.MODE_ALIGN, _k.MODE_IF, _k.MODE_EKF


def profile(pairs, interpolation, deg=False) -> Profile:
    return Profile(tuple(float(t) for t, _ in pairs),
                   tuple(math.radians(v) if deg else float(v) for _, v in pairs), interpolation)


def drive(theta0=0.0, stop=20.0, delta_deg=((0, 0), (15, 5)), omega_ref=None, feed=None, plant=None,
          unit=None) -> dict[str, np.ndarray]:
    """Plant and sensorless unit in the reference's order, one row per control period:
    the row at t_k holds the plant at t_k and the unit's outputs computed at t_{k-1}.
    ``feed(plant)`` gives the (theta_meas, omega_meas) handed to the unit (default: the truth)."""
    plant = plant or Plant(plant=PlantParams(theta_e0=theta0))
    unit = unit or ControlUnit("sensorless", dt=DT)
    delta = profile(delta_deg, "previous", deg=True)
    w_ref = omega_ref or speed_reference(delay=SENSORLESS_START_DELAY)
    n = round(stop / DT)
    cols = {k: np.empty(n + 1) for k in ("t", "omega_ref", "omega_m", "omega_hat", "theta_e", "theta_hat", "T_e",
                                         "x", "mode", "v_alpha", "v_beta", "T_L_hat", "T_L_mech")}
    for k in range(n + 1):
        t = k * DT
        w = w_ref(t)
        for key, value in (("t", t), ("omega_ref", w), ("omega_m", plant.omega_m),
                           ("omega_hat", unit.observer.omega_hat),
                           ("theta_e", plant.theta_e), ("theta_hat", unit.observer.theta_hat), ("T_e", plant.T_e),
                           ("x", plant.x_vehicle), ("mode", unit.mode), ("v_alpha", unit.v_alpha),
                           ("v_beta", unit.v_beta), ("T_L_hat", unit.observer.T_L_hat), ("T_L_mech", plant.T_L_mech)):
            cols[key][k] = value
        if k == n:
            break
        meas = feed(plant) if feed else (plant.theta_e, plant.omega_m)
        out = unit.step(plant.i_alpha, plant.i_beta, w, *meas)
        plant.step(out[0], out[1], delta(t), DT)
    return cols


def wrap(x):
    return (x + np.pi) % (2 * np.pi) - np.pi


def handovers(r) -> list[tuple[int, float, float]]:
    """(row, mode before, mode after) of each mode change."""
    m = r["mode"]
    return [(int(i) + 1, float(m[i]), float(m[i + 1])) for i in np.nonzero(np.diff(m))[0]]


def roll_back(x) -> float:
    """Largest backward travel [m]: the drop of x below its running maximum."""
    return float(np.max(np.maximum.accumulate(x) - x)) if len(x) else 0.0


# -- never reads the angle or the speed --------------------------------------------------------------
def test_nan_angle_and_speed_inputs_change_nothing():
    truth = drive(0.7, stop=6.0)
    blind = drive(0.7, stop=6.0, feed=lambda p: (math.nan, math.nan))
    for key in truth:
        assert np.array_equal(truth[key], blind[key]), key
    assert (truth["mode"] == EKF).any()  # the 6 s cover the handover


def test_the_fmu_never_reads_theta_meas_and_omega_meas():
    fmu = str(project_fmus()["FocSensorless"])
    names = ("i_alpha", "i_beta", "omega_ref", "theta_meas", "omega_meas")

    def run(theta, omega):
        signals = np.array([(0.0, 20.0, -5.0, 50.0, theta, omega), (1.0, 25.0, 3.0, 50.0, theta, omega)],
                           dtype=[("time", float)] + [(n, float) for n in names])
        return simulate_fmu(fmu, stop_time=0.05, step_size=DT, output_interval=DT, input=signals)

    a, b = run(0.4, 10.0), run(math.nan, math.nan)
    for name in a.dtype.names:
        assert np.array_equal(a[name], b[name]), name
    assert np.max(np.abs(a["v_alpha"])) > 0.1  # it acts


# -- start-up from standstill at an unknown angle ----------------------------------------------------
@pytest.mark.parametrize("theta0", [-3.0, -1.5, 0.0, 1.5, 3.0])
def test_start_from_standstill_reaches_the_reference_and_holds_the_angle(theta0):
    """Shortened scenario 1: the 2.5 s start delay, the ramp to 200 rad/s, a 5 deg step at 15 s."""
    r = drive(theta0, stop=20.0)
    t, w, w_ref = r["t"], r["omega_m"], r["omega_ref"]
    changes = handovers(r)
    assert [(a, b) for _, a, b in changes] == [(ALIGN, IF), (IF, EKF)], changes
    t_up = t[changes[1][0]]
    assert 3.5 < t_up < 6.0
    assert abs(w[-1] - w_ref[-1]) < 1.0  # back at the reference after the 5 deg step
    assert np.max(np.abs(w[t >= 12.5] - w_ref[t >= 12.5])) < 10.0
    assert roll_back(r["x"]) < 0.05  # m, level road
    after = t >= t_up + 0.5
    err = wrap(r["theta_hat"] - r["theta_e"])
    assert np.max(np.abs(err[after])) < 0.1  # as recorded: includes -omega_e dt (0.08 rad at 200 rad/s)
    # without the row-timing term (the row's estimate is of t_{k-1}) the error is far smaller
    exact = wrap(err + MotorParams().N * w * DT)
    assert np.max(np.abs(exact[after])) < 0.01


def test_a_single_alignment_step_would_have_no_torque_at_pi():
    """Why the alignment starts on +90 deg: at theta(0) = pi a vector on 0 deg pushes straight
    on the magnet's axis (eq 12 gives zero torque), while the unit still aligns."""
    m = MotorParams()
    i_d, i_q = -60.0, 0.0  # 60 A on 0 deg seen from a rotor at pi
    assert m.N * (m.psi * i_q + (m.L_d - m.L_q) * i_d * i_q) == 0.0
    r = drive(math.pi - 1e-6, stop=4.0, delta_deg=((0, 0),))
    aligned = r["t"] >= StartupParams().align_time - 0.01
    assert np.max(np.abs(wrap(r["theta_e"][aligned][:50]))) < 0.05


# -- handover up and down, stop and restart on a slope ------------------------------------------------
HILL = dict(stop=22.0, delta_deg=((0, 0), (8, 22)),
            omega_ref=profile(((0, 0), (2.5, 0), (7.5, 100), (8, 100), (14, 0), (17, 0), (20, 60)), "linear"))


@pytest.fixture(scope="module", params=[0.0, 1.0], ids=["exact", "noise1A"])
def hill(request):
    plant = Plant(plant=PlantParams(theta_e0=1.0, sensor_noise=request.param))
    return drive(plant=plant, **HILL)


def test_stop_hold_and_restart_on_a_22_deg_slope(hill):
    r = hill
    t = r["t"]
    changes = handovers(r)
    assert [(a, b) for _, a, b in changes] == [(ALIGN, IF), (IF, EKF), (EKF, IF), (IF, EKF)], changes
    t_down, t_up = t[changes[2][0]], t[changes[3][0]]
    assert 12.0 < t_down < 14.0 and 17.0 < t_up < 20.0
    stand = (t >= 15.0) & (t <= 17.0)
    assert np.max(np.abs(r["omega_m"][stand])) < 0.1  # holds on the slope
    assert roll_back(r["x"][t >= 12.0]) < 0.05  # stop, stand and restart: < 5 cm back
    assert r["x"][-1] > r["x"][t >= 17.0][0] + 1.0  # and drives on uphill
    assert abs(r["omega_m"][-1] - 60.0) < 2.0


def test_handovers_change_torque_and_speed_estimate_smoothly(hill):
    """At each handover, up and down: T_e changes by < 5 N m between consecutive control
    periods, omega_hat by < 1 rad/s (50 periods on each side)."""
    r = hill
    for row, before, after in handovers(r):
        if before == ALIGN:
            continue  # the EKF restarts at the aligned angle: not a handover
        w = slice(row - 50, row + 50)
        assert np.max(np.abs(np.diff(r["T_e"][w]))) < 5.0, (before, after)
        assert np.max(np.abs(np.diff(r["omega_hat"][w]))) < 1.0, (before, after)
        # with exact sensors the voltage the inverter holds does not jump either (the PIs are
        # seated on it): its second difference, ~0 for a vector turning smoothly, stays small;
        # with noise the current PIs pass several volts of noise anyway
        if np.std(np.diff(r["v_alpha"][row - 1050:row - 950])) < 0.5:
            d2 = np.hypot(np.diff(r["v_alpha"][w], 2), np.diff(r["v_beta"][w], 2))
            assert np.max(d2) < 0.5, (before, after)


def test_while_the_car_stands_the_angle_is_not_observable(hill):
    """Standing in I-f, there is no back-EMF: with exact sensors the EKF (on J_eq) keeps the
    angle and the slope's load (eq 29); with 1 A noise both drift (the I-f current never
    drops with them), and the restart finds the angle again."""
    t, noisy = hill["t"], hill is not None and np.std(np.diff(hill["T_L_hat"][(hill["t"] > 15)])) > 1e-3
    stand = (t >= 15.0) & (t <= 17.0)
    err = np.abs(wrap(hill["theta_hat"] - hill["theta_e"]))
    assert np.min(hill["T_L_mech"][stand]) > 75.0
    if not noisy:
        assert np.max(np.abs(hill["T_L_hat"][stand] - hill["T_L_mech"][stand])) < 3.0
        assert np.max(err[stand]) < 0.05
    assert np.max(err[t >= 19.0]) < 0.05  # found again after the restart


# -- parameters ------------------------------------------------------------------------------------
def test_the_sensorless_ekf_models_the_whole_drive_inertia():
    j_eq = equivalent_inertia(MotorParams(), VehicleParams())
    assert SENSORLESS_EKF.J_model == j_eq and abs(j_eq - 0.526) < 1e-3
    assert ControlUnit("sensorless").observer.J == j_eq
    assert ControlUnit("ekf5ab").observer.J == MotorParams().J_m  # the paper's J_m elsewhere (eq 22)
    paper = ControlUnit("sensorless", ekf=EkfParams())  # J_model 0: J_m, kept available
    assert paper.observer.J == MotorParams().J_m
    assert paper.observer._c[_k.C_C_TL] == -DT / MotorParams().J_m


@pytest.mark.parametrize("changes,message", [
    ({"omega_down": 40.0}, "omega_down must be < omega_up"),
    ({"i_if": 0.0}, "i_if must be > 0"),
    ({"if_margin": 0.5}, "if_margin must be >= 1"),
    ({"t_sweep": -1.0}, "t_sweep must be finite and >= 0"),
    ({"if_load_angle": 1.6}, r"if_load_angle must be in \(0, pi/2\)"),
    ({"guard_angle": 0.5}, r"guard_angle must be in \[if_load_angle, pi\)"),
    ({"i_rate_load": 0.0}, "i_rate_load must be > 0"),
    ({"fault_time": 0.5}, "fault_time must be > recover_time"),
])
def test_startup_parameters_are_checked(changes, message):
    with pytest.raises(ParameterError, match=message):
        ControlUnit("sensorless", startup=StartupParams(**changes))


def test_x_vehicle_integrates_the_vehicle_speed():
    """Eqs 1, 6: at a constant speed (a vehicle too heavy to change it) x = r_w omega t / n_g."""
    v = VehicleParams(m_v=1e15, c_r=0.0, rho_a=0.0)  # no road load: the speed stays
    plant = Plant(vehicle=v, plant=PlantParams(omega_m0=100.0))
    for _ in range(10000):
        plant.step(0.0, 0.0, 0.0, DT)
    assert plant.x_vehicle == pytest.approx(v.r_w / v.n_g * 100.0 * 1.0, rel=1e-9)


# -- the shipped scenarios ---------------------------------------------------------------------------
def _system(name: str) -> dict:
    return read_toml(Path(str(resources.files("pmsm_cosim.app") / "scenarios" / f"{name}.toml")), "system file")


def test_shipped_sensorless_scenarios_have_the_routes_of_pmsm_ev_scenarios():
    delayed = speed_reference(delay=SENSORLESS_START_DELAY)
    for n in (1, 2):
        spec = _system(f"scenario{n}-sensorless")
        paper = _system(f"scenario{n}")
        assert spec["signals"]["delta"] == paper["signals"]["delta"]
        table = spec["signals"]["omega_ref"]["table"]
        assert (tuple(t for t, _ in table), tuple(v for _, v in table)) == (delayed.times, delayed.values)
        assert list(spec["record"]) == list(ALL_COLUMNS + SENSORLESS_COLUMNS)
        assert spec["components"][0]["fmu"].endswith("FocSensorless.fmu")
    hill_spec = _system("hill-start-if")
    assert [tuple(p) for p in hill_spec["signals"]["delta"]["table"]] == [tuple(p) for p in HILL_START_DEG]
    assert [tuple(p) for p in hill_spec["signals"]["omega_ref"]["table"]] == list(HILL_START_OMEGA_REF)
    assert hill_spec["experiment"]["stop_time"] == HILL_START_STOP_TIME
    assert hill_start_route()["omega_ref"](45.0) == 0.0
    assert SENSORLESS_START_DELAY > StartupParams().align_time


def test_cosimulation_equals_the_reference(tmp_path):
    """FocSensorless + PmsmEvPlant under the master == the monolithic loop, over the first
    6 s of scenario1-sensorless (alignment, I-f, handover), every recorded column, to 1e-9."""
    fmus = project_fmus()
    stop = 6.0
    run_reference(tmp_path / "ref", 1, stop_time=stop, observer="sensorless",
                  omega_ref=speed_reference(delay=SENSORLESS_START_DELAY))
    spec = load_system("scenario1-sensorless")
    spec.stop_time = stop
    spec.set_fmu("ctrl", fmus["FocSensorless"])
    spec.set_fmu("plant", fmus["PmsmEvPlant"])
    m = Master(spec).run(tmp_path / "cosim", catch_sigint=False)
    assert m["status"] == "completed"
    a, b = read_results(tmp_path / "cosim"), read_results(tmp_path / "ref")
    assert list(a) == list(b) == list(ALL_COLUMNS + SENSORLESS_COLUMNS)
    for col in a:
        np.testing.assert_allclose(a[col], b[col], rtol=1e-9, atol=1e-9, err_msg=col)
    assert set(a["mode"]) == {ALIGN, IF, EKF}


def test_saved_state_restores_the_trajectory_exactly():
    """get_state/set_state (the FMU's fmi2Get/SetFMUstate) carry the start-up's state: mode,
    clock, the I-f vector and its damping filter, mid-I-f."""
    plant = Plant(plant=PlantParams(theta_e0=0.4))
    unit = ControlUnit("sensorless", dt=DT)
    w_ref = speed_reference(delay=SENSORLESS_START_DELAY)
    for k in range(30000):  # 3 s: in I-f
        out = unit.step(plant.i_alpha, plant.i_beta, w_ref(k * DT))
        plant.step(out[0], out[1], 0.0, DT)
    assert unit.mode == IF
    snap, plant_snap = unit.get_state(), plant.get_state()
    fresh, fresh_plant = ControlUnit("sensorless", dt=DT), Plant(plant=PlantParams(theta_e0=0.4))
    fresh.set_state(snap)
    fresh_plant.set_state(plant_snap)
    for k in range(30000, 45000):  # on past the handover
        a = unit.step(plant.i_alpha, plant.i_beta, w_ref(k * DT))
        b = fresh.step(fresh_plant.i_alpha, fresh_plant.i_beta, w_ref(k * DT))
        assert a == b, k
        plant.step(a[0], a[1], 0.0, DT)
        fresh_plant.step(b[0], b[1], 0.0, DT)
    assert unit.mode == EKF
