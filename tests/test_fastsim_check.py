"""benchmarks/fastsim_check.py's pure helpers (no FASTSim needed): Table II's vehicle in FASTSim's fields, and
the project's motor + inverter efficiency as FASTSim's two-sided curve."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from pmsm_ev.params import VehicleParams

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "fastsim_check.py"


@pytest.fixture(scope="module")
def fc():
    spec = importlib.util.spec_from_file_location("fastsim_check", _PATH)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # its dataclass looks its module up
    try:
        spec.loader.exec_module(mod)
        yield mod
    finally:
        sys.modules.pop(spec.name, None)


def test_table_ii_in_fastsims_fields_keeps_rho_cd_and_c_r_g(fc):
    v = VehicleParams()
    f = fc.fastsim_chassis(v)
    # FASTSim's drag and rolling resistance with its own air density and gravity give Table II's forces
    assert f["drag_coef"] * fc.RHO_FASTSIM == pytest.approx(v.c_d * v.rho_a, rel=1e-12)
    assert f["wheel_rr_coef"] * fc.G_FASTSIM == pytest.approx(v.c_r * v.g, rel=1e-12)
    assert (f["frontal_area_square_meters"], f["wheel_radius_meters"], f["mass_kilograms"],
            f["transmission_eff"]) == (v.A_f, v.r_w, v.m_v, v.eta)
    assert f["wheel_inertia_kilogram_square_meters"] == 0.0 and f["pwr_aux_base_watts"] == 0.0


def test_a_constant_loss_share_gives_a_flat_curve_on_both_sides(fc):
    # 10 kW at the shaft for 10 s with 1 kW of losses (DC 11 kW), then 10 kW back for 10 s with 1 kW lost (DC 9 kW)
    t = np.arange(0.0, 20.5, 0.5)
    p_dc = np.where(t[1:] <= 10.0, 11e3, -9e3)
    e_dc = np.concatenate([[0.0], np.cumsum(p_dc * 0.5)])
    e_loss = np.concatenate([[0.0], np.cumsum(np.full(len(p_dc), 1e3 * 0.5))])
    frac, eff = fc.efficiency_curve(t, e_dc, e_loss, p_max=80e3)
    assert frac[0] == -1.0 and frac[-1] == 1.0 and np.all(np.diff(frac) > 0) and len(frac) == len(eff)
    assert np.all(eff[frac > 0] == pytest.approx(10 / 11))  # motoring: shaft / DC
    assert np.all(eff[frac < 0] == pytest.approx(9 / 10))  # regenerating: DC / shaft
    # FASTSim inverts the curve on |fraction| / efficiency: it must grow away from 0 on both sides
    assert np.all(np.diff(np.abs(frac[frac > 0]) / eff[frac > 0]) > 0)
    assert np.all(np.diff(np.abs(frac[frac < 0][::-1]) / eff[frac < 0][::-1]) > 0)
