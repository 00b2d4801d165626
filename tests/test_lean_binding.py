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
import re
import shutil
import subprocess
import sys
import sysconfig
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
    """binaries/linux64/: the FMU's loader as <model>.so (fmus/fmu_loader.c), the lean binding behind it as
    pmsm-binding.so, pythonfmu's library behind that as pythonfmu-export.so."""
    for name in NAMES:
        with zipfile.ZipFile(builds["lean"] / f"{name}.fmu") as z:
            info = json.loads(z.read("resources/build_info.json"))
            loader = z.read(f"binaries/linux64/{name}.so")
            lean = z.read("binaries/linux64/pmsm-binding.so")
            inner = z.read("binaries/linux64/pythonfmu-export.so")
        with zipfile.ZipFile(builds["pythonfmu"] / f"{name}.fmu") as z:
            stock_info = json.loads(z.read("resources/build_info.json"))
            stock = z.read(f"binaries/linux64/{name}.so")
            assert "binaries/linux64/pythonfmu-export.so" not in z.namelist()
        assert (info["binding"], stock_info["binding"]) == ("lean", "pythonfmu")
        assert inner == stock  # pythonfmu's library, unchanged, under another name
        assert b"pmsm_fmu_offer" in lean and lean != stock
        assert b"pmsm_fmu_offer" not in loader and b"PMSM_FMU_PYTHON" in loader and b"_Py_NoneStruct" not in loader


RUNS = (("wltc3b-if", "12"), ("scenario2", "2"), ("hill-start-injection", "3"), ("wltc3b-battery", "8"),
        ("wltc3b-thermal", "8"))
# the runs of RUNS one after the other, as ``pmsm-cosim run SCENARIO --stop-time STOP --no-figures --quiet --out
# DIR/SCENARIO``, in one process of their own per binding (FMUs instantiated, run and freed run after run, as a
# sweep's worker does)
_RUNS_SCRIPT = r"""
import sys
from pmsm_cosim.app.cli import main
out = sys.argv[1]
for scenario, stop in zip(sys.argv[2::2], sys.argv[3::2]):
    code = main(["run", scenario, "--stop-time", stop, "--no-figures", "--quiet", "--out", f"{out}/{scenario}"])
    if code:
        sys.exit(f"{scenario}: exit {code}")
"""


@pytest.fixture(scope="module")
def runs(builds, tmp_path_factory):
    """{binding: folder of the runs of RUNS with the FMUs built with it}."""
    out = {}
    for binding, folder in builds.items():
        out[binding] = tmp_path_factory.mktemp(f"runs-{binding}")
        subprocess.run([sys.executable, "-c", _RUNS_SCRIPT, str(out[binding]), *(x for run in RUNS for x in run)],
                       env=_env(binding, folder), check=True, capture_output=True, text=True, timeout=900)
    return out


@pytest.mark.parametrize("scenario, stop", RUNS)
@pytest.mark.slow
def test_a_run_gives_the_same_bytes_with_either_binding(runs, scenario, stop):
    """The whole co-simulation (plant, controller, route FMU; the compiled loop) through each binding:
    ``results.csv`` identical. With the lean binding the FMUs step in compiled code (``pmsm_ev.kernels.fmu``),
    with pythonfmu's their Python ``do_step``. wltc3b-if to 12 s covers the alignment, I-f and the
    handover to the EKF, with the plant's voltage limit, inverter losses and current noise; scenario2 the paper's
    FocEkf5 with the route FMU's elevation; hill-start-injection the injection's acquisition and polarity test
    (``injection_unit_step``); wltc3b-battery the battery in the plant's step and the controller on the measured DC
    link (``battery_step``, ``unit_dc_link``); wltc3b-thermal the thermal network in the plant's step
    (``thermal_network_step``)."""
    outputs = [(runs[binding] / scenario / "results.csv").read_bytes() for binding in ("lean", "pythonfmu")]
    assert len(outputs[0]) > 1000
    assert outputs[0] == outputs[1]
    last = outputs[0].decode().splitlines()[-1]
    assert float(last.split(",")[0]) == float(stop)  # each run to its end


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
    if case == "bad-get":  # a reference of no variable: fmi2Error and the slave's line (DriveSlave.refusal) on the
        # lean binding, where pythonfmu alone answers fmi2Fatal; every call and line before it the same
        from fmpy import read_model_description

        nowhere = max(v.valueReference for v in read_model_description(builds["lean"] / f"{name}.fmu").modelVariables)
        assert lean[:-1] == stock[:-1]
        assert lean[-1] == ["getReal", "status", 3] and stock[-1] == ["getReal", "status", 4]
        assert lean_log[:-1] == stock_log[:len(lean_log) - 1]
        assert lean_log[-1].endswith(f"fmi2GetReal: no variable has the value reference {nowhere + 7}; nothing read")
        return
    assert lean == stock
    assert lean_log == stock_log
    assert [r for r in lean if r[0] == "getRealStatus"][0][2] == pytest.approx(30e-4)
    assert [r for r in lean if r[0] == "state"][0][2] is True
    reads = [r[2] for r in lean if r[0] == "getReal" and r[1] == "ok"]
    assert len(reads) > 60 and all(math.isfinite(x) for x in reads[-1])
    if case != "plant":  # fmi2Fatal, as pythonfmu reports any exception, with the reason logged (an output set, a
        # negative step: refused by pythonfmu's own path, as the stock binding does)
        assert lean[-1][1:] == ["status", 4]
        assert any("Fatal py exception encountered" in line for line in lean_log), lean_log


