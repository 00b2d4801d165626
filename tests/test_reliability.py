"""Reliability: bad input ends in one clear line, failures keep what was computed, runs are
reproducible. One parametrized test per kind of input or fault, through the command line
(``pmsm-cosim run``) where a user would meet it; the messages quoted in docs/errors.md
are the ones these tests check."""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from orchestrator_support import project_fmus, toy_fmus, toy_system
from pmsm_cosim.app.cli import main
from pmsm_cosim.engine.fmu import fmu_reason
from pmsm_cosim.engine.recording import read_results
from pmsm_ev.results import ALL_COLUMNS

STEP = 1e-3  # the toy systems' step


@pytest.fixture(scope="module")
def fmus():
    return project_fmus()


def cli(argv, capsys) -> tuple[int, str, str]:
    """Run ``pmsm-cosim`` in-process: (exit code, stdout, stderr)."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("error: "), lines
    return lines[0]


def refused(argv, capsys, out: Path) -> str:
    """The run is refused with exit code 2 and one line; nothing was written."""
    code, stdout, err = cli([*argv, "--out", out, "--quiet", "--no-figures"], capsys)
    assert code == 2, (stdout, err)
    assert not out.exists()
    return one_error_line(err)


def csv_lines(out: Path) -> list[str]:
    text = (out / "results.csv").read_text(encoding="ascii")
    assert text.endswith("\n")  # never half a line
    return text.splitlines()


def metrics(out: Path) -> dict:
    return json.loads((out / "metrics.json").read_text(encoding="utf-8"))


def scenario2_with(tmp_path: Path, old: str, new: str, name: str = "edited") -> Path:
    """The shipped scenario 2 with one piece of text replaced."""
    from importlib import resources

    text = (resources.files("pmsm_cosim.app") / "scenarios" / "scenario2.toml").read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / f"{name}.toml"
    path.write_text(text.replace(old, new), encoding="utf-8")
    return path


# --- FMU files ------------------------------------------------------------------------------------

def _copy_fmu(src: Path, dst: Path, edit) -> None:
    """``src`` with its modelDescription.xml passed through ``edit``."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = edit(data.decode("utf-8")).encode("utf-8")
            zout.writestr(item, data)


def broken_fmu(tmp_path: Path, fault: str) -> Path:
    real = toy_fmus()["ToySink"]
    path = tmp_path / (re.sub(r"\W+", "_", fault) + ".fmu")
    if fault == "directory":
        path.mkdir()
    elif fault == "not a zip":
        path.write_bytes(b"this is a text file renamed to .fmu\n")
    elif fault == "no modelDescription.xml":
        with zipfile.ZipFile(path, "w") as z:
            z.writestr("binaries/linux64/readme.txt", "no model description here")
    elif fault in ("FMI 1.0", "FMI 4.0"):
        version = fault.split()[1]
        _copy_fmu(real, path, lambda t: t.replace('fmiVersion="2.0"', f'fmiVersion="{version}"', 1))
    elif fault == "Model Exchange only":
        _copy_fmu(real, path, lambda t: re.sub(r"<CoSimulation\b[^>]*/>",
                                               '<ModelExchange modelIdentifier="ToySink"/>', t, count=1))
    else:
        assert fault == "missing"
    return path


@pytest.mark.parametrize("fault, message", [
    ("missing", "snk: FMU not found: {path}"),
    ("directory", "snk: {path}: is a directory, not an .fmu file"),
    ("not a zip", "snk: {path}: not an FMU (not a zip archive)"),
    ("no modelDescription.xml", "snk: {path}: not an FMU (the archive has no modelDescription.xml)"),
    ("FMI 1.0", "snk: {path}: an FMI 1.0 FMU; only FMI 2.0 and FMI 3.0 co-simulation FMUs are supported"),
    ("FMI 4.0", "snk: {path}: an FMI 4.0 FMU; only FMI 2.0 and FMI 3.0 co-simulation FMUs are supported"),
    ("Model Exchange only", "snk: {path}: a Model Exchange FMU without a co-simulation interface"),
])
def test_fmu_file_faults(tmp_path, capsys, fault, message):
    path = broken_fmu(tmp_path, fault)
    line = refused(["run", toy_system(tmp_path), "--fmu", f"snk={path}"], capsys, tmp_path / "out")
    assert message.format(path=path.resolve()) in line


# --- names ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("connection, extra, message", [
    ('"srcc.y -> snk.u"', [], "connection srcc.y -> snk.u: unknown instance 'srcc' (did you mean: src?)"),
    ('"src.yy -> snk.u"', [], "connection src.yy -> snk.u: src (ToySource.fmu) has no variable 'yy' "
                              "(did you mean: y"),
    ('"src.y -> snk.uu"', [], "connection src.y -> snk.uu: snk (ToySink.fmu) has no variable 'uu' "
                              "(did you mean: u"),
    ('"src.y -> snk.u"', ["--set", "snkk.gain=2"], "unknown instance 'snkk' (did you mean: snk?)"),
    ('"src.y -> snk.u"', ["--set", "snk.gian=2"], "start value snk.gian: snk (ToySink.fmu) has no variable "
                                                   "'gian' (did you mean: gain"),
    ('"src.y -> snk.u"', ["--fmu", "snc=x.fmu"], "unknown instance 'snc' (did you mean: src, snk?)"),
])
def test_unknown_instance_or_variable_lists_close_matches(tmp_path, capsys, connection, extra, message):
    path = toy_system(tmp_path, connections=(connection,))
    assert message in refused(["run", path, *extra], capsys, tmp_path / "out")


