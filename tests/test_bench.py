"""The step-cost benchmark's parts (no timing here: figures are printed by the benchmark)."""

from __future__ import annotations

import fmpy
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app import bench
from pmsm_cosim.app.cli import main
from pmsm_cosim.app.reference import CONVERGED_SUBSTEPS
from pmsm_cosim.engine.master import Master
from pmsm_cosim.engine.recording import read_results


def test_bench_refuses_a_short_slice(capsys):
    assert main(["bench", "--slice", "5", "--no-memory"]) == 2
    assert "--slice must be" in capsys.readouterr().err
    assert main(["bench", "--cycle-slice", "5", "--no-memory"]) == 2
    assert "--cycle-slice must be a whole number of 1e-4 s steps and at least 10 s (got 5)" in capsys.readouterr().err
    assert main(["bench", "--cycle-slice", "2000", "--no-memory"]) == 2
    assert "--cycle-slice must be at most wltc3b's 1800 s (got 2000)" in capsys.readouterr().err


@pytest.fixture(scope="module")
def passthrough(tmp_path_factory):
    return bench.passthrough_fmus(tmp_path_factory.mktemp("passthrough"))


def _interface(path):
    md = fmpy.read_model_description(str(path))
    return [(v.name, v.causality, v.variability, v.type, v.valueReference) for v in md.modelVariables]


def test_passthrough_fmus_have_the_interface_of_the_real_ones(passthrough):
    real = project_fmus()
    assert _interface(passthrough["PassThroughPlant"]) == _interface(real["PmsmEvPlant"])
    assert _interface(passthrough["PassThroughFoc"]) == _interface(real["FocEkf5"])


def test_passthrough_fmus_compute_nothing(passthrough, tmp_path):
    spec = bench._spec(0.01, passthrough["PassThroughPlant"], passthrough["PassThroughFoc"])
    spec.output_interval = 1e-3
    m = Master(spec).run(tmp_path / "out", catch_sigint=False)
    assert m["status"] == "completed" and m["macro_steps"] == 100
    r = read_results(tmp_path / "out")
    assert r["omega_ref"][-1] > 0.0  # the signal reached the controller...
    for col in ("v_alpha", "v_beta", "v_q", "omega_hat", "omega_m", "i_d", "T_e"):
        assert (r[col] == r[col][0]).all(), col  # ...which computed nothing, nor did the plant


def test_the_cycle_case_is_the_sensorless_drive_on_wltc(passthrough, tmp_path):
    """(e), (f): the shipped wltc3b-if (the speed range's settings, the feedforward, 1 A noise) with the
    cycle's speed reference (a linear table, set with the controller's connections), the real or the
    pass-through FMUs."""
    real = project_fmus()
    spec = bench.cycle_spec(0.05, real["PmsmEvPlant"], real["FocSensorless"])
    ctrl = spec.component("ctrl", "test")
    assert ctrl.fmu == real["FocSensorless"] and ctrl.start["reference"] == "fw"
    assert ctrl.start["current_control"] == "high_speed" and ctrl.start["discretisation"] == "bilinear"
    assert spec.component("plant", "test").start["gear_model"] == "power_flow"
    assert ctrl.start["speed_feedforward"] == "inertia+road"
    assert spec.component("plant", "test").start["sensor_noise"] == 1
    assert spec.signals["omega_ref"].profile.interpolation == "linear"
    assert spec.stop_time == 0.05
    m = Master(spec)
    assert m.run(tmp_path / "real", catch_sigint=False)["status"] == "completed"
    assert [tr.signals for tr in m.steppers[0].transfers] == [["ctrl.omega_ref"]]
    assert read_results(tmp_path / "real")["mode"][-1] == 0.0  # aligning: the sensorless unit
    dummy = bench.cycle_spec(0.05, passthrough["PassThroughPlant"], passthrough["PassThroughFoc"])
    assert Master(dummy).run(tmp_path / "dummy", catch_sigint=False)["status"] == "completed"


