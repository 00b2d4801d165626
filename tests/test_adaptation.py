"""Adaptation while driving (``pmsm_ev.kernels.adaptation``, eqs AD1-AD6): on a kernel-level drive (the plant and the
sensored unit, no FMI) with a warmed motor, psi_hat and R_s_hat go to the plant's; each stays where it is outside
the condition under which it is observable; "observe" changes nothing in the controller, "use" puts the estimates
into its model; bad settings are refused by name."""

from __future__ import annotations

import math

import pytest

from pmsm_ev import kernels as k
from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.params import ControllerParams, MotorParams, ParameterError, PlantParams
from pmsm_ev.plant import Plant

DT = 1e-4
#: a warm motor: the winding at 120 degC (R_s +39 %), the magnet at 100 degC (psi -9.6 %); sigma = 1 A of noise
WARM = PlantParams(v_dc=360.0, T_winding=120.0, T_magnet=100.0, sensor_noise=1.0, sensor_seed=3)


def _drive(adaptation: str = "observe", **extra):
    """The plant (``WARM``) and a sensored unit in field weakening on the 360 V link; a stiff speed loop (omega_n 20
    rad/s: the sensored drive may) so that it holds the car on a slope at zero speed."""
    ctrl = ControllerParams(reference="fw", v_dc=360.0, current_control="high_speed",
                            speed_feedforward="inertia+road", omega_n=20.0, adaptation=adaptation, **extra)
    return Plant(plant=WARM), ControlUnit("sensored", controller=ctrl, dt=DT)


def _run(plant, unit, seconds, omega_ref, delta_deg, watch=None):
    """Drive for ``seconds``; ``watch(unit)`` after every period, if given."""
    delta = math.radians(delta_deg)
    for _ in range(int(round(seconds / DT))):
        out = unit.step(plant.i_alpha, plant.i_beta, omega_ref, plant.theta_e, plant.omega_m)
        plant.step(out[0], out[1], delta, DT, unit.T_brake)
        if watch is not None:
            watch(unit)


def _truth():
    m = MotorParams()
    return (m.R_s * (1.0 + WARM.alpha_R * (WARM.T_winding - 20.0)),
            m.psi * (1.0 + WARM.alpha_psi * (WARM.T_magnet - 20.0)))


def test_the_estimates_go_to_the_warm_motors_psi_and_r_s():
    """Standing 1 s on 15 deg (166 A, omega 0: R_s observable, psi not), then 800 rad/s for 3 s (psi observable):
    R_s_hat within 2 % of the plant's (+39 % off the model's) at the stand, psi_hat within 0.5 % (-9.6 % off) at
    speed. Measured: -0.6 %, -0.06 %."""
    r_true, psi_true = _truth()
    plant, unit = _drive()
    m = MotorParams()
    assert unit.psi_est == m.psi and unit.R_s_est == m.R_s
    _run(plant, unit, 1.0, 0.0, 15.0)
    assert abs(plant.omega_m) < 0.5 and abs(unit.i_q) > 150.0
    assert unit.R_s_observable == 1.0 and unit.psi_observable == 0.0
    assert unit.R_s_est == pytest.approx(r_true, rel=0.02)
    assert unit.psi_est == m.psi  # not observable at a stand: not moved
    _run(plant, unit, 3.0, 800.0, 0.0)
    assert unit.psi_observable == 1.0 and unit.R_s_observable == 0.0
    assert unit.psi_est == pytest.approx(psi_true, rel=0.005)


def test_each_estimate_is_frozen_outside_its_condition():
    """At a stand psi_hat does not move (no back-EMF); at speed R_s_hat does not move (the back-EMF's error
    swamps R_s |i|^2); below adapt_rs_current neither does it at a stand."""
    plant, unit = _drive()
    seen = []
    _run(plant, unit, 0.5, 0.0, 15.0, watch=lambda u: seen.append(u.psi_est))
    assert set(seen) == {MotorParams().psi}
    _run(plant, unit, 2.5, 800.0, 0.0)  # R_s_hat was fitted on the way up (below 15 rad/s); then not again
    r_fast = []
    _run(plant, unit, 0.5, 800.0, 0.0, watch=lambda u: r_fast.append(u.R_s_est))
    assert len(set(r_fast)) == 1
    plant, unit = _drive()
    r_low = []
    _run(plant, unit, 0.5, 0.0, 3.0, watch=lambda u: r_low.append((u.R_s_est, abs(u.i_q))))  # about 35 A
    assert max(i for _, i in r_low[-100:]) < 100.0
    assert {r for r, _ in r_low} == {MotorParams().R_s}


