"""The battery: its equivalent circuit (the open-circuit voltage at rest, the sag R0 i plus the RC pair's response, the
state of charge against the charge, the charge acceptance and discharge power), its energy balance inside the plant,
the same bits compiled or as plain Python, the controller on a measured DC link, and bad input refused
(docs/speed-range.md, "The battery")."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from pmsm_ev import kernels as k
from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.params import BatteryParams, ControllerParams, ParameterError, PlantParams, VehicleParams
from pmsm_ev.plant import Plant

ECM = BatteryParams(battery="ecm")
DT = 1e-3


def _battery(b: BatteryParams = ECM):
    """The plant's parameter and energy vectors of a plant on the battery ``b`` (plain Python kernels), at rest."""
    plant = Plant(plant=PlantParams(v_dc=360.0, inverter_losses=True), battery=b)
    pp = [float(x) for x in plant._pp]
    ee = [0.0] * k.PLANT_ENERGY
    k.battery_reset(pp, ee)
    return pp, ee


def _ocv(soc: float, b: BatteryParams = ECM) -> float:
    socs, volts = b.ocv_table()
    for z0, z1, v0, v1 in zip(socs, socs[1:], volts, volts[1:]):
        if z0 <= soc <= z1:
            return v0 + (v1 - v0) * (soc - z0) / (z1 - z0)
    raise AssertionError(soc)


def test_the_open_circuit_voltage_at_rest_is_the_tables():
    pp, ee = _battery()
    socs, volts = ECM.ocv_table()
    for z, v in zip(socs, volts):
        assert k.battery_ocv(z, pp) == v
    assert k.battery_ocv(0.5, pp) == pytest.approx(_ocv(0.5), rel=1e-15)
    assert k.battery_ocv(-0.1, pp) == volts[0] and k.battery_ocv(1.2, pp) == volts[-1]
    assert ee[k.E_BAT_V] == pytest.approx(_ocv(0.9), rel=1e-15)  # at rest: the open-circuit voltage
    for _ in range(1000):  # no current: nothing moves
        k.battery_step(0.0, DT, pp, ee)
    assert ee[k.E_BAT_V] == pytest.approx(_ocv(0.9), rel=1e-15) and ee[k.E_BAT_SOC] == 0.9
    assert ee[k.E_BAT_I] == 0.0 and ee[k.E_BAT_CHEM] == 0.0 and ee[k.E_BAT_LOSS] == 0.0


def test_the_sag_is_r0_i_plus_the_rc_pairs_response_and_the_soc_follows_the_charge():
    """30 kW for 60 s, then rest for 60 s: the current solves p = v i at the step's mean terminal voltage; the
    terminal voltage is OCV(soc) - R0 i - v_rc with v_rc the RC pair's exact response to the currents (a reference
    integrated here on its own), the state of charge the start's less the charge over the capacity; at rest the
    voltage recovers with the time constant R1 C1."""
    pp, ee = _battery()
    r0, r1, tau = ECM.bat_R0, ECM.bat_R1, ECM.bat_R1 * ECM.bat_C1
    v_rc = q = 0.0
    for n in range(120000):
        p = 30e3 if n < 60000 else 0.0
        k.battery_step(p, DT, pp, ee)
        i = ee[k.E_BAT_I]
        a = math.exp(-DT / tau)
        v_rc = r1 * i + (v_rc - r1 * i) * a
        q += i * DT
        if n == 0:
            assert i == pytest.approx(30e3 / (_ocv(0.9) - r0 * i), rel=2e-5)  # the first step: R0 alone, nearly
        soc = 0.9 - q / (3600.0 * ECM.bat_capacity)
        assert ee[k.E_BAT_SOC] == pytest.approx(soc, rel=1e-12)
        assert ee[k.E_BAT_V] == pytest.approx(_ocv(soc) - r0 * i - v_rc, rel=1e-12)
        if n == 59999:
            sag_end = _ocv(soc) - ee[k.E_BAT_V]
            i_end, v_rc_end = i, v_rc
        if n == 60000 + round(tau / DT) - 1:  # one time constant into the rest
            assert ee[k.E_BAT_V] == pytest.approx(_ocv(soc) - v_rc_end / math.e, rel=1e-6)
    assert sag_end == pytest.approx(r0 * i_end + r1 * i_end * (1.0 - math.exp(-60.0 / tau)), rel=2e-3)
    assert 75.0 < i_end < 85.0  # 30 kW at ~375 V
    assert ee[k.E_BAT_Q] == pytest.approx(q, rel=1e-12)


