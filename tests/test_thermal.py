"""The motor's thermal network (``PlantParams.thermal_model`` 'lptn', ``pmsm_ev.kernels.thermal_network_step``):
its steady state and time constants against the linear network solved here, heat conserved, R_s and psi following
the winding's and the magnet's temperatures, the compiled step equal to the Python one bit for bit, bad input.
The long drives (WLTC, US06 repeated) are in docs/speed-range.md, "A motor that warms"."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from pmsm_cosim.app import thermal_metrics
from pmsm_cosim.app.drive import load_system
from pmsm_cosim.app.overrides import apply_overrides
from pmsm_cosim.app.thermal_metrics import thermal_figures
from pmsm_ev import accel, cycles
from pmsm_ev import kernels as k
from pmsm_ev.params import (
    SOURCED_IRON,
    MotorParams,
    ParameterError,
    PlantParams,
    flux_model_coefficients,
    magnet_flux,
    winding_resistance,
)
from pmsm_ev.plant import THERMAL_SLOTS, Plant
from pmsm_ev.thermal import steady_temperatures

DT = 1e-4
T_COOL = 65.0
LPTN = PlantParams(thermal_model="lptn", T_ambient=T_COOL, T_winding=T_COOL, T_magnet=T_COOL)


def _conductance_matrix(p: PlantParams) -> np.ndarray:
    """The network's conductance matrix G [W/K] (nodes yoke, tooth, winding, magnet; the coolant grounded), built
    here from the resistances of ``PlantParams`` as Wallscheid and Boecker draw the network."""
    g = np.zeros((4, 4))
    edges = {(0, 2): p.lptn_R_yoke_winding, (0, 1): p.lptn_R_yoke_tooth, (1, 2): p.lptn_R_tooth_winding,
             (1, 3): p.lptn_R_tooth_magnet, (2, 3): p.lptn_R_winding_magnet}
    for (i, j), r in edges.items():
        g[i, j] -= 1.0 / r
        g[j, i] -= 1.0 / r
        g[i, i] += 1.0 / r
        g[j, j] += 1.0 / r
    g[0, 0] += 1.0 / p.lptn_R_yoke_coolant
    g[3, 3] += 1.0 / p.lptn_R_magnet_ambient
    return g


def _capacities(p: PlantParams) -> np.ndarray:
    return np.array([p.lptn_C_yoke, p.lptn_C_tooth, p.lptn_C_winding, p.lptn_C_magnet])


def _network(p: PlantParams):
    """(pp, ee) of a plant with the thermal model ``p``: the kernel's vectors, in plain Python lists."""
    plant = Plant(plant=p)
    return [float(x) for x in plant._pp], [float(x) for x in plant.energy]


def _run_network(p: PlantParams, q_cu: float, q_res: float, dt: float, steps: int):
    """The kernel alone (plain Python): ``steps`` steps of ``dt`` with the copper and residual losses [W] held."""
    pp, ee = _network(p)
    for _ in range(steps):
        k.thermal_network_step(q_cu * dt, q_res * dt, dt, pp, ee)
    return pp, ee


def _temperatures(ee) -> np.ndarray:
    return np.array(ee[k.E_TH_T:k.E_TH_T + 4])


def test_the_steady_state_is_the_losses_through_the_network():
    """1 kW of copper and 400 W of residual losses held: the temperatures settle where G (T - T_cool) = P, the
    network's P R (the linear system solved here): the losses' split (rotor 28.1 %, yoke 74.2 % of the stator's)
    as stated in ``PlantParams``; the one-node winding at T_cool + P R_th."""
    p = LPTN
    q_cu, q_res = 1000.0, 400.0
    # 1.2e5 s: 30 slowest time constants (Euler stable: dt < 2 x the fastest, 16 s)
    _, ee = _run_network(p, q_cu, q_res, dt=10.0, steps=12000)
    rotor = p.lptn_rotor_share * q_res
    yoke = p.lptn_yoke_share * (q_res - rotor)
    power = np.array([yoke, q_res - rotor - yoke, q_cu, rotor])
    expected = T_COOL + np.linalg.solve(_conductance_matrix(p), power)
    assert _temperatures(ee) == pytest.approx(expected, rel=1e-9)
    assert expected[2] - T_COOL > 40.0  # the winding: 45 K per kW of copper losses, 48.5 K here
    one = PlantParams(thermal_R=0.05, thermal_C=20.0, T_ambient=T_COOL, T_winding=T_COOL)
    _, ee = _run_network(one, 1500.0, 0.0, dt=0.01, steps=20000)  # 200 s, 200 time constants
    assert ee[k.E_TH_T + k.TH_W] - T_COOL == pytest.approx(1500.0 * 0.05, rel=1e-12)
    assert ee[k.E_TH_T + k.TH_M] == one.T_magnet  # no magnet node: its temperature holds


