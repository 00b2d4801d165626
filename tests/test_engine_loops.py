"""The engine's three stepping loops give the same results.csv, byte for byte, on every shipped
scenario and on the toys: the compiled one (machine code, the default where numba is), the generated
one and the plain one (ordinary Python, for a debugger); the generated one's tracebacks show its
source lines; a loop that cannot step a system is refused when asked for by name, and replaced by the
generated one otherwise."""

from __future__ import annotations

import linecache
import traceback

import pytest

from orchestrator_support import project_fmus, toy_system
from pmsm_cosim.app.drive import PACKAGED_SCENARIOS, load_system
from pmsm_cosim.engine.errors import CosimError
from pmsm_cosim.engine.master import _NEVER, LOOP_ENV, Master, _StepFailed

#: simulated time per scenario [s]: enough for every component and signal to act a few times
SECONDS = 0.3
LINEAR = '[signals.s]\ninterpolation = "linear"\ntable = [[0, 0], [0.004, 2], [0.007, -1]]\ndrives = "snk.w"\n'


def _run(spec_source, out, loop, stop_time=None):
    spec = load_system(spec_source)
    if stop_time is not None:
        spec.stop_time = stop_time
    m = Master(spec, loop=loop)
    metrics = m.run(out, catch_sigint=False)
    return metrics, (out / "results.csv").read_bytes()


def test_every_shipped_scenario_is_in_the_comparison():
    assert len(PACKAGED_SCENARIOS) == 21


@pytest.mark.parametrize("scenario", PACKAGED_SCENARIOS)
def test_the_three_loops_give_the_same_results_bit_for_bit(tmp_path, scenario):
    project_fmus()
    runs = {loop: _run(scenario, tmp_path / loop, loop, SECONDS) for loop in ("compiled", "generated", "plain")}
    for loop, (metrics, _) in runs.items():
        assert (metrics["status"], metrics["loop"]) == ("completed", loop)
        assert metrics["macro_steps"] == round(SECONDS / metrics["step_size"])
    gen = runs["generated"][1]
    assert gen.count(b"\n") > 2
    assert runs["compiled"][1] == gen
    assert runs["plain"][1] == gen


def test_compiled_loop_through_a_cycle_s_ramps_and_the_row_boundaries(tmp_path):
    """The WLTC's speed reference (a linear table, a breakpoint every 0.1 s, merged into the controller's
    call) is evaluated inside the compiled loop: over 12-13 s it ramps up from the first stop, with its
    segments cut by the rows (every 500 steps) and the chunks."""
    project_fmus()
    out = {}
    for loop in ("compiled", "generated"):
        spec = load_system("wltc3b-sensorless")
        spec.stop_time = 13.0
        m = Master(spec, loop=loop)
        metrics = m.run(tmp_path / loop, catch_sigint=False)
        assert (metrics["status"], metrics["loop"]) == ("completed", loop)
        out[loop] = (tmp_path / loop / "results.csv").read_bytes()
    assert out["compiled"] == out["generated"]
    rows = out["compiled"].decode().splitlines()
    header = rows[0].split(",")
    omega_ref = [float(r.split(",")[header.index("omega_ref")]) for r in rows[1:]]
    assert omega_ref[0] == 0.0 and max(omega_ref) > 10.0  # the car moved off within the run


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("multiples", [(1, 1), (2, 3)])
def test_the_loops_are_equal_on_the_toys(tmp_path, algorithm, multiples):
    path = toy_system(tmp_path, algorithm=algorithm, src_multiple=multiples[0], snk_multiple=multiples[1],
                      stop_time=0.012, signals=LINEAR)
    (m_comp, comp), (_, gen), (_, plain) = (_run(path, tmp_path / loop, loop)
                                            for loop in ("compiled", "generated", "plain"))
    assert m_comp["loop"] == "compiled"
    assert comp == gen == plain