def test_observe_changes_nothing_and_use_puts_the_estimates_into_the_model():
    """"observe": the voltages are bit for bit those with "off"; "use": the controller's psi and the EKF's psi and
    R_s constants are the estimates' (AD6), and a reset puts them back on the model's."""
    runs = {}
    for mode in ("off", "observe", "use"):
        plant, unit = _drive(mode)
        volts = []
        _run(plant, unit, 0.3, 0.0, 15.0, watch=lambda u: volts.append((u.v_alpha, u.v_beta)))
        _run(plant, unit, 1.5, 600.0, 0.0, watch=lambda u: volts.append((u.v_alpha, u.v_beta)))
        runs[mode] = (volts, unit)
    assert runs["observe"][0] == runs["off"][0]
    assert runs["use"][0] != runs["off"][0]
    off, use = runs["off"][1], runs["use"][1]
    assert off.psi_est == 0.0 and off.R_s_est == 0.0 and off.psi_observable == 0.0  # 0: not estimated
    c = use._c
    assert c[k.C_PSI] == use.psi_est != MotorParams().psi
    assert c[k.C_A_RD] == 1.0 - use.R_s_est * DT / MotorParams().L_d
    assert c[k.C_C_WPSI] == pytest.approx(c[k.C_AD_NOM] * use.psi_est / MotorParams().psi, rel=1e-15)
    state = use.get_state()
    use.reset()
    assert c[k.C_PSI] == MotorParams().psi and c[k.C_A_RD] == 1.0 - MotorParams().R_s * DT / MotorParams().L_d
    use.set_state(state)  # a restored FMU state brings its estimates into the model again
    assert c[k.C_PSI] == use.psi_est != MotorParams().psi


@pytest.mark.parametrize(("changes", "message"), [
    ({"adaptation": "on"}, "adaptation must be one of"),
    ({"adapt_time": 0.0}, "adapt_time must be finite and > 0"),
    ({"adapt_rs_current": -1.0}, "adapt_rs_current must be finite and > 0"),
    ({"adapt_rs_speed": 200.0}, "adapt_rs_speed must be >= 0 rad/s and below adapt_psi_speed"),
    ({"model_source": "measured"}, "model_source must be one of"),
])
def test_bad_adaptation_settings_are_refused_by_name(changes, message):
    with pytest.raises(ParameterError, match=message):
        ControllerParams(**changes).validate()


# -- the identified model (AD7, ``ControllerParams.model_source``) ----------------------------------------------------
#: the constants made of L_d, L_q, R_s: the EKF's (A8-A15, A18-A19), the decoupling's, the loss detector's, the current
#: PIs' gains
MODEL_SLOTS = ("C_L_D", "C_L_Q", "C_A_RD", "C_A_RQ", "C_C_WQ", "C_C_WD", "C_C_WPSI", "C_C_VD", "C_C_VQ", "C_C_TDQ",
               "C_EKF_LOS_EMF", "C_KP_ID", "C_KI_ID", "C_KP_IQ", "C_KI_IQ")


def _injection_unit(motor=None, source="identified"):
    from pmsm_ev.params import InjectionParams

    return ControlUnit("sensorless", motor=motor, controller=ControllerParams(model_source=source),
                       injection=InjectionParams(low_speed="injection"))


def test_the_identified_model_is_the_model_a_unit_built_on_the_measured_motor_has():
    """L_d = 1/y_d, L_q = 1/y_q and R_s as measured put into the controller's model give every constant made of them
    as a unit whose motor parameters are those values computes them (its EKF's, its current PIs' gains from the same
    bandwidth); with nothing measured, the given model; a reset goes back to the given model, a restored FMU state to
    the measured one."""
    l_d, l_q, r_s = 2.1e-4, 2.9e-4, 0.0131
    unit = _injection_unit()
    c, s = unit._c, unit._s
    given = {name: c[getattr(k, name)] for name in MODEL_SLOTS}
    k.model_apply(s, c)  # nothing measured: the given model
    assert {name: c[getattr(k, name)] for name in MODEL_SLOTS} == pytest.approx(given, rel=1e-12)
    s[k.S_ID_Y], s[k.S_ID_Y + 1], s[k.S_ID_RS] = 1.0 / l_d, 1.0 / l_q, r_s
    k.model_apply(s, c)
    oracle = _injection_unit(MotorParams(L_d=l_d, L_q=l_q, R_s=r_s), source="given")._c
    for name in MODEL_SLOTS:
        assert c[getattr(k, name)] == pytest.approx(oracle[getattr(k, name)], rel=1e-12), name
    assert c[k.C_L_D] != given["C_L_D"] and c[k.C_KI_ID] != given["C_KI_ID"]
    state = unit.get_state()
    unit.reset()
    assert {name: c[getattr(k, name)] for name in MODEL_SLOTS} == pytest.approx(given, rel=1e-12)
    unit.set_state(state)
    assert c[k.C_L_Q] == pytest.approx(l_q, rel=1e-12) and c[k.C_A_RQ] == pytest.approx(oracle[k.C_A_RQ], rel=1e-12)