def test_the_time_constants_are_the_networks():
    """The one-node winding reaches 1 - 1/e of P R_th after R_th C_th; the four nodes follow the linear network's
    exact solution T(t) = T_inf + V exp(-Lambda t) V^-1 (T0 - T_inf) (eigen-decomposition of C^-1 G) after 600 s,
    to the Euler step's error (dt / tau < 1e-3 here)."""
    one = PlantParams(thermal_R=0.05, thermal_C=20.0, T_ambient=T_COOL, T_winding=T_COOL)
    _, ee = _run_network(one, 1500.0, 0.0, dt=DT, steps=10000)  # one time constant, 1 s, in the plant's steps
    assert ee[k.E_TH_T + k.TH_W] - T_COOL == pytest.approx(75.0 * (1.0 - math.exp(-1.0)), rel=1e-4)
    p = LPTN
    g, c = _conductance_matrix(p), _capacities(p)
    q_cu, q_res, t_end, dt = 2000.0, 500.0, 600.0, 0.01
    _, ee = _run_network(p, q_cu, q_res, dt=dt, steps=int(round(t_end / dt)))
    rotor = p.lptn_rotor_share * q_res
    yoke = p.lptn_yoke_share * (q_res - rotor)
    rise_inf = np.linalg.solve(g, [yoke, q_res - rotor - yoke, q_cu, rotor])
    lam, vec = np.linalg.eig(-g / c[:, None])
    tau = sorted(-1.0 / lam.real)
    assert tau[0] > 15.0 and tau[-1] > 3000.0  # 16 s (the stator's teeth and winding) .. 65 min (the rotor)
    rise = rise_inf + (vec @ np.diag(np.exp(lam * t_end)) @ np.linalg.solve(vec, -rise_inf)).real
    assert _temperatures(ee) - T_COOL == pytest.approx(rise, rel=2e-4)
    assert rise[2] > 50.0 and rise[3] > 5.0  # the winding and the magnet did heat


def test_heat_is_conserved_and_comes_from_the_losses():
    """The plant turning with the sourced iron losses and a torque: the heat put in is the copper, iron and friction
    losses the energy accounting integrates (all of it with 'lptn'), and it is what the nodes store plus what the
    coolant took, to round-off."""
    p = dataclasses.replace(LPTN, iron_c_h=SOURCED_IRON[0], iron_c_e=SOURCED_IRON[1], omega_m0=150.0)
    plant = Plant(plant=p)
    for n in range(4000):
        plant.step(20.0 * math.cos(0.01 * n), 40.0, 0.0, DT)
    e, th = plant.energies(), plant.thermal()
    heat = e["E_copper"] + e["E_iron"] + e["E_friction"]
    assert e["E_iron"] > 1.0 and e["E_copper"] > 1.0 and e["E_friction"] > 0.01
    assert th["Q_heat"] == pytest.approx(heat, rel=1e-12)
    assert th["Q_stored"] + th["Q_coolant"] == pytest.approx(th["Q_heat"], rel=1e-12)
    assert th["Q_coolant"] > 0.0 or plant.T_winding > T_COOL


