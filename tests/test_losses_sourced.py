"""The sourced losses of the drive-cycle and speed-range scenarios (docs/speed-range.md, "The losses"):
each formula against its source's figure at a named point, the plant's powers against them, the
inverter's modulation share against the application note's closed forms, and bad input refused."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest

import pmsm_cosim.app
from pmsm_cosim.engine.system import read_toml
from pmsm_ev.losses import steady_state
from pmsm_ev.params import (
    M330_35A,
    PRIUS2004,
    PRIUS2004_GAP,
    SOURCED_IRON,
    SOURCED_IRON_MASS,
    SOURCED_K_WIND,
    SOURCED_T_M0,
    SOURCED_WINDAGE_POWER,
    WINDAGE_SPEED,
    MotorParams,
    ParameterError,
    PlantParams,
    VehicleParams,
    bearing_friction_torque,
    iron_loss_coefficients,
    lamination_loss_coefficients,
    rotor_windage_power,
    slot_w11_area,
)
from pmsm_ev.plant import Plant

#: the motor as the drive-cycle scenarios have it: the paper's B_m off, the sourced bearings and windage
SOURCED_MOTOR = MotorParams(dq_convention="amplitude_invariant", B_m=0.0, T_m0=SOURCED_T_M0, k_wind=SOURCED_K_WIND)


def test_bearing_friction_is_the_constant_coefficient_model():
    """M = 1/2 mu P d: a deep-groove ball bearing (SKF's mu = 0.0015), 250 N, 35 mm bore: 6.5625e-3 N m; two."""
    assert bearing_friction_torque(0.0015, 250.0, 0.035) == pytest.approx(6.5625e-3, rel=1e-15)
    assert SOURCED_T_M0 == pytest.approx(2 * 6.5625e-3, rel=1e-15)


def test_the_reference_geometry_is_the_2004_prius_models():
    """pyleecan's Toyota_Prius.json: stator 2 x 134.62 / 2 x 80.95 mm, 83.82 mm of stack, rotor 2 x 80.2 mm on a
    110.64 mm shaft: a 0.75 mm gap; its SlotW11 slot, 1 x 1.93 mm of opening and 1/2 (5 + 8) (33.3 - 4) mm^2 +
    a half circle of 4 mm radius: 217.5 mm^2; the stator's iron 15.8 kg in 7650 kg/m^3 at a stacking factor of
    0.95."""
    assert PRIUS2004_GAP == pytest.approx(0.75e-3, rel=1e-12)
    assert slot_w11_area(PRIUS2004["slot"]) * 1e6 == pytest.approx(1.93 + 0.5 * 13 * 29.3 + 8 * math.pi, rel=1e-12)
    annulus = 0.25 * math.pi * (0.26924**2 - 0.1619**2)
    assert SOURCED_IRON_MASS == pytest.approx((annulus - 48 * 217.5127e-6) * 0.08382 * 0.95 * 7650, rel=1e-6)
    assert SOURCED_IRON_MASS == pytest.approx(15.78, abs=0.01)


def test_windage_is_saaris_formula_on_the_prius_rotor():
    """At 1550.8 rad/s the 160.4 mm x 83.82 mm rotor with its 0.75 mm gap is in Saari's 500 < Re < 1e4 regime:
    C_M = 1.03 (2 delta / D)^0.3 / Re^0.5 on the surface, 0.146 / Re_r^0.2 on the faces (Re_r > 3e5) from the
    110.64 mm bore out, worked out here step by step; k_wind returns that power at that speed."""
    rho, mu, w = 1.204, 1.81e-5, WINDAGE_SPEED
    d_r, l_r, gap, d_i = 0.1604, 0.08382, 0.75e-3, 0.11064
    re = rho * w * (d_r / 2) * gap / mu
    assert 500.0 < re < 1e4
    cm = 1.03 * (2 * gap / d_r) ** 0.3 / math.sqrt(re)
    p_cyl = cm * math.pi * rho * w**3 * d_r**4 * l_r / 32
    re_r = rho * w * (d_r / 2) ** 2 / mu
    assert re_r > 3e5
    p_faces = 0.146 / re_r**0.2 * rho * w**3 * (d_r**5 - d_i**5) / 64
    assert (p_cyl, p_faces) == pytest.approx((78.74, 62.86), abs=0.01)
    assert SOURCED_WINDAGE_POWER == pytest.approx(p_cyl + p_faces, rel=1e-12)
    assert rotor_windage_power(w, PRIUS2004["D_r"], PRIUS2004["l"], PRIUS2004_GAP, PRIUS2004["D_ri"]) == (
        SOURCED_WINDAGE_POWER)
    assert SOURCED_K_WIND * w**3 == pytest.approx(SOURCED_WINDAGE_POWER, rel=1e-12)
    # Saari's regimes join without a jump worth the name (the fits meet within a few %)
    for re_edge in (64.0, 500.0, 1e4):
        lo = rotor_windage_power(re_edge * 0.999 * mu / (rho * (d_r / 2) * gap), d_r, l_r, gap, d_r)
        hi = rotor_windage_power(re_edge * 1.001 * mu / (rho * (d_r / 2) * gap), d_r, l_r, gap, d_r)
        assert hi == pytest.approx(lo, rel=0.2)


def test_friction_and_windage_at_top_speed_in_the_plant():
    """The plant's friction power at top speed is the bearings' 20.4 W plus the windage's 141.6 W (the paper's
    B_m, T_m0: 2.56 kW there)."""
    s = steady_state(SOURCED_MOTOR, PlantParams(), VehicleParams(), 0.0, 10.0, WINDAGE_SPEED)
    assert s["P_friction"] == pytest.approx(SOURCED_T_M0 * WINDAGE_SPEED + SOURCED_WINDAGE_POWER, rel=1e-9)
    assert s["P_friction"] == pytest.approx(161.96, abs=0.01)
    paper = steady_state(MotorParams(dq_convention="amplitude_invariant"), PlantParams(), VehicleParams(), 0.0,
                         10.0, WINDAGE_SPEED)
    assert paper["P_friction"] == pytest.approx(1e-3 * WINDAGE_SPEED**2 + 0.1 * WINDAGE_SPEED, rel=1e-9)


def test_the_lamination_reproduces_its_grade_figure():
    """M330-35A: 3.30 W/kg at 1.5 T, 50 Hz (the grade's name), the classical eddy coefficient
    pi^2 d^2 / (6 rho gamma) of a 0.35 mm sheet of 0.48 uOhm m and 7650 kg/m^3; at 1.0 T, 400 Hz the model gives
    19.4 W/kg."""
    k_h, k_e = lamination_loss_coefficients(M330_35A)
    assert k_e == pytest.approx(math.pi**2 * 0.35e-3**2 / (6 * 0.48e-6 * 7650), rel=1e-14)
    assert k_h * 50 * 1.5**2 + k_e * 50**2 * 1.5**2 == pytest.approx(3.30, rel=1e-14)
    assert k_h * 400 + k_e * 400**2 == pytest.approx(19.42, abs=0.01)


def test_the_plants_iron_losses_are_the_laminations_at_no_load():
    """At no load (psi_s = psi) and 6000 rpm, the plant's iron losses are k_build m (k_h f + k_e f^2) B_ref^2 of
    the 15.8 kg Prius stator at 1.5 T: 1034 W; at the same speed in field weakening, psi_s halved, a quarter."""
    m = MotorParams(dq_convention="amplitude_invariant")
    pl = PlantParams(iron_c_h=SOURCED_IRON[0], iron_c_e=SOURCED_IRON[1])
    w = 2.0 * math.pi * 100.0  # 6000 rpm
    f = m.N * w / (2.0 * math.pi)
    k_h, k_e = lamination_loss_coefficients()
    expected = 1.5 * SOURCED_IRON_MASS * (k_h * f + k_e * f**2) * 1.5**2
    s = steady_state(m, pl, VehicleParams(), 0.0, 0.0, w)
    assert s["P_iron"] == pytest.approx(expected, rel=1e-9)
    assert s["P_iron"] == pytest.approx(1034.13, abs=0.01)
    i_d = -0.5 * m.psi / m.L_d  # psi_d = psi / 2
    assert steady_state(m, pl, VehicleParams(), i_d, 0.0, w)["P_iron"] == pytest.approx(expected / 4, rel=1e-9)
    assert iron_loss_coefficients(SOURCED_IRON_MASS, 1.5, 0.08975) == SOURCED_IRON


@pytest.mark.parametrize("i_d,i_q,w", [(-40.0, 150.0, 300.0), (-200.0, 250.0, 550.0), (-60.0, -150.0, 300.0)])
def test_the_inverters_modulation_share_is_the_application_notes(i_d, i_q, w):
    """Averaged over an electrical period, the IGBT's and the diode's knees give Graovac and Puerschel's
    (Infineon AN 2009) closed forms: per switch V_CE0 I (1/(2 pi) + M cos(phi) / 8) and
    V_F0 I (1/(2 pi) - M cos(phi) / 8), M = 2 |v| / v_dc (the space-vector common mode adds nothing to
    them); the slopes alike (r_F = r_CE here): 2 r I^2 / 8 per phase; motoring and generating, within the
    linear range (|v| <= v_dc / sqrt 3)."""
    m = MotorParams(dq_convention="amplitude_invariant")
    pl = PlantParams(v_dc=360.0, inverter_losses=True, inv_r_f=PlantParams().inv_r_on)
    s = steady_state(m, pl, VehicleParams(), i_d, i_q, w)
    amp = math.hypot(i_d, i_q)
    v_amp = math.hypot(s["v_d"], s["v_q"])
    cos_phi = (s["v_d"] * i_d + s["v_q"] * i_q) / (v_amp * amp)
    mod = 2.0 * v_amp / pl.v_dc
    p_igbt = pl.inv_v0 * amp * (1 / (2 * math.pi) + mod * cos_phi / 8)
    p_diode = pl.inv_vf0 * amp * (1 / (2 * math.pi) - mod * cos_phi / 8)
    v_sw = pl.inv_e_sw * pl.v_dc / (pl.switching_period * pl.inv_v_ref * pl.inv_i_ref)
    expected = 6 * (p_igbt + p_diode) + 1.5 * pl.inv_r_on * amp**2 + 6 / math.pi * v_sw * amp
    assert s["P_inverter"] == pytest.approx(expected, rel=1e-5)


def test_the_inverters_figures_at_the_rated_current():
    """The inverter's figures at 400 A, 150 degC: V_CEsat = 1.65 V, V_F = 1.45 V from the knees and slopes;
    28.5 mJ per period at 300 V, 400 A: 285 W of switching per leg at 10 kHz, 342 W at 360 V."""
    pl = PlantParams(v_dc=360.0, inverter_losses=True)
    assert pl.inv_v0 + pl.inv_r_on * 400.0 == pytest.approx(1.65, rel=1e-12)
    assert pl.inv_vf0 + pl.inv_r_f * 400.0 == pytest.approx(1.45, rel=1e-12)
    v_sw = pl.inv_e_sw * pl.v_dc / (pl.switching_period * pl.inv_v_ref * pl.inv_i_ref)
    assert v_sw * 400.0 == pytest.approx(342.0, rel=1e-12)


def test_the_energy_balance_closes_with_the_sourced_losses_at_top_speed():
    """An open-loop coast at top speed in field weakening with every sourced loss on: E_dc = losses + wheel +
    kinetic + magnetic to round-off over 0.2 s (the drive loop's balance: tests/test_energy.py)."""
    p = Plant(SOURCED_MOTOR, VehicleParams(gear_model="power_flow"),
              PlantParams(v_dc=360.0, inverter_losses=True, iron_c_h=SOURCED_IRON[0], iron_c_e=SOURCED_IRON[1],
                          omega_m0=1500.0, i_d0=-250.0, i_q0=30.0))
    m = p.motor
    w_e = m.N * 1500.0
    v_d = m.R_s * -250.0 - w_e * m.L_q * 30.0
    v_q = m.R_s * 30.0 + w_e * (m.psi + m.L_d * -250.0)
    for _ in range(2000):
        c, s = math.cos(p.theta_e), math.sin(p.theta_e)
        p.step(c * v_d - s * v_q, s * v_d + c * v_q, 0.0, 1e-4)
    e = p.energies()
    assert e["E_iron"] > 0 and e["E_inverter"] > 0 and e["E_friction"] > 0
    assert abs(e["residual"]) < 1e-6 * e["E_dc_abs"]


@pytest.mark.parametrize("group,name", [("motor", "k_wind"), ("motor", "T_m0"), ("plant", "iron_c_h"),
                                        ("plant", "iron_c_e"), ("plant", "inv_vf0"), ("plant", "inv_r_f"),
                                        ("plant", "inv_e_sw")])
def test_a_negative_loss_coefficient_is_refused(group, name):
    cls = MotorParams if group == "motor" else PlantParams
    with pytest.raises(ParameterError, match=f"^{name} must be "):
        cls(**{name: -1e-3}).validate()


def test_a_negative_loss_coefficient_on_the_command_line_is_one_line_and_exit_2(tmp_path):
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-c", "from pmsm_cosim.app.cli import entry_point; entry_point()", "run",
                        "hwfet", "--stop-time", "0.01", "--set", "plant.k_wind=-1e-8", "--out", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 2, r.stderr
    errors = [line for line in r.stderr.strip().splitlines() if not line.startswith("note:")]
    assert len(errors) == 1 and "k_wind must be finite and >= 0" in errors[0]
    assert not out.exists()


def test_the_physical_scenarios_carry_the_sourced_losses_and_the_paper_scenarios_none():
    """Every shipped scenario that switches the inverter's losses on takes the sourced friction, windage and
    iron as plant start values (to their printed digits); scenario1 and scenario2 keep eq 8 and no iron."""
    folder = Path(pmsm_cosim.app.__file__).parent / "scenarios"
    sourced = {"B_m": 0.0, "T_m0": SOURCED_T_M0, "k_wind": SOURCED_K_WIND, "iron_c_h": SOURCED_IRON[0],
               "iron_c_e": SOURCED_IRON[1]}
    physical = 0
    for path in sorted(folder.glob("*.toml")):
        doc = read_toml(path, "scenario")  # the engine's reader: tomllib, or tomli on Python 3.10
        plant = next(c for c in doc["components"] if c["name"] == "plant").get("start", {})
        if plant.get("inverter_losses"):
            physical += 1
            for name, value in sourced.items():
                assert plant[name] == pytest.approx(value, rel=2e-3, abs=1e-12), (path.name, name)
        if path.stem in ("scenario1", "scenario2"):
            assert not set(sourced) & set(plant) and not plant.get("inverter_losses")
    assert physical == 21  # 17 (the cycles, their injection and I-f drives, the accelerations, hilly), the 2 batteries,
    # the 2 thermal runs


def test_the_sourced_losses_give_the_same_bits_compiled_or_not():
    """The plant's step with every sourced loss on (windage, iron, the inverter's modulation share): the same
    state and energies, bit for bit, from the compiled kernels as from the plain-Python ones."""
    pytest.importorskip("numba")
    from pmsm_ev import accel
    from pmsm_ev import kernels as plain

    compiled = accel.kernels()
    assert accel.compiled()
    p = Plant(SOURCED_MOTOR, VehicleParams(gear_model="power_flow"),
              PlantParams(v_dc=360.0, inverter_losses=True, iron_c_h=SOURCED_IRON[0], iron_c_e=SOURCED_IRON[1]))
    pp = [float(x) for x in p._pp]
    results = []
    for k in (plain, compiled):
        vec = pp if k is plain else accel.vector(len(pp))
        if k is compiled:
            for i, x in enumerate(pp):
                vec[i] = x
        ee = [0.0] * plain.PLANT_ENERGY if k is plain else accel.vector(plain.PLANT_ENERGY)
        x = (-150.0, 120.0, 700.0, 0.3)
        for j in range(200):
            v_alpha, v_beta = 150.0 * math.cos(0.35 * j), 150.0 * math.sin(0.35 * j)
            x = k.plant_step(x[0], x[1], x[2], x[3], v_alpha, v_beta, 0.02, 1e-4, vec, ee)[:4]
        results.append((tuple(x), tuple(float(e) for e in ee)))
    assert results[0] == results[1]
    assert results[0][1][plain.E_INVERTER] > 0 and results[0][1][plain.E_IRON] > 0
