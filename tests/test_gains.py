"""The controller gains (``pmsm_ev.controller.controller_gains``): derived when a control unit
is built, from the bandwidths of ``ControllerParams`` and the controller's own motor model;
the defaults are the gains the drive has always had, bit for bit; ``ctrl.L_q`` (command line,
API) retunes the q-current PI as the formula says; a changed omega_c changes the measured
rise time of a current step as the sampled first-order loop predicts."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import pmsm_cosim
from orchestrator_support import project_fmus
from pmsm_cosim.app.cli import main
from pmsm_cosim.engine.recording import read_results
from pmsm_ev import kernels as _k
from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.controller import CurrentController, SpeedController, controller_gains
from pmsm_ev.params import (
    SENSORLESS_EKF,
    ControllerParams,
    MotorParams,
    ParameterError,
    StartupParams,
    VehicleParams,
)
from pmsm_ev.plant import Plant
from pmsm_ev.transforms import inverse_park

DT = 1e-4
#: the gains as ``pmsm_ev.params`` computed them from Table I when it was imported, before they
#: were derived at construction (repr of each float: exact)
GAINS_BEFORE = {"kp_w": 5.862388189415042, "ki_w": 5.862388189415042, "kp_id": 0.404, "ki_id": 17.338,
                "kp_iq": 0.58, "ki_iq": 17.338, "T_d": 0.0005}
#: the sensorless unit's I-f damping gain (C_IF_DAMP) as ControlUnit computed it
K_IF_BEFORE = 3.389731678356486
GAIN_SLOTS = {"kp_w": _k.C_KP_W, "ki_w": _k.C_KI_W, "kp_id": _k.C_KP_ID, "ki_id": _k.C_KI_ID,
              "kp_iq": _k.C_KP_IQ, "ki_iq": _k.C_KI_IQ, "T_d": _k.C_T_D}


def _unit_gains(unit: ControlUnit) -> dict:
    """The gains in the unit's parameter vector, the numbers the kernels use."""
    return {name: float(unit._c[slot]) for name, slot in GAIN_SLOTS.items()}


# -- defaults ----------------------------------------------------------------------------------
@pytest.mark.parametrize("observer", ["ekf5", "ekf4", "ekf5ab", "sensored", "sensorless"])
def test_default_gains_are_the_drives_gains_bit_for_bit(observer):
    unit = ControlUnit(observer)
    assert _unit_gains(unit) == GAINS_BEFORE  # floats compared exactly
    assert float(unit._c[_k.C_IF_DAMP]) == (K_IF_BEFORE if observer == "sensorless" else 0.0)


def test_default_gains_are_the_design_formulas_on_tables_i_and_ii():
    g = controller_gains(ControllerParams(), MotorParams())
    # Table I: N = 4, psi = 0.08975, L_d = 0.202 mH, L_q = 0.29 mH, R_s = 8.669 mOhm, J_m = 0.01;
    # Table II: r_w = 0.2933 m, m_v = 900 kg, eta = 0.96, n_g = 12.5; omega_c = 2000, omega_n = 2, zeta = 1
    j_eq = 0.01 + 0.2933**2 * 900.0 / (0.96 * 12.5**2)
    assert j_eq == pytest.approx(0.526, abs=5e-4)
    assert g.kp_id == 0.202e-3 * 2000.0 and g.kp_iq == 0.29e-3 * 2000.0
    assert g.ki_id == g.ki_iq == 8.669e-3 * 2000.0
    assert g.kp_w == 2 * 1.0 * 2.0 * j_eq / (4 * 0.08975)
    assert g.ki_w == 2.0**2 * j_eq / (4 * 0.08975)
    assert g.T_d == 1.0 / 2000.0
    assert ControllerParams().J_load == VehicleParams().reflected_inertia
    k_if = controller_gains(ControllerParams(), MotorParams(), StartupParams(), SENSORLESS_EKF.J_model).k_if
    assert k_if == 2.0 * 0.7 * math.sqrt(j_eq / 0.08975) == K_IF_BEFORE