def test_the_injection_case_is_the_same_drive_with_injection(tmp_path):
    """(g): wltc3b-sensorless, the drive of (e) with low_speed = "injection" on the plant's algebraic flux
    model: acquiring the angle in its first 0.05 s."""
    real = project_fmus()
    spec = bench.cycle_spec(0.05, real["PmsmEvPlant"], real["FocSensorless"], bench.INJECTION_SYSTEM)
    ctrl, plant = spec.component("ctrl", "test"), spec.component("plant", "test")
    assert (ctrl.start["low_speed"], ctrl.start["reference"]) == ("injection", "fw")
    assert plant.start["flux_model"] == "algebraic"
    assert Master(spec).run(tmp_path / "g", catch_sigint=False)["status"] == "completed"
    assert read_results(tmp_path / "g")["mode"][-1] == 3.0  # acquiring the angle by injection


def test_the_plain_fmpy_master_steps_the_system_as_the_master_does(tmp_path):
    """(j): fmpy's FMU2Slave in a Python loop, Gauss-Seidel in the system file's order, is the same
    co-simulation as the master's: the same outputs after 200 steps of scenario 1, bit for bit."""
    real = project_fmus()
    spec = bench._spec(0.02, real["PmsmEvPlant"], real["FocEkf5"])
    spec.output_interval = 0.02
    assert Master(spec).run(tmp_path / "out", catch_sigint=False)["status"] == "completed"
    r = read_results(tmp_path / "out")
    outputs = bench.fmpy_loop(bench._spec(0.02, real["PmsmEvPlant"], real["FocEkf5"]), 200)
    for column, (inst, var) in {"omega_m": ("plant", "omega_m"), "i_alpha": ("plant", "i_alpha"),
                                "theta_e": ("plant", "theta_e"), "omega_hat": ("ctrl", "omega_hat"),
                                "v_alpha": ("ctrl", "v_alpha"), "T_L_hat": ("ctrl", "T_L_hat")}.items():
        assert outputs[inst][var] == r[column][-1], column
    assert r["omega_m"][-1] > 0.0  # the ramp started: not a pair of idle FMUs


def test_a_memory_run_reports_its_own_peak_not_the_bench_s(tmp_path):
    """The memory runs' peak is the child's own high-water mark: wait4's figure would include the memory of the
    process that spawned it (Linux keeps it across the exec), here 600 MB held by the test's process."""
    project_fmus()  # built: the child only runs
    held = bytearray(600 * 1024 * 1024)
    held[::4096] = b"\x01" * len(held[::4096])  # resident
    wall, peak, tail = bench.run_child(0.01, tmp_path / "out")
    assert tail.startswith("completed: 100 steps") and wall > 0
    assert 50.0 < peak < 450.0, (peak, tail)  # a short scenario1 run: ~230 MB of Python, numba and the FMUs
    del held


def test_the_held_speed_case_starts_at_the_speed_and_holds_it():
    """Case (m): the plant started at the speed, the speed reference held there; its converged reference the
    rotor frame's RK4 with the converged sub-steps."""
    spec = bench.held_speed_spec("wltc3b-sensorless", 131.0, 1.0)
    omega = 131.0 / 3.6 / 0.2933 * 12.5
    plant = spec.component("plant", "test")
    assert abs(plant.start["omega_m0"] - omega) < 1e-9 and plant.start["integrator"] == "rk6_stationary"
    ref = spec.signals["omega_ref"].profile
    assert ref(0.0) == ref(0.5) == ref(1.0) == omega and spec.stop_time == 1.0
    converged = bench.held_speed_spec("wltc3b-sensorless", 131.0, 1.0, converged=True).component("plant", "test").start
    assert converged["integrator"] == "rk4_rotor" and converged["rk4_substeps"] == CONVERGED_SUBSTEPS