def test_the_battery_balance_closes():
    """Chemical energy = terminal + the battery's losses + the RC pair's capacitor, over a drive of discharge and
    charge; the losses are R0 i^2 and R1's share."""
    pp, ee = _battery()
    terminal = 0.0
    for n in range(50000):
        p = 40e3 * math.sin(n * 2e-3)
        k.battery_step(p, DT, pp, ee)
        terminal += p * DT
    residual = ee[k.E_BAT_CHEM] - (terminal + ee[k.E_BAT_LOSS] + ee[k.E_BAT_W])
    assert abs(residual) < 1e-9 * abs(ee[k.E_BAT_CHEM]) + 1e-6
    assert ee[k.E_BAT_LOSS] > 0.0


def test_the_limits_charge_acceptance_and_discharge_power():
    pp, ee = _battery()
    r0 = ECM.bat_R0

    def limits(soc):
        ee[k.E_BAT_SOC], ee[k.E_BAT_VRC] = soc, 0.0
        k.battery_limits(pp, ee)
        return ee[k.E_BAT_P_CHG], ee[k.E_BAT_P_DIS]

    e = _ocv(0.5)
    p_chg, p_dis = limits(0.5)
    assert p_chg == pytest.approx((e + r0 * 125.0) * 125.0, rel=1e-12)  # the charge current limit
    assert p_dis == pytest.approx((e - r0 * 250.0) * 250.0, rel=1e-12)
    e = _ocv(0.975)  # half-way up the taper, and the voltage ceiling: whichever is lower
    i_c = min(125.0 * 0.5, (ECM.bat_v_max - e) / r0)
    assert limits(0.975)[0] == pytest.approx((e + r0 * i_c) * i_c, rel=1e-12)
    assert limits(1.0)[0] == 0.0 and limits(1.0)[1] > 0.0  # full: no charge accepted
    e = _ocv(0.01)  # nearly empty: the discharge current within v_min
    i_d = (e - ECM.bat_v_min) / r0
    assert i_d < 250.0 and limits(0.01)[1] == pytest.approx((e - r0 * i_d) * i_d, rel=1e-12)
    assert limits(-0.01)[1] == 0.0


def test_the_controller_follows_the_measured_dc_link():
    """A measured DC link moves the unit's voltage limits (the current control's v_dc / sqrt 3 and the field
    weakening's fw_margin of it) and holds the torque within the battery's powers at the shaft; unconnected (0) it
    changes nothing."""
    u = ControlUnit("sensored", controller=ControllerParams(reference="fw", v_dc=360.0, P_regen_max=0.0))
    c = u._c
    before = [float(x) for x in c]
    u.dc_link(0.0, 1e3, 1e3)
    assert [float(x) for x in c] == before
    u.dc_link(330.0, 20e3, 60e3)
    assert c[k.C_U_MAX] == 330.0 / math.sqrt(3.0)
    assert c[k.C_U_FW] == ControllerParams().fw_margin * c[k.C_U_MAX]
    assert k.battery_power_limit(-100.0, 500.0, 20e3, 60e3) == -40.0  # braking: 20 kW at 500 rad/s
    assert k.battery_power_limit(200.0, 500.0, 20e3, 60e3) == 120.0  # motoring: 60 kW
    assert k.battery_power_limit(10.0, 500.0, 20e3, 60e3) == 10.0
    assert k.battery_power_limit(-50.0, 0.0, 0.0, 0.0) == -50.0  # no power at standstill


