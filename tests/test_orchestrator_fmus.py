"""The orchestrator with the project's FMUs (plant + controller), through the CLI: result
contract, physics on a plateau, observer swaps, refusal at load, and equality with the
monolithic reference. Each run covers well under a second of simulated time."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from orchestrator_support import plateau_system, project_fmus, toy_fmus
from pmsm_cosim.app.cli import main
from pmsm_cosim.app.drive import load_system
from pmsm_cosim.app.reference import run_reference
from pmsm_cosim.engine.errors import CosimError
from pmsm_cosim.engine.master import Master
from pmsm_cosim.engine.recording import read_results
from pmsm_ev.params import VehicleParams
from pmsm_ev.results import ALL_COLUMNS
from pmsm_ev.vehicle import load_torque

METRICS_KEYS = ("status", "wall_time_s", "macro_steps", "us_per_step", "speed_rms_error", "omega_hat_rms_error",
                "theta_error_rms", "theta_error_max", "plateaus", "steps", "algorithm", "step_size", "stop_time",
                "output_interval", "settings", "scenario")


@pytest.fixture(scope="module")
def fmus():
    return project_fmus()


def header(out):
    return (out / "results.csv").read_text().splitlines()[0].split(",")


def cosim(args, capsys=None) -> int:
    return main(["run", *[str(a) for a in args], "--quiet"])


def test_end_to_end_scenario2_slice(fmus, tmp_path, capsys):
    out = tmp_path / "s2"
    assert cosim(["scenario2", "--stop-time", 0.3, "--out", out]) == 0
    summary = capsys.readouterr().out.strip().splitlines()[-1]
    assert summary.startswith("completed: 3000 steps") and str(out) in summary
    # result contract
    assert tuple(header(out)) == ALL_COLUMNS
    r = read_results(out)
    assert len(r["time"]) == round(0.3 / 0.01) + 1
    m = json.loads((out / "metrics.json").read_text())
    for key in METRICS_KEYS:
        assert key in m, key
    assert m["status"] == "completed" and m["macro_steps"] == 3000 and m["scenario"] == "scenario2"
    # physics: the speed follows the start-up ramp (20 rad/s^2), the load is eq 29
    assert np.max(np.abs(r["omega_ref"] - r["time"] * 20.0)) < 1e-12
    # the slow speed loop (omega_n = 2 rad/s) lags the ramp by a few rad/s at first
    assert np.all(np.diff(r["omega_m"]) > 0)
    assert np.max(np.abs(r["omega_m"] - r["omega_ref"])) < 5.0
    assert np.max(np.abs(r["omega_hat"] - r["omega_m"])) < 0.5
    assert np.all(r["delta_deg"] == 0.0)
    p = VehicleParams()
    expected = np.array([load_torque(w, 0.0, p) for w in r["omega_m"]])
    assert np.allclose(r["T_L_mech"], expected, rtol=1e-12, atol=1e-12)
    # figures (when the figures module is there)
    try:
        import pmsm_cosim.app.figures  # noqa: F401
    except ImportError:
        return
    assert sorted(p.suffix for p in (out / "figures").iterdir()) and all(
        p.suffix == ".png" for p in (out / "figures").iterdir())


def test_plateau_load_torque_is_eq29(fmus, tmp_path):
    out = tmp_path / "plateau"
    code = cosim([plateau_system(tmp_path), "--stop-time", 0.5, "--out", out, "--no-figures",
                  "--set", "plant.omega_m0=200", "plant.B_m=0", "plant.T_m0=0"])
    assert code == 0
    r = read_results(out)
    assert len(r["time"]) == 51
    assert r["omega_m"][0] == 200.0
    assert r["T_L_mech"][0] == pytest.approx(3.452, abs=5e-4)  # 0 deg, 200 rad/s
    assert np.all(np.abs(r["T_L_mech"] - 3.452) < 0.01)
    assert np.all(np.abs(r["omega_m"] - 200.0) < 2.0)  # the speed loop holds the plateau
    assert np.all(np.abs(r["omega_hat"][10:] - r["omega_m"][10:]) < 0.5)  # EKF converged


def test_gauss_seidel_equals_the_monolithic_reference(fmus, tmp_path):
    stop = 0.5
    ref = tmp_path / "ref"
    run_reference(ref, 2, stop_time=stop, observer="ekf5")
    out = tmp_path / "cosim"
    assert cosim(["scenario2", "--stop-time", stop, "--out", out, "--no-figures"]) == 0
    a, b = read_results(out), read_results(ref)
    assert tuple(header(out)) == tuple(header(ref))
    for col in ALL_COLUMNS:
        assert len(a[col]) == len(b[col]) == 51
        np.testing.assert_allclose(a[col], b[col], rtol=1e-9, atol=1e-9, err_msg=col)


@pytest.mark.parametrize("controller", ["FocEkf4", "FocEkf5AB", "FocSensored", "FocEkf5"])
def test_swapping_the_observer(fmus, tmp_path, controller):
    out = tmp_path / controller
    assert cosim(["scenario2", "--stop-time", 0.05, "--out", out, "--no-figures",
                  "--controller", fmus[controller]]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["status"] == "completed" and m["rows"] == 6
    assert any(c["fmu"].endswith(f"{controller}.fmu") for c in m["settings"]["components"])


def test_sensorless_and_jacobi_runs(fmus, tmp_path):
    out = tmp_path / "sensorless"
    assert cosim(["scenario1", "--stop-time", 0.05, "--out", out, "--no-figures",
                  "--set", "ctrl.angle_source=estimated"]) == 0
    assert json.loads((out / "metrics.json").read_text())["settings"]["components"][0]["start"] == {
        "angle_source": "estimated"}
    jac = tmp_path / "jacobi"
    assert cosim(["scenario1", "--stop-time", 0.05, "--out", jac, "--no-figures", "--algorithm", "jacobi"]) == 0
    gs = tmp_path / "gs"
    assert cosim(["scenario1", "--stop-time", 0.05, "--out", gs, "--no-figures"]) == 0
    a, b = read_results(jac), read_results(gs)
    assert not np.array_equal(a["omega_m"], b["omega_m"])  # one more step of delay in the loop
    assert np.max(np.abs(a["omega_m"] - b["omega_m"])) < 0.5


@pytest.mark.parametrize("option, toy", [("--plant", "ToySource"), ("--controller", "ToySink")])
def test_an_interface_lacking_a_connected_variable_is_refused_at_load(fmus, tmp_path, capsys, option, toy):
    out = tmp_path / "never"
    assert cosim(["scenario2", "--stop-time", 0.01, "--out", out, option, toy_fmus()[toy]]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "has no variable" in err[0]
    assert not out.exists()  # refused before anything ran


def test_a_non_physical_value_is_refused_in_one_line(fmus, tmp_path, capsys):
    out = tmp_path / "bad"
    assert cosim(["scenario2", "--stop-time", 0.01, "--out", out, "--set", "plant.L_d=-1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: plant") and "L_d must be > 0" in err[0]
    assert not out.exists()  # refused at initialisation, before anything was written


def test_unknown_start_variable_lists_close_matches(fmus, tmp_path, capsys):
    assert cosim(["scenario2", "--stop-time", 0.01, "--out", tmp_path / "x", "--set", "plant.omega_m=3"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "omega_m" in err and "cannot be set" in err
    assert cosim(["scenario2", "--stop-time", 0.01, "--out", tmp_path / "x", "--set", "plant.omega_mo=3"]) == 2
    err = capsys.readouterr().err
    assert "has no variable 'omega_mo' (did you mean:" in err and "omega_m0" in err


def test_units_must_agree(fmus, tmp_path):
    spec = load_system("scenario2")
    spec.connections = [c if c.dst_var != "i_alpha" else type(c)("plant", "omega_m", "ctrl", "i_alpha")
                        for c in spec.connections]
    with pytest.raises(CosimError, match=r"units differ \('rad/s' -> 'A'\)"):
        Master(spec)


def test_values_bit_identical_with_the_reference_delta(fmus, tmp_path):
    # delta in rad = math.radians(deg); its recorded degrees = math.degrees of that
    out = tmp_path / "d"
    assert cosim([plateau_system(tmp_path, delta_deg=22.0), "--stop-time", 0.01, "--out", out,
                  "--no-figures"]) == 0
    r = read_results(out)
    assert np.all(r["delta_deg"] == math.degrees(math.radians(22.0)))