def test_the_given_model_stays_where_the_identification_is_not_used_or_measured_nothing():
    """``model_source = "given"``: the identification's values change nothing of the model (the kernel's step never
    calls ``model_apply``: its constants stay bit for bit); "identified" with R_s alone measured: the given L_d,
    L_q and the measured R_s."""
    unit = _injection_unit(source="given")
    before = list(unit._c)
    assert unit._c[k.C_MODEL_SRC] == k.MODEL_GIVEN
    unit = _injection_unit()
    c, s = unit._c, unit._s
    s[k.S_ID_RS] = 2.0 * MotorParams().R_s
    k.model_apply(s, c)
    assert c[k.C_L_D] == MotorParams().L_d and c[k.C_L_Q] == MotorParams().L_q
    assert c[k.C_A_RD] == pytest.approx(1.0 - 2.0 * MotorParams().R_s * unit.dt / MotorParams().L_d, rel=1e-12)
    assert c[k.C_KI_IQ] == pytest.approx(2.0 * before[k.C_KI_IQ], rel=1e-12)


def _plant_tilt(plant: Plant, i_q: float) -> float:
    """The axis of the plant's least incremental inductance at (0, i_q) less its d axis [rad]: where the injection
    locks."""
    l_dd, l_dq, l_qq = plant.incremental_inductances(0.0, i_q)
    g_dd, g_dq, g_qq = l_qq, -l_dq, l_dd  # the admittance matrix times the determinant: the same axes
    return 0.5 * math.atan2(2.0 * g_dq, g_dd - g_qq)


def test_cross_saturation_is_compensated_on_the_identified_motor_and_its_current_limited():
    """(AD8) A motor with a fifth of the data sheet's saliency (L_d +13 %, L_q -15 %: 1.08) tilts its injection axis
    under load far more than the data sheet's: the identified model's table follows the plant's own tilt (the same flux
    model's shape on the measured L_d, L_q) within 6 deg up to 300 A where the given table is 25 deg off at 150 A;
    the injection's q current is limited where the identified tilt reaches the given tilt at the given limit; a
    motor more salient than the data sheet keeps the given limit; nothing measured puts the given table back bit for
    bit, as a reset does."""
    m0 = MotorParams()
    unit = _injection_unit()
    c, s = unit._c, unit._s
    given_table = [c[k.C_CROSS + j] for j in range(k.CROSS_POINTS)]
    given_limit = c[k.C_INJ_I_MAX]
    l_d, l_q = 1.13 * m0.L_d, 0.85 * m0.L_q
    s[k.S_ID_Y], s[k.S_ID_Y + 1] = 1.0 / l_d, 1.0 / l_q
    k.model_apply(s, c)
    plant = Plant(motor=MotorParams(L_d=l_d, L_q=l_q), plant=PlantParams(flux_model="algebraic"))
    for j in range(1, 7):
        i_q = j * k.CROSS_STEP
        truth = _plant_tilt(plant, i_q)
        assert abs(c[k.C_CROSS + j] - truth) < math.radians(6.0), i_q
    assert abs(given_table[3] - _plant_tilt(plant, 150.0)) > math.radians(25.0)
    limit = c[k.C_INJ_I_MAX]
    assert 100.0 < limit < given_limit
    assert k.cross_offset(c, limit) == pytest.approx(c[k.C_INJ_TILT_MAX], abs=1e-12)
    assert k.cross_offset(c, limit + 1.0) > c[k.C_INJ_TILT_MAX]
    s[k.S_ID_Y], s[k.S_ID_Y + 1] = 1.0 / (0.9 * m0.L_d), 1.0 / (1.1 * m0.L_q)  # more salient: the given limit
    k.model_apply(s, c)
    assert c[k.C_INJ_I_MAX] == given_limit and c[k.C_CROSS + 3] < given_table[3]
    s[k.S_ID_Y], s[k.S_ID_Y + 1] = 1.0 / l_d, 1.0 / l_q
    k.model_apply(s, c)
    unit.reset()
    assert [c[k.C_CROSS + j] for j in range(k.CROSS_POINTS)] == given_table and c[k.C_INJ_I_MAX] == given_limit


def test_no_cross_saturation_compensation_stays_none_on_the_identified_motor():
    """``inj_cross_comp`` off: the identified motor's table stays 0 and its limit the given one."""
    from pmsm_ev.params import InjectionParams

    unit = ControlUnit("sensorless", controller=ControllerParams(model_source="identified"),
                       injection=InjectionParams(low_speed="injection", inj_cross_comp=False))
    c, s = unit._c, unit._s
    s[k.S_ID_Y], s[k.S_ID_Y + 1] = 1.0 / (1.1 * MotorParams().L_d), 1.0 / (0.92 * MotorParams().L_q)
    k.model_apply(s, c)
    assert [c[k.C_CROSS + j] for j in range(k.CROSS_POINTS)] == [0.0] * k.CROSS_POINTS
    assert c[k.C_INJ_I_MAX] == InjectionParams().inj_current_limit
