"""The lean binding (``fmus/lean_binding.c``, fmus/README.md "The lean binding"): the FMUs' Linux library in
front of pythonfmu's. What must hold: the same numbers, the same statuses and messages as pythonfmu's own
binding, call for call, whatever a master does; only the cost of a call differs.

Each test compares the two builds of the same FMU (``PMSM_EV_FMU_BINDING`` "lean", the default, against
"pythonfmu"), built into folders of their own in a subprocess (the build and the FMUs' interpreter state stay
out of this process)."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux") or shutil.which(os.environ.get("CC", "cc")) is None,
    reason="the lean binding is built on Linux with a C compiler")

HERE = Path(__file__).resolve().parent
NAMES = ("PmsmEvPlant", "FocSensorless", "FocEkf5", "RouteProfile")


def _env(binding: str, fmu_dir: Path) -> dict:
    env = dict(os.environ, PMSM_EV_FMU_BINDING=binding, PMSM_COSIM_FMU_DIR=str(fmu_dir))
    env["PYTHONPATH"] = os.pathsep.join([str(HERE), env.get("PYTHONPATH", "")])
    return env


@pytest.fixture(scope="module")
def builds(tmp_path_factory):
    """{binding: folder of the FMUs built with it}."""
    out = {}
    for binding in ("lean", "pythonfmu"):
        folder = tmp_path_factory.mktemp(f"fmus-{binding}")
        subprocess.run([sys.executable, "-m", "pmsm_ev_fmus", "--out", str(folder), *NAMES],
                       env=_env(binding, folder), check=True, capture_output=True, text=True, timeout=600)
        out[binding] = folder
    return out


def test_the_default_build_puts_the_lean_binding_in_front_of_pythonfmus_library(builds):
    for name in NAMES:
        with zipfile.ZipFile(builds["lean"] / f"{name}.fmu") as z:
            info = json.loads(z.read("resources/build_info.json"))
            lean = z.read(f"binaries/linux64/{name}.so")
            inner = z.read("binaries/linux64/pythonfmu-export.so")
        with zipfile.ZipFile(builds["pythonfmu"] / f"{name}.fmu") as z:
            stock_info = json.loads(z.read("resources/build_info.json"))
            stock = z.read(f"binaries/linux64/{name}.so")
            assert "binaries/linux64/pythonfmu-export.so" not in z.namelist()
        assert (info["binding"], stock_info["binding"]) == ("lean", "pythonfmu")
        assert inner == stock  # pythonfmu's library, unchanged, under another name
        assert b"pmsm_fmu_offer" in lean and lean != stock


@pytest.mark.parametrize("scenario, stop", [("wltc3b-sensorless", "12"), ("scenario2", "2")])
def test_a_run_gives_the_same_bytes_with_either_binding(builds, tmp_path, scenario, stop):
    """The whole co-simulation (plant, controller, route FMU; the compiled loop) through each binding:
    ``results.csv`` identical. wltc3b-sensorless to 12 s covers the alignment, I-f and the handover to the
    EKF; scenario2 the paper's FocEkf5 with the route FMU's elevation."""
    outputs = []
    for binding, folder in builds.items():
        out = tmp_path / binding
        subprocess.run([sys.executable, "-m", "pmsm_cosim.app.cli", "run", scenario, "--stop-time", stop,
                        "--no-figures", "--quiet", "--out", str(out)],
                       env=_env(binding, folder), check=True, capture_output=True, text=True, timeout=600)
        outputs.append((out / "results.csv").read_bytes())
    assert len(outputs[0]) > 1000
    assert outputs[0] == outputs[1]


# what a master other than the project's does, call by call; each step's values, statuses and log lines are
# printed as JSON by the subprocess and compared between the bindings
_SCRIPT = r"""
import json, math, sys
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
path, case = sys.argv[1], sys.argv[2]
md = read_model_description(path)
vr = {v.name: v.valueReference for v in md.modelVariables}
log = []
fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                instanceName="m")
fmu.instantiate(loggingOn=True)  # fmpy's default logger prints what the FMU logs: compared too
record = []
def call(name, *args):
    try:
        value = getattr(fmu, name)(*args)
        record.append([name, "ok", value if not isinstance(value, float) or math.isfinite(value) else repr(value)])
        return value
    except FMICallException as exc:
        record.append([name, "status", exc.status])
        print(json.dumps(record)); sys.exit(0)
