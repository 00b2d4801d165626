"""Physics of the plant: transforms, eqs 1-13, balances and steady states."""

import math

import pytest

from pmsm_ev import vehicle as veh
from pmsm_ev.params import MotorParams, ParameterError, PlantParams, VehicleParams, equivalent_inertia
from pmsm_ev.plant import Plant
from pmsm_ev.pmsm import current_derivatives, electromagnetic_torque, friction_torque
from pmsm_ev.transforms import clarke, inverse_clarke, inverse_park, park, wrap_angle


@pytest.mark.parametrize("theta", [-3.0, -0.4, 0.0, 1.1, 2.9, 17.0])
def test_park_round_trip(theta):
    d, q = park(*inverse_park(3.2, -1.7, theta), theta)
    assert d == pytest.approx(3.2, abs=1e-12) and q == pytest.approx(-1.7, abs=1e-12)


def test_clarke_round_trip_and_amplitude_invariance():
    a, b, c = inverse_clarke(2.0, -0.5)
    assert a + b + c == pytest.approx(0.0, abs=1e-12)
    assert clarke(a, b, c) == pytest.approx((2.0, -0.5))
    # a balanced set of amplitude 10 maps to a vector of length 10
    th = 0.3
    abc = [10 * math.cos(th - k * 2 * math.pi / 3) for k in range(3)]
    al, be = clarke(*abc)
    assert math.hypot(al, be) == pytest.approx(10.0)


def test_wrap_angle_range():
    for x in (-10.0, -math.pi, 0.0, math.pi, 7.0):
        w = wrap_angle(x)
        assert -math.pi <= w < math.pi
        assert math.isclose(math.cos(w), math.cos(x), abs_tol=1e-12)


def test_equivalent_inertia_eq9():
    assert equivalent_inertia(MotorParams(), VehicleParams()) == pytest.approx(0.526, abs=5e-4)


# eq 29 at 200 rad/s for each plateau angle (B_m, T_m0 do not enter eq 29)
EQ29 = {0: 3.452, 5: 22.249, 10: 40.879, 15: 59.201, 20: 77.076, 22: 84.071, 25: 94.368}


@pytest.mark.parametrize("deg,expected", sorted(EQ29.items()))
def test_load_torque_eq29(deg, expected):
    for model in ("physical", "paper"):
        t = veh.load_torque(200.0, math.radians(deg), VehicleParams(load_model=model))
        assert t == pytest.approx(expected, abs=1.5e-3)


def test_eq9_follows_from_eqs_1_to_8():
    """J_eq dw/dt = T_e - B w - T_m0 - T_L (9) is eq 8 with T_m from eqs 1-7."""
    m, v = MotorParams(), VehicleParams()
    omega, delta, t_e = 150.0, math.radians(7.0), 60.0
    t_l = veh.load_torque(omega, delta, v)
    dw = (t_e - friction_torque(omega, m, "paper") - t_l) / equivalent_inertia(m, v)  # (9)
    v_v = veh.vehicle_speed(omega, v)
    a_v = v.r_w * dw / v.n_g  # (1) with alpha_w = dw/dt / n_g (6)
    t_w = veh.wheel_torque(veh.inertia_force(a_v, v), veh.gradient_force(delta, v),
                           veh.rolling_force(v_v, delta, v), veh.aero_force(v_v, v), v)  # (5)
    t_m = veh.motor_side_torque(t_w, v)  # (7)
    assert m.J_m * dw == pytest.approx(t_e - friction_torque(omega, m, "paper") - t_m, rel=1e-12)  # (8)


def test_pmsm_power_balance():
    """Electrical power in = copper loss + d/dt magnetic energy + mechanical power (10-12)."""
    m = MotorParams()
    for i_d, i_q, w, v_d, v_q in ((3.0, 50.0, 120.0, -5.0, 40.0), (-20.0, 200.0, 200.0, -17.0, 80.0)):
        did, diq = current_derivatives(i_d, i_q, w, v_d, v_q, m)
        p_in = v_d * i_d + v_q * i_q
        p_cu = m.R_s * (i_d**2 + i_q**2)
        dw_mag = m.L_d * i_d * did + m.L_q * i_q * diq
        p_mech = w * electromagnetic_torque(i_d, i_q, m)
        assert p_in == pytest.approx(p_cu + dw_mag + p_mech, rel=1e-12)