# --- the fast path's contract: a counter the binding keeps per instance (pmsm_fmu_fast_calls) ----------------------
# A closed loop of FocEkf5 and PmsmEvPlant instances driven by fmpy's FMU2Slave, call by call (Gauss-Seidel: the
# controller reads the plant, steps, the plant takes its voltage and steps). Each pair: 3 calls per FMU per step,
# every one of them after the initialisation, so every one is the binding's to serve directly. Printed as JSON: each
# pair's outputs at every step, the calls made and the binding's count of each instance.
_PAIRS_SCRIPT = r"""
import ctypes, json, os, sys, threading
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
plant_path, ctrl_path, mode, steps = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
refs = [float(x) for x in sys.argv[5:]]
H = float(os.environ.get("PAIR_H", "1e-4"))  # the step (the controller's dt is 0: its first step's size)
unpacked = {}

def load(path, name):
    if path not in unpacked:
        md = read_model_description(path)
        unpacked[path] = (md, extract(path))
    md, folder = unpacked[path]
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=name)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    return fmu, vr

def counter(fmu, name):
    fn = getattr(fmu.dll, name)  # AttributeError: not the lean binding
    fn.argtypes, fn.restype = [ctypes.c_void_p], ctypes.c_ulonglong
    return fn(fmu.component)

def fast_calls(fmu):
    return counter(fmu, "pmsm_fmu_fast_calls")

def compiled_calls(fmu):
    return counter(fmu, "pmsm_fmu_compiled_calls")

def pulls(fmu):
    return counter(fmu, "pmsm_fmu_pulls")

COUNTERS = os.environ.get("PAIR_COUNTERS", "1") == "1"
READ_ALL = os.environ.get("PAIR_READ_ALL", "0") == "1"  # also every Real output of both, each step (a recorder)
V_DC = float(os.environ.get("PAIR_V_DC", "0"))  # the plant's DC link (0: no voltage limit)

class Pair:
    def __init__(self, k, ref):
        self.ctrl, cv = load(ctrl_path, f"ctrl{k}")
        self.plant, pv = load(plant_path, f"plant{k}")
        self.c_in = [cv[n] for n in ("i_alpha", "i_beta", "omega_ref", "theta_meas", "omega_meas")]
        self.c_out = [cv[n] for n in ("v_alpha", "v_beta", "omega_hat", "theta_hat")]
        self.p_in = [pv["v_alpha"], pv["v_beta"]]
        self.p_out = [pv[n] for n in ("i_alpha", "i_beta", "theta_e", "omega_m")]
        self.ref, self.y, self.trace = ref, [0.0, 0.0, 0.0, 0.0], []
        self.all = {fmu: [v.valueReference for v in unpacked[path][0].modelVariables
                          if v.causality == "output" and v.type == "Real"]
                    for fmu, path in ((self.ctrl, ctrl_path), (self.plant, plant_path))}
        self.calls = {"ctrl": 0, "plant": 0}
        for fmu in (self.ctrl, self.plant):
            fmu.instantiate()
            fmu.setupExperiment(startTime=0.0, stopTime=1.0)
            fmu.enterInitializationMode()
            if fmu is self.plant and V_DC:
                fmu.setReal([pv["v_dc"]], [V_DC])
            fmu.exitInitializationMode()
        self.start = self.counters()

    def counters(self):
        if not COUNTERS:
            return {}
        return {"fast": {"ctrl": fast_calls(self.ctrl), "plant": fast_calls(self.plant)},
                "compiled": {"ctrl": compiled_calls(self.ctrl), "plant": compiled_calls(self.plant)},
                "pulls": {"ctrl": pulls(self.ctrl), "plant": pulls(self.plant)}}

    def step(self, k):
        t = k * H
        ia, ib, theta, omega = self.y
        self.ctrl.setReal(self.c_in, [ia, ib, self.ref, theta, omega])
        self.ctrl.doStep(t, H)
        u = self.ctrl.getReal(self.c_out)
        self.plant.setReal(self.p_in, u[:2])
        self.plant.doStep(t, H)
        self.y = self.plant.getReal(self.p_out)
        self.calls["ctrl"] += 3
        self.calls["plant"] += 3
        self.trace.append(u + self.y)
        if READ_ALL:
            for fmu, name in ((self.ctrl, "ctrl"), (self.plant, "plant")):
                self.trace.append(fmu.getReal(self.all[fmu]))
                self.calls[name] += 1

    def run(self):
        for k in range(steps):
            self.step(k)

    def report(self):
        return {"trace": self.trace, "calls": self.calls, "start": self.start, **self.counters()}

pairs = [Pair(k, ref) for k, ref in enumerate(refs)]
if mode == "interleaved":
    for k in range(steps):
        for pair in pairs:
            pair.step(k)
elif mode == "threads":
    threads = [threading.Thread(target=pair.run) for pair in pairs]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
else:
    for pair in pairs:
        pair.run()
print(json.dumps([pair.report() for pair in pairs]))
"""
STEPS = 300


