"""The master's own mechanics, with toy FMUs (tests/toy_fmus): coupling order, multi-rate,
scenario signals, start values, load-time checks, recording, failure and interruption."""

from __future__ import annotations

import _ctypes
import ctypes
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from orchestrator_support import toy_system
from pmsm_cosim.app.drive import load_system
from pmsm_cosim.engine.errors import CosimError
from pmsm_cosim.engine.master import Master
from pmsm_cosim.engine.recording import read_results
from pmsm_ev.scenarios import Profile

STEP = 1e-3


def run(path, out, **kw):
    m = Master(load_system(path))
    return m.run(out, catch_sigint=False, **kw), read_results(out)


def rows_of(out):
    return (out / "results.csv").read_text().splitlines()


# --- coupling ---------------------------------------------------------------------------

def test_gauss_seidel_reads_the_freshest_outputs(tmp_path):
    # order src, snk: at step n src advances first (y = n + 1), snk then reads it
    m, r = run(toy_system(tmp_path, order=("src", "snk")), tmp_path / "out")
    assert m["status"] == "completed" and m["macro_steps"] == 10
    assert list(r["y"]) == [float(k) for k in range(11)]
    assert list(r["last_u"]) == list(r["y"])  # row n: snk saw y after src's step n-1


def test_gauss_seidel_order_matters(tmp_path):
    # order snk, src: snk reads y before src's step -> one step behind
    _, r = run(toy_system(tmp_path, order=("snk", "src")), tmp_path / "out")
    assert list(r["last_u"][1:]) == [float(k) for k in range(10)]


@pytest.mark.parametrize("order", [("src", "snk"), ("snk", "src")])
def test_jacobi_reads_the_values_at_t_k(tmp_path, order):
    _, r = run(toy_system(tmp_path, order=order, algorithm="jacobi"), tmp_path / "out")
    assert list(r["last_u"][1:]) == [float(k) for k in range(10)]  # independent of the order


def test_communication_points_are_step_counter_times_step(tmp_path):
    step = 1e-4
    _, r = run(toy_system(tmp_path, step=step, stop_time=0.003), tmp_path / "out")
    assert list(r["time"]) == [k * step for k in range(31)]
    assert list(r["last_t"][1:]) == [k * step for k in range(30)]  # never an accumulated sum
    assert set(r["last_h"][1:]) == {step}


# --- multi-rate -----------------------------------------------------------------------------

@pytest.mark.parametrize("src_k, snk_k", [(1, 3), (2, 3), (4, 1)])
def test_multi_rate_step_counts(tmp_path, src_k, snk_k):
    stop = 0.024
    m, r = run(toy_system(tmp_path, stop_time=stop, src_multiple=src_k, snk_multiple=snk_k,
                          record={"time": '"time"', "src_calls": '"src.calls"', "src_n": '"src.n_steps"',
                                  "snk_calls": '"snk.calls"', "snk_h": '"snk.last_h"', "u_sets": '"snk.u_sets"',
                                  "last_t": '"snk.last_t"'}),
               tmp_path / "out")
    assert m["macro_steps"] == 24
    assert r["src_calls"][-1] == round(stop / (src_k * STEP))
    assert r["src_n"][-1] == round(stop / (src_k * STEP))  # an Integer output, recorded
    assert r["snk_calls"][-1] == round(stop / (snk_k * STEP))
    assert r["snk_h"][-1] == snk_k * STEP
    # the slow component's inputs are set only when it steps (y changes at each src step)
    assert r["u_sets"][-1] <= r["snk_calls"][-1]
    # and it is stepped at the multiples of its period
    assert all(round(t / STEP) % snk_k == 0 for t in r["last_t"][1:])


def test_multi_rate_stop_time_must_fit_the_slow_step(tmp_path):
    with pytest.raises(CosimError, match="not a multiple of snk's step"):
        Master(load_system(toy_system(tmp_path, stop_time=0.010, snk_multiple=3)))