# --- connections ---------------------------------------------------------------------------------

@pytest.mark.parametrize("connection, message", [
    ("snk.u -> src.slope", "snk.u is an input, not an output"),
    ("src.y -> snk.last_u", "snk.last_u is an output, not an input"),
    ("src.y -> snk.gain", "snk.gain is a parameter, not an input"),
    ("src.n_steps -> snk.u", "src.n_steps is an Integer, snk.u is a Real: a connection joins variables of the "
                             "same type (no conversion)"),
    ("plant.omega_m -> ctrl.i_alpha", "units differ ('rad/s' -> 'A')"),
])
def test_a_bad_connection_names_both_ends(tmp_path, capsys, connection, message):
    if connection.startswith("plant"):
        project_fmus()
        path = scenario2_with(tmp_path, "plant.i_alpha -> ctrl.i_alpha", connection)
    else:
        path = toy_system(tmp_path, connections=(f'"{connection}"',))
    line = refused(["run", path, "--stop-time", 0.01], capsys, tmp_path / "out")
    assert f"connection {connection}: {message}" in line


# --- non-physical values --------------------------------------------------------------------------

@pytest.mark.parametrize("args, message", [
    (["--set", "plant.m_v=0"], "plant (PmsmEvPlant.fmu): fmi2ExitInitializationMode (start values) refused: "
                               "m_v must be > 0 kg (got 0.0)"),
    (["--set", "plant.m_v=-900"], "m_v must be > 0 kg (got -900.0)"),
    (["--set", "plant.eta=0"], "eta must be in (0, 1] (got 0.0)"),
    (["--set", "plant.eta=1.2"], "eta must be in (0, 1] (got 1.2)"),
    (["--set", "plant.L_d=0"], "plant (PmsmEvPlant.fmu): fmi2ExitInitializationMode (start values) refused: "
                               "L_d must be > 0 H (got 0.0)"),
    (["--set", "plant.L_q=-1e-4"], "L_q must be > 0 H (got -0.0001)"),
    (["--set", "ctrl.L_q=0"], "ctrl (FocEkf5.fmu): fmi2ExitInitializationMode (start values) refused: "
                              "L_q must be > 0 H (got 0.0)"),
    (["--step", "0"], "argument --step: must be a finite number > 0 (got 0)"),
    (["--step=-1e-4"], "argument --step: must be a finite number > 0 (got -1e-4)"),
    (["--stop-time", "-1"], "argument --stop-time: must be a finite number > 0 (got -1)"),
    (["--stop-time", "0"], "argument --stop-time: must be a finite number > 0 (got 0)"),
    (["--output-interval", "nan"], "argument --output-interval: must be a finite number > 0 (got nan)"),
])
def test_non_physical_values_are_refused_before_the_run(fmus, tmp_path, capsys, args, message):
    line = refused(["run", "scenario2", "--stop-time", 0.01, *args], capsys, tmp_path / "out")
    assert message in line


@pytest.mark.parametrize("args, message", [
    (["--set", "ctrl.omega_down=40"], "ctrl (FocSensorless.fmu): fmi2ExitInitializationMode (start values) refused: "
                                      "omega_down must be < omega_up (got 40.0 >= 30.0 rad/s)"),
    (["--set", "ctrl.if_margin=0.5"], "if_margin must be >= 1 (got 0.5)"),
    (["--set", "ctrl.J_model=-1"], "J_model must be finite and >= 0 (got -1.0)"),
])
def test_sensorless_start_up_values_are_refused_before_the_run(fmus, tmp_path, capsys, args, message):
    line = refused(["run", "hill-start-if", "--stop-time", 0.01, *args], capsys, tmp_path / "out")
    assert message in line


@pytest.mark.parametrize("args, message", [
    (["--set", "plant.dead_time=2e-6"], "plant (PmsmEvPlant.fmu): fmi2ExitInitializationMode (start values) refused: "
                                        "dead_time = 2e-06 s needs the DC-link voltage: set v_dc > 0 V"),
    (["--set", "plant.sat_i_q=-1"], "sat_i_q must be >= 0 A, 0 = off (got -1.0)"),
    (["--set", "plant.T_magnet=-300"], "T_magnet must be above -273.15 degC (got -300.0)"),
    (["--set", "ctrl.dead_time_comp=-7.2"], "dead_time_comp must be >= 0 V (got -7.2)"),
    (["--set", "ctrl.psi_adapt=1"], "ctrl (FocEkf5.fmu): fmi2ExitInitializationMode (start values) refused: "
                                    "psi_adapt needs the stationary-frame EKF5 "
                                    "(observer ekf5ab or sensorless; got ekf5)"),
])
def test_plant_effect_values_are_refused_before_the_run(fmus, tmp_path, capsys, args, message):
    line = refused(["run", "scenario2", "--stop-time", 0.01, *args], capsys, tmp_path / "out")
    assert message in line


@pytest.mark.parametrize("args, message", [
    (["--set", "ctrl.reference=fw"], "ctrl (FocEkf5.fmu): fmi2ExitInitializationMode (start values) refused: "
                                     "reference 'fw' (field weakening) needs the DC-link voltage: set v_dc > 0 V"),
    (["--set", "ctrl.i_max=0"], "i_max must be > 0 A (got 0.0)"),
    (["--set", "ctrl.T_max=200"], "T_max = 200 N m is above the 153.1 N m that i_max = 400 A gives on MTPA"),
    (["--set", "ctrl.P_regen_max=-30000"], "P_regen_max must be >= 0 W, a power the motor may take back, 0 = no "
                                           "limit (got -30000.0)"),
    (["--set", "ctrl.v_dc=360", "--set", "ctrl.u_max=150"], "u_max = 150 V and v_dc = 360 V are both given"),
])
def test_speed_range_values_are_refused_before_the_run(fmus, tmp_path, capsys, args, message):
    line = refused(["run", "scenario2", "--stop-time", 0.01, *args], capsys, tmp_path / "out")
    assert message in line


