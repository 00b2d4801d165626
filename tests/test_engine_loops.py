"""The engine's two stepping loops give the same results.csv, byte for byte, on every shipped scenario
and on the toys: the compiled one (machine code, the default) and the plain one (ordinary Python, for a
debugger). A system the compiled loop cannot step runs the plain one with a line saying why, and is
refused, with the reason, when the compiled loop is asked for by name; a missing numba falls back the
same way; any other failure while the compiled loop is set up is an error naming it."""

from __future__ import annotations

import sys

import pytest

from orchestrator_support import project_fmus, toy_system
from pmsm_cosim import engine
from pmsm_cosim.app.drive import PACKAGED_SCENARIOS, load_system
from pmsm_cosim.engine import native
from pmsm_cosim.engine.errors import CosimError
from pmsm_cosim.engine.master import LOOP_ENV, Master

#: simulated time per scenario [s]: enough for every component and signal to act a few times
SECONDS = 0.3
LINEAR = '[signals.s]\ninterpolation = "linear"\ntable = [[0, 0], [0.004, 2], [0.007, -1]]\ndrives = "snk.w"\n'


def _run(spec_source, out, loop, stop_time=None, note=None):
    spec = load_system(spec_source)
    if stop_time is not None:
        spec.stop_time = stop_time
    m = Master(spec, loop=loop, note=note)
    metrics = m.run(out, catch_sigint=False)
    return metrics, (out / "results.csv").read_bytes()


def test_every_shipped_scenario_is_in_the_comparison():
    assert len(PACKAGED_SCENARIOS) == 31  # with the thermal network's two (wltc3b-thermal, us06x5-thermal)


@pytest.mark.parametrize("scenario", PACKAGED_SCENARIOS)
def test_the_two_loops_give_the_same_results_bit_for_bit(tmp_path, scenario):
    project_fmus()
    runs = {loop: _run(scenario, tmp_path / loop, loop, SECONDS) for loop in ("compiled", "plain")}
    for loop, (metrics, _) in runs.items():
        assert (metrics["status"], metrics["loop"]) == ("completed", loop)
        assert metrics["macro_steps"] == round(SECONDS / metrics["step_size"])
        assert "loop_note" not in metrics
    plain = runs["plain"][1]
    assert plain.count(b"\n") > 2
    assert runs["compiled"][1] == plain


def test_compiled_loop_through_a_cycle_s_ramps_and_the_row_boundaries(tmp_path):
    """The WLTC's speed reference (a linear table, a breakpoint every 0.1 s, merged into the controller's
    call) is evaluated inside the compiled loop: over 12-13 s it ramps up from the first stop, with its
    segments cut by the rows (every 500 steps) and the chunks."""
    project_fmus()
    out = {}
    for loop in ("compiled", "plain"):
        spec = load_system("wltc3b-if")
        spec.stop_time = 13.0
        m = Master(spec, loop=loop)
        metrics = m.run(tmp_path / loop, catch_sigint=False)
        assert (metrics["status"], metrics["loop"]) == ("completed", loop)
        out[loop] = (tmp_path / loop / "results.csv").read_bytes()
    assert out["compiled"] == out["plain"]
    rows = out["compiled"].decode().splitlines()
    header = rows[0].split(",")
    omega_ref = [float(r.split(",")[header.index("omega_ref")]) for r in rows[1:]]
    assert omega_ref[0] == 0.0 and max(omega_ref) > 10.0  # the car moved off within the run


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("multiples", [(1, 1), (2, 3)])
def test_the_loops_are_equal_on_the_toys(tmp_path, algorithm, multiples):
    path = toy_system(tmp_path, algorithm=algorithm, src_multiple=multiples[0], snk_multiple=multiples[1],
                      stop_time=0.012, signals=LINEAR)
    (m_comp, comp), (_, plain) = (_run(path, tmp_path / loop, loop) for loop in ("compiled", "plain"))
    assert m_comp["loop"] == "compiled"
    assert comp == plain