# -- the controller's own motor model and design ------------------------------------------------
def test_the_controllers_motor_model_sets_its_gains():
    base = _unit_gains(ControlUnit("ekf5"))
    L_q = 0.4e-3
    g = _unit_gains(ControlUnit("ekf5", motor=MotorParams(L_q=L_q)))
    assert g["kp_iq"] == L_q * 2000.0  # K_p,q = L_q omega_c
    assert {k: v for k, v in g.items() if k != "kp_iq"} == {k: v for k, v in base.items() if k != "kp_iq"}
    g = _unit_gains(ControlUnit("ekf5", motor=MotorParams(R_s=10e-3, L_d=0.25e-3)))
    assert (g["ki_id"], g["ki_iq"], g["kp_id"]) == (10e-3 * 2000.0, 10e-3 * 2000.0, 0.25e-3 * 2000.0)
    g = _unit_gains(ControlUnit("sensored", motor=MotorParams(J_m=0.11)))  # J = 0.11 + 0.516
    j = 0.11 + VehicleParams().reflected_inertia
    assert g["kp_w"] == pytest.approx(2 * 2.0 * j / (4 * 0.08975), rel=1e-15)
    assert g["kp_w"] / base["kp_w"] == pytest.approx(j / 0.526, rel=2e-3)
    g = _unit_gains(ControlUnit("sensored", motor=MotorParams(psi=0.1)))  # k_t = N psi
    assert g["ki_w"] == pytest.approx(base["ki_w"] * 0.08975 / 0.1, rel=1e-15)


def test_the_bandwidths_set_the_gains():
    g = controller_gains(ControllerParams(omega_c=500.0, omega_n=4.0, zeta=0.5, J_load=1.0), MotorParams())
    assert (g.kp_id, g.kp_iq, g.ki_id, g.T_d) == (0.202e-3 * 500.0, 0.29e-3 * 500.0, 8.669e-3 * 500.0, 1 / 500.0)
    assert g.kp_w == pytest.approx(2 * 0.5 * 4.0 * 1.01 / (4 * 0.08975), rel=1e-15)
    assert g.ki_w == pytest.approx(16.0 * 1.01 / (4 * 0.08975), rel=1e-15)
    unit = ControlUnit("ekf5", controller=ControllerParams(omega_c=500.0))
    assert float(unit._c[_k.C_KP_IQ]) == 0.29e-3 * 500.0 and float(unit._c[_k.C_T_D]) == 1 / 500.0


def test_explicit_gains_override_the_derived_ones():
    p = ControllerParams(kp_iq=1.5, ki_w=3.0, T_d=1e-3)
    g = _unit_gains(ControlUnit("ekf5", motor=MotorParams(L_q=0.4e-3), controller=p))
    assert (g["kp_iq"], g["ki_w"], g["T_d"]) == (1.5, 3.0, 1e-3)
    assert g["kp_id"] == GAINS_BEFORE["kp_id"] and g["kp_w"] == GAINS_BEFORE["kp_w"]  # the others derived
    # the blocks on their own derive the same gains
    assert SpeedController(p, MotorParams(), DT).gains == CurrentController(p, MotorParams(), DT).gains


@pytest.mark.parametrize("bad, message", [
    (dict(omega_c=0.0), "omega_c must be > 0 rad/s (got 0.0)"),
    (dict(omega_n=-2.0), "omega_n must be > 0 rad/s (got -2.0)"),
    (dict(zeta=0.0), "zeta must be > 0 (got 0.0)"),
    (dict(J_load=-0.5), "J_load must be >= 0 kg m^2 (got -0.5)"),
    (dict(omega_c=math.inf), "omega_c must be finite (got inf)"),
    (dict(kp_iq=-1.0), "kp_iq must be >= 0, 0 = derived (got -1.0)"),
    (dict(T_d=-1e-3), "T_d must be >= 0 s, 0 = 1/omega_c (got -0.001)"),
])
def test_a_bad_design_parameter_is_refused_by_name(bad, message):
    with pytest.raises(ParameterError, match=f"^{re.escape(message)}$"):
        ControlUnit("ekf5", controller=ControllerParams(**bad))


# -- the current loop's bandwidth, measured on the plant ------------------------------------
def _current_step(omega_c: float, axis: str, ref: float = 50.0, steps: int = 400):
    """A current step of ``ref`` on one axis (the other held at 0) by ``CurrentController`` on
    ``Plant`` (RK4 of eqs 10-13, rotor free at standstill); the current relative to ``ref`` at
    each period."""
    m = MotorParams()
    plant = Plant(m)
    cc = CurrentController(ControllerParams(omega_c=omega_c), m, DT)
    x = np.empty(steps)
    for k in range(steps):
        i_d, i_q = plant.i_d, plant.i_q
        x[k] = (i_d if axis == "d" else i_q) / ref
        v_d, v_q = cc.step(ref if axis == "d" else 0.0, ref if axis == "q" else 0.0, i_d, i_q, plant.omega_m)
        plant.step(*inverse_park(v_d, v_q, plant.theta_e), 0.0, DT)
    return x


def _rise_time(x: np.ndarray) -> float:
    """10-90 % rise time [s] of a sampled step response (linear interpolation between periods)."""
    n = int(np.argmax(x >= 0.9)) + 1
    t = np.arange(n) * DT
    return float(np.interp(0.9, x[:n], t) - np.interp(0.1, x[:n], t))