@pytest.mark.parametrize("change, message", [
    ({"step": 0}, "experiment.step_size must be a finite number > 0 (got 0.0)"),
    ({"step": -1e-3}, "experiment.step_size must be a finite number > 0 (got -0.001)"),
    ({"stop_time": -1.0}, "experiment.stop_time must be a finite number > 0 (got -1.0)"),
    ({"stop_time": 0.0}, "experiment.stop_time must be a finite number > 0 (got 0.0)"),
])
def test_non_physical_time_grid_in_a_system_file(tmp_path, capsys, change, message):
    path = toy_system(tmp_path, **change)
    line = refused(["run", path], capsys, tmp_path / "out")
    assert f"{path}: {message}" in line


# Instances that failed are kept referenced (FMI 2.0: no call at all into an instance after
# fmi2Fatal, fmi2FreeInstance included) so that their logger callbacks stay alive.
_FAILED_INSTANCES: list = []


class RawInstance:
    """An FMU driven as another master would, through fmpy's low-level FMU2Slave."""

    def __init__(self, path: Path, unzip_dir: Path):
        import fmpy
        from fmpy.fmi2 import (
            FMU2Slave,
            calloc,
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
            fmi2CallbackLoggerTYPE,
            free,
        )

        self.md = fmpy.read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.messages: list[tuple[int, str]] = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(
            lambda env, name, status, category, message: self.messages.append((status, message.decode())))
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        directory = fmpy.extract(str(path), unzipdir=str(unzip_dir))
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=directory,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="other")
        self.fmu.instantiate(callbacks=self.callbacks, loggingOn=True)


@pytest.mark.parametrize("name, start, experiment, step, call, reason", [
    ("PmsmEvPlant", {"m_v": 0.0}, (0.0, 1.0), 1e-4, "fmi2ExitInitializationMode", "m_v must be > 0 kg (got 0.0)"),
    ("PmsmEvPlant", {"m_v": -900.0}, (0.0, 1.0), 1e-4, "fmi2ExitInitializationMode",
     "m_v must be > 0 kg (got -900.0)"),
    ("PmsmEvPlant", {"eta": 0.0}, (0.0, 1.0), 1e-4, "fmi2ExitInitializationMode", "eta must be in (0, 1] (got 0.0)"),
    ("PmsmEvPlant", {"eta": 1.5}, (0.0, 1.0), 1e-4, "fmi2ExitInitializationMode", "eta must be in (0, 1] (got 1.5)"),
    ("PmsmEvPlant", {"L_d": 0.0}, (0.0, 1.0), 1e-4, "fmi2ExitInitializationMode", "L_d must be > 0 H (got 0.0)"),
    ("PmsmEvPlant", {"L_q": -1e-4}, (0.0, 1.0), 1e-4, "fmi2ExitInitializationMode",
     "L_q must be > 0 H (got -0.0001)"),
    ("FocEkf5", {"L_d": -1.0}, (0.0, 1.0), 1e-4, "fmi2ExitInitializationMode", "L_d must be > 0 H (got -1.0)"),
    ("FocEkf5", {"L_q": 0.0}, (0.0, 1.0), 1e-4, "fmi2ExitInitializationMode", "L_q must be > 0 H (got 0.0)"),
    ("PmsmEvPlant", {}, (1.0, 0.5), 1e-4, "fmi2SetupExperiment", "stop time 0.5 s is before the start time 1.0 s"),
    ("FocEkf5", {}, (1.0, 0.5), 1e-4, "fmi2SetupExperiment", "stop time 0.5 s is before the start time 1.0 s"),
    ("PmsmEvPlant", {}, (0.0, 1.0), 0.0, "fmi2DoStep", "communication step size must be > 0 s (got 0.0)"),
    ("PmsmEvPlant", {}, (0.0, 1.0), -1e-4, "fmi2DoStep", "communication step size must be > 0 s (got -0.0001)"),
    ("FocEkf5", {}, (0.0, 1.0), 0.0, "fmi2DoStep", "communication step size must be > 0 s (got 0.0)"),
    ("FocEkf5", {"dt": -1e-4}, (0.0, 1.0), 1e-4, "fmi2ExitInitializationMode",
     "dt must be > 0 s, or 0 for the size of the first communication step (got -0.0001)"),
])
def test_the_fmus_refuse_non_physical_values_from_another_master(fmus, tmp_path, name, start, experiment, step,
                                                                 call, reason):
    """Set from another master (fmpy's low-level FMU2Slave), a non-physical value fails
    the FMI call with the reason in the FMU's log (status fmi2Fatal, the wrapper's
    ``Fatal py exception encountered: [call] ...`` with the exception's repr); the call
    returns **fmi2Fatal**, not fmi2Error.

    Why fmi2Fatal: pythonfmu 0.7.0 gives a slave no way to return fmi2Error. Its C++
    wrapper (pythonfmu-export, ``PySlaveInstance.cpp``) discards what
    ``setup_experiment``, ``enter_initialization_mode`` and ``exit_initialization_mode``
    return (``Py_DECREF(f)``: a slave returning False from exit_initialization_mode still
    gets fmi2OK), and turns a Python exception, in these as in every other call, into
    ``handle_py_exception``, which always throws ``pythonfmu::fatal_error``; the FMI
    functions map that to fmi2Fatal. Only other C++ exceptions become fmi2Error, and Python
    code cannot raise those. The wrapper logs the exception's repr; the slaves log nothing
    of their own in a failing call (the wrapper would pass it to the host's logger with the
    exception still set, which Python 3.13 refuses). A failed instance is not called again
    (FMI 2.0 allows no call after fmi2Fatal).
    """
    from fmpy.fmi1 import FMICallException

    inst = RawInstance(fmus[name], tmp_path / "unzipped")
    fmu = inst.fmu
    failed = False
    try:
        fmu.setupExperiment(startTime=experiment[0], stopTime=experiment[1])
        fmu.enterInitializationMode()
        for var, value in start.items():
            fmu.setReal([inst.vr[var]], [value])
        fmu.exitInitializationMode()
        fmu.doStep(experiment[0], step)
    except FMICallException as exc:
        failed = True
        assert exc.function == call
        assert exc.status == 4  # fmi2Fatal: see the docstring
    finally:
        if failed:
            _FAILED_INSTANCES.append(inst)
        else:
            fmu.terminate()
            fmu.freeInstance()
    assert failed, f"{name} accepted {start} / {experiment} / step {step}"
    fatal = [text for status, text in inst.messages if status == 4]
    assert any(text.startswith("Fatal py exception encountered: [") and fmu_reason(text).endswith(reason)
               for text in fatal), inst.messages
    assert not any("SystemError" in text for _, text in inst.messages), inst.messages