# --- scenario signals ---------------------------------------------------------------------------

SIGNALS = '''
[signals.angle]
unit = "deg"
interpolation = "previous"
table = [[0, 0], [0.0035, 5], [0.007, 5], [0.008, 10]]
drives = "snk.u"

[signals.ramp]
interpolation = "linear"
table = [[0.001, 0.0], [0.006, 1.3]]
drives = ["snk.w"]
'''


def test_signals_are_profile_values_at_k_times_step_and_set_only_on_change(tmp_path):
    path = toy_system(tmp_path, connections=(), signals=SIGNALS, stop_time=0.01,
                      record={"time": '"time"', "angle_deg": '{ from = "signals.angle", unit = "deg" }',
                              "angle": '"signals.angle"', "ramp": '"signals.ramp"',
                              "last_u": '"snk.last_u"', "last_w": '"snk.last_w"', "u_sets": '"snk.u_sets"'})
    m, r = run(path, tmp_path / "out")
    assert m["status"] == "completed"
    deg = Profile((0.0, 0.0035, 0.007, 0.008), (0.0, 5.0, 5.0, 10.0), "previous")
    ramp = Profile((0.001, 0.006), (0.0, 1.3), "linear")
    for n in range(11):
        t = n * STEP
        assert r["angle"][n] == math.radians(deg(t))  # bit-identical
        assert r["angle_deg"][n] == math.degrees(math.radians(deg(t)))
        assert r["ramp"][n] == ramp(t)
        if n:
            assert r["last_u"][n] == math.radians(deg((n - 1) * STEP))
            assert r["last_w"][n] == ramp((n - 1) * STEP)
    # u set at initialization (0), at t = 0.004 (5 deg) and t = 0.008 (10 deg) only
    assert r["u_sets"][-1] == 3


RAMP_INTO_W = """
[signals.ramp]
interpolation = "linear"
table = [[0.001, 0.0], [0.006, 1.3], [0.0075, -0.4]]
drives = "snk.w"
"""


@pytest.mark.parametrize("loop", ["compiled", "plain"])
@pytest.mark.parametrize("algorithm, snk_multiple", [("gauss-seidel", 1), ("jacobi", 1), ("gauss-seidel", 3)])
def test_a_ramp_goes_in_the_set_of_the_connections(tmp_path, loop, algorithm, snk_multiple):
    """A linear table's input into a component with Real connections is set in their fmi2SetReal (one
    call, its value after theirs): the component sees the table's value at each of its steps, bit for
    bit, as when the input is set on its own (the input recorded: it is, so that the row shows it)."""
    ramp = Profile((0.001, 0.006, 0.0075), (0.0, 1.3, -0.4), "linear")
    record = {"time": '"time"', "ramp": '"signals.ramp"', "last_w": '"snk.last_w"', "last_u": '"snk.last_u"',
              "y": '"src.y"', "calls": '"snk.calls"'}
    runs = {}
    for merged in (True, False):
        rec = dict(record) if merged else {**record, "w": '"snk.w"'}
        path = toy_system(tmp_path, signals=RAMP_INTO_W, stop_time=0.012, algorithm=algorithm,
                          snk_multiple=snk_multiple, record=rec, name=f"ramp{int(merged)}")
        # (a multi-rate component whose signal input is queued: the compiled loop hands the steps up to its
        # step to the plain one)
        m = Master(load_system(path), loop=loop)
        out = tmp_path / f"out{int(merged)}"
        assert m.run(out, catch_sigint=False)["status"] == "completed"
        assert m.loop == loop
        snk = m.steppers[1]
        assert [tr.signals for tr in snk.transfers] == ([["snk.w"]] if merged else [[]])
        runs[merged] = read_results(out)
    r = runs[True]
    assert list(r["ramp"]) == [ramp(n * STEP) for n in range(13)]
    for n in range(1, 13):  # the value at the component's last step, n0 = the last multiple below n
        n0 = (n - 1) // snk_multiple * snk_multiple
        assert r["last_w"][n] == ramp(n0 * STEP)
    for col in record:
        assert list(r[col]) == list(runs[False][col])