def test_the_loops_report_a_failed_step_alike(tmp_path):
    path = toy_system(tmp_path, snk_start="raise_at = 4")
    m_gen, gen = _run(path, tmp_path / "gen", "generated")
    assert m_gen["status"].startswith("failed: snk: fmi2DoStep failed at t = 0.003 s")
    for loop in ("compiled", "plain"):
        m, rows = _run(path, tmp_path / loop, loop)
        assert (m["status"], m["macro_steps"], rows) == (m_gen["status"], 3, gen)


def test_a_sum_that_overflows_is_not_a_value_that_is_not_finite(tmp_path):
    """src.y = 1e308 reaches snk.u and snk.w: their sum overflows, each is finite, the run goes on; at the
    next step y = 2e308 = inf, which the loop refuses, naming the connection."""
    path = toy_system(tmp_path, connections=('"src.y -> snk.u"', '"src.y -> snk.w"'),
                      record={"time": '"time"', "last_u": '"snk.last_u"'})
    runs = {}
    for loop in ("compiled", "generated", "plain"):
        spec = load_system(path)
        spec.set_start("src.slope=1e308")
        runs[loop] = Master(spec, loop=loop).run(tmp_path / loop, catch_sigint=False)
        assert runs[loop]["status"] == "failed: src.y is not finite (inf) at t = 0.001 s, before it reached snk.u"
        assert runs[loop]["macro_steps"] == 1
    assert (tmp_path / "compiled" / "results.csv").read_bytes() == (tmp_path / "generated" / "results.csv").read_bytes()


def test_a_system_the_compiled_loop_cannot_step(tmp_path):
    """A multi-rate component with a signal input that is not merged into its connections' call (a
    piecewise-constant table, queued until that component's step) is the generated loop's by default, and
    refused, with the reason, when the compiled loop is asked for by name."""
    sig = '[signals.s]\ninterpolation = "previous"\ntable = [[0, 0], [0.004, 2]]\ndrives = "snk.w"\n'
    path = toy_system(tmp_path, snk_multiple=3, stop_time=0.012, signals=sig)
    m_default, default = _run(path, tmp_path / "default", None)
    assert m_default["loop"] == "generated"
    assert default == _run(path, tmp_path / "plain", "plain")[1]
    with pytest.raises(CosimError, match=r"^the compiled loop cannot step toy: snk is stepped every 3 steps and "
                                         r"has signal inputs$"):
        Master(load_system(path), loop="compiled").run(tmp_path / "named", catch_sigint=False)
    assert not (tmp_path / "named").exists()  # refused before anything was written


def test_loop_from_the_environment(tmp_path, monkeypatch):
    spec = load_system(toy_system(tmp_path))
    monkeypatch.setenv(LOOP_ENV, "plain")
    m = Master(spec)
    assert m.loop == "plain"
    m.close()
    assert Master(spec, loop="generated").loop == "generated"  # the argument wins
    monkeypatch.delenv(LOOP_ENV)
    assert Master(spec).loop == "compiled"  # the default (where numba can run it: after the set-up)
    monkeypatch.setenv(LOOP_ENV, "unrolled")
    with pytest.raises(CosimError, match=r"^PMSM_COSIM_LOOP: 'unrolled' is not a stepping loop; choose one of "
                                         r"compiled, generated, plain$"):
        Master(spec)
    with pytest.raises(CosimError, match=r"^loop: 'fast' is not a stepping loop"):
        Master(spec, loop="fast")


def test_generated_loop_tracebacks_show_its_lines(tmp_path):
    m = Master(load_system(toy_system(tmp_path, snk_start="fail_at = 2", name="tb")), loop="generated")
    try:
        m._build()
        filename = m._steps.__code__.co_filename
        assert filename == "<generated steps of tb>"
        lines = m.step_source.splitlines()
        assert [linecache.getline(filename, i + 1).rstrip("\n") for i in range(len(lines))] == lines
        with pytest.raises(_StepFailed) as exc:
            m._steps(0, 10, _NEVER)
        text = "".join(traceback.format_exception(exc.value))
        assert f'File "{filename}", line ' in text
        assert "raise fail_step(st1, t, s)" in text  # the generated line that raised
    finally:
        m.close()
