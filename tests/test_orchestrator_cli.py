"""pmsm-cosim: help on every command, one-line user errors with exit code 2, info, plot,
the progress bar. (Runs with the project's FMUs are in test_orchestrator_fmus.py.)"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys

import pytest

from orchestrator_support import toy_fmus, toy_system
from pmsm_cosim.app.cli import main
from pmsm_cosim.engine.progress import ProgressBar


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["export-ssp", "--help"], ["build", "--help"],
                                  ["info", "--help"], ["plot", "--help"], ["compare", "--help"], ["report", "--help"],
                                  ["sweep", "--help"]])
def test_help_on_every_command(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 0
    assert "usage: pmsm-cosim" in capsys.readouterr().out


def test_console_script_help():
    proc = subprocess.run([sys.executable, "-m", "pmsm_cosim.app.cli", "run", "--help"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and "--algorithm" in proc.stdout


def one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("error: ")
    return err[0]


@pytest.mark.parametrize("argv, message", [
    (["run", "missing.toml"], "system file not found"),
    (["run", "scenario3"], "no scenario or system file 'scenario3' (did you mean: "),
    (["run", "scenario1", "--set", "plant_omega=1"], "expected INSTANCE.VARIABLE"),
    (["run", "scenario1", "--set", "plant.omega_m0"], "expected INSTANCE.VAR=VALUE"),
    (["run", "scenario1", "--set", "plnt.omega_m0=1"], "did you mean: plant"),
    (["run", "scenario1", "--profile", "delta=nope.csv"], "profile file not found"),
    (["run", "scenario1", "--profile", "dlta=nope.csv"], "unknown signal 'dlta'"),
    (["run", "scenario1", "--fmu", "ctrl"], "expected INSTANCE=FMU"),
    (["info", "nope.fmu"], "FMU not found"),
    (["plot", "nope_dir"], "no such run directory"),
])
def test_user_errors_are_one_line_with_exit_code_2(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    assert message in one_line_error(capsys)


def test_bad_system_file(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text("name = 'x'\n[experiment\n")
    assert main(["run", str(path)]) == 2
    assert "not valid TOML" in one_line_error(capsys)


def test_missing_fmu_of_a_system_file(tmp_path, capsys):
    path = toy_system(tmp_path)
    text = path.read_text().replace(str(toy_fmus()["ToySink"]), str(tmp_path / "Gone.fmu"))
    path.write_text(text)
    assert main(["run", str(path), "--out", str(tmp_path / "o")]) == 2
    assert "FMU not found" in one_line_error(capsys)


def test_run_a_toy_system(tmp_path, capsys):
    out = tmp_path / "toy_out"
    assert main(["run", str(toy_system(tmp_path)), "--out", str(out), "--quiet", "--stop-time", "0.005",
                 "--set", "snk.gain=2"]) == 0
    summary = capsys.readouterr().out.strip()
    assert summary.startswith("completed: 5 steps") and str(out) in summary
    m = json.loads((out / "metrics.json").read_text())
    assert m["settings"]["command_line"]["set"] == ["snk.gain=2"]
    snk = next(c for c in m["settings"]["components"] if c["name"] == "snk")
    assert snk["start"]["gain"] == 2.0 and isinstance(snk["start"]["gain"], float)  # the Real the FMU got, not "2"
    assert m["stop_time"] == 0.005


def test_figures_of_merit_that_fail_are_said(tmp_path, monkeypatch, capsys):
    """A run whose figures of merit raise keeps its rows and its bookkeeping, and says so in one line, even with
    --quiet (metrics.json's ``metrics_error``); the run itself completed: exit 0."""
    from pmsm_cosim.app import cli

    def broken(*_args, **_kwargs):
        raise ValueError("no such column")

    monkeypatch.setattr(cli, "drive_metrics", broken)
    out = tmp_path / "o"
    assert main(["run", str(toy_system(tmp_path)), "--out", str(out), "--quiet", "--stop-time", "0.005"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["warning: the figures of merit could not be computed (ValueError: no such column); metrics.json "
                   "holds the run's bookkeeping only"]
    m = json.loads((out / "metrics.json").read_text())
    assert m["metrics_error"] == "ValueError: no such column" and m["status"] == "completed"
    assert (out / "results.csv").is_file()


def test_default_out_dir_is_runs_scenario_name(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(toy_system(tmp_path, name="mytoy")), "--quiet"]) == 0
    assert (tmp_path / "runs" / "mytoy" / "results.csv").is_file()


def test_failed_run_exit_code_1(tmp_path, capsys):
    out = tmp_path / "f"
    assert main(["run", str(toy_system(tmp_path, snk_start="fail_at = 2")), "--out", str(out), "--quiet"]) == 1
    assert capsys.readouterr().out.startswith("failed: snk: fmi2DoStep failed")


def test_info_lists_variables(capsys):
    assert main(["info", str(toy_fmus()["ToySink"])]) == 0
    out = capsys.readouterr().out
    assert "ToySink (FMI 2.0, co-simulation" in out
    lines = {ln.split()[0]: ln.split() for ln in out.splitlines()[3:] if ln.strip()}
    assert lines["u"][1:4] == ["input", "continuous", "Real"]
    assert lines["label"][1:4] == ["parameter", "fixed", "String"]
    assert main(["info", str(toy_fmus()["ToySink"]), "--causality", "input"]) == 0
    out = capsys.readouterr().out
    assert " u " in out and " gain " not in out


def test_plot_needs_the_contract_columns(tmp_path, capsys):
    out = tmp_path / "toy"
    assert main(["run", str(toy_system(tmp_path)), "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    pytest.importorskip("pmsm_cosim.app.figures")
    assert main(["plot", str(out)]) == 2
    assert "missing columns" in one_line_error(capsys)


# --- progress bar ------------------------------------------------------------------------------

class FakeTTY(io.StringIO):
    def isatty(self):
        return True


def test_progress_bar_only_on_a_tty():
    assert ProgressBar.wanted(False, FakeTTY())
    assert not ProgressBar.wanted(True, FakeTTY())
    assert not ProgressBar.wanted(False, io.StringIO())


def test_progress_bar_is_rate_limited_and_cleared():
    stream = FakeTTY()
    bar = ProgressBar(10.0, stream=stream, rate=4.0)
    for k in range(1000):
        bar.update(k * 0.01)
    text = stream.getvalue()
    assert text.count("\r[") == 1  # a thousand updates within 1/4 s: drawn once
    assert "sim-s/s" in text and "ETA" in text and "/10 s" in text
    bar.close()
    assert stream.getvalue().endswith("\r")


def test_the_fmu_folder_override_is_undone(tmp_path, monkeypatch):
    """--fmu-dir sets $PMSM_COSIM_FMU_DIR for the command (its child processes see it too)
    and puts back what was there."""
    from pmsm_cosim.app.drive import fmu_dir_override, load_system, project_fmu_dir

    monkeypatch.setenv("PMSM_COSIM_FMU_DIR", str(tmp_path / "before"))
    with fmu_dir_override(tmp_path / "mine"):
        assert project_fmu_dir() == tmp_path / "mine"
        assert {c.fmu.parent for c in load_system("scenario1").components} == {tmp_path / "mine"}
        child = subprocess.run([sys.executable, "-c", "import os; print(os.environ['PMSM_COSIM_FMU_DIR'])"],
                               capture_output=True, text=True, check=True)
        assert child.stdout.strip() == str(tmp_path / "mine")
    assert project_fmu_dir() == tmp_path / "before"
    with fmu_dir_override(None):
        assert project_fmu_dir() == tmp_path / "before"
    monkeypatch.delenv("PMSM_COSIM_FMU_DIR")
    with fmu_dir_override(tmp_path / "mine"):
        pass
    assert "PMSM_COSIM_FMU_DIR" not in os.environ


@pytest.mark.parametrize("argv", [["run", "scenario1"], ["export-ssp", "scenario1", "-o", "x.ssp"], ["sweep", "s"],
                                  ["build"], ["info", "x.fmu"], ["report"], ["bench"]])
def test_every_command_that_uses_the_fmus_takes_fmu_dir(argv, tmp_path):
    from pmsm_cosim.app.cli import build_parser

    assert build_parser().parse_args([*argv, "--fmu-dir", str(tmp_path)]).fmu_dir == str(tmp_path)