call("setupExperiment", None, 0.0, 1.0)
call("enterInitializationMode")
if case == "plant":
    call("setReal", [vr["m_v"]], [1500.0])
outs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
inputs = [v.valueReference for v in md.modelVariables if v.causality == "input" and v.type == "Real"]
call("getReal", outs)  # the initial unknowns, from the parameters set
call("exitInitializationMode")
call("getReal", outs)
for k in range(30):
    call("setReal", inputs, [0.5 + 0.01 * k + i for i in range(len(inputs))])
    call("doStep", k * 1e-4, 1e-4)
    call("getReal", outs)
    call("getReal", inputs[::-1])
record.append(["getRealStatus", "ok", fmu.getRealStatus(2)])  # fmi2LastSuccessfulTime
state = fmu.getFMUstate()
call("doStep", 30e-4, 1e-4)
after = call("getReal", outs)
fmu.setFMUstate(state)
call("doStep", 30e-4, 1e-4)
again = call("getReal", outs)
record.append(["state", "ok", after == again])
call("reset")
call("setupExperiment", None, 0.0, 1.0)
call("enterInitializationMode")
call("exitInitializationMode")
call("setReal", inputs, [1.0] * len(inputs))
call("doStep", 0.0, 1e-4)
call("getReal", outs)
if case == "bad-get":
    call("getReal", [max(vr.values()) + 7])
if case == "bad-set":
    call("setReal", [outs[0]], [1.0])
if case == "bad-step":
    call("doStep", 1e-4, -1e-4)
print(json.dumps(record))
"""


def _calls(fmu: Path, case: str, env: dict) -> tuple[list, list]:
    """(the calls' record, the lines the FMU logged)."""
    done = subprocess.run([sys.executable, "-c", _SCRIPT, str(fmu), case], env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    lines = done.stdout.strip().splitlines()
    return json.loads(lines[-1]), lines[:-1]


@pytest.mark.parametrize("name, case", [("PmsmEvPlant", "plant"), ("FocSensorless", "bad-get"),
                                        ("FocEkf5", "bad-set"), ("PmsmEvPlant", "bad-step")])
def test_another_master_sees_the_same_values_statuses_and_states(builds, name, case):
    """Inputs set, steps, outputs read (also in another order), the last successful time, an FMU state taken,
    stepped from and restored, a reset and a new initialisation, then a call that fails (an unknown value
    reference, an output set, a negative step): the same values and statuses, call for call."""
    lean, lean_log = _calls(builds["lean"] / f"{name}.fmu", case, _env("lean", builds["lean"]))
    stock, stock_log = _calls(builds["pythonfmu"] / f"{name}.fmu", case, _env("pythonfmu", builds["pythonfmu"]))
    assert lean == stock
    assert lean_log == stock_log
    assert [r for r in lean if r[0] == "getRealStatus"][0][2] == pytest.approx(30e-4)
    assert [r for r in lean if r[0] == "state"][0][2] is True
    reads = [r[2] for r in lean if r[0] == "getReal" and r[1] == "ok"]
    assert len(reads) > 60 and all(math.isfinite(x) for x in reads[-1])
    if case != "plant":  # fmi2Fatal, as pythonfmu reports any exception, with the reason logged
        assert lean[-1][1:] == ["status", 4]
        assert any("Fatal py exception encountered" in line for line in lean_log), lean_log