def test_r_s_and_psi_follow_the_temperatures():
    """After heating: R_s = R_s20 (1 + alpha_R (T_w - 20)), psi = psi20 (1 + alpha_psi (T_m - 20)) in the vector eqs
    10-12 read, so the torque of a current falls with the magnet's temperature; the algebraic flux model's magnet
    (i_f, psi0, w0) is ``flux_model_coefficients``' at that psi."""
    p = dataclasses.replace(LPTN, T_magnet=120.0, lptn_C_magnet=50.0, lptn_C_winding=20.0, lptn_C_tooth=50.0,
                            lptn_C_yoke=100.0)  # small capacities: the temperatures move within the test
    plant = Plant(plant=p)
    for _ in range(5000):
        plant.step(0.0, 2.0, 0.0, DT)
    m, th = plant.motor, plant.thermal()
    assert th["T_pm"] < 119.0 and th["T_wdg"] > T_COOL  # the hot magnet cools, the winding heats
    assert th["R_s"] == winding_resistance(m.R_s, th["T_wdg"], p.alpha_R)
    assert th["psi"] == magnet_flux(m.psi, th["T_pm"], p.alpha_psi)
    i_d, i_q = plant.i_d, plant.i_q
    assert plant.T_e == pytest.approx(m.k_dq * m.N * (th["psi"] * i_q + (m.L_d - m.L_q) * i_d * i_q), rel=1e-12)
    alg = dataclasses.replace(p, flux_model="algebraic")
    plant = Plant(plant=alg)
    for _ in range(2000):
        plant.step(0.0, 2.0, 0.0, DT)
    psi_t = plant.thermal()["psi"]
    assert psi_t == magnet_flux(m.psi, plant.T_magnet, p.alpha_psi) and plant.T_magnet < 119.5
    ref = flux_model_coefficients(m, alg, psi_t)
    got = [float(plant._pp[k.P_FLUX_C + j]) for j in range(12)]
    assert got[:9] == list(ref[:9])  # the iron's curve: the 20 degC one
    assert got[9:] == pytest.approx(ref[9:], rel=1e-13, abs=1e-15)  # i_f, psi0, w0 of the hot magnet
    # the plant's memo of psi(i) (``plant_flux_linkages``) is the hot magnet's: the flux solved afresh (to the
    # rounding of the currents the step derives from its state, the flux linkages; the cold magnet's is % away)
    kk = plant._kernels
    fresh = kk.flux_linkages(plant.i_d, plant.i_q, plant._pp, k.P_FLUX_C)
    assert kk.plant_flux_linkages(plant.i_d, plant.i_q, plant._pp) == pytest.approx(fresh, rel=1e-13, abs=1e-15)
    warm = [float(x) for x in plant._pp[k.P_FLUX_MEMO:k.P_FLUX_MEMO + 5]]
    assert warm[:3] == [1.0, plant.i_d, plant.i_q]
    assert warm[3:] == pytest.approx(fresh, rel=1e-13, abs=1e-15)


def test_the_compiled_step_is_the_python_step_bit_for_bit():
    """``Plant.step`` (the compiled ``plant_advance``), the plant FMU's C step ``plant_fmu_step`` on the same buffers
    and the plain-Python kernel give the same bits over 300 steps with the network on and psi, R_s moving (small
    capacities), the iron losses and current noise on."""
    if not accel.compiled():
        pytest.skip("needs numba")
    p = dataclasses.replace(LPTN, lptn_C_magnet=5.0, lptn_C_winding=2.0, lptn_C_tooth=5.0, lptn_C_yoke=10.0,
                            lptn_R_yoke_coolant=0.5, iron_c_h=SOURCED_IRON[0], iron_c_e=SOURCED_IRON[1],
                            sensor_noise=1.0, omega_m0=100.0, flux_model="algebraic")
    a, b = Plant(plant=p), Plant(plant=p)
    plain = Plant(plant=p)
    pio, ppp, pee = list(plain.io), list(plain._pp), list(plain.energy)
    fmu_step = a._kernels.plant_fmu_step
    for n in range(300):
        v = (30.0 * math.cos(0.02 * n), 25.0)
        a.step(*v, 0.0, DT)
        b.io[k.PIO_V_ALPHA], b.io[k.PIO_V_BETA], b.io[k.PIO_DELTA], b.io[k.PIO_T_BRAKE] = *v, 0.0, 0.0
        assert fmu_step(b.io, b._pp, b.energy, DT) == k.STEP_TAKEN
        assert k.plant_advance(pio, ppp, pee, *v, 0.0, 0.0, DT, False)
    state = slice(k.PIO_I_ALPHA, k.PIO_SAVE)  # the outputs and the state (not the inputs the FMU wrote, the scratch)
    assert a.io.tolist()[state] == b.io.tolist()[state] == pio[state]
    assert a._pp.tolist() == b._pp.tolist() == ppp
    assert a.energy.tolist() == b.energy.tolist() == pee
    assert a.T_winding > T_COOL + 1.0 and a.thermal()["psi"] != magnet_flux(a.motor.psi, T_COOL, p.alpha_psi)


def test_the_outputs_with_the_model_off_are_the_start_temperatures():
    """Off (the default): no heat, the nodes hold the start temperatures, R_s and psi are those of ``T_winding``,
    ``T_magnet`` (the effect that was there before the network)."""
    p = PlantParams(T_winding=90.0, T_magnet=70.0)
    plant = Plant(plant=p)
    for _ in range(100):
        plant.step(5.0, 5.0, 0.0, DT)
    th = plant.thermal()
    assert (th["T_wdg"], th["T_pm"], th["T_yoke"], th["T_tooth"]) == (90.0, 70.0, 90.0, 90.0)
    assert th["Q_heat"] == th["Q_coolant"] == th["over_temperature"] == 0.0
    assert th["R_s"] == winding_resistance(MotorParams().R_s, 90.0, p.alpha_R)
    assert th["psi"] == magnet_flux(MotorParams().psi, 70.0, p.alpha_psi)
    assert set(THERMAL_SLOTS) <= set(th)