# --- the time grid ----------------------------------------------------------------------------------

@pytest.mark.parametrize("args, system, message", [
    (["--stop-time", "0.0105"], {}, "stop time 0.0105 s is not a whole number of 0.001 s steps "
                                    "(the nearest that are: 0.01 or 0.011 s)"),
    (["--step", "3e-3"], {}, "stop time 0.01 s is not a whole number of 0.003 s steps "
                             "(the nearest that are: 0.009 or 0.012 s)"),
    (["--stop-time", "1e-4"], {}, "stop time 0.0001 s is shorter than one 0.001 s step"),
    (["--output-interval", "0.0015"], {}, "output interval 0.0015 s is not a multiple of the 0.001 s step "
                                          "(the nearest that are: 0.001 or 0.002 s)"),
    ([], {"output_interval": 2.5e-3}, "output interval 0.0025 s is not a multiple of the 0.001 s step "
                                      "(the nearest that are: 0.002 or 0.003 s)"),
    ([], {"snk_multiple": 3}, "stop time 0.01 s is not a multiple of snk's step (3 x 0.001 s)"),
])
def test_a_time_grid_that_does_not_fit_is_refused(tmp_path, capsys, args, system, message):
    path = toy_system(tmp_path, **system)
    assert f"{path}: {message}" in refused(["run", path, *args], capsys, tmp_path / "out")


# --- scenario CSV files ---------------------------------------------------------------------------

CSV_FAULTS = [
    ("", "route.csv:1: empty profile file (expected a header row, then time,value rows)"),
    ("\n\n", "route.csv:1: empty profile file"),
    ("time,grade\n", "route.csv:2: no data rows after the header"),
    ("time\n0\n", "route.csv:1: the header needs two columns (time, value), got 'time'"),
    ("time,grade\n0,1\n5\n", "route.csv:3: missing column: need time,value, got '5'"),
    ("time,grade\n0,1\n5,abc\n", "route.csv:3: value is not a number: 'abc'"),
    ("time,grade\n0,1\nfive,2\n", "route.csv:3: time is not a number: 'five'"),
    ("time,grade\n0,1\n5,\n", "route.csv:3: value is not a number: ''"),
    ("time,grade\n0,1\n5,2\n5,3\n", "route.csv:4: time does not increase (5.0 after 5.0)"),
    ("time,grade\n0,1\n2,1\n\n1,0\n", "route.csv:5: time does not increase (1.0 after 2.0)"),
    ("time,grade\n0,nan\n", "route.csv:2: value is not finite: 'nan'"),
    ("time,grade\n0,1\ninf,2\n", "route.csv:3: time is not finite: 'inf'"),
    ("time,grade\n0,1\n1,-1e999\n", "route.csv:3: value is not finite: '-1e999'"),
    ("0,0\n1,5\n", "route.csv:1: the first line must be a header naming the columns (e.g. time,value), "
                   "got numbers '0,0'"),
    ('time,grade\n0,1\n1,"2\n', "route.csv:3: not valid CSV (unexpected end of data)"),
]


@pytest.mark.parametrize("how", ["system file", "--profile"])
@pytest.mark.parametrize("text, message", CSV_FAULTS)
def test_scenario_csv_errors_name_the_file_and_line(tmp_path, capsys, how, text, message):
    csv = tmp_path / "route.csv"
    csv.write_text(text, encoding="utf-8")
    where = 'csv = "route.csv"' if how == "system file" else "table = [[0, 0]]"
    path = toy_system(tmp_path, signals=f'[signals.grade]\n{where}\ndrives = "snk.w"\n')
    args = ["run", path] + (["--profile", f"grade={csv}"] if how == "--profile" else [])
    line = refused(args, capsys, tmp_path / "out")
    assert f"signal 'grade': {tmp_path}{os.sep}{message}" in line