def test_rolling_resistance_sign():
    """Paper mode pushes back at standstill (eq 3 as printed); physical mode does not."""
    assert veh.rolling_force(0.0, 0.0, VehicleParams(load_model="paper")) > 100.0
    assert veh.rolling_force(0.0, 0.0, VehicleParams()) == 0.0
    assert veh.rolling_force(-1.0, 0.0, VehicleParams()) < -100.0


def test_plant_at_standstill_stays_at_rest():
    plant = Plant()
    for _ in range(10000):  # 1 s
        plant.step(0.0, 0.0, 0.0, 1e-4)
    # physical load model: only the 2 m/s head wind acts, held by rolling resistance
    # (a smooth sign, so the car creeps at well under 1 mm/s: 0.01 rad/s = 0.2 mm/s)
    assert abs(plant.omega_m) < 1e-2
    assert abs(plant.i_d) < 1e-3 and abs(plant.i_q) < 0.1  # short-circuit current of the creep


def test_plant_paper_load_model_rolls_back_at_standstill():
    plant = Plant(vehicle=VehicleParams(load_model="paper"))
    for _ in range(10000):
        plant.step(0.0, 0.0, 0.0, 1e-4)
    # eq 3 without sign(v) drives the car backwards (against the short-circuit braking
    # of the windings at zero voltage)
    assert plant.omega_m < -0.1


def test_locked_rotor_first_order_current():
    m = MotorParams()
    plant = Plant(m, VehicleParams(m_v=1e15), PlantParams(theta_e0=0.0))
    v_d, dt = 1.0, 1e-4
    tau = m.L_d / m.R_s
    n = round(tau / dt)
    for _ in range(n):
        plant.step(v_d, 0.0, 0.0, dt)  # theta = 0: alpha-beta = dq
    assert plant.i_d == pytest.approx(v_d / m.R_s * (1 - math.exp(-n * dt / tau)), rel=1e-6)
    for _ in range(9 * n):
        plant.step(v_d, 0.0, 0.0, dt)
    assert plant.i_d == pytest.approx(v_d / m.R_s, rel=1e-3)
    assert abs(plant.omega_m) < 1e-6
    assert abs(plant.i_q) < 1e-3 * plant.i_d


def test_plant_rk4_is_fourth_order():
    """Halving the RK4 sub-step cuts the error ~16x once h is small (vs 64 sub-steps, 20 ms at 200 rad/s)."""
    def run(n):
        p = Plant(plant=PlantParams(rk4_substeps=n, omega_m0=200.0, i_q0=50.0))
        for _ in range(200):
            p.step(*inverse_park(-5.0, 75.0, p.theta_e + 0.04), math.radians(5.0), 1e-4)
        return p.i_q
    exact = run(64)
    e1, e4, e8 = (abs(run(n) - exact) for n in (1, 4, 8))
    assert e1 < 1e-6 * abs(exact)  # default, one sub-step: < 1e-6 relative after 200 steps
    assert 12.0 < e4 / e8 < 17.0


@pytest.mark.parametrize("bad", [dict(m_v=0.0), dict(m_v=-1.0), dict(eta=0.0), dict(eta=1.2), dict(load_model="x")])
def test_vehicle_rejects_nonphysical(bad):
    with pytest.raises(ParameterError):
        Plant(vehicle=VehicleParams(**bad))


@pytest.mark.parametrize("bad", [dict(L_d=0.0), dict(L_q=-1e-3), dict(R_s=0.0), dict(J_m=0.0)])
def test_motor_rejects_nonphysical(bad):
    with pytest.raises(ParameterError):
        Plant(motor=MotorParams(**bad))
