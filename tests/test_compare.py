"""pmsm-cosim compare: the table's numbers equal the runs' metrics (and an independent
recomputation from results.csv); bad input is a one-line error with exit code 2. Also
the shipped scenario variants: they load, differ from scenario 2 only in the plant's
start values, and really switch the sensor noise / offset / initial angle on."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app.cli import main
from pmsm_cosim.app.compare import COLUMNS, format_value
from pmsm_cosim.app.drive import PACKAGED_SCENARIOS, load_system
from pmsm_cosim.app.metrics.windows import figures_where, run_timing
from pmsm_cosim.engine.recording import read_results
from pmsm_ev.params import MotorParams, VehicleParams
from pmsm_ev.results import row_timing_corrected_angle_error

T_STEP = 0.3  # [s] elevation step of the test runs
T_FROM = 1.0  # [s] start of the "after" window
STOP = 2.5  # [s] the segment after the step is >= 2 s long: one plateau


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    """EKF5 (paper mode), EKF4 and the sensored drive on scenario 2 at 200 rad/s, 0 -> 10 deg at 0.3 s."""
    fmus = project_fmus()
    base = tmp_path_factory.mktemp("cmp")
    (base / "delta.csv").write_text(f"time,deg\n0,0\n{T_STEP},10\n")
    (base / "wref.csv").write_text("time,w\n0,200\n")
    runs = {}
    for label, fmu in (("ekf5", "FocEkf5"), ("ekf4", "FocEkf4"), ("sensored", "FocSensored")):
        out = base / label
        assert main(["run", "scenario2", "--controller", str(fmus[fmu]),
                     "--stop-time", str(STOP), "--out", str(out), "--quiet", "--no-figures",
                     "--profile", f"delta={base / 'delta.csv'}", "--profile", f"omega_ref={base / 'wref.csv'}",
                     "--set", "plant.omega_m0=200", "ctrl.x0_omega=200"]) == 0
        runs[label] = out
    return base, runs


def test_compare_table_equals_the_runs_metrics(two_runs, capsys):
    base, runs = two_runs
    out = base / "cmp_out"
    assert main(["compare", str(runs["ekf5"]), str(runs["ekf4"]), "--out", str(out),
                 "--labels", "EKF5", "EKF4", "--from", str(T_FROM)]) == 0
    printed = capsys.readouterr().out
    with open(out / "metrics.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["label"] for r in rows] == ["EKF5", "EKF4"]
    md_lines = (out / "metrics.md").read_text().splitlines()
    assert md_lines[-2].startswith("| EKF5 | scenario2 | completed |") and md_lines[-1].startswith("| EKF4 |")
    assert md_lines[-1] in printed
    for row, md_line, label in zip(rows, md_lines[-2:], ("ekf5", "ekf4")):
        m = json.loads((runs[label] / "metrics.json").read_text())
        r = read_results(runs[label])
        t = r["time"]
        # whole-run figure: exactly metrics.json's
        assert float(row["speed_rms_error"]) == m["speed_rms_error"]
        assert float(row["stop_time"]) == STOP
        # the step: one, at T_STEP; its dip is the largest speed error after it
        assert len(m["steps"]) == 1 and m["steps"][0]["t"] == pytest.approx(T_STEP)
        after_step = t >= T_STEP - 1e-9
        dip = np.max(np.abs(r["omega_ref"] - r["omega_m"])[after_step])
        assert float(row["step_dev_max"]) == float(row["step_dev_min"]) == m["steps"][0]["max_speed_deviation"] == dip
        assert 1.0 < dip < 20.0  # a 10 deg step costs a few rad/s
        # windowed figures, recomputed here from the rows
        w = t >= T_FROM
        assert float(row["speed_rms_after"]) == pytest.approx(
            math.sqrt(np.mean((r["omega_ref"] - r["omega_m"])[w] ** 2)), rel=1e-12)
        assert float(row["omega_hat_rms_after"]) == pytest.approx(
            math.sqrt(np.mean((r["omega_hat"] - r["omega_m"])[w] ** 2)), rel=1e-12)
        err = (r["theta_hat"] - r["theta_e"] + math.pi) % (2 * math.pi) - math.pi
        assert np.max(np.abs(err)) < 1.0  # no slip in 2.5 s: the wrapped error is the error
        assert float(row["theta_max_after"]) == pytest.approx(np.max(np.abs(err[w])), rel=1e-12)
        assert float(row["theta_drift"]) == pytest.approx(err[w][-1] - err[w][0], abs=1e-12)
        # the Markdown cells are the CSV values, formatted
        cells = [c.strip() for c in md_line.strip("|").split("|")]
        for (key, _, fmt), cell in zip(COLUMNS, cells):
            value = row[key] if fmt == "s" else (float(row[key]) if row[key] else None)
            assert cell == format_value(value, fmt), key
    # the torque estimate: EKF5 has one (eq 31: T_L_mech + friction + the reflected inertia
    # times dw/dt, a few N m while the speed still recovers), EKF4 has no load state ("-")
    m5 = json.loads((runs["ekf5"] / "metrics.json").read_text())
    (plateau,) = [p for p in m5["plateaus"] if p["delta_deg"] == 10.0]
    assert float(rows[0]["T_L_err_max"]) == pytest.approx(
        max(abs(p["T_L_hat_mean"] - p["T_L_mech_mean"]) for p in m5["plateaus"]), rel=1e-12)
    assert abs(plateau["T_L_hat_mean"] - plateau["T_L_mech_mean"]) < 5.0 < plateau["T_L_mech_mean"] / 5
    assert rows[1]["T_L_err_max"] == rows[1]["T_L_eq31_rms_after"] == "" and md_lines[-1].rstrip().endswith("| - | - |")
    # eq 31 (T_L_mech + B_m w + T_m0 + (J_eq - J_m) dw/dt), recomputed here
    r = read_results(runs["ekf5"])
    mp, vp = MotorParams(), VehicleParams()
    eq31 = r["T_L_mech"] + mp.B_m * r["omega_m"] + mp.T_m0 + vp.reflected_inertia * np.gradient(r["omega_m"], r["time"])
    w = r["time"] >= T_FROM
    rms = math.sqrt(np.mean((r["T_L_hat"] - eq31)[w] ** 2))
    assert float(rows[0]["T_L_eq31_rms_after"]) == pytest.approx(rms, rel=1e-12)
    assert rms < 0.5  # after the step's transient the estimate follows eq 31 closely
    # the two observers give different numbers (the table is not one run twice)
    assert rows[0]["omega_hat_rms_after"] != rows[1]["omega_hat_rms_after"]
    for name in ("compare_speed.png", "compare_angle_error.png", "compare_torque.png"):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) < 150_000


def test_row_timing_term_is_removed_with_the_runs_step_and_pole_pairs(two_runs):
    """The sensored drive's theta_hat is the measured angle at the previous step, so its recorded
    error is the row-timing term alone, -N omega dt (-0.08 rad at 200 rad/s): removed with the run's
    own step and pole pairs (``run_timing`` of its metrics.json) what is left is the angle the rotor
    turns differently from N omega dt within a step, < 1e-4 rad; with a wrong step it stays."""
    _, runs = two_runs
    m = json.loads((runs["sensored"] / "metrics.json").read_text())
    r = read_results(runs["sensored"])
    assert run_timing(m) == (1e-4, 4.0)
    raw = (r["theta_hat"] - r["theta_e"] + math.pi) % (2 * math.pi) - math.pi
    w = r["time"] >= T_FROM
    lag = 4 * r["omega_m"][w] * 1e-4  # N omega dt, 0.077 rad at the 193 rad/s after the step
    assert np.mean(raw[w]) == pytest.approx(-np.mean(lag), rel=1e-3) and np.mean(lag) > 0.075
    assert np.max(np.abs(row_timing_corrected_angle_error(r, *run_timing(m))[w])) < 1e-4
    assert np.mean(row_timing_corrected_angle_error(r, 2e-4, 4)[w]) == pytest.approx(np.mean(lag), rel=1e-3)
    # the run's own settings win: a controller stepping every 2 communication steps, a plant with N = 5
    m2 = {**m, "settings": {**m["settings"], "components": [
        {**c, "step_multiple": 2} if c["name"] == "ctrl" else {**c, "start": {**c["start"], "N": 5}}
        for c in m["settings"]["components"]]}}
    assert run_timing(m2) == (2e-4, 5.0)
    with pytest.raises(ValueError, match="no step size"):
        run_timing({"speed_rms_error": 1.0})


def one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("error: ")
    return err[0]


def test_compare_bad_input_is_one_line_exit_2(tmp_path, capsys):
    assert main(["compare", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert "no such run directory" in one_line_error(capsys)
    (tmp_path / "empty").mkdir()
    assert main(["compare", str(tmp_path / "empty"), "--out", str(tmp_path / "o")]) == 2
    assert "no results.csv" in one_line_error(capsys)
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "results.csv").write_text("time,x\n0,1\n1,2\n")
    assert main(["compare", str(tmp_path / "bad"), "--out", str(tmp_path / "o")]) == 2
    assert "missing columns: delta_deg" in one_line_error(capsys)


def test_compare_labels_must_match(two_runs, capsys):
    base, runs = two_runs
    assert main(["compare", str(runs["ekf5"]), "--labels", "a", "b", "--out", str(base / "o2")]) == 2
    assert "2 labels for 1 run directories" in one_line_error(capsys)


# --- scenario variants ---------------------------------------------------------------

VARIANTS = {
    "scenario2-noisy": {"sensor_noise": 0.1, "sensor_seed": 1},
    "scenario2-noisy1A": {"sensor_noise": 1.0, "sensor_seed": 1},
    "scenario2-offset": {"sensor_offset_a": 2.0, "sensor_offset_b": -1.0},
    "scenario2-angle-error": {"theta_e0": 0.5},
}


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_variants_are_scenario2_with_plant_start_values(name):
    assert name in PACKAGED_SCENARIOS
    spec, base = load_system(name), load_system("scenario2")
    assert spec.name == name
    assert spec.component("plant").start == VARIANTS[name]
    spec.component("plant").start = {}
    a, b = spec.settings(), base.settings()
    for s in (a, b):
        s.pop("system"), s.pop("system_file")
    assert a == b
    assert [c.name for c in spec.columns] == [c.name for c in base.columns]


@pytest.mark.parametrize("name, noise, offset_a", [("scenario2-noisy", 0.1, 0.0), ("scenario2-noisy1A", 1.0, 0.0),
                                                   ("scenario2-offset", 0.0, 2.0), ("scenario2", 0.0, 0.0)])
def test_variant_sensors_are_really_on(name, noise, offset_a, tmp_path, capsys):
    """Phase-a measurement error = i_alpha - true i_alpha (inverse Park of the true dq
    currents at the true angle), from a run recorded at every step."""
    project_fmus()
    out = tmp_path / name
    assert main(["run", name, "--stop-time", "0.1", "--output-interval", "1e-4", "--out", str(out),
                 "--quiet", "--no-figures"]) == 0
    r = read_results(out)
    err = r["i_alpha"] - (r["i_d"] * np.cos(r["theta_e"]) - r["i_q"] * np.sin(r["theta_e"]))
    assert len(err) == 1001
    if noise:
        assert abs(np.std(err) / noise - 1.0) < 0.1
    else:
        assert np.std(err) < 1e-9
    assert abs(np.mean(err) - offset_a) < max(0.2 * noise, 1e-9)


def test_angle_error_variant_starts_the_rotor_at_half_a_radian(tmp_path):
    project_fmus()
    out = tmp_path / "ae"
    assert main(["run", "scenario2-angle-error", "--stop-time", "0.01", "--output-interval", "1e-4",
                 "--out", str(out), "--quiet", "--no-figures"]) == 0
    r = read_results(out)
    assert r["theta_e"][0] == 0.5 and r["theta_hat"][0] == 0.0


def test_figures_where_on_a_known_window():
    """``figures_where``: speed, angle (row timing removed) and position figures of the selected rows."""
    t = np.arange(0.0, 10.0, 0.01)
    w = 100.0 + np.where(t >= 5.0, 2.0, -1.0)  # 1 rad/s under the reference, then 2 over
    theta = (4 * w * t + math.pi) % (2 * math.pi) - math.pi
    x = np.where(t < 7.0, t, 7.0 - 0.5 * (t - 7.0))  # rolls back 1.5 m in the last 3 s
    r = {"time": t, "omega_ref": np.full_like(t, 100.0), "omega_m": w, "theta_e": theta,
         "theta_hat": theta - 4 * w * 1e-4 + 0.01, "x_vehicle": x}
    f = figures_where(r, t >= 5.0, 1e-4, 4)
    assert f["speed_rms_error"] == pytest.approx(2.0) and f["speed_bias"] == pytest.approx(2.0)
    assert f["speed_error_max"] == pytest.approx(2.0) and f["speed_max"] == pytest.approx(102.0)
    assert f["angle_rms"] == pytest.approx(0.01) and f["angle_max"] == pytest.approx(0.01)
    assert f["roll_back"] == pytest.approx(1.495, abs=1e-9) and f["travel"] == pytest.approx(2.0)
    assert figures_where(r, t < 5.0)["speed_bias"] == pytest.approx(-1.0)
    assert figures_where(r, t < 5.0)["angle_rms"] is None  # no step, no pole pairs: no angle figures
    assert set(figures_where(r, t > 99.0).values()) == {None}
