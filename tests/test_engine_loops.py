"""The engine's two stepping loops: the plain one (ordinary Python, for a debugger) gives
the same results.csv, byte for byte, as the generated one on every shipped scenario; the
generated one's tracebacks show its source lines."""

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
def test_plain_loop_gives_the_generated_loops_results_bit_for_bit(tmp_path, scenario):
    project_fmus()
    m_gen, gen = _run(scenario, tmp_path / "gen", "generated", SECONDS)
    m_plain, plain = _run(scenario, tmp_path / "plain", "plain", SECONDS)
    assert (m_gen["status"], m_plain["status"]) == ("completed", "completed")
    assert (m_gen["loop"], m_plain["loop"]) == ("generated", "plain")
    assert m_gen["macro_steps"] == m_plain["macro_steps"] > 0
    assert gen.count(b"\n") > 2
    assert plain == gen


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("multiples", [(1, 1), (2, 3)])
def test_plain_loop_equals_the_generated_one_on_the_toys(tmp_path, algorithm, multiples):
    sig = '[signals.s]\ninterpolation = "linear"\ntable = [[0, 0], [0.004, 2], [0.007, -1]]\ndrives = "snk.w"\n'
    path = toy_system(tmp_path, algorithm=algorithm, src_multiple=multiples[0], snk_multiple=multiples[1],
                      stop_time=0.012, signals=sig)
    _, gen = _run(path, tmp_path / "gen", "generated")
    _, plain = _run(path, tmp_path / "plain", "plain")
    assert plain == gen


def test_plain_loop_reports_a_failed_step_as_the_generated_one(tmp_path):
    path = toy_system(tmp_path, snk_start="raise_at = 4")
    m_gen, gen = _run(path, tmp_path / "gen", "generated")
    m_plain, plain = _run(path, tmp_path / "plain", "plain")
    assert m_gen["status"].startswith("failed: snk: fmi2DoStep failed at t = 0.003 s")
    assert (m_plain["status"], m_plain["macro_steps"], plain) == (m_gen["status"], 3, gen)


def test_loop_from_the_environment(tmp_path, monkeypatch):
    spec = load_system(toy_system(tmp_path))
    monkeypatch.setenv(LOOP_ENV, "plain")
    m = Master(spec)
    assert m.loop == "plain"
    m.close()
    assert Master(spec, loop="generated").loop == "generated"  # the argument wins
    monkeypatch.setenv(LOOP_ENV, "unrolled")
    with pytest.raises(CosimError, match=r"^PMSM_COSIM_LOOP: 'unrolled' is not a stepping loop; choose one of "
                                         r"generated, plain$"):
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