def test_signal_from_csv(tmp_path):
    csv = tmp_path / "route.csv"
    csv.write_text("time,angle_deg\n0,0\n0.002,3\n0.005,-4\n")
    sig = f'[signals.angle]\nunit = "deg"\ncsv = "{csv.name}"\ndrives = "snk.u"\n'
    path = toy_system(tmp_path, connections=(), signals=sig, stop_time=0.008,
                      record={"time": '"time"', "angle": '"signals.angle"'})
    _, r = run(path, tmp_path / "out")
    assert list(r["angle"]) == [math.radians(d) for d in (0, 0, 3, 3, 3, -4, -4, -4, -4)]


# --- start values ------------------------------------------------------------------------------

ECHO = {"time": '"time"', "gain": '"snk.echo_gain"', "count": '"snk.echo_count"',
        "flag": '"snk.echo_flag"', "label_len": '"snk.echo_label_len"'}


def test_start_values_by_type_from_the_system_file(tmp_path):
    path = toy_system(tmp_path, snk_start='gain = 2.5, count = 3, flag = true, label = "hello"', record=ECHO)
    _, r = run(path, tmp_path / "out")
    assert (r["gain"][0], r["count"][0], r["flag"][0], r["label_len"][0]) == (2.5, 3.0, 1.0, 5.0)


def test_start_values_from_strings(tmp_path):
    spec = load_system(toy_system(tmp_path, record=ECHO))
    for a in ("snk.gain=1e-3", "snk.count=4", "snk.flag=true", "snk.label=abcdefg"):
        spec.set_start(a)
    Master(spec).run(tmp_path / "out", catch_sigint=False)
    r = read_results(tmp_path / "out")
    assert (r["gain"][0], r["count"][0], r["flag"][0], r["label_len"][0]) == (1e-3, 4.0, 1.0, 7.0)


@pytest.mark.parametrize("assignment, message", [
    ("snk.count=1.5", "not a valid Integer"),
    ("snk.flag=maybe", "not a valid Boolean"),
    ("snk.gain=abc", "not a valid Real"),
    ("snk.calls=1", "cannot be set"),
    ("snk.gian=1", "did you mean: gain"),
    ("snkk.gain=1", "did you mean: snk"),
])
def test_bad_start_values(tmp_path, assignment, message):
    spec = load_system(toy_system(tmp_path))
    with pytest.raises(CosimError, match=message):
        spec.set_start(assignment)
        m = Master(spec)
        m.run(tmp_path / "out", catch_sigint=False)


# --- load-time checks ----------------------------------------------------------------------------

@pytest.mark.parametrize("connection, message", [
    ('"src.yy -> snk.u"', r"has no variable 'yy' \(did you mean: y"),
    ('"src.y -> snk.uu"', r"has no variable 'uu' \(did you mean: u"),
    ('"srcc.y -> snk.u"', r"unknown instance 'srcc' \(did you mean: src"),
    ('"snk.u -> src.slope"', "is a input, not an output|not an output"),
    ('"src.y -> snk.last_u"', "not an input"),
    ('"src.n_steps -> snk.u"', "is an Integer, snk.u is a Real: a connection joins variables of the same type"),
])
def test_connections_are_checked_at_load(tmp_path, connection, message):
    with pytest.raises(CosimError, match=message) as exc:
        Master(load_system(toy_system(tmp_path, connections=(connection,))))
    assert "\n" not in str(exc.value)


def test_unknown_recorded_variable(tmp_path):
    with pytest.raises(CosimError, match=r"no variable 'clls' \(did you mean: calls"):
        Master(load_system(toy_system(tmp_path, record={"time": '"time"', "c": '"src.clls"'})))


