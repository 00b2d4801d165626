"""FMI 2.0's behaviour under misuse (fmus/README.md, "Errors"): a master that calls the FMUs in the wrong state,
gives them non-finite inputs, steps from a communication point that does not continue the last one, or steps the
plant further than it integrates to its accuracy, is refused with the standard's status (fmi2Error; fmi2Discard
for the step too long) and one log line, and the FMU stays usable. Each call sequence runs in a Python process
of its own (fmpy's low-level FMU2Slave, as another master would call it; a crash is one failed test), on the
default build (the lean binding: ``DriveSlave.refusal`` asked by ``fmus/lean_binding.c``).

The same sequences under AddressSanitizer and UndefinedBehaviorSanitizer: the FMUs' C code (the lean binding and
the loader, fmus/fmu_loader.c) compiled with ``-fsanitize=address,undefined`` (``PMSM_EV_BINDING_CFLAGS``), run by
fmpy in a process with the sanitizers' runtime preloaded: no report, and the same statuses, log lines and numbers as
the plain build."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from orchestrator_support import project_fmus
from pmsm_ev_fmus import build as fmu_build
from sanitizer_support import build_sanitized, is_sanitized, needs_asan, no_report, sanitized_env

pytestmark = pytest.mark.skipif(fmu_build.binding_requested() != "lean",
                                reason="fmi2Error needs the lean binding (pythonfmu's alone returns fmi2Fatal)")

H = 1e-4

# call sequences on one FMU, each on an instance of its own (instantiated, then terminated and freed): per
# sequence, the statuses of the calls (0 for one that returned fmi2OK), the FMU's log lines, values read
_SCRIPT = r"""
import json, math, sys
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
path = sys.argv[1]
md = read_model_description(path)
vr = {v.name: v.valueReference for v in md.modelVariables}
def sequence(case):
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="m")
    fmu.instantiate(loggingOn=True)  # fmpy's default logger prints "[ERROR] message": read back from stdout
    out = {"calls": [], "values": {}}
    def call(name, *args):
        try:
            getattr(fmu, name)(*args)
            out["calls"].append([name, 0])
            return 0
        except FMICallException as exc:
            out["calls"].append([name, exc.status])
            return exc.status
    def init():
        call("setupExperiment", None, 0.0)
        call("enterInitializationMode")
        call("exitInitializationMode")
    def read(label, names):
        out["values"][label] = [v if math.isfinite(v) else repr(v) for v in fmu.getReal([vr[n] for n in names])]
    if case == "step-before-init":
        call("setupExperiment", None, 0.0)
        call("doStep", 0.0, 1e-4)
        call("enterInitializationMode")
        call("doStep", 0.0, 1e-4)
        call("exitInitializationMode")
        call("doStep", 0.0, 1e-4)
    elif case == "step-after-terminate":
        init()
        call("doStep", 0.0, 1e-4)
        call("terminate")
        call("doStep", 1e-4, 1e-4)
    elif case == "enter-twice":
        call("setupExperiment", None, 0.0)
        call("enterInitializationMode")
        call("enterInitializationMode")
        call("exitInitializationMode")
        call("exitInitializationMode")
        call("setupExperiment", None, 0.0)
        call("doStep", 0.0, 1e-4)
    elif case == "non-finite":
        init()
        inputs = [v.name for v in md.modelVariables if v.causality == "input" and v.type == "Real"]
        call("setReal", [vr[inputs[0]]], [float("inf")])
        call("setReal", [vr[n] for n in inputs], [1.0] * (len(inputs) - 1) + [float("nan")])
        call("doStep", 0.0, 1e-4)
        read("after", [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"])
    elif case == "time":
        init()
        call("doStep", 0.0, 1e-4)
        call("doStep", 1e-4, 1e-4)
        call("doStep", 0.0, 1e-4)       # back in time
        call("doStep", 5e-4, 1e-4)      # a gap
        state = fmu.getFMUstate()       # at 2e-4
        call("doStep", 2e-4, 1e-4)
        fmu.setFMUstate(state)
        call("doStep", 2e-4, 1e-4)      # from the restored state: the same point again
        call("doStep", 3e-4 + 1e-19, 1e-4)  # a master's rounding: continues
    elif case == "wrong-reference":  # no such variable, or one of another type: fmi2Error, nothing read or set
        init()
        nowhere = max(v.valueReference for v in md.modelVariables) + 1000
        text = next(v for v in md.modelVariables if v.type == "String")
        real = next(v for v in md.modelVariables if v.causality == "output" and v.type == "Real")
        call("getReal", [nowhere])
        call("getReal", [vr[real.name], vr[text.name]])
        call("setReal", [nowhere], [1.0])
        call("getInteger", [nowhere])
        call("setBoolean", [vr[real.name]], [True])
        call("getString", [vr[real.name]])
        call("doStep", 0.0, 1e-4)
        read("after", [real.name])
        out["values"]["names"] = [nowhere, text.name, real.name]
    elif case == "long-step":
        init()
        call("setReal", [vr["v_alpha"], vr["v_beta"]], [20.0, 5.0])
        call("doStep", 0.0, 1e-4)
        call("doStep", 1e-4, 5.0)
        read("after", ["omega_m", "i_d", "i_q"])
        out["values"]["last"] = fmu.getRealStatus(2)
        out["values"]["terminated"] = fmu.getBooleanStatus(3)
        call("doStep", 1e-4, 1e-4)
        read("then", ["omega_m", "i_d", "i_q"])
    elif case == "foreign-instance":  # a freed instance, then NULL: fmi2Error each, nothing touched
        import ctypes
        init()
        call("doStep", 0.0, 1e-4)
        dll, freed = fmu.dll, fmu.component
        fmu.terminate()
        fmu.freeInstance()
        refs, values = (ctypes.c_uint * 1)(vr[md.modelVariables[0].name]), (ctypes.c_double * 1)(0.0)
        for label, c in (("freed", freed), ("null", None)):
            out["values"][label] = [dll.fmi2DoStep(c, 1e-4, 1e-4, 1), dll.fmi2GetReal(c, refs, 1, values),
                                    dll.fmi2SetReal(c, refs, 1, values),
                                    dll.fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0),
                                    dll.fmi2EnterInitializationMode(c), dll.fmi2ExitInitializationMode(c),
                                    dll.fmi2Terminate(c), dll.fmi2Reset(c)]
        dll.fmi2FreeInstance(freed)  # again: nothing
        dll.fmi2FreeInstance(None)
        print(END + json.dumps(out), flush=True)
        return
    elif case == "threads":  # instances side by side, then two threads each stepping its own: the same numbers
        import threading
        inputs = [vr[v.name] for v in md.modelVariables if v.causality == "input" and v.type == "Real"]
        outputs = [vr[v.name] for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
        def make(name):
            f = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                          instanceName=name)
            f.instantiate()
            f.setupExperiment(None, 0.0)
            f.enterInitializationMode()
            f.exitInitializationMode()
            return f
        def drive(f, n, into):
            for k in range(n):
                f.setReal(inputs, [0.5 + 0.001 * j for j in range(len(inputs))])
                f.doStep(k * 1e-4, 1e-4)
            into.append(f.getReal(outputs))
        serial = []
        drive(fmu, 0, [])
        fmu.setupExperiment(None, 0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        drive(fmu, 500, serial)
        pair, found = [make("a"), make("b")], [[], []]
        threads = [threading.Thread(target=drive, args=(f, 500, into)) for f, into in zip(pair, found)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        out["values"]["same"] = [found[0] == serial, found[1] == serial]
        for f in pair:
            f.terminate()
            f.freeInstance()
    fmu.terminate()
    fmu.freeInstance()
    print(END + json.dumps(out), flush=True)  # the end of the sequence's log lines
END = sys.argv[2]
for case in sys.argv[3:]:
    sequence(case)
"""
#: the mark of the line that ends a sequence (its JSON after it)
_END = "@@sequence@@ "


@pytest.fixture(scope="module")
def fmus() -> dict[str, Path]:
    return project_fmus()  # the user's cache: the call sequences on each FMU run in a process of their own


#: the call sequences the tests below make on each FMU, run one after the other in one process per FMU
SEQUENCES = {"PmsmEvPlant": ("step-before-init", "step-after-terminate", "non-finite", "time", "long-step",
                             "foreign-instance", "threads", "wrong-reference"),
             "FocSensorless": ("step-before-init", "step-after-terminate", "enter-twice", "time", "foreign-instance",
                               "threads", "wrong-reference"),
             "RouteProfile": ("step-before-init",), "FocEkf5": ("non-finite",)}
_RUNS: dict = {}  # {(FMU, case): its result}, of the sequences run so far


def run_all(fmu: Path, cases, env: dict | None = None, check=None) -> dict[str, tuple[list, list[str], dict]]:
    """{case: (the calls with their statuses, the FMU's log lines, the values read)} of the call sequences
    ``cases`` on ``fmu``, one after the other in a process of their own (with ``env``), each on an instance of its
    own; ``check(completed process)`` first, if given."""
    done = subprocess.run([sys.executable, "-c", _SCRIPT, str(fmu), _END, *cases], capture_output=True, text=True,
                          timeout=600, env=env)
    if check is not None:
        check(done)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    results, log = {}, []
    for line in done.stdout.strip().splitlines():
        if line.startswith(_END):
            out = json.loads(line[len(_END):])
            results[cases[len(results)]] = (out["calls"], log, out["values"])
            log = []
        elif line.startswith("[") or not log:  # a message of several lines (pythonfmu's, with the exception's
            log.append(line)                     # repr): one entry
        else:
            log[-1] += "\n" + line
    assert list(results) == list(cases) and not log
    return results


def run(fmu: Path, case: str) -> tuple[list, list[str], dict]:
    """(the calls with their statuses, the FMU's log lines, the values read) of ``case`` on ``fmu``, one of the FMUs
    of ``SEQUENCES`` (its sequences run in a process of their own the first time one of them is asked for)."""
    if (fmu, case) not in _RUNS:
        cases = SEQUENCES[fmu.stem]
        assert case in cases, (fmu.stem, case)
        _RUNS.update({(fmu, c): result for c, result in run_all(fmu, cases).items()})
    return _RUNS[(fmu, case)]


ERROR, DISCARD = 3, 2


@pytest.mark.parametrize("name", ["PmsmEvPlant", "FocSensorless", "RouteProfile"])
def test_a_step_before_initialisation_is_an_error(fmus, name):
    calls, log, _ = run(fmus[name], "step-before-init")
    assert calls == [["setupExperiment", 0], ["doStep", ERROR], ["enterInitializationMode", 0], ["doStep", ERROR],
                     ["exitInitializationMode", 0], ["doStep", 0]]
    assert log == ["[ERROR] fmi2DoStep before fmi2ExitInitializationMode (the FMU is in instantiated)",
                   "[ERROR] fmi2DoStep before fmi2ExitInitializationMode (the FMU is in initialization mode)"]


@pytest.mark.parametrize("name", ["PmsmEvPlant", "FocSensorless"])
def test_a_step_after_terminate_is_an_error(fmus, name):
    calls, log, _ = run(fmus[name], "step-after-terminate")
    assert calls == [["setupExperiment", 0], ["enterInitializationMode", 0], ["exitInitializationMode", 0],
                     ["doStep", 0], ["terminate", 0], ["doStep", ERROR]]
    assert log == ["[ERROR] fmi2DoStep after fmi2Terminate (the FMU is in terminated)"]


def test_calls_of_the_initialisation_out_of_order_are_errors(fmus):
    calls, log, _ = run(fmus["FocSensorless"], "enter-twice")
    assert calls == [["setupExperiment", 0], ["enterInitializationMode", 0], ["enterInitializationMode", ERROR],
                     ["exitInitializationMode", 0], ["exitInitializationMode", ERROR], ["setupExperiment", ERROR],
                     ["doStep", 0]]
    assert log == [
        "[ERROR] fmi2EnterInitializationMode in initialization mode: allowed once, after fmi2Instantiate or "
        "fmi2Reset",
        "[ERROR] fmi2ExitInitializationMode in step mode: allowed only after fmi2EnterInitializationMode",
        "[ERROR] fmi2SetupExperiment in step mode: allowed only before fmi2EnterInitializationMode"]


@pytest.mark.parametrize("name, first", [("FocEkf5", "i_alpha"), ("PmsmEvPlant", "v_alpha")])
def test_non_finite_inputs_are_refused_naming_the_variable(fmus, name, first):
    """inf, or a NaN among finite values, is not set (the whole call refused): the step after runs on the inputs
    held before and every output stays finite. (FocSensorless takes any value on the inputs it never reads,
    theta_meas and omega_meas: tests/test_sensorless.py feeds them NaN.)"""
    calls, log, values = run(fmus[name], "non-finite")
    assert calls[-3:] == [["setReal", ERROR], ["setReal", ERROR], ["doStep", 0]]
    assert log[0] == f"[ERROR] fmi2SetReal: input {first!r} = inf is not finite; not set"
    assert log[1].startswith("[ERROR] fmi2SetReal: input '") and log[1].endswith("' = nan is not finite; not set")
    assert len(log) == 2
    assert all(isinstance(v, float) and math.isfinite(v) for v in values["after"])


@pytest.mark.parametrize("name", ["PmsmEvPlant", "FocSensorless"])
def test_a_value_reference_of_no_variable_or_of_another_type_is_an_error(fmus, name):
    """fmi2Error and a line naming the reference (pythonfmu alone raises and answers fmi2Fatal, after which a host
    may not call the FMU again: an FMI 3.0 host that took the controller's clock for a Float64 met that); nothing
    read or set, and the FMU steps on."""
    calls, log, values = run(fmus[name], "wrong-reference")
    nowhere, text, real = values["names"]
    assert calls[3:] == [["getReal", ERROR], ["getReal", ERROR], ["setReal", ERROR], ["getInteger", ERROR],
                         ["setBoolean", ERROR], ["getString", ERROR], ["doStep", 0]]
    assert [line.split(":")[0] for line in log] == ["[ERROR] fmi2GetReal", "[ERROR] fmi2GetReal", "[ERROR] fmi2SetReal",
                                                    "[ERROR] fmi2GetInteger", "[ERROR] fmi2SetBoolean",
                                                    "[ERROR] fmi2GetString"]
    assert log[0] == f"[ERROR] fmi2GetReal: no variable has the value reference {nowhere}; nothing read"
    assert log[1].endswith(f" is {text!r}, a String, not a Real; nothing read")
    assert log[2] == f"[ERROR] fmi2SetReal: no variable has the value reference {nowhere}; nothing set"
    assert log[3] == f"[ERROR] fmi2GetInteger: no variable has the value reference {nowhere}; nothing read"
    assert log[4].endswith(f" is {real!r}, a Real, not a Boolean; nothing set")
    assert log[5].endswith(f" is {real!r}, a Real, not a String; nothing read")
    assert all(isinstance(v, float) and math.isfinite(v) for v in values["after"])


@pytest.mark.parametrize("name", ["PmsmEvPlant", "FocSensorless"])
def test_a_communication_point_that_does_not_continue_the_last_is_refused(fmus, name):
    """Back in time or past a gap: fmi2Error; from a restored FMU state the same point again is fine, and so is a
    master's rounding of t + h."""
    calls, log, _ = run(fmus[name], "time")
    assert [status for _, status in calls[3:]] == [0, 0, ERROR, ERROR, 0, 0, 0]
    assert log == [
        "[ERROR] fmi2DoStep at t = 0.0 s does not continue the last step, which ended at 0.0002 s (restore an FMU "
        "state to step from another time)",
        "[ERROR] fmi2DoStep at t = 0.0005 s does not continue the last step, which ended at 0.0002 s (restore an "
        "FMU state to step from another time)"]


def test_a_plant_step_longer_than_it_integrates_is_discarded(fmus):
    """5 s at once (the plant integrates 2.3 ms to its accuracy): fmi2Discard with the reason, the state left as it
    was (no 1e20), the last successful time where the step began, the run not terminated: a shorter step goes on."""
    calls, log, values = run(fmus["PmsmEvPlant"], "long-step")
    assert [status for _, status in calls[3:]] == [0, 0, DISCARD, 0]
    assert len(log) == 1 and log[0].startswith("[DISCARD] fmi2DoStep of 5.0 s discarded: longer than the plant "
                                               "integrates to its accuracy (0.0023")
    assert "take shorter steps or raise rk4_substeps" in log[0]
    assert values["last"] == pytest.approx(1e-4) and values["terminated"] is False
    assert all(abs(v) < 1e3 for v in values["after"] + values["then"])
    assert values["then"] != values["after"]


def test_through_pythonfmus_library_alone_the_same_calls_are_refused_as_fatal(tmp_path):
    """An FMU built with pythonfmu's library alone (``PMSM_EV_FMU_BINDING=pythonfmu``: no C compiler, another
    platform) refuses the same calls, as fmi2Fatal (pythonfmu gives a slave no other status), the reason in
    pythonfmu's log line; a step too long is discarded there too (with the terminated status, pythonfmu's)."""
    env = dict(os.environ, PMSM_EV_FMU_BINDING="pythonfmu", PMSM_COSIM_FMU_DIR=str(tmp_path))
    subprocess.run([sys.executable, "-m", "pmsm_ev_fmus", "--out", str(tmp_path), "PmsmEvPlant"], env=env,
                   check=True, capture_output=True, text=True, timeout=600)
    plant = tmp_path / "PmsmEvPlant.fmu"
    runs = run_all(plant, ("step-after-terminate", "long-step"))
    calls, log, _ = runs["step-after-terminate"]
    assert calls[-1] == ["doStep", 4]
    assert len(log) == 1 and log[0].startswith("[FATAL] ") and "fmi2DoStep after fmi2Terminate" in log[0]
    calls, log, values = runs["long-step"]
    assert calls[5] == ["doStep", DISCARD] and values["terminated"] is True
    assert any("longer than the plant integrates to its accuracy" in line for line in log)


@pytest.mark.parametrize("name", ["PmsmEvPlant", "FocSensorless"])
def test_a_freed_or_null_instance_is_an_error_and_touched_nowhere(fmus, name):
    """Every call on an instance already freed, or on NULL, returns fmi2Error (there is no logger to tell: the
    host's callbacks belong to the instance); freeing it again does nothing."""
    _, _, values = run(fmus[name], "foreign-instance")
    assert values["freed"] == values["null"] == [ERROR] * 8


@pytest.mark.parametrize("name", ["PmsmEvPlant", "FocSensorless"])
def test_instances_side_by_side_and_in_two_threads_give_the_serial_numbers(fmus, name):
    _, log, values = run(fmus[name], "threads")
    assert values["same"] == [True, True] and log == []


# -- under the sanitizers ----------------------------------------------------------------------------------------
SANITIZED = ("PmsmEvPlant", "FocSensorless")  # every sequence of the suite is run on one of them


@pytest.fixture(scope="module")
def sanitized(tmp_path_factory) -> dict[str, Path]:
    return build_sanitized(tmp_path_factory.mktemp("fmus-sanitized"), SANITIZED)


@needs_asan
@pytest.mark.slow
def test_the_sanitized_build_is_sanitized(sanitized):
    """The binding and the loader inside the FMU link the sanitizers' runtimes (so that the test below checks what
    it says)."""
    for name, fmu in sanitized.items():
        for library in ("pmsm-binding.so", f"{name}.so"):
            assert is_sanitized(fmu, f"binaries/linux64/{library}"), library


@needs_asan
@pytest.mark.parametrize("name", SANITIZED)
@pytest.mark.slow
def test_the_misuse_suite_under_the_sanitizers_reports_nothing_and_answers_as_the_plain_build(fmus, sanitized, name):
    found = run_all(sanitized[name], SEQUENCES[name], env=sanitized_env(), check=no_report)
    assert found == {case: run(fmus[name], case) for case in SEQUENCES[name]}