def test_the_plant_on_the_battery_closes_both_balances_and_sags():
    """The sensored drive accelerating the car to 1000 rad/s for 3 s on the battery, its controller on the measured
    DC link: the plant's energy balance and the battery's both close; the terminal voltage sags below the
    open-circuit voltage while it draws."""
    p = Plant(plant=PlantParams(v_dc=360.0, inverter_losses=True), vehicle=VehicleParams(gear_model="power_flow"),
              battery=ECM)
    u = ControlUnit("sensored", controller=ControllerParams(reference="fw", v_dc=360.0, current_control="high_speed"))
    for n in range(30000):
        u.dc_link(p.energy[k.E_BAT_V], p.energy[k.E_BAT_P_CHG], p.energy[k.E_BAT_P_DIS])
        u.step(p.i_alpha, p.i_beta, min(n * 1e-4 * 400.0, 1000.0), p.theta_e, p.omega_m)
        p.step(*u.v_out, 0.0, 1e-4, u.T_brake)
    e = p.energies()
    assert p.omega_m > 700.0 and e["E_dc"] > 1e5
    assert abs(e["residual"]) < 1e-6 * e["E_dc_abs"]
    assert abs(e["residual_battery"]) < 1e-9 * e["E_chemical"]
    assert e["soc"] < 0.9 and e["i_bat"] > 100.0 and e["v_bat"] < _ocv(e["soc"]) - ECM.bat_R0 * 100.0
    assert e["E_chemical"] > e["E_dc"] > 0.0


def test_the_battery_gives_the_same_bits_compiled_or_not():
    pytest.importorskip("numba")
    from pmsm_ev import accel

    compiled = accel.kernels()
    assert accel.compiled()
    p = Plant(plant=PlantParams(v_dc=360.0, inverter_losses=True, dead_time=2e-6), battery=ECM)
    pp = [float(x) for x in p._pp]
    results = []
    for kk in (k, compiled):
        vec = pp[:] if kk is k else accel.vector(len(pp))
        if kk is compiled:
            for i, x in enumerate(pp):
                vec[i] = x
        ee = [0.0] * k.PLANT_ENERGY if kk is k else accel.vector(k.PLANT_ENERGY)
        kk.battery_reset(vec, ee)
        x = (-150.0, 120.0, 700.0, 0.3)
        for j in range(300):
            v_alpha, v_beta = 150.0 * math.cos(0.35 * j), 150.0 * math.sin(0.35 * j)
            x = kk.plant_step(x[0], x[1], x[2], x[3], v_alpha, v_beta, 0.02, 1e-4, vec, ee)[:4]
        results.append((tuple(x), tuple(float(e) for e in ee), kk.dc_link_limit(vec, ee, 0.0)))
    assert results[0] == results[1]
    assert results[0][1][k.E_BAT_CHEM] != 0.0


@pytest.mark.parametrize("change,message", [
    ({"bat_ocv_soc": "0, 0.3, 0.6, 1", "bat_ocv_v": "288, 380, 370, 401"},
     "bat_ocv_v (the open-circuit voltage table) is not monotonic"),
    ({"bat_ocv_soc": "0, 0.5, 0.4, 1", "bat_ocv_v": "288, 350, 380, 401"}, "bat_ocv_soc is not monotonic"),
    ({"bat_ocv_soc": "0, 0.5, 1"}, "bat_ocv_soc and bat_ocv_v must have as many points"),
    ({"bat_capacity": 0.0}, "bat_capacity must be > 0 Ah"),
    ({"bat_capacity": -5.0}, "bat_capacity must be > 0 Ah"),
    ({"bat_soc0": 1.2}, "bat_soc0 must be in [0, 1]"),
    ({"bat_soc0": -0.1}, "bat_soc0 must be in [0, 1]"),
    ({"bat_R0": -1e-3}, "bat_R0 must be finite and >= 0"),
    ({"bat_R1": -1e-3}, "bat_R1 must be finite and >= 0"),
    ({"bat_ocv_v": "288, x, 401"}, "bat_ocv_v: 'x' is not a number"),
    ({"battery": "lead"}, "battery must be one of"),
])
def test_bad_battery_input_is_refused(change, message):
    with pytest.raises(ParameterError) as info:
        BatteryParams(**change).validate()
    assert str(info.value).startswith(message)