def test_an_input_driven_twice_is_refused(tmp_path):
    sig = '[signals.s]\ntable = [[0, 1]]\ndrives = "snk.u"\n'
    with pytest.raises(CosimError, match="driven twice"):
        load_system(toy_system(tmp_path, signals=sig))


def test_unconnected_inputs_are_reported(tmp_path):
    m = Master(load_system(toy_system(tmp_path)))
    assert any("snk.w" in w for w in m.warnings)
    m.close()


# --- recording --------------------------------------------------------------------------------

def test_rows_every_output_interval_plus_the_stop_time(tmp_path):
    m, r = run(toy_system(tmp_path, stop_time=0.01, output_interval=0.003), tmp_path / "out")
    assert list(r["time"]) == [0.0, 3 * STEP, 6 * STEP, 9 * STEP, 10 * STEP]
    assert m["rows"] == 5
    assert list(r["y"]) == [0.0, 3.0, 6.0, 9.0, 10.0]


def test_output_interval_must_be_a_multiple_of_the_step(tmp_path):
    with pytest.raises(CosimError, match="output interval"):
        Master(load_system(toy_system(tmp_path, output_interval=0.0015)))


def test_metrics_json_bookkeeping(tmp_path):
    run(toy_system(tmp_path), tmp_path / "out")
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    for key in ("status", "wall_time_s", "macro_steps", "us_per_step", "algorithm", "step_size",
                "stop_time", "output_interval", "settings"):
        assert key in m
    assert m["status"] == "completed" and m["macro_steps"] == 10
    assert [c["name"] for c in m["settings"]["components"]] == ["src", "snk"]


def test_a_failed_step_keeps_the_rows_and_says_why(tmp_path):
    m, r = run(toy_system(tmp_path, snk_start="fail_at = 4"), tmp_path / "out")
    assert m["status"].startswith("failed: snk: fmi2DoStep failed at t = 0.003 s")
    assert "fails on purpose" in m["status"]
    assert m["macro_steps"] == 3
    assert list(r["time"]) == [0.0, STEP, 2 * STEP, 3 * STEP]
    assert json.loads((tmp_path / "out" / "metrics.json").read_text())["status"] == m["status"]


class StopAfter:
    """A progress 'bar' that asks the master to stop, as Ctrl-C does."""

    def __init__(self, calls):
        self.calls, self.master = calls, None

    def update(self, t):
        self.calls -= 1
        if self.calls == 0:
            self.master.request_stop()

    def close(self):
        pass


def test_interruption_keeps_the_rows_and_writes_metrics(tmp_path):
    master = Master(load_system(toy_system(tmp_path, stop_time=0.05)))
    stopper = StopAfter(3)
    stopper.master = master
    m = master.run(tmp_path / "out", progress=stopper, catch_sigint=False)
    assert m["status"] == "interrupted"
    r = read_results(tmp_path / "out")
    # stop asked at the 3rd check (t = 2 steps): that chunk ends, its row is written, stop
    assert m["macro_steps"] == 3
    assert list(r["time"]) == [0.0, STEP, 2 * STEP, 3 * STEP] and m["rows"] == 4
    assert json.loads((tmp_path / "out" / "metrics.json").read_text())["status"] == "interrupted"


def test_signal_into_a_multi_rate_component_is_set_when_it_steps(tmp_path):
    sig = '[signals.s]\ntable = [[0, 0], [0.0015, 1], [0.0025, 2], [0.0075, 3]]\ndrives = "snk.u"\n'
    path = toy_system(tmp_path, connections=(), signals=sig, snk_multiple=3, stop_time=0.012,
                      record={"time": '"time"', "s": '"signals.s"', "last_u": '"snk.last_u"',
                              "u_sets": '"snk.u_sets"', "calls": '"snk.calls"'})
    _, r = run(path, tmp_path / "out")
    assert list(r["s"]) == [0, 0, 1, 2, 2, 2, 2, 2, 3, 3, 3, 3, 3]
    # snk steps at n = 0, 3, 6, 9 with the value at that step
    assert list(r["last_u"]) == [0, 0, 0, 0, 2, 2, 2, 2, 2, 2, 3, 3, 3]
    assert r["calls"][-1] == 4
    assert r["u_sets"][-1] == 3  # at initialization, at n = 3 (1 then 2 queued: one set), at n = 9