@pytest.mark.parametrize("axis", ["d", "q"])
def test_omega_c_sets_the_measured_current_step_rise_time(axis):
    """With the PI zero on R/L the loop is omega_c / (s + omega_c): a 10-90 % rise in ln 9 / omega_c
    (= 2.2 / omega_c). Sampled at dt (forward-Euler integral, voltage held) its pole is z = 1 - omega_c dt,
    a rise of ln 9 dt / -ln(1 - omega_c dt): 0.985 ms at 2000 rad/s (2.2 / omega_c = 1.1 ms), 4.28 ms at
    500 rad/s (4.4 ms). Measured: 0.987 and 4.29 ms; within 2 % of the sampled loop, 12 % of 2.2 / omega_c."""
    rise, sampled = {}, {}
    for omega_c in (500.0, 2000.0):
        x = _current_step(omega_c, axis)
        rise[omega_c] = _rise_time(x)
        sampled[omega_c] = math.log(9.0) * DT / -math.log(1.0 - omega_c * DT)
        assert rise[omega_c] == pytest.approx(sampled[omega_c], rel=0.02), omega_c
        assert rise[omega_c] == pytest.approx(2.2 / omega_c, rel=0.12), omega_c
        assert x.max() < 1.001 and x[-1] == pytest.approx(1.0, abs=1e-3)  # first order: no overshoot
    # a quarter of the bandwidth: four times slower, 4.35 with the sampling (measured 4.35)
    assert rise[500.0] / rise[2000.0] == pytest.approx(sampled[500.0] / sampled[2000.0], rel=0.02)


# -- through the FMUs: --set ctrl.L_q, the API ----------------------------------------------
def _kp_iq_seen(r) -> float:
    """K_p,q as the controller applied it in its first period that acts (t = 1e-4 s, row 2; the
    rows hold the outputs of the period before): v_q = K_p,q (i_qref - i_q) + N omega_hat psi (eqs
    16 and 20: the q integral and the filtered d reference are still 0 after the period at t = 0,
    whose errors were 0)."""
    m = MotorParams()
    v_q, i_qref, omega_hat, i_q = r["v_q"][2], r["i_qref"][2], r["omega_hat"][2], r["i_q"][1]
    assert i_qref - i_q > 1e-3  # the speed PI asks for current
    return (v_q - m.N * omega_hat * m.psi) / (i_qref - i_q)


@pytest.fixture(scope="module")
def fmus():
    return project_fmus()


@pytest.mark.parametrize("L_q", [None, 0.4e-3])
def test_set_ctrl_L_q_retunes_the_q_current_pi(fmus, L_q, tmp_path):
    args = ["--set", f"ctrl.L_q={L_q!r}"] if L_q else []
    out = tmp_path / "run"
    assert main(["run", "scenario1", "--stop-time", "0.0005", "--output-interval", "1e-4", "--no-figures",
                 "--quiet", "--out", str(out), *args]) == 0
    expected = (L_q or MotorParams().L_q) * ControllerParams().omega_c  # 0.58 or 0.8 V/A
    assert _kp_iq_seen(read_results(out)) == pytest.approx(expected, rel=1e-9)
    result, metrics = pmsm_cosim.simulate("scenario1", stop_time=0.0005, output_interval=1e-4,
                                          set={"ctrl.L_q": L_q} if L_q else None)
    assert metrics["status"] == "completed"
    assert _kp_iq_seen(result) == pytest.approx(expected, rel=1e-9)


def test_set_ctrl_omega_c_and_an_explicit_gain(fmus):
    result, _ = pmsm_cosim.simulate("scenario1", stop_time=0.0005, output_interval=1e-4,
                                    set={"ctrl.omega_c": 1000.0})
    assert _kp_iq_seen(result) == pytest.approx(0.29e-3 * 1000.0, rel=1e-9)
    result, _ = pmsm_cosim.simulate("scenario1", stop_time=0.0005, output_interval=1e-4,
                                    set={"ctrl.omega_c": 1000.0, "ctrl.kp_iq": 0.7})
    assert _kp_iq_seen(result) == pytest.approx(0.7, rel=1e-9)


def test_a_bad_bandwidth_is_a_one_line_error(fmus, capsys, tmp_path):
    """The line docs/errors.md quotes."""
    assert main(["run", "scenario2", "--stop-time", "0.01", "--set", "ctrl.omega_c=0", "--out",
                 str(tmp_path / "run")]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "error: ctrl (FocEkf5.fmu): fmi2ExitInitializationMode (start values) refused: omega_c must be > 0 rad/s "
        "(got 0.0)"]
    assert not (tmp_path / "run").exists()
