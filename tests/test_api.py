"""The Python API (``pmsm_cosim.simulate``): the numbers of ``pmsm-cosim run``, as a numpy
structured array and the metrics dict, with no file written unless asked; a user's system
without the drive's columns runs and says it has no drive metrics."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import pmsm_cosim
from orchestrator_support import project_fmus, toy_system
from pmsm_cosim.app.api import prepare
from pmsm_cosim.app.cli import main
from pmsm_cosim.app.drive import load_system
from pmsm_cosim.engine.errors import CosimError
from pmsm_cosim.engine.recording import read_results

STOP = 0.3


@pytest.fixture(scope="module")
def fmus():
    return project_fmus()


@pytest.fixture(scope="module")
def cli_run(fmus, tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "run"
    assert main(["run", "scenario2", "--stop-time", str(STOP), "--no-figures", "--quiet", "--out", str(out),
                 "--controller", "ekf4", "--set", "ctrl.angle_source=estimated"]) == 0
    return read_results(out), json.loads((out / "metrics.json").read_text())


def test_simulate_gives_the_numbers_of_the_command_line_and_writes_nothing(fmus, cli_run, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result, metrics = pmsm_cosim.simulate("scenario2", stop_time=STOP, controller="ekf4",
                                          set={"ctrl.angle_source": "estimated"})
    columns, cli_metrics = cli_run
    assert isinstance(result, np.ndarray) and result.dtype.names == tuple(columns)
    assert len(result) == round(STOP / 0.01) + 1
    for name, values in columns.items():
        assert np.array_equal(result[name], values), name  # bit for bit
    assert metrics["status"] == "completed"
    for key in ("speed_rms_error", "theta_error_max", "omega_hat_rms_error"):
        assert metrics[key] == cli_metrics[key]
    ctrl = next(c for c in metrics["settings"]["components"] if c["name"] == "ctrl")
    assert ctrl["fmu"].endswith("FocEkf4.fmu") and ctrl["start"]["angle_source"] == "estimated"
    assert list(tmp_path.iterdir()) == []  # no runs/ directory, no file


def test_simulate_writes_the_run_files_when_asked(fmus, tmp_path):
    out = tmp_path / "run"
    result, metrics = pmsm_cosim.simulate("scenario1", stop_time=0.1, output_dir=out,
                                          set=["ctrl.q_TL=0.02"])
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json", "results.csv"]
    assert np.array_equal(read_results(out)["omega_m"], result["omega_m"])
    assert json.loads((out / "metrics.json").read_text())["speed_rms_error"] == metrics["speed_rms_error"]


def test_a_user_system_without_the_drive_columns_runs_and_says_so(tmp_path, capsys):
    path = toy_system(tmp_path, stop_time=0.01)
    result, metrics = pmsm_cosim.simulate(path)
    assert metrics["status"] == "completed"
    assert "speed_rms_error" not in metrics
    assert metrics["metrics_note"].startswith("no drive metrics: the recorded columns lack delta_deg, omega_ref")
    assert result.dtype.names == ("time", "y", "src_calls", "last_u", "snk_calls", "last_h", "last_t")
    assert len(result) == 11
    out = tmp_path / "cli"
    assert main(["run", str(path), "--out", str(out), "--no-figures"]) == 0
    assert "note: no drive metrics: the recorded columns lack" in capsys.readouterr().err
    assert json.loads((out / "metrics.json").read_text())["metrics_note"] == metrics["metrics_note"]


@pytest.mark.parametrize("kwargs,message", [
    ({"stop_time": -1.0}, "stop_time=-1.0: must be a finite number > 0 s"),
    ({"controller": "ekf6"}, "controller='ekf6': not an .fmu file, an observer or a shipped FMU (did you mean: "),
    ({"set": {"ctrl.nope": 1}}, "has no variable 'nope'"),
    ({"set": ["ctrl.q_TL"]}, "set='ctrl.q_TL': expected INSTANCE.VAR=VALUE"),
    ({"start_values": {"ctrl.nope": 1}}, "has no variable 'nope'"),
    ({"algorithm": "euler"}, "algorithm='euler': choose gauss-seidel or jacobi"),
    ({"record": ["omega"]}, "record='omega': not a column of scenario2 (did you mean: omega_m"),
    ({"output": ["plnt.omega_m"]}, "unknown instance 'plnt' (did you mean: plant?)"),
    ({"set": {"ctrl.q_TL": 0.02}, "start_values": {"ctrl.q_TL": 0.02}},
     "give set= or start_values= (fmpy's name for it), not both"),
    ({"record": ["omega_m"], "output": ["omega_m"]}, "give record= or output= (fmpy's name for it), not both"),
])
def test_bad_input_is_a_one_line_error(fmus, kwargs, message):
    with pytest.raises(CosimError) as e:
        pmsm_cosim.simulate("scenario2", **{"stop_time": 0.01, **kwargs})
    assert message in str(e.value) and "\n" not in str(e.value)


def test_an_unknown_scenario_names_the_close_ones():
    with pytest.raises(CosimError, match="no scenario or system file 'scenario3'.*did you mean"):
        pmsm_cosim.simulate("scenario3")


def test_the_readme_example_runs_as_written(fmus, tmp_path, monkeypatch, capsys):
    text = (Path(__file__).resolve().parent.parent / "README.md").read_text(encoding="utf-8")
    block = text.split("**From Python.**", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(block, "README.md", "exec"), scope)  # noqa: S102 - the README's own example
    status, rms = capsys.readouterr().out.split()
    assert status == "completed" and 0 < float(rms) < 20
    assert len(scope["omega_error"]) == 6001 and list(tmp_path.iterdir()) == []


CHOICES = "choose one of ekf5, ekf4, ekf5ab, sensored, sensorless, PmsmEvPlant, FocEkf5, FocEkf4, FocEkf5AB, "


@pytest.mark.parametrize("option, api", [("--controller", "controller"), ("--plant", "plant")])
def test_an_unknown_fmu_name_is_one_line_listing_the_choices_on_both(option, api, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["run", "scenario2", option, "ekf9", "--stop-time", "0.01", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {option} ekf9: not an .fmu file, an observer or a shipped FMU")
    assert CHOICES in err[0] and err[0].endswith("or give an .fmu file")
    with pytest.raises(CosimError) as e:
        pmsm_cosim.simulate("scenario2", **{api: "ekf9"})
    assert str(e.value) == err[0].removeprefix("error: ").replace(f"{option} ekf9", f"{api}='ekf9'")
    assert list(tmp_path.iterdir()) == []


def test_every_observer_name_and_fmu_name_is_taken_on_both(fmus, tmp_path, monkeypatch):
    """The names resolve to the project's FMUs on both (one function), an FMU path and
    {fmus}/X.fmu as well; --fmu INSTANCE=FMU is fmus={INSTANCE: FMU}."""
    from pmsm_cosim.app.cli import _load_with_overrides, build_parser
    from pmsm_cosim.app.drive import project_fmu_dir

    monkeypatch.chdir(fmus["FocSensored"].parent)
    for value, expected in (("ekf4", "FocEkf4"), ("ekf5", "FocEkf5"), ("ekf5ab", "FocEkf5AB"),
                            ("sensored", "FocSensored"), ("sensorless", "FocSensorless"), ("FocEkf4", "FocEkf4"),
                            ("{fmus}/FocEkf5AB.fmu", "FocEkf5AB"), ("FocSensored.fmu", fmus["FocSensored"])):
        expected = expected if isinstance(expected, Path) else project_fmu_dir() / f"{expected}.fmu"
        cli = _load_with_overrides(build_parser().parse_args(
            ["run", "scenario1", "--controller", value, "--fmu", "plant=PmsmEvPlant"]))
        api = prepare("scenario1", controller=value, fmus={"plant": "PmsmEvPlant"})
        assert cli.component("ctrl").fmu == api.component("ctrl").fmu == expected, value
        assert cli.component("plant").fmu == api.component("plant").fmu == project_fmu_dir() / "PmsmEvPlant.fmu"


def test_simulate_leaves_the_system_given_unchanged(fmus):
    spec = load_system("scenario2")
    before = copy.deepcopy(spec)
    starts = {"ctrl.angle_source": "estimated"}
    result, metrics = pmsm_cosim.simulate(spec, stop_time=0.05, step_size=1e-4, output_interval=0.01,
                                          algorithm="jacobi", controller="ekf4", plant="PmsmEvPlant", set=starts,
                                          record=["omega_m", "plant.i_d"])
    assert metrics["status"] == "completed" and len(result) == 6
    assert spec == before and spec.stop_time == 350.0 and spec.component("ctrl").fmu.name == "FocEkf5.fmu"
    assert spec.component("ctrl").start == {"angle_source": "measured"} and len(spec.columns) == 22
    assert starts == {"ctrl.angle_source": "estimated"}
    assert metrics["settings"]["components"][0]["start"] == {"angle_source": "estimated"}


def test_fmpys_start_values_and_output_are_set_and_record(fmus):
    """fmpy's names: start_values {"instance.var": value} is set, output [names] is record
    (time first, then each column as named: the system's own or a variable)."""
    ours, _ = pmsm_cosim.simulate("scenario2", stop_time=0.1, controller="ekf4", set={"ctrl.angle_source": "estimated",
                                  "plant.m_v": 1500.0}, record=["omega_m", "plant.i_d", "signals.delta"])
    fmpys, metrics = pmsm_cosim.simulate("scenario2", stop_time=0.1, controller="ekf4",
                                         start_values={"ctrl.angle_source": "estimated", "plant.m_v": 1500.0},
                                         output=["omega_m", "plant.i_d", "signals.delta"])
    assert ours.dtype.names == fmpys.dtype.names == ("time", "omega_m", "plant.i_d", "signals.delta")
    assert all(np.array_equal(ours[n], fmpys[n]) for n in ours.dtype.names) and len(ours) == 11
    assert np.max(ours["omega_m"]) > 0 and metrics["metrics_note"].startswith("no drive metrics")
    full, _ = pmsm_cosim.simulate("scenario2", stop_time=0.1, controller="ekf4",
                                  set=["ctrl.angle_source=estimated", "plant.m_v=1500.0"])
    assert np.array_equal(full["omega_m"], ours["omega_m"]) and np.array_equal(full["i_d"], ours["plant.i_d"])
    assert not np.array_equal(full["omega_m"], pmsm_cosim.simulate("scenario2", stop_time=0.1,
                                                                   controller="ekf4")[0]["omega_m"])


def test_record_on_the_command_line(fmus, tmp_path):
    out = tmp_path / "r"
    assert main(["run", "scenario1", "--stop-time", "0.02", "-q", "--no-figures", "--out", str(out),
                 "--record", "omega_m", "ctrl.omega_hat"]) == 0
    columns = read_results(out)
    result, _ = pmsm_cosim.simulate("scenario1", stop_time=0.02, output=["omega_m", "ctrl.omega_hat"])
    assert list(columns) == list(result.dtype.names) == ["time", "omega_m", "ctrl.omega_hat"]
    assert all(np.array_equal(columns[n], result[n]) for n in columns)


# --- leaving the process -----------------------------------------------------------------------
# A process that ran simulate exits normally, with its own exit code: no abort in the native
# teardown (pythonfmu's wrapper library, see docs/errors.md "Crash at exit"). Fresh processes,
# with glibc's checking allocator where the machine has it (it makes a heap write after free
# abort at once instead of now and then).
EXIT_CHILD = """
import sys
import pmsm_cosim
overrides = {"plant.psi": 1e8} if sys.argv[1] == "failing" else None
result, metrics = pmsm_cosim.simulate("scenario1", stop_time=0.05, set=overrides)
compiled = sorted(m for m in sys.modules if m.startswith("pmsm_ev_kernels_") and "." not in m)
print(metrics["status"], "|", len(result), "|", len(compiled), flush=True)
"""
MALLOC_DEBUG = Path("/lib/x86_64-linux-gnu/libc_malloc_debug.so.0")
GLIBC_TROUBLE = ("corrupted", "double free", "free()", "malloc", "munmap_chunk", "Fatal Python error")


def exit_of_a_fresh_process(kind: str, tmp_path: Path) -> tuple[int, str, str]:
    env = dict(os.environ, PMSM_EV_JIT="1")
    if MALLOC_DEBUG.is_file():
        env.update(LD_PRELOAD=str(MALLOC_DEBUG), MALLOC_CHECK_="3")
    r = subprocess.run([sys.executable, "-c", EXIT_CHILD, kind], capture_output=True, text=True, env=env,
                       cwd=tmp_path, timeout=600)
    return r.returncode, r.stdout.strip(), r.stderr


@pytest.mark.parametrize("repeat", [0] + [pytest.param(k, marks=pytest.mark.slow) for k in range(1, 4)])  # again: slow
def test_a_process_that_simulated_with_compiled_kernels_exits_with_code_0(fmus, tmp_path, repeat):
    code, out, err = exit_of_a_fresh_process("completed", tmp_path)
    assert code == 0, f"exit code {code}: {err[-2000:]}"
    assert not [t for t in GLIBC_TROUBLE if t in err], err[-2000:]
    status, rows, compiled = out.splitlines()[-1].split(" | ")
    assert (status, int(rows), int(compiled)) == ("completed", 6, 1)  # 0..0.05 s every 10 ms, numba's kernels


@pytest.mark.parametrize("repeat", range(2))
def test_a_process_whose_fmu_failed_mid_run_exits_with_code_0(fmus, tmp_path, repeat):
    code, out, err = exit_of_a_fresh_process("failing", tmp_path)
    assert code == 0, f"exit code {code}: {err[-2000:]}"
    assert not [t for t in GLIBC_TROUBLE if t in err], err[-2000:]
    status, rows, compiled = out.splitlines()[-1].split(" | ")
    # psi = 1e8 V s/rad: the first step's torque runs the rotor away, the second step (its RK4 sub-steps
    # raised by substep_angle for that speed, up to MAX_SUBSTEPS) overflows
    assert status.startswith("failed: plant: fmi2DoStep failed at t = 0.0001 s: SimulationError: plant state is "
                             "not finite at t = 0.0002"), status
    assert (int(rows), int(compiled)) == (1, 1)