def test_the_loops_report_a_failed_step_alike(tmp_path):
    path = toy_system(tmp_path, snk_start="raise_at = 4")
    m_plain, plain = _run(path, tmp_path / "plain", "plain")
    assert m_plain["status"].startswith("failed: snk: fmi2DoStep failed at t = 0.003 s")
    m, rows = _run(path, tmp_path / "compiled", "compiled")
    assert (m["status"], m["macro_steps"], rows) == (m_plain["status"], 3, plain)


def test_a_sum_that_overflows_is_not_a_value_that_is_not_finite(tmp_path):
    """src.y = 1e308 reaches snk.u and snk.w: their sum overflows, each is finite, the run goes on; at the
    next step y = 2e308 = inf, which the loop refuses, naming the connection."""
    path = toy_system(tmp_path, connections=('"src.y -> snk.u"', '"src.y -> snk.w"'),
                      record={"time": '"time"', "last_u": '"snk.last_u"'})
    runs = {}
    for loop in ("compiled", "plain"):
        spec = load_system(path)
        spec.set_start("src.slope=1e308")
        runs[loop] = Master(spec, loop=loop).run(tmp_path / loop, catch_sigint=False)
        assert runs[loop]["status"] == "failed: src.y is not finite (inf) at t = 0.001 s, before it reached snk.u"
        assert runs[loop]["macro_steps"] == 1
    assert (tmp_path / "compiled" / "results.csv").read_bytes() == (tmp_path / "plain" / "results.csv").read_bytes()


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_a_multi_rate_component_with_a_queued_signal_input_runs_compiled(tmp_path, algorithm):
    """A multi-rate component with a signal input that is not merged into its connections' call (a
    piecewise-constant table, queued until that component's step) runs on the compiled loop: the steps from
    the signal's change to that component's step are the plain loop's, the rest machine code; the same rows."""
    sig = ('[signals.s]\ninterpolation = "previous"\ntable = [[0, 0], [0.004, 2], [0.0065, -3], [0.011, 5]]\n'
           'drives = "snk.w"\n')
    record = {"time": '"time"', "last_u": '"snk.last_u"', "last_w": '"snk.last_w"', "snk_calls": '"snk.calls"',
              "src_calls": '"src.calls"'}
    path = toy_system(tmp_path, snk_multiple=3, stop_time=0.015, signals=sig, algorithm=algorithm, record=record)
    notes = []
    m_comp, comp = _run(path, tmp_path / "compiled", None, note=notes.append)
    m_plain, plain = _run(path, tmp_path / "plain", "plain")
    assert (m_comp["loop"], m_comp["status"], notes) == ("compiled", "completed", [])
    assert comp == plain
    rows = comp.decode().splitlines()
    last_w = [float(r.split(",")[2]) for r in rows[1:]]
    assert sorted(set(last_w)) == [-3.0, 0.0, 2.0, 5.0]  # every value of the table reached the sink


def test_a_system_the_compiled_loop_cannot_step(tmp_path, monkeypatch):
    """A system the compiled loop cannot step runs the plain loop, with one line saying which loop and why
    (also in metrics.json); asked for by name, the compiled loop is refused with the reason, before anything
    is written. (String connections are what it cannot step: tests/test_engine_c_fmus.py; here the same
    reason is given by ``native.unsupported``.)"""
    path = toy_system(tmp_path, stop_time=0.005)
    monkeypatch.setattr(native, "unsupported", lambda master: "snk has String connections (copied between the calls)")
    notes = []
    m_default, default = _run(path, tmp_path / "default", None, note=notes.append)
    assert m_default["loop"] == "plain"
    assert notes == ["the plain loop steps toy: snk has String connections (copied between the calls)"]
    assert m_default["loop_note"] == notes[0]
    assert default == _run(path, tmp_path / "plain", "plain")[1]
    with pytest.raises(CosimError, match=r"^the compiled loop cannot step toy: snk has String connections "
                                         r"\(copied between the calls\)$"):
        Master(load_system(path), loop="compiled").run(tmp_path / "named", catch_sigint=False)
    assert not (tmp_path / "named").exists()  # refused before anything was written