# the command line's path once in the default run; the other settings' messages are test_bad_battery_input_is_refused's
@pytest.mark.parametrize("setting,message", [("plant.bat_capacity=0", "bat_capacity must be > 0 Ah"),
                                             pytest.param("plant.bat_ocv_v=288,380,370,390,395,396,397,398,399,400,401",
                                                          "bat_ocv_v (the open-circuit voltage table) is not monotonic",
                                                          marks=pytest.mark.slow),
                                             pytest.param("plant.bat_soc0=1.5", "bat_soc0 must be in [0, 1]",
                                                          marks=pytest.mark.slow),
                                             pytest.param("plant.bat_R0=-0.1", "bat_R0 must be finite and >= 0",
                                                          marks=pytest.mark.slow)])
def test_bad_battery_input_on_the_command_line_is_one_line_and_exit_2(tmp_path, setting, message):
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-c", "from pmsm_cosim.app.cli import entry_point; entry_point()", "run",
                        "wltc3b-battery", "--stop-time", "0.01", "--set", setting, "--out", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 2, r.stderr
    errors = [line for line in r.stderr.strip().splitlines() if not line.startswith("note:")]
    assert len(errors) == 1 and message in errors[0], r.stderr
    assert not out.exists()


def test_the_first_60_s_of_wltc3b_battery_close_the_balances(tmp_path):
    """The shipped scenario on the battery: the plant's balance (ideal link's terms) and the battery's close to
    1e-6 of the throughput; the state of charge falls from 0.9 by the charge drawn; the controller reads the
    battery's voltage (the run completes in the band); from a full pack the charge acceptance refuses the braking
    the friction brake then takes."""
    from pmsm_cosim.app.cli import main
    from pmsm_cosim.app.metrics import cycle_energy as ce
    from pmsm_cosim.engine.recording import read_results

    out = tmp_path / "b60"
    assert main(["run", "wltc3b-battery", "--stop-time", "60", "--out", str(out), "--quiet", "--no-figures"]) == 0
    r = read_results(out)
    metrics = json.loads((out / "metrics.json").read_text())
    _, vehicle = ce.plant_params(metrics)
    run = ce.whole_run(r, vehicle)
    assert run["balance"]["passed"] and abs(run["balance"]["relative"]) < 1e-6
    bat = metrics["energy"]["battery"]
    assert bat["soc_start"] == pytest.approx(0.9, abs=1e-6)
    assert bat["soc_end"] == pytest.approx(0.9 - bat["charge_Ah"] / ECM.bat_capacity, abs=1e-9)
    assert abs(bat["residual_Wh"]) < 1e-6 * metrics["energy"]["drawn_Wh"]
    assert bat["chemical_Wh"] > bat["terminal_Wh"] > 0.0 and bat["v_bat_min"] < bat["v_bat_max"]
    assert metrics["trace"]["inside_share"] > 0.99
    # from a full pack the charge acceptance is 0 and grows as the charge falls: the friction brake takes the rest
    full = tmp_path / "full"
    assert main(["run", "wltc3b-battery", "--stop-time", "60", "--set", "plant.bat_soc0=1.0", "--out", str(full),
                 "--quiet", "--no-figures"]) == 0
    refused = json.loads((full / "metrics.json").read_text())["energy"]
    assert metrics["energy"]["brake_Wh"] < 1e-9 and refused["brake_Wh"] > 3.0
    assert refused["regen_Wh"] < 0.5 * metrics["energy"]["regen_Wh"]