def test_a_valid_scenario_csv_is_read_exactly(tmp_path, capsys):
    """The other side of the CSV rows: blank lines, CRLF, a byte-order mark, spaces and
    extra columns are accepted; values arrive bit-identical."""
    csv = tmp_path / "route.csv"
    csv.write_bytes(b"\xef\xbb\xbftime , grade, note\r\n0, 0.1 ,start\r\n\r\n0.0035,-2.5e-1\r\n0.007,3\r\n")
    path = toy_system(tmp_path, connections=(), signals='[signals.grade]\ncsv = "route.csv"\ndrives = "snk.w"\n',
                      record={"time": '"time"', "grade": '"signals.grade"', "last_w": '"snk.last_w"'})
    code, _, _ = cli(["run", path, "--out", tmp_path / "out", "--quiet"], capsys)
    assert code == 0
    r = read_results(tmp_path / "out")
    assert list(r["grade"]) == [0.1, 0.1, 0.1, 0.1, -0.25, -0.25, -0.25, 3.0, 3.0, 3.0, 3.0]
    assert list(r["last_w"][1:]) == list(r["grade"][:-1])


# --- failures during the run ------------------------------------------------------------------------

@pytest.mark.parametrize("system, args, status, last_time", [
    ("toy", ["--set", "snk.raise_at=4"],
     "failed: snk: fmi2DoStep failed at t = 0.003 s: RuntimeError: toy failure: step 4 raises on purpose", 0.003),
    ("toy", ["--set", "snk.raise_at=4", "--algorithm", "jacobi", "--output-interval", "0.002"],
     "failed: snk: fmi2DoStep failed at t = 0.003 s: RuntimeError: toy failure: step 4 raises on purpose", 0.002),
    ("toy", ["--set", "snk.fail_at=2"], "failed: snk: fmi2DoStep failed at t = 0.001 s: step 2 fails on purpose",
     0.001),
    ("scenario2", ["--set", "plant.psi=1e300", "--output-interval", "1e-4"],
     "failed: plant: fmi2DoStep failed at t = 0 s: SimulationError: plant state is not finite at t = 0.0001 s "
     "(omega_m=nan, i_d=inf, i_q=nan)", 0.0),
])
def test_an_exception_inside_do_step_stops_the_run_and_keeps_the_rows(tmp_path, capsys, system, args, status,
                                                                       last_time):
    """The message names the instance, the simulated time and the FMU's own logged reason;
    the rows up to the last good step are kept, metrics.json says why."""
    if system == "toy":
        path, columns = toy_system(tmp_path, stop_time=0.01), None
    else:
        project_fmus()
        path, columns = "scenario2", ",".join(ALL_COLUMNS)
    out = tmp_path / "out"
    code, stdout, err = cli(["run", path, "--stop-time", 0.01, "--out", out, "--quiet", "--no-figures", *args],
                            capsys)
    assert code == 1, err
    assert stdout.startswith(status) and err == ""
    m = metrics(out)
    assert m["status"].startswith(status)
    lines = csv_lines(out)
    if columns:
        assert lines[0] == columns
    times = [float(ln.split(",")[0]) for ln in lines[1:]]
    assert times[-1] == pytest.approx(last_time, abs=1e-15) and m["rows"] == len(times)
    assert all(ln.count(",") == lines[0].count(",") for ln in lines)


@pytest.mark.parametrize("system, args, status, rows", [
    ("toy", ["--set", "src.slope=1e308"],
     "failed: src.y is not finite (inf) at t = 0.001 s, before it reached snk.u", 2),
    ("toy-unconnected", ["--set", "src.slope=1e308"], "failed: src.y is not finite (inf) at t = 0.002 s", 2),
    ("scenario2", ["--set", "ctrl.kp_iq=1e308", "--output-interval", "1e-4"],
     "failed: ctrl.v_alpha is not finite (nan) at t = 0.0002 s, before it reached plant.v_alpha", 3),
])
def test_a_signal_that_becomes_nan_or_inf_stops_the_run(tmp_path, capsys, system, args, status, rows):
    """An absurd gain: the run stops at the step where a value turns NaN or infinite,
    naming the signal and the time; the rows before are kept and all finite."""
    if system == "scenario2":
        project_fmus()
        path = system
    else:
        path = toy_system(tmp_path, connections=() if system == "toy-unconnected" else ('"src.y -> snk.u"',))
    out = tmp_path / "out"
    code, stdout, err = cli(["run", path, "--stop-time", 0.01, "--out", out, "--quiet", "--no-figures", *args],
                            capsys)
    assert code == 1 and stdout.startswith(status), (stdout, err)
    assert metrics(out)["status"] == status
    lines = csv_lines(out)
    assert len(lines) == rows + 1 and metrics(out)["rows"] == rows
    assert all(math.isfinite(float(x)) for ln in lines[1:] for x in ln.split(","))


# --- interruption ---------------------------------------------------------------------------------

