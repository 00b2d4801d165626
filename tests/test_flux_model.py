"""The plant's algebraic magnetic model (``PlantParams.flux_model`` 'algebraic', docs/sensorless.md "The
plant's flux model"): reciprocity, the magnet's asymmetry, Newton's round trip, the reduction to eqs 10-12,
the torque as the co-energy's derivative, the energy balance, the coefficients' targets, bad parameters and
the plant FMU. The kernels are called as plain Python (``pmsm_ev.kernels``); the runs use ``Plant``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pmsm_ev import kernels as k
from pmsm_ev.params import (
    MotorParams,
    ParameterError,
    PlantParams,
    VehicleParams,
    flux_model_coefficients,
    magnet_flux,
)
from pmsm_ev.plant import Plant

M = MotorParams()
ALGEBRAIC = PlantParams(flux_model="algebraic")
C = list(flux_model_coefficients(M, ALGEBRAIC))  # the default shape, at 20 degC
#: the currents the drive reaches: the 400 A limit in every direction, and the grid's corners beyond
GRID = [(i_d, i_q) for i_d in np.linspace(-400.0, 400.0, 9) for i_q in np.linspace(-400.0, 400.0, 9)]


def _psi(i_d, i_q, c=C):
    return k.flux_linkages(i_d, i_q, c, 0)


def _coenergy(i_d, i_q, c=C):
    """W'(i) = i . psi(i) - E(psi(i)), E the field energy (``flux_energy``, dE = i . dpsi): dW' = psi . di."""
    psi_d, psi_q = _psi(i_d, i_q, c)
    return i_d * psi_d + i_q * psi_q - k.flux_energy(psi_d, psi_q, c, 0)


# -- the model -----------------------------------------------------------------------------------
@pytest.mark.parametrize("i_d, i_q", [(0.0, 0.0), (50.0, 233.0), (-150.0, 300.0), (120.0, -400.0),
                                      (-300.0, -80.0)])
def test_the_model_is_reciprocal(i_d, i_q):
    """d psi_d / d i_q = d psi_q / d i_d (central differences of Newton's psi(i)), and the incremental
    inductance matrix is that derivative: symmetric, positive definite."""
    h = 1e-3
    dpsi_d_diq = (_psi(i_d, i_q + h)[0] - _psi(i_d, i_q - h)[0]) / (2 * h)
    dpsi_q_did = (_psi(i_d + h, i_q)[1] - _psi(i_d - h, i_q)[1]) / (2 * h)
    dpsi_d_did = (_psi(i_d + h, i_q)[0] - _psi(i_d - h, i_q)[0]) / (2 * h)
    dpsi_q_diq = (_psi(i_d, i_q + h)[1] - _psi(i_d, i_q - h)[1]) / (2 * h)
    assert dpsi_d_diq == pytest.approx(dpsi_q_did, rel=1e-6, abs=1e-12)
    l_dd, l_dq, l_qq = k.incremental_inductances(i_d, i_q, C, 0)
    assert (l_dd, l_dq, l_qq) == pytest.approx((dpsi_d_did, dpsi_d_diq, dpsi_q_diq), rel=1e-6, abs=1e-12)
    assert l_dd > 0 and l_qq > 0 and l_dd * l_qq > l_dq * l_dq
    # and the flux-to-current map's own Jacobian: di_d/dpsi_q = di_q/dpsi_d
    psi_d, psi_q = _psi(i_d, i_q)
    e = 1e-7
    di_d = (k.flux_currents(psi_d, psi_q + e, C, 0)[0] - k.flux_currents(psi_d, psi_q - e, C, 0)[0]) / (2 * e)
    di_q = (k.flux_currents(psi_d + e, psi_q, C, 0)[1] - k.flux_currents(psi_d - e, psi_q, C, 0)[1]) / (2 * e)
    assert di_d == pytest.approx(di_q, rel=1e-6, abs=1e-6)
    assert di_d == pytest.approx(k.flux_jacobian(psi_d, psi_q, C, 0)[1], rel=1e-6, abs=1e-6)


def test_the_magnet_makes_the_d_axis_asymmetric():
    """Positive i_d adds to the magnet's flux and saturates the d path (lower incremental L_d), negative i_d
    relieves it (higher); by flux_d_asymmetry of L_d at +-flux_d_current."""
    l0 = k.incremental_inductances(0.0, 0.0, C, 0)[0]
    for i in (50.0, 100.0, 200.0, 400.0):
        l_plus = k.incremental_inductances(i, 0.0, C, 0)[0]
        l_minus = k.incremental_inductances(-i, 0.0, C, 0)[0]
        assert l_plus < l0 < l_minus, (i, l_plus, l0, l_minus)
    i = ALGEBRAIC.flux_d_current
    l_plus, l_minus = (k.incremental_inductances(s * i, 0.0, C, 0)[0] for s in (1.0, -1.0))
    assert (l_minus - l_plus) / M.L_d == pytest.approx(ALGEBRAIC.flux_d_asymmetry, rel=1e-9)
    assert _psi(i, 0.0)[0] > M.psi > _psi(-i, 0.0)[0]


def test_newton_gives_the_flux_of_a_current_to_round_off():
    """i -> psi (Newton) -> i (the explicit model) over currents up to +-400 A per axis, and psi -> i -> psi."""
    worst = 0.0
    for i_d, i_q in GRID:
        psi_d, psi_q = _psi(i_d, i_q)
        f_d, f_q = k.flux_currents(psi_d, psi_q, C, 0)
        worst = max(worst, abs(f_d - i_d), abs(f_q - i_q))
        back = _psi(f_d, f_q)
        assert back == pytest.approx((psi_d, psi_q), rel=1e-13, abs=1e-16)
    assert worst < 1e-10, worst  # A: the model's i_f (~435 A) times a few ulp


def test_with_no_saturation_it_is_eqs_10_to_12():
    """No asymmetry, no q saturation, no cross-saturation (a_dd = a_qq = a_dq = 0): the plant's derivatives,
    torque and field energy are eqs 10-12's to ~1e-12."""
    linear = PlantParams(flux_model="algebraic", flux_d_asymmetry=0.0, flux_q_ratio=1.0, flux_cross=0.0)
    c = flux_model_coefficients(M, linear)
    assert (c[k.FX_ADD], c[k.FX_AQQ], c[k.FX_ADQ]) == (0.0, 0.0, 0.0)
    assert (c[k.FX_AD0], c[k.FX_AQ0], c[k.FX_IF]) == pytest.approx((1 / M.L_d, 1 / M.L_q, M.psi / M.L_d), rel=1e-14)
    p_alg, p_lin = Plant(plant=linear), Plant()
    pa, pl = list(p_alg._pp), list(p_lin._pp)
    for i_d, i_q, w, th, v_a, v_b in ((0.0, 0.0, 0.0, 0.0, 10.0, 0.0), (-120.0, 233.0, 150.0, 1.0, 30.0, -80.0),
                                      (300.0, -50.0, -400.0, -2.5, -120.0, 60.0)):
        a = k.plant_derivatives(i_d, i_q, w, th, v_a, v_b, 0.05, pa)
        b = k.plant_derivatives(i_d, i_q, w, th, v_a, v_b, 0.05, pl)
        assert a == pytest.approx(b, rel=1e-12, abs=1e-9)
        t_a = k.plant_outputs(i_d, i_q, w, th, 0.0, pa)[2]
        assert t_a == pytest.approx(k.electromagnetic_torque(i_d, i_q, M.psi, M.L_d, M.L_q, M.N), rel=1e-12, abs=1e-12)
        w_a = k.stored_energies(i_d, i_q, w, pa)[0]
        assert w_a == pytest.approx(k.stored_energies(i_d, i_q, w, pl)[0], rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("i_d, i_q", [(0.0, 233.0), (-100.0, 300.0), (150.0, -200.0), (-350.0, 350.0)])
def test_the_torque_is_the_co_energy_derivative(i_d, i_q):
    """T_e = N dW'/dtheta_m at constant stationary-frame currents (the rotor turned by delta under a
    fixed current vector: (i_d, i_q) rotated by -delta) equals eq 12's flux form N (psi_d i_q - psi_q i_d)."""
    h = 1e-6

    def turned(delta):
        c, s = math.cos(delta), math.sin(delta)
        return _coenergy(c * i_d + s * i_q, -s * i_d + c * i_q)

    numeric = M.N * (turned(h) - turned(-h)) / (2 * h)
    psi_d, psi_q = _psi(i_d, i_q)
    assert numeric == pytest.approx(k.flux_torque(i_d, i_q, psi_d, psi_q, M.N), rel=1e-6)
    p = Plant(plant=ALGEBRAIC)
    assert k.plant_outputs(i_d, i_q, 0.0, 0.0, 0.0, list(p._pp))[2] == pytest.approx(numeric, rel=1e-6)


# -- the coefficients from the parameters ---------------------------------------------------------
def test_the_coefficients_give_the_requested_motor():
    """Table I's L_d, L_q at zero current, the magnet's psi there (at its temperature), the q axis's
    incremental inductance at flux_q_current and psi_d's fall there as asked."""
    for plant in (ALGEBRAIC, PlantParams(flux_model="algebraic", flux_q_ratio=0.7, flux_q_current=300.0,
                                         flux_cross=0.1, flux_d_asymmetry=0.05, flux_d_current=100.0)):
        c = flux_model_coefficients(M, plant)
        assert k.incremental_inductances(0.0, 0.0, c, 0) == pytest.approx((M.L_d, 0.0, M.L_q), rel=1e-12, abs=1e-15)
        assert _psi(0.0, 0.0, c) == pytest.approx((M.psi, 0.0), rel=1e-14, abs=1e-15)
        i_q = plant.flux_q_current
        assert k.incremental_inductances(0.0, i_q, c, 0)[2] / M.L_q == pytest.approx(plant.flux_q_ratio, rel=1e-9)
        assert _psi(0.0, i_q, c)[0] / M.psi == pytest.approx(1.0 - plant.flux_cross, rel=1e-9)
        l_plus, l_minus = (k.incremental_inductances(s * plant.flux_d_current, 0.0, c, 0)[0] for s in (1, -1))
        assert (l_minus - l_plus) / M.L_d == pytest.approx(plant.flux_d_asymmetry, rel=1e-9)
        assert k.stored_energies(0.0, 0.0, 0.0, list(Plant(plant=plant)._pp))[0] == pytest.approx(0.0, abs=1e-12)
    # a hot magnet: its flux at zero current is psi(T), the iron's curve unchanged
    hot = PlantParams(flux_model="algebraic", T_magnet=100.0)
    p = Plant(plant=hot)
    psi_hot = magnet_flux(M.psi, 100.0, hot.alpha_psi)
    assert p.flux_linkages(0.0, 0.0) == pytest.approx((psi_hot, 0.0), rel=1e-14, abs=1e-15)
    c_hot = flux_model_coefficients(M, hot)
    assert c_hot[:k.FX_IF] == tuple(C[:k.FX_IF]) and c_hot[k.FX_IF] < C[k.FX_IF]
    assert p.incremental_inductances(0.0, 0.0)[0] > M.L_d  # less magnet: a less saturated d path


def test_the_saliency_falls_with_the_load():
    """What the default motor gives an injection: the saliency L_qq - L_dd shrinks as i_q grows (the q path
    saturates) and vanishes before the current limit."""
    saliency = [k.incremental_inductances(0.0, i_q, C, 0)[2] - k.incremental_inductances(0.0, i_q, C, 0)[0]
                for i_q in (0.0, 100.0, 233.0, 300.0, 400.0)]
    assert saliency[0] == pytest.approx(M.L_q - M.L_d, rel=1e-12)
    assert all(a > b for a, b in zip(saliency, saliency[1:]))
    assert saliency[2] > 0.0 > saliency[4]


@pytest.mark.parametrize("change, message", [
    ({"flux_model": "cubic"}, "flux_model must be one of ('linear', 'algebraic') (got 'cubic')"),
    ({"sat_i_q": 900.0}, "flux_model 'algebraic' has its own saturation: set sat_i_q = sat_i_d = 0"),
    ({"flux_q_ratio": 0.0}, "flux_q_ratio must be in (0, 1]"),
    ({"flux_q_ratio": 1.2}, "flux_q_ratio must be in (0, 1]"),
    ({"flux_q_current": -400.0}, "flux_q_current must be > 0 A (got -400.0)"),
    ({"flux_d_current": float("nan")}, "flux_d_current must be > 0 A"),
    ({"flux_d_asymmetry": -0.1}, "flux_d_asymmetry must be in [0, 1) (got -0.1)"),
    ({"flux_cross": 1.0}, "flux_cross must be in [0, 1) (got 1.0)"),
    ({"flux_S": 0.0}, "flux_S must be > 0 (got 0.0)"),
    ({"flux_V": -1.0}, "flux_V must be >= 0 (got -1.0)"),
    ({"flux_d_asymmetry": 0.9}, "flux_d_asymmetry = 0.9 is beyond the"),
    ({"flux_cross": 0.35}, "flux_cross = 0.35 with flux_q_ratio = 0.5 gives a flux model that is not physical at"),
    ({"flux_cross": 0.4}, "flux_q_ratio = 0.5 at flux_q_current = 400 A is not reachable by the model with flux_cross"),
])
def test_bad_parameters_are_refused_with_one_line(change, message):
    kwargs = {"flux_model": "algebraic", **change}
    with pytest.raises(ParameterError) as err:
        Plant(plant=PlantParams(**kwargs))
    text = str(err.value)
    assert message in text and "\n" not in text, text


# -- the plant with the model on ------------------------------------------------------------------
def test_the_energy_balance_closes_with_the_algebraic_model():
    """Voltage steps in the rotor frame, the rotor accelerating and braking on a grade, the iron losses on:
    E_dc = copper + iron + friction + gear + road + changes of the kinetic and field energies, to 1e-6 of
    the throughput; the field energy is the model's (``flux_energy``), not eqs 10-12's."""
    p = Plant(plant=PlantParams(flux_model="algebraic", iron_c_h=9.9, iron_c_e=3.9e-3),
              vehicle=VehicleParams(gear_model="power_flow", m_v=300.0))
    dt = 1e-4
    peak_i = peak_w = gap = 0.0
    for j in range(8000):
        t = j * dt
        v_d = (-2.0 if t < 0.3 else 1.5) if t < 0.5 else -2.5
        v_q = (2.5 if t < 0.4 else -1.5) + p.omega_m * M.N * M.psi
        c, s = math.cos(p.theta_e), math.sin(p.theta_e)
        p.step(c * v_d - s * v_q, s * v_d + c * v_q, 0.06, dt)
        peak_i, peak_w = max(peak_i, abs(p.i_d), abs(p.i_q)), max(peak_w, abs(p.omega_m))
        # eqs 10-12's field energy (less the magnet's, zero at zero current) against the model's
        gap = max(gap, abs(p.stored[0] - 0.5 * (M.L_d * p.i_d ** 2 + M.L_q * p.i_q ** 2)))
    e = p.energies()
    rel = e["residual"] / e["E_dc_abs"]
    print(f"\nalgebraic flux model: throughput {e['E_dc_abs']:.1f} J, regen {e['E_regen']:.1f} J, field "
          f"{e['W_magnetic']:.2f} J, iron {e['E_iron']:.2f} J; residual {e['residual']:.2e} J = {rel:.1e}; "
          f"peak |i_d|, |i_q| {peak_i:.0f} A, |omega_m| {peak_w:.0f} rad/s")
    assert 200.0 < peak_i < 450.0 and peak_w > 30.0 and e["E_regen"] > 0.0 and e["E_iron"] > 0.0
    assert abs(rel) < 1e-6
    # the field energy is the model's: eqs 10-12's differs by far more than the residual
    assert gap > 1e3 * abs(e["residual"]), gap


def test_the_plant_derivatives_are_the_flux_form_through_the_inductances():
    """di/dt = L_inc^-1 (v - R_s i + w_e J psi): the plant's derivatives with the model on."""
    p = Plant(plant=ALGEBRAIC)
    i_d, i_q, w, th = -60.0, 250.0, 120.0, 0.7
    v_d, v_q = 20.0, 60.0
    c, s = math.cos(th), math.sin(th)
    did, diq, _, _ = p.derivatives(i_d, i_q, w, th, c * v_d - s * v_q, s * v_d + c * v_q, 0.0)
    psi_d, psi_q = p.flux_linkages(i_d, i_q)
    w_e = M.N * w
    dpsi = np.array([v_d - M.R_s * i_d + w_e * psi_q, v_q - M.R_s * i_q - w_e * psi_d])
    l_dd, l_dq, l_qq = p.incremental_inductances(i_d, i_q)
    assert np.array([[l_dd, l_dq], [l_dq, l_qq]]) @ np.array([did, diq]) == pytest.approx(dpsi, rel=1e-9)


def test_the_plant_fmu_takes_the_flux_model():
    """The plant FMU's slave (in plain Python, no build) takes flux_model and the shape as parameters."""
    from pmsm_ev_fmus.pmsm_ev_plant import PmsmEvPlant

    slave = PmsmEvPlant(instance_name="flux")
    ref = {v.name: vr for vr, v in slave.vars.items()}
    slave.set_string([ref["flux_model"]], ["algebraic"])
    slave.set_real([ref["flux_q_ratio"], ref["flux_cross"], ref["i_q0"]], [0.6, 0.08, 233.0])
    slave.enter_initialization_mode()
    slave.exit_initialization_mode()
    plant = slave._plant
    assert plant._pp[k.P_FLUX] == 1.0
    assert plant.incremental_inductances(0.0, 400.0)[2] / M.L_q == pytest.approx(0.6, rel=1e-9)
    psi_d, psi_q = plant.flux_linkages(0.0, 233.0)
    t_e = slave.get_real([ref["T_e"]])[0]
    assert t_e == pytest.approx(M.N * psi_d * 233.0, rel=1e-12)
    assert t_e < M.N * M.psi * 233.0  # cross-saturation: less torque than eq 12 at i_d = 0
    slave.do_step(0.0, 1e-4)
    assert math.isfinite(slave.get_real([ref["i_q"]])[0])
