"""The reference generator (pmsm_ev.kernels.references, pmsm_ev.references): against a brute-force
search over the current plane, its regions and their boundaries, the one-line errors of its parameters,
and a closed loop (Plant + sensored ControlUnit, reference 'fw') that accelerates the car through field
weakening and brakes it regeneratively within a power limit (docs/speed-range.md)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from pmsm_ev import accel
from pmsm_ev import kernels as k
from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.params import ControllerParams, DriveParams, MotorParams, ParameterError, PlantParams
from pmsm_ev.plant import Plant
from pmsm_ev.references import (
    limits,
    motor_share,
    operating_points,
    reference,
    region_speeds,
    torque_envelope,
)

FW = ControllerParams(reference="fw", v_dc=360.0)
#: a motor whose MTPV lies within the current limit: psi / L_d = 299 A < I_max = 400 A
MTPV_MOTOR = MotorParams(L_d=0.3e-3, L_q=0.45e-3)
#: a non-salient motor
ROUND_MOTOR = MotorParams(L_d=0.25e-3, L_q=0.25e-3)
SPEEDS = (0.0, 200.0, 590.0, 800.0, 1554.0)
STEP = 0.25  #: the brute force's grid [A]


def brute_force(lim, omega):
    """Every current of a STEP grid over the disc |i| <= I_max with the flux within the circle
    lambda = u_fw / (N |omega|) (the generator's voltage limit): (i_d, i_q >= 0, |i|, torque)."""
    axis = np.arange(-lim.i_max, lim.i_max + STEP / 2, STEP)
    i_d, i_q = np.meshgrid(axis, axis[axis >= 0], indexing="ij")
    i = np.hypot(i_d, i_q)
    ok = i <= lim.i_max
    w_e = abs(lim.N * omega)
    if lim.u_fw > 0 and w_e > 0:
        ok &= np.hypot(lim.psi + lim.L_d * i_d, lim.L_q * i_q) <= lim.u_fw / w_e
    t = lim.k * i_q * (lim.psi + (lim.L_d - lim.L_q) * i_d)
    return i_d[ok], i_q[ok], i[ok], t[ok]


def within_limits(lim, r, omega):
    i = math.hypot(r.i_d, r.i_q)
    flux = math.hypot(lim.psi + lim.L_d * r.i_d, lim.L_q * r.i_q)
    w_e = abs(lim.N * omega)
    return i <= lim.i_max * (1 + 1e-9) and (w_e == 0 or flux * w_e <= lim.u_fw * (1 + 1e-9))


@pytest.mark.parametrize("motor, name", [(MotorParams(), "Table I"), (MTPV_MOTOR, "psi/L_d < I_max"),
                                         (ROUND_MOTOR, "L_d = L_q")])
def test_against_a_brute_force_search(motor, name):
    """At each speed: the torque available is the grid's most torque (to what the grid resolves), and for
    demands of both signs below it the references give the torque asked, within the limits, with the
    least current: no point of the grid gives the torque with less, and the grid comes within four steps of
    it (four steps: in field weakening the optimum lies on the flux circle, which cuts the grid at a slant);
    at negative speed the same references."""
    lim = limits(FW, motor)
    print(f"\n{name}: u_fw = {lim.u_fw:.1f} V, I_max = {lim.i_max:g} A, T_max = {lim.T_max:.1f} N m")
    for omega in SPEEDS:
        i_d, i_q, i, t = brute_force(lim, omega)
        t_grid = t.max()
        top = reference(1e9, omega, lim)
        assert top.T == pytest.approx(t_grid, rel=2e-3, abs=0.05) and top.T >= t_grid - 1e-9
        assert top.T == pytest.approx(top.T_avail, rel=1e-12) and within_limits(lim, top, omega)
        worst = 0.0
        for share in (0.1, 0.5, 0.9):
            for sign in (1.0, -1.0):
                demand = sign * share * top.T_avail
                r = reference(demand, omega, lim)
                assert r.T == pytest.approx(demand, rel=1e-9)
                assert within_limits(lim, r, omega)
                assert math.copysign(1.0, r.i_q) == sign
                i_least = i[t >= abs(demand)].min()  # the grid's least current for at least |demand|
                excess = math.hypot(r.i_d, r.i_q) - i_least
                # no grid point does better; the grid comes within its resolution of it
                assert -4 * STEP <= excess <= 1e-9, (omega, demand, excess)
                worst = max(worst, abs(excess))
                # negative speed: the same references (the voltage limit depends on |omega|)
                r_neg = reference(demand, -omega, lim)
                assert (r_neg.i_d, r_neg.i_q, r_neg.T) == pytest.approx((r.i_d, r.i_q, r.T), rel=1e-12, abs=1e-9)
        print(f"  {omega:6.0f} rad/s: T_avail = {top.T_avail:6.2f} N m (grid {t_grid:6.2f}), region {top.region}; "
              f"|i| - least |i| of the grid, worst {worst:.3f} A")


def test_the_table_i_motor_envelope_is_the_brute_force_one_with_the_full_voltage():
    """fw_margin = 1: the envelope of Table I's motor at 200, 590, 800, 1554 rad/s, 153.1, 129.5, 101.3,
    53.3 N m without the R_s drop; the brute force with the R_s drop (steady-state eqs 10-11, |v| <= 208 V)
    gives 153.1, 128.0, 99.8, 52.3: the R_s drop takes 1-2 %, within fw_margin's 10 %."""
    lim = limits(replace(FW, fw_margin=1.0))
    motoring, braking, region = torque_envelope([200.0, 590.0, 800.0, 1554.0], lim)
    axis = np.arange(-400.0, 400.01, 0.5)
    i_d, i_q = np.meshgrid(axis, axis[axis >= 0], indexing="ij")
    ok = np.hypot(i_d, i_q) <= 400.0
    m = MotorParams()
    for omega, t_env in zip((200.0, 590.0, 800.0, 1554.0), motoring):
        w_e = m.N * omega
        v = np.hypot(m.R_s * i_d - w_e * m.L_q * i_q, m.R_s * i_q + w_e * (m.psi + m.L_d * i_d))
        t = m.N * i_q * (m.psi + (m.L_d - m.L_q) * i_d)
        t_rs = t[ok & (v <= 360.0 / math.sqrt(3.0))].max()
        print(f"{omega:6.0f} rad/s: envelope {t_env:6.2f} N m, with the R_s drop {t_rs:6.2f} N m "
              f"({(t_env - t_rs) / t_rs:+.2%})")
        assert 0.0 <= t_env - t_rs <= 0.025 * t_rs
    assert np.array_equal(-braking, motoring)  # no regen limit: the same both ways
    assert list(region) == [k.REGION_LIMIT, k.REGION_CURRENT_FW, k.REGION_CURRENT_FW, k.REGION_CURRENT_FW]


def test_mtpa_below_base_speed():
    """Below the base speed: MTPA, negative i_d for Table I's salient motor (the reluctance torque: 153.1 N m
    at 400 A against 143.6 N m with i_d = 0), i_d = 0 for a non-salient one; at zero speed no voltage limit."""
    lim = limits(FW)
    r = reference(100.0, 200.0, lim)
    assert r.region == k.REGION_MTPA and r.i_d < -10.0
    # on MTPA the torque per ampere is the most: no other angle at that |i| gives more
    i = math.hypot(r.i_d, r.i_q)
    angles = np.linspace(0.5 * math.pi, math.pi, 20001)
    t = lim.k * i * np.sin(angles) * (lim.psi + (lim.L_d - lim.L_q) * i * np.cos(angles))
    assert t.max() == pytest.approx(100.0, rel=1e-7)
    top = reference(1e9, 0.0, lim)
    print(f"\nTable I at 400 A: MTPA {top.T:.2f} N m (i_d = {top.i_d:.1f} A), i_d = 0: {lim.k * lim.psi * 400:.2f} N m")
    assert top.T == pytest.approx(153.127, abs=1e-3) and top.region == k.REGION_LIMIT
    assert math.hypot(top.i_d, top.i_q) == pytest.approx(400.0, rel=1e-12)
    round_lim = limits(FW, ROUND_MOTOR)
    for omega in (0.0, 200.0, -300.0):
        r = reference(-60.0, omega, round_lim)
        assert r.i_d == 0.0 and r.region == k.REGION_MTPA and r.T == pytest.approx(-60.0, rel=1e-12)


def test_torque_limit_and_mtpa_mode():
    """T_max caps the torque on MTPA (region 4) and in field weakening (region 1); the mode 'mtpa' has no
    voltage limit (MTPA at any speed)."""
    lim = limits(replace(FW, T_max=100.0))
    r = reference(130.0, 100.0, lim)
    assert r.T == 100.0 and r.region == k.REGION_LIMIT and r.T_avail == 100.0
    r = reference(130.0, 700.0, lim)
    assert r.T == pytest.approx(100.0, rel=1e-12) and r.region == k.REGION_FW
    mtpa = limits(replace(FW, reference="mtpa", v_dc=0.0))
    r = reference(130.0, 1554.0, mtpa)
    assert r.region == k.REGION_MTPA and r.i_d == reference(130.0, 0.0, mtpa).i_d


def test_mtpv_is_reached_when_psi_over_l_d_is_below_i_max():
    """psi / L_d = 299 A < 400 A: at high speed the most torque is the MTPV point of the flux circle, its
    current below I_max (region 2), and no speed is out of reach; Table I's motor (444 A > 400 A) never
    reaches MTPV and loses all torque at u_fw / (N (psi - L_d I_max))."""
    lim = limits(FW, MTPV_MOTOR)
    speeds = region_speeds(lim)
    print(f"\npsi/L_d = {lim.psi / lim.L_d:.0f} A: " + ", ".join(f"{n} {v:.1f}" for n, v in speeds.items()))
    assert speeds["base_speed"] < speeds["mtpv_speed"] < math.inf and speeds["max_speed"] == math.inf
    for omega in (1.05 * speeds["mtpv_speed"], 3000.0, 10000.0):
        top = reference(-1e9, omega, lim)
        assert top.region == k.REGION_MTPV and math.hypot(top.i_d, top.i_q) < lim.i_max
        # the MTPV point: the most torque on the flux circle, at any current
        lam = lim.u_fw / (lim.N * omega)
        d = np.linspace(0.0, math.pi, 200001)
        t = lim.k * lam * np.sin(d) * (lam * np.cos(d) * (1 / lim.L_q - 1 / lim.L_d) + lim.psi / lim.L_d)
        assert -top.T == pytest.approx(t.max(), rel=1e-9)
    table = limits(FW)
    speeds = region_speeds(table)
    print("Table I: " + ", ".join(f"{n} {v:.1f}" for n, v in speeds.items()))
    assert speeds["mtpv_speed"] == math.inf
    assert speeds["max_speed"] == pytest.approx(table.u_fw / (table.N * (table.psi - table.L_d * table.i_max)))


@pytest.mark.parametrize("motor", [MotorParams(), MTPV_MOTOR])
def test_region_boundaries(motor):
    """Just below and just above each speed of ``region_speeds`` the envelope's region changes as stated:
    4 -> 3 at the base speed (Table I) or 4 -> 3 -> 2 (the MTPV motor), and 3 -> 5 at the maximum speed."""
    lim = limits(FW, motor)
    s = region_speeds(lim)
    below, above = 1 - 1e-6, 1 + 1e-6
    _, _, r = torque_envelope([s["base_speed"] * below, s["base_speed"] * above], lim)
    assert list(r) == [k.REGION_LIMIT, k.REGION_CURRENT_FW]
    if s["mtpv_speed"] < math.inf:
        _, _, r = torque_envelope([s["mtpv_speed"] * below, s["mtpv_speed"] * above], lim)
        assert list(r) == [k.REGION_CURRENT_FW, k.REGION_MTPV]
    if s["max_speed"] < math.inf:
        t, _, r = torque_envelope([s["max_speed"] * below, s["max_speed"] * above], lim)
        assert list(r) == [k.REGION_CURRENT_FW, k.REGION_NONE] and 0 < t[0] < 0.1 and t[1] == 0.0
        zero = reference(50.0, s["max_speed"] * 1.1, lim)  # graceful: no torque, the flux weakened most
        assert zero.T == 0.0 and zero.i_d == -lim.i_max and zero.i_q == 0.0
    # the operating points of a grid: within the voltage (with the margin's R_s drop) and the current
    grid = operating_points(np.linspace(-200, 200, 9), np.linspace(-1554, 1554, 9), lim)
    assert (grid.i <= lim.i_max * (1 + 1e-9)).all()
    assert (grid.v <= lim.u_fw / FW.fw_margin).all()  # the R_s drop is within the margin
    assert set(np.unique(grid.region)) <= {0, 1, 2, 3, 4}


def test_regenerative_limit_and_blending():
    """A braking demand goes to the motor up to P_regen_max / |omega| and the envelope; the rest, x n_g eta,
    is the friction brake's; motoring and a demand within the limit are untouched."""
    lim = limits(replace(FW, P_regen_max=30e3))
    given, brake = motor_share(-100.0, 800.0, lim)
    assert given == pytest.approx(-30e3 / 800.0, rel=1e-12)
    assert brake == pytest.approx((100.0 - 30e3 / 800.0) * 12.5 * 0.96, rel=1e-12)
    assert motor_share(80.0, 800.0, lim) == (pytest.approx(80.0), 0.0)  # motoring
    assert motor_share(-20.0, 800.0, lim) == (pytest.approx(-20.0), 0.0)  # within the limit
    given, brake = motor_share(50.0, -1554.0, lim)  # braking backwards
    assert given == pytest.approx(30e3 / 1554.0, rel=1e-12) and brake > 0
    given, brake = motor_share(-500.0, 1554.0, limits(FW))  # no regen limit: beyond the envelope
    assert given == pytest.approx(-reference(0.0, 1554.0, limits(FW)).T_avail)
    assert brake == pytest.approx((500.0 + given) * 12.5 * 0.96)
    _, braking, _ = torque_envelope([100.0, 800.0], lim)
    assert braking[0] == pytest.approx(-153.127, abs=1e-3) and braking[1] == pytest.approx(-37.5)


@pytest.mark.parametrize("change, message", [
    ({"reference": "fw"}, "reference 'fw' (field weakening) needs the DC-link voltage: set v_dc > 0 V"),
    ({"i_max": 0.0}, "i_max must be > 0 A (got 0.0)"),
    ({"i_max": -5.0}, "i_max must be > 0 A (got -5.0)"),
    ({"reference": "mtpa", "T_max": 200.0}, "T_max = 200 N m is above the 153.1 N m that i_max = 400 A gives on "
                                            "MTPA"),
    ({"P_regen_max": -1.0}, "P_regen_max must be >= 0 W, a power the motor may take back, 0 = no limit (got -1.0)"),
    ({"v_dc": 400.0, "u_max": 200.0}, "u_max = 200 V and v_dc = 400 V are both given: set one of the two"),
    ({"reference": "weak"}, "reference must be one of ('paper', 'mtpa', 'fw') (got 'weak')"),
    ({"fw_margin": 1.5}, "fw_margin must be in (0, 1] (got 1.5)"),
])
def test_bad_parameters_get_one_line(change, message):
    with pytest.raises(ParameterError) as exc:
        ControlUnit("sensored", controller=ControllerParams(**change))
    assert message in str(exc.value) and "\n" not in str(exc.value)
    with pytest.raises(ParameterError):
        DriveParams(controller=ControllerParams(**change)).validate()


def test_paper_mode_is_unchanged_and_its_outputs():
    """reference 'paper' (default): the generator's slots are never written; i_dref = i_d_ref, T_ref = k_t
    i_qref, T_brake = 0, region 0. v_dc > 0 gives the current PIs the limit v_dc / sqrt(3)."""
    unit = ControlUnit("sensored", controller=ControllerParams(i_d_ref=-5.0))
    for _ in range(50):
        unit.step(10.0, 0.0, 200.0, 0.0, 0.0)
    assert unit.i_dref == -5.0 and unit.T_ref == pytest.approx(4 * 0.08975 * unit.i_qref) and unit.T_ref > 0
    assert unit.T_brake == 0.0 and unit.ref_region == 0.0
    assert unit._s[k.S_T_REF] == 0.0 and unit._s[k.S_I_DREF] == 0.0
    unit = ControlUnit("sensored", controller=ControllerParams(v_dc=300.0))
    assert unit._c[k.C_U_MAX] == 300.0 / math.sqrt(3.0)
    assert ControlUnit("sensored")._c[k.C_U_MAX] == ControllerParams().u_max


def test_closed_loop_acceleration_and_regenerative_braking():
    """Plant (v_dc = 360 V: its inverter limits the voltage) + sensored ControlUnit, reference 'fw',
    P_regen_max = 30 kW: full torque from standstill to 1100 rad/s on a level road, through field weakening
    (the speed PI clamped at the torque available: no windup), then a brake to 0 from 7 s. Printed: the
    times to 590 and 1000 rad/s, the overshoot, the torques, the motor's largest regenerative power and the
    friction brake's share."""
    dt = 1e-4
    plant = Plant(plant=PlantParams(v_dc=360.0))
    unit = ControlUnit("sensored", controller=ControllerParams(reference="fw", v_dc=360.0, P_regen_max=30e3), dt=dt)
    i_a, i_b = plant.i_alpha, plant.i_beta
    t_590 = t_1000 = None
    w_peak = 0.0
    p_regen = 0.0  # the motor's most negative power while braking [W]
    worst_gap = 0.0  # |T_e - T_ref| in field weakening, after the transients [N m]
    brake_ok = True
    regions = set()
    for n in range(int(18.0 / dt)):
        t = n * dt
        ref = 1100.0 if t < 7.0 else 0.0
        out = unit.step(i_a, i_b, ref, plant.theta_e, plant.omega_m)
        plant.step(out[0], out[1], 0.0, dt)
        i_a, i_b = plant.i_alpha, plant.i_beta
        w = plant.omega_m
        regions.add(unit.ref_region)
        if t_590 is None and w >= 590.0:
            t_590 = t
        if t_1000 is None and w >= 1000.0:
            t_1000 = t
        if t < 7.0:
            w_peak = max(w_peak, w)
            if 1.0 < t < 5.0:
                worst_gap = max(worst_gap, abs(plant.T_e - unit.T_ref))
                assert unit.T_ref == pytest.approx(unit.T_avail, rel=1e-6)  # at the envelope, no windup
        elif t > 7.05 and w > 50.0:
            p_regen = min(p_regen, plant.T_e * w)
            if w > 30e3 / unit.T_avail:  # the regen limit acts: the rest of the braking demand (the envelope,
                # the speed PI at its clamp) is the friction brake's, at the wheels
                demand = unit.T_ref - unit.T_brake / (12.5 * 0.96)
                brake_ok &= unit.T_brake > 0 and demand == pytest.approx(-unit.T_avail, rel=1e-6)
                brake_ok &= unit.T_ref == pytest.approx(-30e3 / w, rel=0.02)
    print(f"\n0-590 rad/s {t_590:.2f} s, 0-1000 rad/s {t_1000:.2f} s, peak {w_peak:.1f} rad/s "
          f"(overshoot {w_peak - 1100:.1f} rad/s); |T_e - T_ref| in field weakening at most {worst_gap:.2f} N m; "
          f"regenerative power at most {-p_regen / 1e3:.2f} kW (limit 30 kW); regions {sorted(regions)}; "
          f"speed at 18 s {plant.omega_m:.1f} rad/s")
    # the envelope's own time to 1000 rad/s (J_eq dw/dt = T_avail - road load) bounds it from below
    assert t_1000 is not None and t_1000 < 6.0 and t_590 < 2.5
    assert w_peak - 1100.0 < 5.0  # no windup: the PI's clamp is the torque available
    assert worst_gap < 1.0
    assert -p_regen <= 30e3 * 1.02 and brake_ok
    assert {k.REGION_LIMIT, k.REGION_CURRENT_FW} <= regions
    assert abs(plant.omega_m) < 5.0


def test_sensorless_unit_runs_the_generator_in_its_ekf_mode():
    """The sensorless unit from standstill, reference 'fw', v_dc = 360 V, P_regen_max = 30 kW: alignment, I-f,
    the handover to FOC seated on the generator's references, a ramp to 500 rad/s (field weakening at full
    torque would start at 367 rad/s; here at 500 rad/s with little torque), then a brake: the regen limit and
    the friction brake act, the handover back down to I-f, no fault. Printed: the speed error in FOC, the
    regions, the largest regenerative power."""
    dt = 1e-4
    plant = Plant(plant=PlantParams(v_dc=360.0))
    unit = ControlUnit("sensorless", controller=ControllerParams(reference="fw", v_dc=360.0, P_regen_max=30e3),
                       dt=dt)
    i_a, i_b = plant.i_alpha, plant.i_beta
    modes, regions = set(), set()
    worst = p_regen = brake = 0.0
    for n in range(int(12.0 / dt)):
        t = n * dt
        ref = min(max(t - 2.3, 0.0) * 100.0, 500.0) if t < 9.0 else 0.0
        out = unit.step(i_a, i_b, ref)
        plant.step(out[0], out[1], 0.0, dt)
        i_a, i_b = plant.i_alpha, plant.i_beta
        modes.add(out[12])
        regions.add(unit.ref_region)
        if 5.0 < t < 7.0:  # (the speed PI, omega_n = 2 rad/s, has caught up with the ramp after the handover)
            worst = max(worst, abs(ref - plant.omega_m))
        if t > 9.0 and plant.omega_m > 100.0:
            p_regen = min(p_regen, plant.T_e * plant.omega_m)
            brake = max(brake, unit.T_brake)
        assert out[13] == 0.0  # no fault
    print(f"\nsensorless, 'fw': ramp error in FOC at most {worst:.2f} rad/s; regions {sorted(regions)}; "
          f"regenerative power at most {-p_regen / 1e3:.2f} kW; friction brake up to {brake:.0f} N m at the wheels; "
          f"modes {sorted(modes)}, speed at 12 s {plant.omega_m:.1f} rad/s")
    assert modes == {0.0, 1.0, 2.0} and out[12] == 1.0  # handed over up, and back down at the end
    assert worst < 5.0
    assert k.REGION_FW in regions and k.REGION_MTPA in regions
    assert -p_regen <= 30e3 * 1.02 and brake > 100.0
    assert abs(plant.omega_m) < 25.0


def test_compiled_and_plain_python_give_the_same_bits_in_field_weakening():
    """The generator's kernels compiled with numba and as plain Python give the same numbers, bit for bit
    (``pmsm_ev.kernels``: only functions both compute alike): a flying sensored start at 800 rad/s, reference
    'fw', the speed reference stepped to 1300 rad/s and then to 300 rad/s (field weakening, the limits,
    regenerative braking with a 20 kW limit)."""
    compiled = accel.kernels()
    if compiled is k:
        pytest.skip("numba is not available: the kernels run as plain Python only")

    def run(kernels):
        plant = Plant(plant=PlantParams(v_dc=360.0, omega_m0=800.0))
        unit = ControlUnit("sensored", controller=ControllerParams(reference="fw", v_dc=360.0, P_regen_max=20e3))
        plant._kernels = unit._kernels = kernels
        rows = []
        for n in range(1500):
            out = unit.step(plant.i_alpha, plant.i_beta, 1300.0 if n < 700 else 300.0, plant.theta_e, plant.omega_m)
            plant.step(out[0], out[1], 0.0, 1e-4)
            rows.append((*out, unit.i_dref, unit.T_ref, unit.T_brake, unit.ref_region, plant.omega_m))
        return rows

    jit, plain = run(compiled), run(k)
    assert jit == plain
    regions = {row[-2] for row in jit}
    print(f"\n1500 periods from 800 rad/s: the same bits compiled and plain; regions {sorted(regions)}, "
          f"T_brake up to {max(row[-3] for row in jit):.0f} N m")
    assert k.REGION_CURRENT_FW in regions
    assert max(row[-3] for row in jit) > 0.0


def test_the_paper_speed_step_is_speed_pi_at_i_q_max():
    """``speed_step`` (the paper's path, written out) and ``speed_pi`` at +-i_q_max: the same output and
    integral, bit for bit, inside, at and beyond the clamp, both signs."""
    rng = np.random.default_rng(7)
    a, b = ControlUnit("sensored"), ControlUnit("sensored")
    for _ in range(2000):
        omega_ref, omega = rng.uniform(-300, 300, 2)
        out_a = k.speed_step(a._s, a._c, omega_ref, omega)
        out_b = k.speed_pi(b._s, b._c, omega_ref, omega, b._c[k.C_I_Q_MAX])
        assert out_a == out_b and a._s[k.S_W_INT] == b._s[k.S_W_INT]
    assert a._s[k.S_W_INT] != 0.0
