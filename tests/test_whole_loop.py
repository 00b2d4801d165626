"""The whole-loop reference (``pmsm_cosim.app.whole_loop``, ``pmsm-cosim bench`` case (h)): the same system as the
co-simulation, row for row and bit for bit (no timing here: figures are printed by the benchmark)."""

from __future__ import annotations

import filecmp
import io

import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app import bench
from pmsm_cosim.app.drive import load_system
from pmsm_cosim.app.overrides import apply_overrides
from pmsm_cosim.app.whole_loop import run_whole_loop
from pmsm_cosim.engine.master import Master, SignalClock
from pmsm_cosim.engine.recording import read_results
from pmsm_ev import accel
from pmsm_ev.whole_loop import NotCovered, WholeLoop

pytestmark = pytest.mark.skipif(not accel.compiled(), reason="the whole loop runs the compiled kernels")


def _same(make_spec, tmp_path):
    """The master's results.csv of ``make_spec()`` and the whole loop's, byte for byte; the rows."""
    m = Master(make_spec()).run(tmp_path / "cosim", catch_sigint=False)
    assert m["status"] == "completed" and m["loop"] == "compiled"
    w = run_whole_loop(make_spec(), tmp_path / "loop")
    assert w["macro_steps"] == m["macro_steps"] and len(w["rows"]) == m["rows"]
    assert filecmp.cmp(tmp_path / "cosim" / "results.csv", tmp_path / "loop" / "results.csv", shallow=False)
    return read_results(tmp_path / "loop")


def test_scenario2_every_step_is_the_cosimulations(tmp_path):
    """The system of scenario 2 (FocEkf5 on the measured angle, the speed ramp), every one of 3000 steps
    recorded: the same file as the co-simulation's."""
    def spec():
        s = load_system("scenario2")
        s.stop_time, s.output_interval = 0.3, 1e-4
        return s

    r = _same(spec, tmp_path)
    assert len(r["time"]) == 3001 and r["omega_ref"][-1] > 0.0 and r["omega_m"][-1] > 0.0


def test_the_cycle_system_of_bench_e_every_step_is_the_cosimulations(tmp_path):
    """The system of bench case (e) (FocSensorless on wltc3b with field weakening, the regenerative limit and
    the brake, the inverter's losses, 1 A of current noise) and every column of its record (the energies, the
    stored energies, the reference generator's outputs), every one of 4000 steps recorded."""
    real = project_fmus()

    def spec():
        s = bench.cycle_spec(0.4, real["PmsmEvPlant"], real["FocSensorless"])
        s.output_interval = 1e-4
        return s

    r = _same(spec, tmp_path)
    assert len(r["time"]) == 4001 and r["E_dc"][-1] != 0.0 and r["W_magnetic"][-1] > 0.0
    assert r["i_dref"][-1] > 0.0  # aligning: the vector's magnitude (the unit's property)


def test_the_thermal_network_in_the_whole_loop_is_the_cosimulations(tmp_path):
    """wltc3b-thermal (the plant's thermal network on: R_s and psi follow its temperatures each step) with the
    sensorless unit (the whole loop's controllers are FocEkf5 and FocSensorless) for 3 s, a row every 10 ms with the
    temperatures recorded: the same file as the co-simulation's."""
    def spec():
        return apply_overrides("wltc3b-thermal", controller="sensorless", stop_time=3.0, output_interval=0.01)

    r = _same(spec, tmp_path)
    assert r["T_wdg"][-1] > r["T_wdg"][0] and r["Q_heat"][-1] > 0.0 and r["psi_now"][-1] != r["psi_now"][0]


def test_the_bench_a_system_is_the_cosimulations(tmp_path):
    """The system of bench case (a) (scenario 1), a row every 10 ms as the benchmark records it."""
    real = project_fmus()
    _same(lambda: bench._spec(0.5, real["PmsmEvPlant"], real["FocEkf5"]), tmp_path)


def test_a_plant_step_at_the_voltage_limit_is_the_fmus_python_step(tmp_path, monkeypatch):
    """A plant voltage at the DC link's limit (v_dc 5 V: from 0.59 s on): the FMU's compiled step declines it and
    its Python step runs (``math.hypot`` decides the limit); the whole loop takes it the same way, bit for bit."""
    taken = []
    step = WholeLoop.python_plant_step
    monkeypatch.setattr(WholeLoop, "python_plant_step", lambda self, n, h: taken.append(n) or step(self, n, h))

    def spec():
        s = load_system("scenario2")
        s.stop_time, s.output_interval = 0.7, 1e-4
        s.component("plant", "test").start["v_dc"] = 5.0
        return s

    _same(spec, tmp_path)
    assert len(taken) > 100 and taken[0] == 5885


def test_signal_events_are_the_masters_values():
    """``SignalClock.events``: a ramp's formula from the step after its start to its end, the profile's value
    where the master evaluates it."""
    s = load_system("scenario2")
    events = SignalClock(s).events(round(60.0 / s.step_size))
    (n, v, end, v0, dv, t0, dt), after = events["omega_ref"]
    assert (n, v, end) == (0, 0.0, 100000) and (v0, dv, t0, dt) == (0.0, 200.0, 0.0, 10.0)
    assert after[:3] == (100000, 200.0, 0)
    assert [e[0] for e in events["delta"]] == [0, 500000]


def test_a_system_it_does_not_cover_is_refused(tmp_path):
    s = load_system("scenario2")
    s.stop_time, s.algorithm = 0.01, "jacobi"
    with pytest.raises(NotCovered, match="Gauss-Seidel only"):
        run_whole_loop(s)
    s = load_system("wltc3b-battery-sensorless")  # the battery's link to the controller: not in the loop
    s.stop_time = 0.01
    with pytest.raises(NotCovered, match="the ideal DC link only"):
        run_whole_loop(s)


@pytest.mark.slow
def test_bench_has_the_whole_loop_cases(monkeypatch):
    """``pmsm-cosim bench`` prints (h), the whole loop of (e)'s system, (i), of (a)'s, and the ratios e/h, a/i
    (the cases' runs replaced by fixed figures here)."""
    seen = []
    monkeypatch.setattr(bench, "cosim_us_per_step", lambda *a, **k: (4.0, 4.0))
    monkeypatch.setattr(bench, "reference_us_per_step", lambda *a, **k: (9.0, 9.0))
    monkeypatch.setattr(bench, "whole_loop_us_per_step", lambda spec: seen.append(spec) or (2.0, 1.0))
    monkeypatch.setattr(bench, "bindings", lambda: "lean")
    out = io.StringIO()
    results = bench.run_bench(10.0, memory=False, libcosim=False, out=out, cycle_slice=10.0)
    text = out.getvalue()
    assert results["h"] == (2.0, 1.0) and results["i"] == (2.0, 1.0)
    assert [s.name for s in seen] == ["wltc3b-if", "scenario1"]
    assert [c.start.get("reference") for s in seen for c in s.components if c.name == "ctrl"] == ["fw", None]
    assert "(h) whole compiled loop (no FMI), system of (e)" in text
    assert "(i) whole compiled loop (no FMI), system of (a)" in text
    e_h = next(line for line in text.splitlines() if line.startswith("e/h"))
    assert e_h.split()[1:] == ["2.00", "4.00"]