@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_sigint_or_sigterm_keeps_every_completed_row(fmus, tmp_path, signum):
    """``pmsm-cosim run scenario1`` in a subprocess, signalled once results.csv has rows:
    it stops at its next check, results.csv holds every completed row and ends on a
    complete line, metrics.json says interrupted (and by which signal), exit code 130."""
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "pmsm_cosim.app.cli", "run", "scenario1", "--out", str(out),
                             "--no-figures", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and proc.poll() is None:
            csv = out / "results.csv"
            if csv.exists() and csv.read_text(encoding="ascii").count("\n") >= 4:
                break
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signum)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, (stdout, stderr)
    assert stdout.startswith("interrupted: ")
    m = metrics(out)
    assert m["status"] == "interrupted" and m["stop_signal"] == signal.Signals(signum).name
    lines = csv_lines(out)
    assert lines[0] == ",".join(ALL_COLUMNS)
    assert all(ln.count(",") == len(ALL_COLUMNS) - 1 for ln in lines)
    times = [float(ln.split(",")[0]) for ln in lines[1:]]
    assert len(times) == m["rows"] >= 3
    assert all(abs(t - k * 0.01) < 1e-12 for k, t in enumerate(times))
    # the loop stops on an output step: the last row is the state after the last step taken
    assert times[-1] == pytest.approx(m["macro_steps"] * 1e-4, abs=1e-12)


# --- normal runs ----------------------------------------------------------------------------------

@pytest.mark.parametrize("system", ["toy", "scenario2"])
def test_a_normal_run_says_completed(tmp_path, capsys, system):
    if system == "scenario2":
        project_fmus()
        path = system
    else:
        path = toy_system(tmp_path)
    out = tmp_path / "out"
    code, stdout, _ = cli(["run", path, "--stop-time", 0.02, "--out", out, "--quiet", "--no-figures"], capsys)
    assert code == 0 and stdout.startswith("completed: ")
    m = metrics(out)
    step = STEP if system == "toy" else 1e-4
    assert m["status"] == "completed" and m["macro_steps"] == round(0.02 / step)
    assert m["rows"] == len(csv_lines(out)) - 1


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_two_runs_of_the_same_command_are_byte_identical(fmus, tmp_path, capsys, algorithm):
    files = []
    for k in range(2):
        out = tmp_path / f"run{k}"
        code, _, _ = cli(["run", "scenario2", "--stop-time", 0.05, "--output-interval", 1e-3, "--algorithm",
                          algorithm, "--set", "plant.sensor_noise=0.5", "--out", out, "--quiet", "--no-figures"],
                         capsys)
        assert code == 0
        files.append((out / "results.csv").read_bytes())
    assert files[0] == files[1]
    assert files[0].count(b"\n") == 52  # header + 51 rows: the comparison is not of empty files


# --- the output directory ------------------------------------------------------------------------

@pytest.mark.parametrize("args, message", [
    (["--set", "plant.m_v=0"], "m_v must be > 0 kg"),  # refused by the FMU at initialisation
    (["--set", "plant.m_vv=0"], "has no variable 'm_vv'"),  # refused at load
    (["--stop-time", "0.01005"], "not a whole number"),
    (["--profile", "delta=missing.csv"], "profile file not found"),
    (["--controller", "missing.fmu"], "FMU not found"),
])
def test_a_run_refused_at_load_leaves_the_previous_results(fmus, tmp_path, capsys, args, message):
    """A previous run's files are replaced only when the new run starts writing."""
    out = tmp_path / "out"
    assert cli(["run", "scenario2", "--stop-time", 0.02, "--out", out, "--quiet", "--no-figures"], capsys)[0] == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert set(before) == {"results.csv", "metrics.json"}
    code, _, err = cli(["run", "scenario2", "--stop-time", 0.01, "--out", out, "--quiet", "--no-figures", *args],
                       capsys)
    assert code == 2 and message in one_error_line(err)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    # the same command without the fault replaces them
    code, _, _ = cli(["run", "scenario2", "--stop-time", 0.01, "--out", out, "--quiet", "--no-figures"], capsys)
    assert code == 0
    assert len(csv_lines(out)) == 3 and metrics(out)["stop_time"] == 0.01


# --- property-based: the scenario CSV reader and the system-file loader -------------------------
# Random bytes and near-valid content: always a clean one-line error of the project's own
# type or a valid load, never another exception. Example counts stay modest (the suite's time).

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from pmsm_cosim.app.drive import load_system  # noqa: E402
from pmsm_cosim.engine.errors import CosimError  # noqa: E402
from pmsm_cosim.engine.signals import Table, TableError, load_table_csv  # noqa: E402
from pmsm_cosim.engine.system import SystemSpec  # noqa: E402

PROPERTY = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("properties")


def load_csv_cleanly(path: Path) -> Table | None:
    """The reader's contract: a valid Table, or a one-line TableError naming the file."""
    try:
        prof = load_table_csv(path)
    except TableError as exc:
        assert "\n" not in str(exc) and str(exc).startswith(str(path)), str(exc)
        return None
    assert len(prof.times) == len(prof.values) >= 1
    assert all(math.isfinite(x) for x in prof.times + prof.values)
    assert all(b > a for a, b in zip(prof.times, prof.times[1:]))
    return prof


def mutate(data: bytes, draw) -> bytes:
    """A few random byte edits: delete, insert or replace a byte, cut the file, duplicate
    or drop a line."""
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["delete", "insert", "replace", "cut", "dup-line", "drop-line"]))
        i = draw(st.integers(0, max(len(data) - 1, 0)))
        byte = bytes([draw(st.sampled_from(b',."\n\r -+e0123456789[]{}=#\'\\xab\x00\xff'))])
        if kind == "delete":
            data = data[:i] + data[i + 1:]
        elif kind == "insert":
            data = data[:i] + byte + data[i:]
        elif kind == "replace":
            data = data[:i] + byte + data[i + 1:]
        elif kind == "cut":
            data = data[:i]
        else:
            lines = data.split(b"\n")
            j = draw(st.integers(0, len(lines) - 1))
            lines[j:j + 1] = [lines[j]] * (2 if kind == "dup-line" else 0)
            data = b"\n".join(lines)
    return data