def test_the_fmi3_cases_are_in_the_table_and_its_ratios(monkeypatch):
    """(k), (l): the system of (a) on the FMI 3.0 units, ticked in event mode and not, a run each (their rows), then
    in lock step with (a), the rounds in turn; the ratios k/a, l/a, the median of the rounds', printed (the
    measurements replaced by fixed figures here: no timing)."""
    import io

    calls, orders = [], []

    def measured(stop_time, work, plant=None, ctrl=None, spec=None, event_mode=True, clock=None):
        calls.append((plant, ctrl, event_mode, clock is not None))
        return (3.0, 2.0) if plant is not None and plant.parent.name == "fmi3" else (2.0, 2.0)

    def lock_step_costs(self, steppers):  # each run as given, one after the other (the ratios: fixed, below)
        for stepper in steppers:
            stepper(object())
        return [None] * self.count

    def rounds(n, lock_step):
        for _ in range(n):
            orders.append(lock_step(["a", "k", "l"]))
        return {"k/a": [(1.5, 1.0)] * n, "l/a": [(1.5, 1.0)] * n}

    monkeypatch.setattr(bench, "cosim_us_per_step", measured)
    monkeypatch.setattr(bench.LockStep, "run", lock_step_costs)
    monkeypatch.setattr(bench, "fmi3_rounds", rounds)
    for name in ("reference_us_per_step", "whole_loop_us_per_step"):
        monkeypatch.setattr(bench, name, lambda *args, **kwargs: (1.0, 1.0))
    out = io.StringIO()
    results = bench.run_bench(10.0, memory=False, libcosim=False, out=out, fmpy_case=False, speed_slice=0.0)
    text = out.getvalue()
    fmi3, why = bench.fmi3_units()
    real_plant, real_ctrl = (project_fmus()[name] for name in ("PmsmEvPlant", "FocEkf5"))
    assert [label[:3] for label in bench.CASES.values()] == [f"({c})" for c in "abcdefghijkl"]
    if fmi3 is None:
        assert results["k"] is None and f"(no FMI 3.0 units: {why})" in text
        return
    # after the other cases: (k), (l) alone, then the rounds of (a), (k), (l) in lock step
    run_a, run_k, run_l = ((real_plant, real_ctrl, True), (fmi3["PmsmEvPlant"], fmi3["FocEkf5"], True),
                           (fmi3["PmsmEvPlant"], fmi3["FocEkf5"], False))
    alone, locked = calls[-2 - 3 * bench.FMI3_ROUNDS:-3 * bench.FMI3_ROUNDS], calls[-3 * bench.FMI3_ROUNDS:]
    assert alone == [(*run_k, False), (*run_l, False)]
    assert locked == [(*run, True) for run in (run_a, run_k, run_l)] * bench.FMI3_ROUNDS
    assert len(orders) == bench.FMI3_ROUNDS
    assert results["k"] == results["l"] == (3.0, 2.0)
    lines = {line.split()[0]: line.split()[1:] for line in text.splitlines() if line.strip()}
    assert lines["k/a"] == lines["l/a"] == ["(in", "lock", "step,", str(bench.FMI3_ROUNDS), "rounds)", "1.500", "1.000"]
    assert results["k/a"] == results["l/a"] == (1.5, 1.0)
    assert "k/a, l/a: (a), (k), (l) stepped in lock step" in text
    assert any(line.startswith("(k) (a) on the FMI 3.0 units, clock ticked") for line in text.splitlines())


def test_the_fmi3_ratios_are_the_median_over_the_turns_then_over_the_rounds():
    """k/a, l/a of a round: the median over its turns of their ratios (the j-th of k to the j-th of a); the rounds in
    turn, a k l, then l k a."""
    orders = []
    a = [(1.0, 2.0), (1.0, 2.0), (1.0, 2.0), (5.0, 2.0)]  # a turn that waited: its ratio is an outlier
    k = [(1.1, 2.2), (1.2, 2.0), (1.05, 2.0), (1.0, 2.0)]
    l_ = [(0.9, 2.0), (1.0, 2.0), (1.0, 1.0), (1.0, 2.0)]

    def lock_step(order):
        orders.append("".join(order))
        return {"a": a, "k": k, "l": l_}

    pairs = bench.fmi3_rounds(3, lock_step)
    assert orders == ["akl", "lka", "akl"]
    assert pairs["k/a"] == [(pytest.approx(1.1 * 0.5 + 1.05 * 0.5), 1.0)] * 3  # the median of 1.1, 1.2, 1.05, 0.2
    assert pairs["l/a"] == [(pytest.approx(0.95), 1.0)] * 3  # of 0.9, 1.0, 1.0, 0.2 (wall); 1.0, 1.0, 0.5, 1.0
    assert bench.median([3.0, 1.0]) == 2.0 and bench.median([5.0]) == 5.0