def test_the_default_note_is_one_line_on_stderr(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(native, "unsupported", lambda master: "a reason")
    metrics = Master(load_system(toy_system(tmp_path, stop_time=0.003))).run(tmp_path / "out", catch_sigint=False)
    assert metrics["loop"] == "plain"
    assert capsys.readouterr().err == "note: the plain loop steps toy: a reason\n"


def _without(monkeypatch, module: str) -> None:
    """``import module`` fails (ModuleNotFoundError naming it) and the compiled loop's module is imported again."""
    monkeypatch.setitem(sys.modules, module, None)
    monkeypatch.delitem(sys.modules, "pmsm_cosim.engine.native")
    monkeypatch.delattr(engine, "native")


def test_without_numba_the_plain_loop_runs_with_a_line_saying_so(tmp_path, monkeypatch):
    """Only numba missing (its own ImportError) falls back; asked for by name, it is an error."""
    path = toy_system(tmp_path, stop_time=0.005)
    _without(monkeypatch, "numba")
    notes = []
    metrics, rows = _run(path, tmp_path / "default", None, note=notes.append)
    assert (metrics["status"], metrics["loop"]) == ("completed", "plain")
    assert len(notes) == 1 and notes[0].startswith("the plain loop steps toy: numba is not installed (")
    assert rows == _run(path, tmp_path / "plain", "plain")[1]
    with pytest.raises(CosimError, match=r"^the compiled loop cannot step toy: numba is not installed"):
        _run(path, tmp_path / "named", "compiled")


def test_an_import_error_inside_numba_is_not_a_missing_numba(tmp_path, monkeypatch):
    _without(monkeypatch, "numba.extending")
    notes = []
    with pytest.raises(CosimError, match=r"^setting up the compiled loop of toy failed: ModuleNotFoundError: "
                                         r"import of numba\.extending halted") as exc:
        _run(toy_system(tmp_path, stop_time=0.003), tmp_path / "out", None, note=notes.append)
    assert isinstance(exc.value.__cause__, ImportError) and notes == []


@pytest.mark.parametrize("where", ["compile", "init"])
def test_a_failure_while_setting_up_the_compiled_loop_is_reported_as_what_it_is(tmp_path, monkeypatch, where):
    """Not "numba is not available", not a silent fallback: a CosimError naming the system and the real
    cause, chained, before anything is written; the FMUs are freed."""
    path = toy_system(tmp_path, stop_time=0.005, name="setup")
    cause = RuntimeError("LLVM ERROR: Cannot select: 0x55d0")

    def fail(*args, **kwargs):
        raise cause

    monkeypatch.setattr(native.NativeSteps, "compile" if where == "compile" else "__init__", fail)
    notes = []
    m = Master(load_system(path), note=notes.append)
    with pytest.raises(CosimError) as exc:
        m.run(tmp_path / "out", catch_sigint=False)
    assert str(exc.value) == ("setting up the compiled loop of setup failed: RuntimeError: LLVM ERROR: "
                              "Cannot select: 0x55d0")
    assert exc.value.__cause__ is cause
    assert notes == [] and not (tmp_path / "out").exists()
    assert all(inst.handle is None for inst in m.instances.values())


def test_loop_from_the_environment(tmp_path, monkeypatch):
    spec = load_system(toy_system(tmp_path))
    monkeypatch.setenv(LOOP_ENV, "plain")
    m = Master(spec)
    assert m.loop == "plain"
    m.close()
    assert Master(spec, loop="compiled").loop == "compiled"  # the argument wins
    monkeypatch.delenv(LOOP_ENV)
    assert Master(spec).loop == "compiled"  # the default (where numba can run it: after the set-up)
    for gone in ("generated", "unrolled"):
        monkeypatch.setenv(LOOP_ENV, gone)
        with pytest.raises(CosimError, match=rf"^PMSM_COSIM_LOOP: '{gone}' is not a stepping loop; choose one of "
                                             r"compiled, plain$"):
            Master(spec)
    with pytest.raises(CosimError, match=r"^loop: 'fast' is not a stepping loop"):
        Master(spec, loop="fast")