@PROPERTY
@given(data=st.binary(max_size=400))
def test_csv_reader_on_random_bytes(scratch, data):
    path = scratch / "random.csv"
    path.write_bytes(data)
    load_csv_cleanly(path)


CSV_CELLS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-10**6, 10**6).map(str),
    st.sampled_from(["", " ", "nan", "inf", "-inf", "1e999", "abc", '"3"', '"', "0x10", "1_000", "\u0663",
                     "\t2", "1e", "--1", "1,5", "\x00"]),
    st.text(max_size=6),
)


@PROPERTY
@given(header=st.sampled_from(["time,value", "t,deg", "time", "", "0,0", "time,value,note", "\ufefftime,value"]),
       rows=st.lists(st.lists(CSV_CELLS, max_size=4), max_size=8),
       eol=st.sampled_from(["\n", "\r\n", "\r"]))
def test_csv_reader_on_near_valid_tables(scratch, header, rows, eol):
    path = scratch / "near.csv"
    path.write_bytes(eol.join([header] + [",".join(r) for r in rows]).encode("utf-8", "surrogatepass"))
    load_csv_cleanly(path)


@PROPERTY
@given(points=st.lists(st.tuples(st.floats(-1e6, 1e6), st.floats(allow_nan=False, allow_infinity=False)),
                       min_size=1, max_size=8, unique_by=lambda p: p[0]),
       data=st.data())
def test_csv_reader_on_mutated_valid_files(scratch, points, data):
    points = sorted(points)
    text = "time,value\n" + "".join(f"{t!r},{v!r}\n" for t, v in points)
    path = scratch / "valid.csv"
    path.write_text(text, encoding="utf-8")
    prof = load_csv_cleanly(path)  # the valid file is read exactly (repr round trip)
    assert prof is not None and prof.times == tuple(t for t, _ in points)
    assert prof.values == tuple(v for _, v in points)
    path.write_bytes(mutate(text.encode("utf-8"), data.draw))
    load_csv_cleanly(path)


# A system file whose values are slots: each keeps its valid literal or gets a random TOML value.
SYSTEM_TEMPLATE = """\
name = {name}
description = {description}
connections = {connections}

[experiment]
step_size = {step_size}
stop_time = {stop_time}
output_interval = {output_interval}
algorithm = {algorithm}

[[components]]
name = {comp_a}
fmu = {fmu_a}
start = {start}

[[components]]
name = "b"
fmu = {fmu_b}
step_multiple = {step_multiple}

[signals.s]
unit = {unit}
interpolation = {interpolation}
table = {table}
drives = {drives}

[signals.r]
csv = {csv}
drives = ["a.u"]

[record]
time = "time"
{column} = {record_y}
s_deg = {record_s}
"""
VALID_SLOTS = {
    "name": '"prop"', "description": '"property test"', "connections": '["a.y -> b.u", "b.z -> a.v"]',
    "step_size": "0.001", "stop_time": "1.0", "output_interval": "0.01", "algorithm": '"jacobi"',
    "comp_a": '"a"', "fmu_a": '"A.fmu"', "start": '{ k = 2.5, flag = true, label = "x" }',
    "fmu_b": '"{fmus}/B.fmu"', "step_multiple": "2", "unit": '"deg"', "interpolation": '"linear"',
    "table": "[[0, 0], [0.5, 3]]", "drives": '"b.w"', "csv": '"route.csv"', "column": "y", "record_y": '"a.y"',
    "record_s": '{ from = "signals.s", unit = "deg" }',
}
#: values a user could plausibly write in each slot, each of them wrong
TRICKY_SLOTS = [
    ("name", '"runs/../x"'), ("name", '"a\\b"'), ("name", '"tab\there"'), ("name", "3"), ("name", '".."'),
    ("description", "[1, 2]"), ("connections", '"a.y -> b.u"'), ("connections", '["a.y -> b.u -> a.v"]'),
    ("connections", '["a.y -> b"]'), ("step_size", "0"), ("step_size", "-1e-3"), ("step_size", "nan"),
    ("step_size", '"1e-3"'), ("stop_time", "inf"), ("stop_time", "true"), ("output_interval", "-0.0"),
    ("algorithm", '"newton"'), ("algorithm", "[]"), ("comp_a", '"b"'), ("comp_a", '"time"'), ("comp_a", '"a-b"'),
    ("fmu_a", '"~nobody_here_at_all/x.fmu"'), ("fmu_a", '"A\u0000.fmu"'), ("fmu_a", '""'), ("fmu_a", "1"),
    ("fmu_b", '"{fmus}/\u0000"'), ("start", "[1]"), ("start", "{ k = [1] }"), ("start", "{ k = 1979-05-27 }"),
    ("start", "{ k = { x = 1 } }"), ("step_multiple", "0"), ("step_multiple", "1.5"), ("step_multiple", "true"),
    ("unit", "[1]"), ("unit", "{ x = 1 }"), ("interpolation", '"cubic"'), ("interpolation", "[1]"),
    ("table", "[]"), ("table", "[[0]]"), ("table", "[[1, 0], [0, 1]]"), ("table", "[[0, nan]]"),
    ("table", "[[0, inf]]"), ("table", '[["0", 1]]'), ("table", "[[true, 1]]"), ("table", "0"),
    ("drives", "[1]"), ("drives", '"bw"'), ("drives", '"c.w"'), ("drives", '"a.u"'), ("drives", '"b.u"'),
    ("csv", '"missing.csv"'), ("csv", '"~nobody_here_at_all/r.csv"'), ("csv", '"r\u0000.csv"'), ("csv", "1"),
    ("csv", '"."'), ("column", '"x,y"'), ("column", '"x\"y"'), ("column", '"caf\u00e9"'), ("column", '"a\nb"'),
    ("column", '" "'), ("column", '"time"'), ("record_y", '"signals.nope"'), ("record_y", '"c.y"'),
    ("record_y", "1"), ("record_y", '"a"'), ("record_y", '{ from = "a.y", unit = "rpm" }'),
    ("record_y", '{ from = "a.y", unit = [1] }'), ("record_y", '{ from = "a.y", unit = { k = 1 } }'),
    ("record_y", '{ unit = "deg" }'), ("record_y", '{ from = "time", unit = "deg" }'),
    ("record_s", '{ from = "signals.s", unit = 3 }'),
]


