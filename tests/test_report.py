"""pmsm-cosim report on a tiny configuration (two configurations, 1.5 s runs): the
numbers in docs/results.md are the runs' metrics; runs are reused when their settings
are unchanged and rerun when they change; --only reruns only its configurations."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app import report
from pmsm_cosim.app.cli import main
from pmsm_cosim.engine.recording import read_results

STOP = 1.5
T_FROM = 0.5
TINY = [c for c in report.CONFIGS if c.id in ("s2-ekf5-paper", "s2-ekf5ab")]


def table_row(text: str, heading: str, label: str) -> list[str]:
    """Cells of the row ``label`` in the first table after ``heading``."""
    part = text[text.index(heading):]
    for line in part.splitlines():
        if line.startswith(f"| {label} |"):
            return [c.strip() for c in line.strip().strip("|").split("|")]
    raise AssertionError(f"no row {label!r} after {heading!r}")


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    project_fmus()
    base = tmp_path_factory.mktemp("report")
    logs = []
    path = report.generate(out=base / "docs", runs_dir=base / "runs", jobs=2, stop_time=STOP, configs=TINY,
                           log=logs.append, t_from=T_FROM)
    return base, path, logs


def test_report_tables_are_the_runs_metrics(tiny):
    base, path, logs = tiny
    assert "0 runs reused, 2 to run, 2 at a time" in logs[0]
    text = path.read_text(encoding="utf-8")
    assert "pmsm-cosim report" in text and f"stop time {STOP:g} s" in text
    keys = report.TABLE_KEYS
    for cfg in TINY:
        run_dir = base / "runs" / cfg.id
        m = json.loads((run_dir / "metrics.json").read_text())
        assert m["status"] == "completed" and m["stop_time"] == STOP
        r = read_results(run_dir)
        cells = dict(zip(keys, table_row(text, "## Scenario 2", cfg.label)))
        assert cells["status"] == "completed"
        # whole run: metrics.json's figure
        assert cells["speed_rms_error"] == format(m["speed_rms_error"], ".3f")
        # after T_FROM: recomputed here from results.csv
        w = r["time"] >= T_FROM
        assert cells["speed_rms_after"] == format(math.sqrt(np.mean((r["omega_ref"] - r["omega_m"])[w] ** 2)), ".3f")
        assert cells["omega_hat_rms_after"] == format(
            math.sqrt(np.mean((r["omega_hat"] - r["omega_m"])[w] ** 2)), ".3f")
        err = (r["theta_hat"] - r["theta_e"] + math.pi) % (2 * math.pi) - math.pi
        assert cells["theta_max_after"] == format(np.max(np.abs(err[w])), ".3f")
        assert cells["step_dev_max"] == "-"  # no elevation step in 1.5 s
        # the run was made with the configuration's settings
        settings = m["settings"]
        ctrl = next(c for c in settings["components"] if c["name"] == "ctrl")
        assert ctrl["fmu"].endswith(report.OBSERVER_FMUS[cfg.setup.observer] + ".fmu")
        assert ctrl["start"]["angle_source"] == cfg.setup.angle_source
        if cfg.setup.flying:  # flying start at 200 rad/s, constant reference
            assert r["omega_m"][0] == 200.0 and np.all(r["omega_ref"] == 200.0) and r["omega_hat"][0] == 200.0
            assert abs(r["omega_m"][-1] - 200.0) < 5.0
        else:  # the start-up ramp, 20 rad/s^2
            assert r["omega_m"][0] == 0.0 and r["omega_ref"][-1] == pytest.approx(20.0 * STOP)
    # the two configurations are different runs
    a, b = (table_row(text, "## Scenario 2", c.label) for c in TINY)
    assert a[2:] != b[2:]
    # the prose quotes the same numbers as the table
    assert f"ω̂ RMS err after {T_FROM:g} s" in text
    theta = dict(zip(keys, table_row(text, "## Scenario 2", "EKF5 paper mode")))["theta_drift"]
    assert f"{theta} rad (scenario 2)" in text
    figs = sorted((base / "docs" / "results").glob("*.png"))
    assert {p.stem for p in figs} >= {"s2_speed", "s2_angle_error", "s2_torque"}
    for p in figs:
        assert 0 < p.stat().st_size < 150_000
        assert f"(results/{p.name})" in text


def test_report_reuses_and_reruns(tiny):
    base, path, _ = tiny
    runs = base / "runs"
    stamp = {c.id: (runs / c.id / "metrics.json").stat().st_mtime_ns for c in TINY}
    logs = []
    report.generate(out=base / "docs", runs_dir=runs, stop_time=STOP, configs=TINY, log=logs.append, t_from=T_FROM)
    assert "2 runs reused, 0 to run" in logs[0]
    assert {c.id: (runs / c.id / "metrics.json").stat().st_mtime_ns for c in TINY} == stamp
    # --only: only the selected configuration reruns
    logs = []
    report.generate(out=base / "docs", runs_dir=runs, stop_time=STOP, configs=TINY, log=logs.append,
                    only=["ekf5ab"], force=True, t_from=T_FROM)
    assert "1 runs reused, 1 to run" in logs[0] and any(m.startswith("s2-ekf5ab: completed") for m in logs)
    assert (runs / "s2-ekf5-paper" / "metrics.json").stat().st_mtime_ns == stamp["s2-ekf5-paper"]
    assert (runs / "s2-ekf5ab" / "metrics.json").stat().st_mtime_ns != stamp["s2-ekf5ab"]
    # an interrupted run (or one with other settings) is not reused
    m = json.loads((runs / "s2-ekf5-paper" / "metrics.json").read_text())
    m["status"] = "interrupted"
    (runs / "s2-ekf5-paper" / "metrics.json").write_text(json.dumps(m))
    key = report._key(TINY[0], STOP, runs / "omega_ref_flying.csv", report._fmu_hashes({"FocEkf5", "PmsmEvPlant"}))
    assert not report.reusable(runs / "s2-ekf5-paper", key)
    assert not report.reusable(runs / "s2-ekf5ab", report._key(TINY[1], 2 * STOP, runs / "x.csv", {
        "FocEkf5AB": "?", "PmsmEvPlant": "?"}), ignore_hashes=True)
    assert report.reusable(runs / "s2-ekf5ab", report._key(TINY[1], STOP, runs / "x.csv", {
        "FocEkf5AB": "?", "PmsmEvPlant": "?"}), ignore_hashes=True)


def test_report_cli_errors(tmp_path, capsys):
    assert main(["report", "--only", "nosuchconfig", "--runs", str(tmp_path / "r"), "--out",
                 str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --only nosuchconfig: matches no configuration")
    assert main(["report", "--jobs", "0", "--runs", str(tmp_path / "r")]) == 2
    assert main(["report", "--list"]) == 0
    ids = capsys.readouterr().out.split()
    assert "s1-ekf5-paper:" in ids and "s2-angle-ekf5ab:" in ids and "sl-hill-exact-sensorless:" in ids
    assert len(report.CONFIGS) == 28 + 18 + 16 + 3 + 9  # paper and realism; sensorless: 3 x 3 x 2 + 8 angles x 2;
    # the whole speed range: 3 acceleration runs; the drive cycles: 4 cycles x 2 controllers + wltc3b-hilly


def synthetic_run(t, theta_err, delta_deg, omega_m):
    """A Run whose angle error, elevation and speed are given (other columns zero)."""
    from pmsm_cosim.app.compare import Run

    z = np.zeros_like(t)
    theta_e = (7.0 * t + math.pi) % (2 * math.pi) - math.pi
    r = {"time": t, "theta_e": theta_e, "theta_hat": theta_e + theta_err, "delta_deg": delta_deg,
         "omega_m": omega_m, "omega_ref": z + 200.0, "omega_hat": omega_m, "T_L_hat": z, "T_L_mech": z}
    return Run("synthetic", Path("."), {}, r)


def test_recovery_needs_the_error_to_stay_small():
    t = np.arange(0.0, 60.0, 0.01)
    zero = np.zeros_like(t)
    converging = synthetic_run(t, -0.5 * np.exp(-t / 0.2), zero, zero + 200.0)
    rc = report.recovery(converging)
    assert rc["start"] == pytest.approx(-0.5) and abs(rc["at_1s"]) < 0.01
    assert rc["t_recovered"] == pytest.approx(0.2 * math.log(0.5 / report.RECOVERED), abs=0.011)
    drifting = synthetic_run(t, -0.5 - 0.2 * t, zero, zero + 200.0)  # crosses the band, never stays
    assert report.recovery(drifting)["t_recovered"] is None


def test_load_split_sums_drift_per_plateau_kind():
    t = np.arange(0.0, 90.0, 0.01)
    delta = np.where((t >= 30) & (t < 60), 22.0, 0.0)
    err = np.cumsum(np.where(delta == 0, -0.001, 0.0))  # -0.1 rad/s on level plateaus
    omega = 200.0 + np.where(delta == 0, 5.0 * np.sin(t), 0.0)
    sp = report.load_split(synthetic_run(t, err, delta, omega), t_from=20.0)
    assert sp["level_drift"] == pytest.approx(-0.1 * (10 + 30), abs=0.01)  # 20-30 s and 60-90 s
    assert sp["inclined_drift"] == pytest.approx(0.0, abs=1e-12)
    assert sp["level_ptp"] == pytest.approx(10.0, abs=0.01) and sp["inclined_ptp"] == 0.0


# -- the section "Sensorless from standstill" ---------------------------------------------------------
SENSORLESS_TINY = [c for c in report.CONFIGS
                   if c.id in ("sl-s1-exact-sensorless", "sl-s1-exact-sensored", "sl-start0-exact-sensorless")]


@pytest.mark.slow
def test_sensorless_section_quotes_its_runs(tmp_path):
    """6 s runs (alignment, I-f, handover): the table's handover time and roll-back are the
    runs' own, read back from results.csv; targets without rows to judge show '-'."""
    from pmsm_cosim.app.metrics.rows import roll_back

    project_fmus()
    assert len(SENSORLESS_TINY) == 3
    start0 = next(c for c in SENSORLESS_TINY if c.id == "sl-start0-exact-sensorless")
    assert "plant.theta_e0=-3.141592653589793" in start0.run_args(None, tmp_path / "x.csv")
    path = report.generate(out=tmp_path / "docs", runs_dir=tmp_path / "runs", jobs=2, stop_time=6.0,
                           configs=SENSORLESS_TINY, log=lambda *_: None)
    text = path.read_text(encoding="utf-8")
    assert "## Sensorless from standstill" in text
    r = read_results(tmp_path / "runs" / "sl-s1-exact-sensorless")
    cells = table_row(text, "## Sensorless from standstill", "Scenario 1")  # the first row: sensorless
    t_up = r["time"][np.nonzero(np.diff(r["mode"]))[0][-1] + 1]
    assert cells[2] == "sensorless" and cells[4] == f"{t_up:.2f}"
    assert cells[-2] == f"{100 * roll_back(r['x_vehicle']):.2f}"
    assert set(read_results(tmp_path / "runs" / "sl-s1-exact-sensored")["mode"]) == {2.0}  # no other modes
    r0 = read_results(tmp_path / "runs" / "sl-start0-exact-sensorless")
    assert r0["theta_e"][0] == pytest.approx(-math.pi)
    row = table_row(text, "Start-up from eight initial rotor angles", "-3.142")
    assert row[4] == f"{100 * roll_back(r0['x_vehicle']):.2f}"
    assert (tmp_path / "docs" / "results" / "sensorless_startup.png").is_file()