def test_over_temperature_flags_the_node_that_reached_its_limit():
    """The flags say which limit is reached: the winding's insulation limit first with copper losses (1), the magnet's
    too once it is past its own (1 + 2)."""
    p = dataclasses.replace(LPTN, T_winding_max=T_COOL + 10.0, T_magnet_max=T_COOL + 1.0)
    pp, ee = _network(p)
    assert ee[k.E_TH_OVER] == 0.0
    steps = 0
    while ee[k.E_TH_OVER] == 0.0 and steps < 10000:
        k.thermal_network_step(5000.0, 0.0, 1.0, pp, ee)
        steps += 1
    assert ee[k.E_TH_OVER] == k.TH_OVER_WINDING and ee[k.E_TH_T + k.TH_W] >= T_COOL + 10.0
    while ee[k.E_TH_OVER] == k.TH_OVER_WINDING and steps < 10000:
        k.thermal_network_step(5000.0, 0.0, 1.0, pp, ee)
        steps += 1
    assert ee[k.E_TH_OVER] == k.TH_OVER_WINDING + k.TH_OVER_MAGNET


@pytest.mark.parametrize("changes,message", [
    ({"lptn_R_tooth_magnet": -0.5}, "lptn_R_tooth_magnet must be > 0 K/W (got -0.5)"),
    ({"lptn_C_magnet": 0.0}, "lptn_C_magnet must be > 0 J/K (got 0.0)"),
    ({"T_winding_max": 60.0}, "T_winding_max = 60.0 degC must be above the coolant's T_ambient = 65.0 degC"),
    ({"T_magnet_max": 65.0}, "T_magnet_max = 65.0 degC must be above the coolant's T_ambient = 65.0 degC"),
    ({"lptn_rotor_share": 1.5}, "lptn_rotor_share must be in [0, 1] (got 1.5)"),
    ({"thermal_model": "fem"}, "thermal_model must be one of"),
    ({"thermal_R": 0.05}, "thermal_model 'lptn' has its own winding-to-coolant path: set thermal_R = 0"),
    ({"lptn_C_winding": 1e-3}, "the thermal network's fastest node has C / sum"),
])
def test_bad_input_is_one_line_naming_the_field(changes, message):
    with pytest.raises(ParameterError, match=re.escape(message)) as err:
        dataclasses.replace(LPTN, **changes).validate()
    assert "\n" not in str(err.value)


# -- the application's figures (metrics.json 'thermal') and the heat run's cycle --------------------------------------
def _columns(t_w, t_m, time=None):
    n = len(t_w)
    time = np.arange(n, dtype=float) if time is None else time
    p = LPTN
    psi = np.array([magnet_flux(MotorParams().psi, x, p.alpha_psi) for x in t_m])
    r_s = np.array([winding_resistance(MotorParams().R_s, x, p.alpha_R) for x in t_w])
    over = (np.asarray(t_w) >= p.T_winding_max) * 1.0 + (np.asarray(t_m) >= p.T_magnet_max) * 2.0
    return {"time": time, "T_wdg": np.asarray(t_w, float), "T_pm": np.asarray(t_m, float), "psi_now": psi,
            "R_s_now": r_s, "over_temperature": over}


@pytest.mark.parametrize("t_w,t_m,first,when", [
    ([65, 120, 181, 185, 170], [65, 90, 140, 151, 152], "winding", 2.0),
    ([65, 120, 150, 170, 175], [65, 100, 149, 150, 160], "magnet", 3.0),
    ([65, 100, 120, 110, 100], [65, 80, 90, 95, 99], "neither", None),
])
def test_what_limits_first_is_the_first_limit_reached(t_w, t_m, first, when):
    th = thermal_figures(_columns(t_w, t_m), LPTN.T_winding_max, LPTN.T_magnet_max)
    assert th["limits_first"] == first
    assert (th["t_winding_limit"] if first == "winding" else th["t_magnet_limit"]) == when
    assert th["winding"]["T_peak"] == max(t_w) and th["magnet"]["T_peak"] == max(t_m)
    assert th["psi_fall"] == pytest.approx(1.0 - (1.0 + LPTN.alpha_psi * (max(t_m) - 20.0))
                                           / (1.0 + LPTN.alpha_psi * (65.0 - 20.0)), rel=1e-12)
    assert (th["t_over_temperature"] is None) == (first == "neither")