@pytest.mark.parametrize("slot, value", TRICKY_SLOTS)
def test_system_loader_on_plausible_mistakes(tmp_path, slot, value):
    """Each a one-line CosimError naming the system file or the file it refers to."""
    (tmp_path / "route.csv").write_text("time,value\n0,1\n2,3\n", encoding="utf-8")
    path = tmp_path / "system.toml"
    path.write_text(SYSTEM_TEMPLATE.format(**{**VALID_SLOTS, slot: value}), encoding="utf-8")
    with pytest.raises(CosimError) as exc:
        load_system(path)
    assert "\n" not in str(exc.value)
    assert str(tmp_path) in str(exc.value)


def _toml_float(x: float) -> str:
    return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf") if math.isinf(x) else repr(x)


TOML_SCALARS = st.one_of(
    st.integers(-2**63, 2**63 - 1).map(str),
    st.floats().map(_toml_float),
    st.booleans().map(lambda b: "true" if b else "false"),
    st.text(max_size=12).map(lambda s: json.dumps(s)),
    st.sampled_from(['"a.y"', '"signals.s"', '"time"', '"a"', '"b.w -> a.y"', '"~nobody_here/x.fmu"',
                     '"A.fmu\\u0000"', '"sub/../A.fmu"', '"deg"', '"previous"', '"gauss-seidel"', "1979-05-27",
                     '"route.csv"', '"x,y"', '"\\n"']),
)
TOML_VALUES = st.recursive(
    TOML_SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3).map(lambda xs: "[" + ", ".join(xs) + "]"),
        st.dictionaries(st.sampled_from(["from", "unit", "k", "x", "1"]), inner, max_size=2).map(
            lambda d: "{ " + ", ".join(f'"{k}" = {v}' for k, v in d.items()) + " }"),
    ),
    max_leaves=4,
)


def load_system_cleanly(path: Path) -> SystemSpec | None:
    try:
        spec = load_system(path)
    except CosimError as exc:
        assert "\n" not in str(exc), str(exc)
        return None
    assert isinstance(spec, SystemSpec) and spec.components and spec.columns
    assert spec.step_size > 0 and spec.stop_time > 0 and spec.output_interval > 0
    return spec


@PROPERTY
@given(data=st.binary(max_size=400))
def test_system_loader_on_random_bytes(scratch, data):
    path = scratch / "random.toml"
    path.write_bytes(data)
    load_system_cleanly(path)


@pytest.mark.parametrize("column", ['"\\n"', '"a\\tb"', '"\\u0007"'])
def test_a_column_name_that_is_not_printable_is_named_on_one_line(tmp_path, column):
    """A record column named by a control character: the error names it quoted, on one line (a property test
    found a column named "\\n" whose error broke the line where the record key was named)."""
    (tmp_path / "route.csv").write_text("time,value\n0,1\n2,3\n", encoding="utf-8")
    path = tmp_path / "system.toml"
    path.write_text(SYSTEM_TEMPLATE.format(**{**VALID_SLOTS, "column": column}), encoding="utf-8")
    with pytest.raises(CosimError, match="a column name must be non-empty printable ASCII") as exc:
        load_system(path)
    assert "\n" not in str(exc.value)


@PROPERTY
@given(changes=st.one_of(
    st.dictionaries(st.sampled_from(sorted(VALID_SLOTS)), TOML_VALUES, min_size=1, max_size=2),
    st.lists(st.sampled_from(TRICKY_SLOTS), min_size=2, max_size=3).map(dict)))
def test_system_loader_on_near_valid_values(scratch, changes):
    """One or two values of a valid system file replaced by random TOML values."""
    (scratch / "route.csv").write_text("time,value\n0,1\n2,3\n", encoding="utf-8")
    path = scratch / "near.toml"
    path.write_text(SYSTEM_TEMPLATE.format(**VALID_SLOTS), encoding="utf-8")
    spec = load_system_cleanly(path)
    assert spec is not None and spec.signals["r"].profile.values == (1.0, 3.0)
    path.write_text(SYSTEM_TEMPLATE.format(**{**VALID_SLOTS, **changes}), encoding="utf-8", errors="surrogatepass")
    load_system_cleanly(path)


@PROPERTY
@given(data=st.data())
def test_system_loader_on_mutated_valid_files(scratch, data):
    (scratch / "route.csv").write_text("time,value\n0,1\n2,3\n", encoding="utf-8")
    text = SYSTEM_TEMPLATE.format(**VALID_SLOTS).encode("utf-8")
    path = scratch / "mutated.toml"
    path.write_bytes(text)
    assert load_system_cleanly(path) is not None
    path.write_bytes(mutate(text, data.draw))
    load_system_cleanly(path)