_PAIR_RUNS: dict = {}  # the runs made, by their arguments: a run asked for again (the same process, the same
# arguments: the same JSON) is read from here


def _pairs(builds, binding: str, mode: str, *refs: float, **env) -> list[dict]:
    key = (str(builds[binding]), binding, mode, refs, tuple(sorted(env.items())))
    if key not in _PAIR_RUNS:
        _PAIR_RUNS[key] = _run_pairs(builds, binding, mode, *refs, **env)
    return json.loads(_PAIR_RUNS[key])


def _run_pairs(builds, binding: str, mode: str, *refs: float, **env) -> str:
    folder = builds[binding]
    done = subprocess.run([sys.executable, "-c", _PAIRS_SCRIPT, str(folder / "PmsmEvPlant.fmu"),
                           str(folder / "FocEkf5.fmu"), mode, str(STEPS), *map(str, refs)],
                          env={**_env(binding, folder), **env}, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout.strip().splitlines()[-1]


def _all_fast(pair: dict) -> None:
    """Every fmi2SetReal, fmi2DoStep and fmi2GetReal made after the initialisation served by the binding itself,
    in compiled code: no Python on the way (``pmsm_fmu_compiled_calls``)."""
    none = {"ctrl": 0, "plant": 0}
    assert pair["start"] == {"fast": none, "compiled": none, "pulls": none}  # nothing before (pythonfmu's path)
    assert pair["pulls"] == none  # the buffers never handed back to Python
    assert pair["calls"] == {"ctrl": 3 * STEPS, "plant": 3 * STEPS}
    assert pair["fast"] == pair["calls"]
    assert pair["compiled"] == pair["calls"]


def test_every_per_step_call_takes_the_fast_path(builds):
    """The counter the binding exposes equals the calls made: a binding that falls back to pythonfmu's path (or
    an FMU whose library is pythonfmu's alone) fails here, not only in a benchmark. The same numbers either way."""
    (pair,) = _pairs(builds, "lean", "serial", 80.0)
    _all_fast(pair)
    assert len(pair["trace"]) == STEPS and pair["trace"][-1] != pair["trace"][0]
    assert all(math.isfinite(x) for row in pair["trace"] for x in row)
    # pythonfmu's own library has no such counter (this test would fail on it), and computes the same numbers
    done = subprocess.run([sys.executable, "-c", _PAIRS_SCRIPT, str(builds["pythonfmu"] / "PmsmEvPlant.fmu"),
                           str(builds["pythonfmu"] / "FocEkf5.fmu"), "serial", "20", "80.0"],
                          env=_env("pythonfmu", builds["pythonfmu"]), capture_output=True, text=True, timeout=600)
    assert done.returncode != 0 and "pmsm_fmu_fast_calls" in done.stderr


def test_every_per_step_call_runs_compiled_code_with_the_python_step_still_there(builds):
    """The compiled step's contract (``pmsm_fmu_compiled_calls``): with the kernels compiled, every fmi2SetReal,
    fmi2DoStep and fmi2GetReal of the loop is served with no Python (a binding or a slave that falls back to the
    Python step fails here); the numbers are those of pythonfmu's own binding, which runs the slaves' Python
    ``do_step``, bit for bit."""
    (pair,) = _pairs(builds, "lean", "serial", 80.0)
    _all_fast(pair)
    (stock,) = _pairs(builds, "pythonfmu", "serial", 80.0, PAIR_COUNTERS="0")
    assert pair["trace"] == stock["trace"]
    # with the kernels as plain Python there is no compiled step: the binding's direct path calls the Python one
    (plain,) = _pairs(builds, "lean", "serial", 80.0, PMSM_EV_JIT="0")
    assert plain["fast"] == plain["calls"] and plain["compiled"] == {"ctrl": 0, "plant": 0}
    assert plain["trace"] == pair["trace"]


def test_a_recorder_reading_every_output_keeps_the_steps_compiled(builds):
    """A master that records every Real output of both FMUs at each step (as a row is recorded): the controller's
    are all in its buffers (every call compiled); the plant's stored energies W_magnetic and E_kinetic are computed
    by its Python from the plant's buffers (``compiled_live``), so that get is direct but not compiled, and the
    buffers stay the compiled step's: no pull, no refill (``pmsm_fmu_pulls`` 0). pythonfmu's numbers, bit for bit."""
    (pair,) = _pairs(builds, "lean", "serial", 80.0, PAIR_READ_ALL="1")
    (stock,) = _pairs(builds, "pythonfmu", "serial", 80.0, PAIR_READ_ALL="1", PAIR_COUNTERS="0")
    assert pair["trace"] == stock["trace"]
    assert pair["calls"] == {"ctrl": 4 * STEPS, "plant": 4 * STEPS}
    assert pair["fast"] == pair["calls"]
    assert pair["compiled"] == {"ctrl": 4 * STEPS, "plant": 3 * STEPS}
    assert pair["pulls"] == {"ctrl": 0, "plant": 0}


def test_a_step_the_compiled_code_declines_is_pythons(builds):
    """A plant voltage at the DC link's limit (v_dc = 60 V: the controller asks for more from the first steps on):
    the limit is CPython's math.hypot's to the last bit, so the compiled step declines those steps and the binding
    runs the slave's Python step on the same values; the others stay compiled. The numbers are pythonfmu's, bit
    for bit."""
    (pair,) = _pairs(builds, "lean", "serial", 80.0, PAIR_V_DC="60")
    (stock,) = _pairs(builds, "pythonfmu", "serial", 80.0, PAIR_V_DC="60", PAIR_COUNTERS="0")
    assert pair["trace"] == stock["trace"]
    assert pair["fast"] == pair["calls"]
    assert pair["compiled"]["ctrl"] == pair["calls"]["ctrl"]
    assert 0 < pair["compiled"]["plant"] < pair["calls"]["plant"]  # some steps Python's, the rest compiled


def test_a_first_step_that_rebuilds_the_unit_is_pythons_and_the_rest_compiled(builds):
    """The controller's dt is 0 (the first step's size) and the first step is 5e-5 s, not the 1e-4 s its unit was
    built with: that step rebuilds the unit (new vectors) in Python, declined by the compiled step; the binding
    takes the new vectors at the next call, and every later call is compiled. pythonfmu's numbers, bit for bit."""
    (pair,) = _pairs(builds, "lean", "serial", 80.0, PAIR_H="5e-5")
    (stock,) = _pairs(builds, "pythonfmu", "serial", 80.0, PAIR_H="5e-5", PAIR_COUNTERS="0")
    assert pair["trace"] == stock["trace"]
    assert pair["fast"] == pair["calls"]
    # the first fmi2DoStep Python's, and the fmi2GetReal after it (the slave's attributes hold the values then)
    assert pair["compiled"] == {"ctrl": pair["calls"]["ctrl"] - 2, "plant": pair["calls"]["plant"]}


def test_a_unit_with_a_step_of_its_own_gets_no_other_compiled_step(tmp_path):
    """The benchmark's pass-through units subclass the plant and the controller with a ``do_step`` that computes
    nothing: their compiled step is their own (nothing computed, every call compiled), never the parent's physics;
    the outputs keep their initial values."""
    names = ("PassThroughPlant", "PassThroughFoc")
    subprocess.run([sys.executable, "-c", "import sys; from pmsm_ev_fmus import build; "
                    "[build.build_fmu(n, sys.argv[1]) for n in sys.argv[2:]]", str(tmp_path), *names],
                   env=_env("lean", tmp_path), check=True, capture_output=True, text=True, timeout=600)
    done = subprocess.run([sys.executable, "-c", _PAIRS_SCRIPT, str(tmp_path / "PassThroughPlant.fmu"),
                           str(tmp_path / "PassThroughFoc.fmu"), "serial", str(STEPS), "80.0"],
                          env=_env("lean", tmp_path), capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    (pair,) = json.loads(done.stdout.strip().splitlines()[-1])
    _all_fast(pair)
    assert all(row == pair["trace"][0] for row in pair["trace"])


def test_several_instances_in_one_process_each_count_their_own(builds):
    """Two plants and two controllers stepping interleaved, call by call: each pair's outputs equal those of a
    process with that pair alone, bit for bit; each instance's counter is its own calls."""
    alone = [_pairs(builds, "lean", "serial", ref)[0] for ref in (80.0, -60.0)]
    together = _pairs(builds, "lean", "interleaved", 80.0, -60.0)
    for one, other in zip(alone, together):
        _all_fast(other)
        assert other["trace"] == one["trace"]
    assert together[0]["trace"] != together[1]["trace"]  # two different runs, not one seen twice


def test_a_threaded_host(builds):
    """Two threads of the host, each stepping its own pair of instances: the results of the serial run, bit for
    bit, and every call on the fast path."""
    serial = _pairs(builds, "lean", "serial", 80.0, -60.0)
    threaded = _pairs(builds, "lean", "threads", 80.0, -60.0)
    for one, other in zip(serial, threaded):
        _all_fast(other)
        assert other["trace"] == one["trace"]


def test_another_pythonfmu_is_refused_by_the_build(tmp_path, monkeypatch, capsys):
    """pythonfmu outside the versions the binding and the slaves are checked against: one line, no FMU."""
    from pmsm_ev_fmus import build

    assert build.WRAPPER_CHECKED == ("0.6.5", "0.7.0")
    build.check_pythonfmu("0.7.0")
    build.check_pythonfmu("0.6.5")
    monkeypatch.setattr(build, "_pythonfmu_version", lambda: "0.7.1")
    assert build.main(["--out", str(tmp_path), "RouteProfile"]) == 1
    err = capsys.readouterr().err
    assert err == ("error: RouteProfile: pythonfmu 0.7.1 is not a version the FMUs are checked against (0.6.5 to "
                   "0.7.0: the lean binding and the slaves rely on its wrapper); install one, e.g. "
                   "pip install 'pythonfmu==0.7.0'\n")
    assert not list(tmp_path.iterdir())
    with pytest.raises(build.BuildError, match=r"^pythonfmu 0\.6\.4 is not a version"):
        build.check_pythonfmu("0.6.4")


def test_the_constants_the_binding_shares_with_the_slaves_have_one_home(tmp_path):
    """COMPILED_BUFFER, LIVE_SLOT and the time tolerance are slave_support's (BINDING_CONSTANTS): the C source
    defines none of them and does not compile without the build's -D definitions of them."""
    from pmsm_ev_fmus import build
    from pmsm_ev_fmus.slave_support import BINDING_CONSTANTS, COMPILED_BUFFER, LIVE_SLOT

    source = build.LEAN_SOURCE.read_text()
    for name in BINDING_CONSTANTS:
        assert not re.search(rf"^\s*#\s*define\s+{name}\b", source, flags=re.M), name
    assert BINDING_CONSTANTS["COMPILED_BUFFER"] == f"{COMPILED_BUFFER}L" and BINDING_CONSTANTS["LIVE_SLOT"] == \
        f"({LIVE_SLOT}L)"
    bare = subprocess.run([os.environ.get("CC", "cc"), "-fsyntax-only", f"-I{sysconfig.get_paths()['include']}",
                           str(build.LEAN_SOURCE)], capture_output=True, text=True)
    assert bare.returncode != 0 and "BINDING_CONSTANTS" in bare.stderr
    library, why = build.lean_library()
    assert library is not None and library.is_file(), why