def test_read_results_of_some_columns_parses_only_those(tmp_path):
    """``read_results(columns=...)``: the columns asked for that the file has, in the file's order, the same
    doubles as a whole read; a cut last line left out as in a whole read; none asked for that it has: {}."""
    path = tmp_path / "results.csv"
    path.write_text("time,a,b,c\n0.0,1.5,2.5,3.5\n0.1,1.25,2.25,3.25\n0.2,1.1", encoding="ascii")
    whole = read_results(path)
    some = read_results(path, columns=("c", "time", "missing"))
    assert list(some) == ["time", "c"]
    for name in some:
        assert some[name].tolist() == whole[name].tolist() and len(some[name]) == 2
    assert read_results(tmp_path, columns=("x",)) == {}


# --- leaving the process ------------------------------------------------------------------------
# pythonfmu's library keeps its interpreter guard in a static shared_ptr (the symbol below) that exit()'s C++
# destructors free and its ELF destructor then resets once more: a write into freed memory at exit (docs/errors.md,
# "Crash at exit"). The project's FMUs reset it themselves; for an FMU of another origin (these toys are pythonfmu's
# alone) the master does, from Python's atexit, while the pointer is alive.
GUARD_SYMBOL = "_ZN12_GLOBAL__N_17pyStateE"  # (anonymous namespace)::pyState of pythonfmu's PySlaveInstance.cpp


def guard_address(library: str) -> int:
    """Where the loaded ``library`` keeps its guard: its load address (/proc/self/maps, the mapping at offset 0)
    plus the symbol's (nm; its symbol table is not stripped)."""
    nm = subprocess.run(["nm", library], capture_output=True, text=True, check=True).stdout
    offset = next(int(line.split()[0], 16) for line in nm.splitlines() if line.endswith(" " + GUARD_SYMBOL))
    maps = Path("/proc/self/maps").read_text().splitlines()
    base = next(int(line.split("-")[0], 16) for line in maps
                if line.endswith(library) and line.split()[2] == "00000000")
    return base + offset


@pytest.mark.skipif(not sys.platform.startswith("linux") or shutil.which("nm") is None,
                    reason="the guard is read through Linux's /proc and nm")
def test_the_interpreter_guard_of_a_foreign_pythonfmu_fmu_is_reset_before_exit():
    from orchestrator_support import toy_fmus
    from pmsm_cosim.engine import fmu as engine_fmu

    instance = engine_fmu.FmuInstance("src", toy_fmus()["ToySource"])
    instance.instantiate(0.0, 1.0, {})
    library = instance.fmu.dll._name
    held = ctypes.CDLL(library)  # the library stays loaded after close (the hazard: loaded at exit), as it does
    try:  # whenever another library has bound to its unique symbols
        guard = ctypes.c_void_p.from_address(guard_address(library))
        assert guard.value  # fmi2Instantiate made it
        instance.close()
        assert guard.value  # still held by the library's static after the instance is freed: exit's hazard
        assert library in engine_fmu._GUARDED_LIBRARIES
        engine_fmu.reset_guards()  # what Python's atexit runs
        assert guard.value is None
        engine_fmu.reset_guards()  # a second reset (the project's FMUs do theirs too) finds nothing to do
        assert guard.value is None
    finally:
        instance.close()
        _ctypes.dlclose(held._handle)  # unloaded now, if nothing else holds it: its destructors run in order