def test_lock_step_takes_the_runs_of_steps_in_turn_and_times_each_alone(tmp_path):
    """LockStep: the masters' turns of ``stride`` rows in turn (a, b, a, b, ...), each timed from its beginning to its
    last row; a master that fails, before its first row or on the way, is passed over and its error raised; two real
    runs of the system of (a) in lock step, a turn's cost for each two of their rows after the first."""
    seen = []

    def fake(name, rows, fail_at=None):
        def stepper(hook):
            for row in range(rows):
                if row == fail_at:
                    raise ValueError(f"{name} failed")
                hook.update(row * 100 * 1e-4)
                seen.append((name, row))
            return name
        return stepper

    lock = bench.LockStep(2, 1e-4, stride=1)
    assert lock.run([fake("a", 4), fake("b", 4)]) == ["a", "b"]
    assert seen == [(name, row) for row in range(4) for name in "ab"]
    assert [len(c) for c in lock.costs] == [3, 3] and all(w >= 0.0 for c in lock.costs for w, _c in c)
    seen.clear()
    with pytest.raises(ValueError, match="b failed"):
        bench.LockStep(3, 1e-4, stride=1).run([fake("a", 3), fake("b", 3, fail_at=1), fake("c", 3)])
    assert seen == [("a", 0), ("b", 0), ("c", 0), ("a", 1), ("c", 1), ("a", 2), ("c", 2)]
    with pytest.raises(ValueError, match="a failed"):
        bench.LockStep(2, 1e-4, stride=1).run([fake("a", 3, fail_at=0), fake("b", 3)])
    plant, ctrl = (project_fmus()[name] for name in ("PmsmEvPlant", "FocEkf5"))
    lock = bench.LockStep(2, 1e-4, stride=2)
    lock.run([lambda hook: bench.cosim_us_per_step(0.05, tmp_path, plant, ctrl, clock=hook)] * 2)
    assert [len(c) for c in lock.costs] == [2, 2]  # rows at 0, 10, ..., 40 ms, turns of 2 rows; after the last: none
    assert all(w > 0.0 for c in lock.costs for w, _c in c)


def test_the_fmi3_cases_run_the_system_of_a(tmp_path):
    """(k), (l) run (a)'s system on the FMI 3.0 units: the controller ticked in event mode in (k) only, and the
    results those of (a), byte for byte."""
    import filecmp

    fmi3, why = bench.fmi3_units()
    if fmi3 is None:
        pytest.skip(why)
    real = project_fmus()
    assert all(fmpy.read_model_description(str(p)).fmiVersion == "3.0" for p in fmi3.values())
    runs = {"a": (real["PmsmEvPlant"], real["FocEkf5"], True), "k": (fmi3["PmsmEvPlant"], fmi3["FocEkf5"], True),
            "l": (fmi3["PmsmEvPlant"], fmi3["FocEkf5"], False)}
    for case, (plant, ctrl, event_mode) in runs.items():
        spec = bench._spec(0.02, plant, ctrl)
        spec.output_interval = 1e-3
        master = Master(spec, event_mode=event_mode)
        assert master.run(tmp_path / case, catch_sigint=False)["status"] == "completed"
        assert set(master.ticks) == ({"ctrl"} if case == "k" else set()), case
        assert filecmp.cmp(tmp_path / "a" / "results.csv", tmp_path / case / "results.csv", shallow=False), case
