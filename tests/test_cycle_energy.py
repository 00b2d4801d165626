"""Energy over a drive cycle (pmsm_cosim.app.metrics.cycle_energy; docs/cycles.md, "Energy over a cycle"): the per-phase
figures on made-up columns whose answer is known, the two acceptance checks (the balance to 1e-6 of the DC
throughput, the wheel energy against the trace's road-load integral to 1 %), and both on the first 120 s of
the shipped wltc3b."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app.cli import main
from pmsm_cosim.app.metrics import cycle_energy as ce
from pmsm_cosim.engine.recording import read_results
from pmsm_ev import cycles
from pmsm_ev import vehicle as veh
from pmsm_ev.cycles import Cycle, Phase
from pmsm_ev.params import MotorParams, VehicleParams
from pmsm_ev.results import ENERGY_COLUMNS

WH = 3600.0


def toy_cycle():
    t = np.arange(0.0, 41.0)
    return Cycle("toy", t, np.full(t.shape, 10.0), phases=(Phase("a", 0.0, 20.0), Phase("b", 20.0, 40.0)))


def toy_rows(t_end=40.0, residual_w=0.01):
    """Rows every 0.5 s: 10 m/s on a level road; P_dc 1000 W in phase a (0-20 s), 600 W from 20 to 30 s and
    -400 W (regeneration) from 30 to 40 s; copper 100 W; the aerodynamic work takes the rest but
    ``residual_w`` [W] (the balance's residual)."""
    t = np.arange(0.0, t_end + 1e-9, 0.5)
    p_dc = np.where(t < 20.0, 1000.0, np.where(t < 30.0, 600.0, -400.0))
    e_dc = np.concatenate(([0.0], np.cumsum(p_dc[:-1] * 0.5)))
    e_regen = np.concatenate(([0.0], np.cumsum(np.maximum(-p_dc[:-1], 0.0) * 0.5)))
    r = {k: np.zeros_like(t) for k in ENERGY_COLUMNS}
    r.update(time=t, E_dc=e_dc, E_regen=e_regen, E_copper=100.0 * t, E_aero=e_dc - 100.0 * t - residual_w * t,
             x_vehicle=10.0 * t, v_vehicle=np.full(t.shape, 10.0), delta_deg=np.zeros_like(t))
    # the kinetic energy of the car at 10 m/s, constant: its changes are 0
    r["E_kinetic"] = np.full(t.shape, 0.5 * VehicleParams().m_v * 100.0)
    return r


def test_the_phases_energy_of_made_up_columns():
    ph = ce.phase_energy(toy_rows(), toy_cycle())
    a, b = ph
    assert [p["name"] for p in ph] == ["a", "b"] and a["complete"] and b["complete"]
    # phase a: 1000 W for 20 s = 5.556 Wh over 200 m
    assert a["energy"]["dc_Wh_per_km"] == pytest.approx(1000.0 * 20 / WH / 0.2, rel=1e-12)
    assert a["energy"]["regen_Wh"] == 0.0 and a["regen_share"] == 0.0 and a["regen_of_braking"] is None
    # phase b: 600 W x 10 s drawn, 400 W x 10 s back; regenerated / drawn = 2/3
    assert b["energy"]["drawn_Wh"] == pytest.approx(6000.0 / WH, rel=1e-12)
    assert b["energy"]["regen_Wh"] == pytest.approx(4000.0 / WH, rel=1e-12)
    assert b["regen_share"] == pytest.approx(2.0 / 3.0, rel=1e-12)
    # the wheels gave back 400 W + 100 W copper for 10 s: 4000 J of 5000 J reached the DC link
    assert b["wheel"]["braking_Wh"] == pytest.approx(5000.0 / WH, rel=1e-9)
    assert b["regen_of_braking"] == pytest.approx(0.8, rel=1e-9)
    assert b["energy"]["losses_Wh"]["copper"] == pytest.approx(100.0 * 20 / WH, rel=1e-12)
    # the residual 0.01 W x 20 s, relative to the throughput drawn + regenerated (10000 J)
    assert b["energy"]["residual_Wh"] == pytest.approx(0.2 / WH, rel=1e-9)
    assert b["residual_rel"] == pytest.approx(0.2 / 10000.0, rel=1e-9)
    # the phases meet at a row: their differences add up to the run's
    whole = ce.whole_run(toy_rows())
    assert a["energy"]["dc_Wh"] + b["energy"]["dc_Wh"] == pytest.approx(whole["energy"]["dc_Wh"], rel=1e-12)
    assert whole["balance"]["relative"] == pytest.approx(0.4 / (20000.0 + 6000.0 + 4000.0), rel=1e-9)
    assert whole["balance"]["passed"] is False  # 1.3e-5 > 1e-6
    assert ce.whole_run(toy_rows(residual_w=0.0))["balance"]["passed"] is True


def test_a_run_shorter_than_the_cycle_and_a_cycle_without_phases():
    ph = ce.phase_energy(toy_rows(t_end=30.0), toy_cycle())
    assert [(p["name"], p["complete"], p["end"]) for p in ph] == [("a", True, 20.0), ("b", False, 30.0)]
    assert ph[1]["energy"]["regen_Wh"] == 0.0
    assert [p["name"] for p in ce.phase_energy(toy_rows(t_end=20.0), toy_cycle())] == ["a"]
    plain = Cycle("plain", np.arange(0.0, 41.0), np.full(41, 10.0))
    (whole,) = ce.phase_energy(toy_rows(), plain)
    assert whole["name"] == ce.WHOLE and whole["complete"]
    assert whole["energy"]["dc_Wh"] == pytest.approx((20000.0 + 6000.0 - 4000.0) / WH, rel=1e-12)


def test_the_road_load_integral_of_known_drives():
    p = VehicleParams(v_a=0.0)
    t = np.arange(0.0, 10.0 + 1e-9, 0.05)
    # 20 m/s on a 5 deg climb for 10 s: (rolling + drag + grade) x 20 m/s x 10 s, exactly
    r = {"time": t, "v_vehicle": np.full(t.shape, 20.0), "delta_deg": np.full(t.shape, 5.0)}
    d = math.radians(5.0)
    force = p.c_r * p.m_v * p.g * math.cos(d) * math.tanh(20.0 / p.v_eps) + 0.5 * p.rho_a * p.c_d * p.A_f * 400.0 \
        + p.m_v * p.g * math.sin(d)
    assert np.sum(ce.road_load_increments(r, p)) == pytest.approx(force * 20.0 * 10.0, rel=1e-12)
    # from standstill to 10 m/s in 10 s on a level road without rolling or drag: 1/2 m v^2, whatever the rows
    bare = VehicleParams(v_a=0.0, c_r=0.0, c_d=0.0)
    for step in (0.05, 1.0):
        tt = np.arange(0.0, 10.0 + 1e-9, step)
        rr = {"time": tt, "v_vehicle": tt ** 2 / 10.0, "delta_deg": np.zeros_like(tt)}
        assert np.sum(ce.road_load_increments(rr, bare)) == pytest.approx(0.5 * bare.m_v * 100.0, rel=1e-12)


def fine_plant_rows(brake_w=0.0):
    """A plant's accumulators integrated finely (1e-4 s) along v(t) = 15 sin^2(pi t / 20) over 20 s on a
    climb of 3 deg, sampled every 0.05 s: road forces by eqs 2-4, the kinetic energy of the power_flow gear
    (1/2 J_m omega^2 + 1/2 m_v v^2), copper 50 W, gear loss 4 % of the wheel power's magnitude, and the DC
    energy that closes the balance; ``brake_w`` [W] of friction brake while decelerating."""
    p, m = VehicleParams(gear_model="power_flow"), MotorParams()
    tf = np.arange(0.0, 20.0 + 1e-9, 1e-4)
    v = 15.0 * np.sin(np.pi * tf / 20.0) ** 2
    a = 15.0 * np.pi / 20.0 * np.sin(2 * np.pi * tf / 20.0)
    d = math.radians(3.0)
    f_roll = np.array([veh.rolling_force(x, d, p) for x in v[::50]])
    f_aero = np.array([veh.aero_force(x, p) for x in v[::50]])
    f_roll, f_aero = np.interp(tf, tf[::50], f_roll), np.interp(tf, tf[::50], f_aero)
    f_grade = p.m_v * p.g * math.sin(d)
    brake = np.where(a < 0, brake_w, 0.0)
    p_wheel = (p.m_v * a + f_roll + f_aero + f_grade) * v + brake

    def cum(power):
        return np.concatenate(([0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * 1e-4)))

    omega = v * p.n_g / p.r_w
    kin = 0.5 * m.J_m * omega ** 2 + 0.5 * p.m_v * v ** 2
    cols = {"E_aero": cum(f_aero * v), "E_rolling": cum(f_roll * v), "E_grade": cum(f_grade * v),
            "E_brake": cum(brake), "E_copper": 50.0 * tf, "E_gear": cum(0.04 * np.abs(p_wheel)),
            "E_kinetic": kin}
    cols["E_dc"] = sum(cols[k] for k in cols if k != "E_kinetic") + kin - kin[0]
    p_dc = np.gradient(cols["E_dc"], tf)
    cols["E_regen"] = cum(np.maximum(-p_dc, 0.0))
    rows = slice(None, None, 500)
    r = {k: v_[rows] for k, v_ in cols.items()}
    r.update(time=tf[rows], v_vehicle=v[rows], delta_deg=np.full(tf[rows].shape, 3.0), x_vehicle=cum(v)[rows],
             E_inverter=np.zeros(tf[rows].shape), E_iron=np.zeros(tf[rows].shape), E_friction=np.zeros(tf[rows].shape),
             W_magnetic=np.zeros(tf[rows].shape))
    return r, p


@pytest.mark.parametrize("brake_w", [0.0, 2000.0])
def test_the_wheel_energy_agrees_with_the_road_load_integral_and_a_wrong_one_does_not(brake_w):
    r, p = fine_plant_rows(brake_w)
    w = ce.wheel_check(r, p)
    print(json.dumps(w))
    assert w["passed"] and abs(w["net_rel"]) < 1e-4 and abs(w["traction_rel"]) < 1e-4
    assert w["wheel"]["braking_Wh"] > 0 and w["brake_Wh"] == pytest.approx(r["E_brake"][-1] / WH)
    assert ce.balance_check(r)["passed"] and abs(ce.balance_check(r)["relative"]) < 1e-9
    # 2 % more DC energy than the wheels took: the wheel side is off by more than 1 %, the balance too
    bad = dict(r, E_dc=r["E_dc"] * 1.02)
    assert not ce.wheel_check(bad, p)["passed"] and ce.wheel_check(bad, p)["traction_rel"] < -0.01
    assert ce.balance_check(bad)["passed"] is False
    # the road-load integral at the wrong mass is off too
    assert not ce.wheel_check(r, VehicleParams(gear_model="power_flow", m_v=950.0))["passed"]


def test_the_plants_parameters_from_a_runs_settings():
    m = {"settings": {"components": [{"name": "ctrl", "start": {"m_v": 1.0}},
                                     {"name": "plant", "start": {"m_v": 1200, "gear_model": "power_flow",
                                                                 "J_m": 0.02, "v_dc": 360.0}}]}}
    motor, vehicle = ce.plant_params(m)
    assert vehicle.m_v == 1200.0 and vehicle.gear_model == "power_flow" and motor.J_m == 0.02
    assert ce.plant_params({}) == (MotorParams(), VehicleParams())
    with pytest.raises(ValueError, match="m_v = 'heavy' is not a float"):
        ce.plant_params({"settings": {"components": [{"name": "plant", "start": {"m_v": "heavy"}}]}})


@pytest.fixture(scope="module")
def fmus():
    return project_fmus()


def test_the_first_120_s_of_wltc3b_close_the_balance_and_match_the_road_load(fmus, tmp_path):
    out = tmp_path / "w120"
    assert main(["run", "wltc3b", "--stop-time", "120", "--out", str(out), "--quiet", "--no-figures"]) == 0
    r = read_results(out)
    metrics = json.loads((out / "metrics.json").read_text())
    _, vehicle = ce.plant_params(metrics)
    assert vehicle.gear_model == "power_flow"
    run = ce.whole_run(r, vehicle)
    b, w = run["balance"], run["wheel"]
    print(f"balance {b['residual_Wh']:.3e} Wh of {b['throughput_Wh']:.2f} Wh ({b['relative']:.2e}); wheel "
          f"{w['wheel']['net_Wh']:.4f} Wh net ({w['wheel']['traction_Wh']:.4f} traction), road-load integral "
          f"{w['road_load']['net_Wh']:.4f} ({w['road_load']['traction_Wh']:.4f}): {w['net_rel']:.2e}, "
          f"{w['traction_rel']:.2e}; regenerated {100 * run['regen_share']:.1f} % of drawn, "
          f"{100 * run['regen_of_braking']:.1f} % of the braking at the wheels")
    assert b["passed"] and abs(b["relative"]) < ce.BALANCE_TOL
    assert w["passed"] and abs(w["net_rel"]) < 1e-3 and abs(w["traction_rel"]) < 1e-3
    (low,) = ce.phase_energy(r, cycles.load("wltc3b"), vehicle)
    assert low["name"] == "low" and not low["complete"] and low["end"] == 120.0
    assert low["energy"]["dc_Wh"] == pytest.approx(run["energy"]["dc_Wh"], rel=1e-12)
    assert low["modes"]["closed"] == pytest.approx(120.0)  # the sensored drive: closed loop throughout