def test_the_sustained_figures_are_the_networks_steady_state_under_the_last_repetitions_losses():
    """Two repetitions of 10 s: the second's mean losses (copper 800 W, iron 300 W, friction 50 W) held give the
    network's steady state (``steady_temperatures``, checked against the matrix solved here), the current per torque
    of each repetition the least-squares slope of |i_s| on |T_e|."""
    time = np.linspace(0.0, 20.0, 201)
    r = _columns(np.full(201, 70.0), np.full(201, 66.0), time)
    ramp = np.where(time > 10.0, time - 10.0, 0.0)
    r.update(E_copper=100.0 * time + 800.0 * ramp, E_iron=300.0 * ramp, E_friction=50.0 * ramp,
             T_e=np.where(time >= 10.0, 100.0, 50.0), i_d=np.zeros(201), i_q=np.where(time >= 10.0, 420.0, 200.0))
    th = thermal_figures(r, LPTN.T_winding_max, LPTN.T_magnet_max, repeats=2, params=LPTN)
    sus = th["sustained"]
    assert sus["P_copper_W"] == pytest.approx(900.0) and sus["P_residual_W"] == pytest.approx(350.0)
    rotor = LPTN.lptn_rotor_share * 350.0
    yoke = LPTN.lptn_yoke_share * (350.0 - rotor)
    expected = T_COOL + np.linalg.solve(_conductance_matrix(LPTN), [yoke, 350.0 - rotor - yoke, 900.0, rotor])
    assert list(steady_temperatures(LPTN, 900.0, 350.0)) == pytest.approx(list(expected), rel=1e-12)
    assert (sus["T_winding"], sus["T_magnet"]) == pytest.approx((expected[2], expected[3]), rel=1e-12)
    assert sus["T_coolant_magnet_limit"] == pytest.approx(LPTN.T_magnet_max - (expected[3] - T_COOL))
    assert sus["limits_first"] == ("magnet" if sus["margin_magnet_K"] < sus["margin_winding_K"] else "winding")
    assert th["current_per_torque_by_repeat"] == pytest.approx([4.0, 4.2])
    assert th["current_per_torque_rise"] == pytest.approx(0.05)


def test_a_cycle_repeated_is_driven_back_to_back():
    us06 = cycles.load("us06")
    five = cycles.repeated(us06, 5)
    assert five.duration == 5 * us06.duration and five.repeats == 5 and five.name == "us06x5"
    assert np.array_equal(five.speed[600:1201], us06.speed) and np.all(np.diff(five.time) > 0)
    wltc = cycles.repeated(cycles.load("wltc3b"), 2)
    assert [p.name for p in wltc.phases][3:5] == ["extra_high_1", "low_2"] and wltc.phases[4].start == 1800.0
    assert cycles.repeated(us06, 1) is us06
    with pytest.raises(cycles.CycleError, match="repeat must be a whole number >= 1"):
        cycles.repeated(us06, 0)
    spec = load_system("us06x5-thermal")
    assert spec.stop_time == 3000.0 and spec.signals["omega_ref"].cycle.repeats == 5


def test_the_limits_and_the_network_are_the_runs_own():
    """The verdict's limits and the sustained figures' network are the run's plant's: its system file's values and the
    command line's (text there: ``--set plant.T_magnet_max=120``)."""
    spec = apply_overrides("us06x5-thermal", set=["plant.T_ambient=90", "plant.T_magnet_max=120"], cli=True)
    p = thermal_metrics._plant_params(spec)
    assert (p.thermal_model, p.T_ambient, p.T_magnet_max, p.T_winding_max, p.T_winding) == (
        "lptn", 90.0, 120.0, 180.0, 65.0)


def test_the_network_on_where_its_columns_are_not_recorded_is_said():
    """``--set plant.thermal_model=lptn`` on a scenario that records none of the network's columns: the run's figures
    as they are, and a note (metrics.json's ``metrics_note``, printed by ``pmsm-cosim run``) that no thermal figures
    were made and why; with the network off, the figures untouched."""
    def figures(out_dir, columns, rows):
        return {"rows": rows}

    on = apply_overrides("wltc3b-sensorless", set=["plant.thermal_model=lptn"], cli=True)
    m = thermal_metrics.with_thermal_figures(figures, on)(None, [], 10)
    assert m["rows"] == 10 and "thermal" not in m
    assert m["metrics_note"].startswith("no thermal figures: the thermal network is on, but T_wdg, T_pm")
    assert thermal_metrics.with_thermal_figures(figures, load_system("wltc3b-sensorless")) is figures
