"""Robustness maps (orchestrator/pmsm_cosim/app/report/robustness/,
orchestrator/pmsm_cosim/app/sweeps/robust_*.toml): the sweep engine's signal factor, the figures
of merit of a run and the stability rule, the failure-rate interval, a small version of every map
(3 x 3, 6 s runs: past the sensorless unit's start-up; the drive cycle's Monte-Carlo cut to 6 s) on a
2-worker local cluster, page included,
and the page's claims on synthetic summaries (a changed input changes the claim)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app.report import robustness as rr
from pmsm_cosim.app.report.robustness import document as rdoc
from pmsm_cosim.app.report.robustness.metrics import DeadRun
from pmsm_cosim.app.studies import PACKAGED_SWEEPS, load_sweep
from pmsm_cosim.engine.recording import read_results
from pmsm_cosim.sweeps import prepare_runs
from pmsm_ev.params import MotorParams


def test_scale_multiplies_the_signal_table(tmp_path):
    project_fmus()
    path = tmp_path / "s.toml"
    path.write_text('system = "scenario2"\nstop_time = 1.0\n[grid]\n"scale.delta" = [0.5, 2.0]\n', encoding="utf-8")
    runs = prepare_runs(load_sweep(path))
    base = [math.radians(v) for v in (0, 22, 0, 22, 0, 22, 0, 22, 0, 22, 0)]
    for run, k in zip(runs, (0.5, 2.0)):
        assert list(run.spec.signals["delta"].profile.values) == pytest.approx([k * v for v in base], rel=1e-15)
    assert runs[0].signature != runs[1].signature


def test_shipped_robustness_sweeps_are_listed_and_parse():
    for name in rr.SWEEPS:
        assert name in PACKAGED_SWEEPS
        sweep = rr.sweep_spec(name)
        small = rr.sweep_spec(name, small=True, stop_time=2.0)
        assert small.stop_time == 2.0
        if sweep.grid:
            assert all(len(v) <= 3 for v in small.grid.values())
            assert [v[0] for v in small.grid.values()] == [v[0] for v in sweep.grid.values()]
    m = MotorParams()
    grid = rr.sweep_spec("robust_rs_psi_sensorless").grid
    assert grid["plant.R_s"][0] == pytest.approx(0.5 * m.R_s) and grid["plant.R_s"][-1] == pytest.approx(2 * m.R_s)
    assert grid["plant.psi"][0] == pytest.approx(0.8 * m.psi) and grid["plant.psi"][-1] == pytest.approx(1.2 * m.psi)
    assert len(rr.sweep_spec(rr.MONTE_CARLO).runs) >= 200


def _synthetic(slip_rate: float, speed_offset: float, t_end: float = 30.0) -> dict:
    t = np.arange(0.0, t_end + 1e-9, 0.01)
    w = np.full_like(t, 200.0)
    theta = (4 * w * t + np.pi) % (2 * np.pi) - np.pi
    drift = np.where(t > 22.0, slip_rate * (t - 22.0), 0.0)  # estimate falls behind after 22 s
    return {"time": t, "omega_ref": w, "omega_m": w + speed_offset, "theta_e": theta,
            "theta_hat": theta - 4 * (w + speed_offset) * 1e-4 - drift, "mode": np.full_like(t, 2.0),
            "i_q": np.full_like(t, 100.0)}


def test_run_metrics_count_slips_and_classify():
    """The row-timing term (N omega dt, with the run's step and pole pairs) is removed: the synthetic
    estimate trails by exactly that, so its angle error is 0; a wrong dt leaves it in."""
    ok = rr.run_metrics(_synthetic(0.0, 0.5), 1e-4, 4)
    assert ok["speed_rms_after"] == pytest.approx(0.5) and ok["angle_rms_after"] < 1e-9
    assert ok["i_q_after"] == 100.0 and ok["omega_ref_after"] == 200.0
    assert (ok["slips"], ok["stable"], ok["diverged"]) == (0, True, False)
    assert rr.run_metrics(_synthetic(0.0, 0.5), 2e-4, 4)["angle_rms_after"] == pytest.approx(4 * 200.5 * 1e-4)
    biased = rr.run_metrics(_synthetic(0.0, -12.0), 1e-4, 4)
    assert (biased["stable"], biased["diverged"]) == (False, False)
    slipping = rr.run_metrics(_synthetic(2 * np.pi * 1.5, 0.0), 1e-4, 4)  # 1.5 electrical turns per second, 8 s
    assert slipping["slips"] == 12 and slipping["slips_after"] == 12
    assert (slipping["stable"], slipping["diverged"]) == (False, True)
    # the paper's EKF5 in its own mode drives on the measured angle: its slips do not count
    assert rr.run_metrics(_synthetic(2 * np.pi * 1.5, 0.0), 1e-4, 4, angle_used=False)["stable"]
    assert rr.classify({"speed_rms_after": 60.0})["diverged"] and not rr.classify({"speed_rms_after": 1.0}, False)[
        "stable"]


def test_wilson_interval():
    lo, hi = rr.wilson(10, 200)
    assert (lo, hi) == (pytest.approx(0.0274, abs=2e-4), pytest.approx(0.0896, abs=2e-4))
    lo, hi = rr.wilson(0, 200)
    assert lo == 0.0 and hi == pytest.approx(0.0188, abs=2e-4)


STOP = 6.0  #: [s] the small maps' runs: past the 2.3 s alignment, the I-f start and the handover
T_FROM_SMALL = STOP / 2  #: the window generate() takes for runs this short


def followed_the_start(r: dict) -> bool:
    """The sensorless unit's start-up happened within the run: the rotor turned with the reference
    (within 2 rad/s of the 70 rad/s it reached at the end), in the closed loop (mode 2) at the end."""
    return bool(r["omega_ref"][-1] > 60.0 and abs(r["omega_m"][-1] - r["omega_ref"][-1]) < 2.0
                and r["mode"][-1] == 2.0)


@pytest.mark.slow
def test_small_maps_on_a_two_worker_cluster(tmp_path):
    """Every map 3 x 3 with 6 s runs (the sensorless unit aligns until 2.3 s, starts in I-f on the
    reference ramped from 2.5 s and hands over to the EKF at about 4.3 s; the EKF5 flying starts hold
    200 rad/s), the Monte-Carlo run with a few samples and the dead-time runs, on a LocalCluster of 2
    workers; then the page with its figures. The figures are after 3 s: the sensorless runs are judged
    on the ramp they follow, so a unit that did not start would be far from stable."""
    pytest.importorskip("distributed")
    project_fmus()
    runs = tmp_path / "runs"
    timing = rr.run_sweeps(runs, workers=2, small=True, stop_time=STOP, log=lambda msg: None)
    n_maps = len(rr.MAPS) * len(rr.CONTROLLERS)
    assert timing["runs"] == n_maps * 9 + 2 * rr.SMALL_SAMPLES + 4 + rr.SMALL_SAMPLES  # ... + the drive cycle
    page = rr.generate(out=tmp_path / "docs", runs_dir=runs, small=True, stop_time=STOP, run=False,
                       log=lambda msg: None)
    c = rr.collect(runs, t_from=T_FROM_SMALL)
    for m in rr.MAPS:
        for key, _ in rr.CONTROLLERS:
            g = c.grids[m.key][key]
            assert g["speed"].shape == (3, 3) and (g["status"] == "completed").all()
            assert g["x"][1] == pytest.approx(0.0)  # the nominal value in the middle
    # the paper's EKF5 on the measured angle, nominal motor, level road: holds 200 rad/s
    g = c.grids["lq_load"]["ekf5paper"]
    assert g["stable"][0, 1] and g["speed"][0, 1] < 2.0  # 1 % of 200 rad/s, 3 s after the flying start
    # the sensorless unit started: with the nominal motor, and on every cell of the L_q x load map, it
    # follows the ramp from 3 s on (stable: speed RMS error < 5 rad/s, no turn slipped) ...
    for key in ("sensorless", "sensorless_adapt"):
        assert c.grids["rs_psi"][key]["stable"][1, 1] and c.grids["lq_load"][key]["stable"].all()
        assert np.nanmax(c.grids["lq_load"][key]["omega_ref"]) == pytest.approx(40.0, abs=0.5)  # mean of 10..70 rad/s
    # ... and its nominal run reached the reference in the closed loop; the same run with a rotor that
    # never turned fails both checks
    rows = {row["run"]: row for row in rr.sweep_results(runs / "robust_rs_psi_sensorless", T_FROM_SMALL)}
    (nominal,) = [k for k, row in rows.items() if float(row["plant.R_s"]) == pytest.approx(MotorParams().R_s)
                  and float(row["plant.psi"]) == pytest.approx(MotorParams().psi)]
    r = read_results(runs / "robust_rs_psi_sensorless" / "runs" / nominal)
    assert followed_the_start(r) and rows[nominal]["stable"]
    stuck = {**r, "omega_m": np.zeros_like(r["omega_m"])}
    assert not followed_the_start(stuck) and not rr.run_metrics(stuck, 1e-4, 4, T_FROM_SMALL)["stable"]
    assert [len(rows) for rows in c.mc.values()] == [rr.SMALL_SAMPLES] * 2 and len(c.dead) == 4
    assert len(c.cycle) == rr.SMALL_SAMPLES and all(r["status"] == "completed" for r in c.cycle)
    assert c.routes["robust_rs_psi_sensorless"]["ramp_from"] == pytest.approx(2.5)
    assert c.routes["robust_rs_psi_ekf5ab"]["step_at"] == pytest.approx(5.0)
    text = page.read_text(encoding="utf-8")
    assert "Small version" in text and "failure rate" in text and "95 % interval" in text
    assert f"speed RMS error after {T_FROM_SMALL:g} s is below" in text
    assert "sensorless unit, from standstill: 6 s, reference 0 → 70 rad/s over 2.5-6 s" in text
    assert f"## Monte-Carlo on a drive cycle\n\n{rr.SMALL_SAMPLES} samples (of the file's 30)" in text
    for name in ("map_rs_psi.png", "map_lq_load.png", "monte_carlo.png", "monte_carlo_adapt.png",
                 "dead_time_hill.png", "cycle_monte_carlo.png"):
        assert (tmp_path / "docs" / "robustness" / name).stat().st_size > 5000


# -- the page's text: computed from the summaries it describes -----------------------------------------

RS = [-50.0, 0.0, 100.0]  # R_s mismatch [%]
PSI = [-20.0, -10.0, 0.0, 10.0, 20.0]  # psi mismatch [%]


def _grid(xs, ys, bias, angle=0.01, i_q=100.0, omega=200.0, diverged=None) -> dict:
    """A map's grid as ``metrics.grid_of`` makes it, from a steady speed error per cell [y, x]."""
    bias = np.asarray(bias, float)
    shape = bias.shape
    div = np.zeros(shape, bool) if diverged is None else np.asarray(diverged, bool)
    speed = np.abs(bias) + 0.1
    return {"x": list(xs), "y": list(ys), "speed": speed, "bias": bias, "angle": np.broadcast_to(angle, shape) * 1.0,
            "i_q": np.full(shape, i_q), "omega_ref": np.full(shape, omega), "slips": np.zeros(shape, int),
            "stable": ~div & (speed < rr.SPEED_LIMIT), "diverged": div,
            "status": np.full(shape, "completed", dtype=object)}


def _psi_bias(per_psi, rs_effect=0.1):
    """Steady speed error [rad/s] per psi row (-20 .. +20 %), plus ``rs_effect`` across R_s."""
    return [[b + rs_effect * (j - 1) for j in range(len(RS))] for b in per_psi]


def test_rs_psi_claims_follow_the_grids():
    biased = _grid(RS, PSI, _psi_bias([8.0, 6.0, 0.0, -4.0, -8.0]))
    text = "\n".join(rdoc.rs_psi_text({"sensorless": biased, "ekf5ab": biased}))
    assert "**ψ mismatch biases the speed, R_s mismatch hardly matters at speed**" in text
    assert "has the sign of −Δψ, and none of them diverged, as a wrong ψ acts" in text
    assert "A hot magnet (ψ −10 %) alone takes the sensorless unit out of the 2.5 % speed tolerance" in text
    assert "back-EMF N ω ψ (72 V) is 83 times the resistive drop R_s i_q (0.87 V" in text  # 4 x 200 x 0.08975
    assert "+100 % R_s is a 1.2 % voltage error" in text
    # R_s as strong as psi: the headline changes; so do the sign, the hot magnet and the back-EMF
    both = _grid(RS, PSI, _psi_bias([8.0, 3.0, 0.0, 4.0, -8.0], rs_effect=4.0), omega=100.0)
    text = "\n".join(rdoc.rs_psi_text({"sensorless": both}))
    assert "**ψ and R_s mismatch both bias the speed**" in text and "hardly matters" not in text
    assert "does not have the sign of −Δψ in every cell" in text and "A wrong ψ alone does not explain it" in text
    assert "keeps the sensorless unit within the 5.0 % speed tolerance" in text
    assert "back-EMF N ω ψ (36 V)" in text
    diverging = _grid(RS, PSI, _psi_bias([8.0, 6.0, 0.0, -4.0, -8.0]),
                      diverged=[[False] * 3] * 4 + [[False, True, False]])
    assert "some of them diverged" in "\n".join(rdoc.rs_psi_text({"sensorless": diverging}))


def test_adaptation_claim_follows_the_stable_cells():
    without = _grid(RS, PSI, _psi_bias([8.0, 6.0, 0.0, -4.0, -8.0]))
    better = _grid(RS, PSI, _psi_bias([0.5, 0.3, 0.0, -0.3, -0.5]))
    text = "\n".join(rdoc.rs_psi_text({"sensorless": without, "sensorless_adapt": better}))
    assert "**The magnet-flux adaptation widens the stable region from 6 to 15 of 15 cells**" in text
    assert "left: 0.60 rad/s against 8.10 without" in text
    text = "\n".join(rdoc.rs_psi_text({"sensorless": better, "sensorless_adapt": without}))
    assert "narrows the stable region from 15 to 6 of 15 cells" in text and "widens" not in text


def test_adaptation_bias_leaves_out_a_diverged_cell():
    """A diverged cell has no steady bias: the largest bias left is over the cells that diverged in
    neither, and the text counts the diverged ones."""
    corner = [[True, False, False]] + [[False] * 3] * 4
    runaway = [[206.0, 0.3, 0.2], [0.3, 0.1, 0.0], [0.0] * 3, [-0.3, -0.1, 0.0], [-0.5, -0.4, -0.3]]
    without = _grid(RS, PSI, _psi_bias([8.0, 6.0, 0.0, -4.0, -8.0]), diverged=corner)
    text = "\n".join(rdoc.rs_psi_text({"sensorless": without,
                                       "sensorless_adapt": _grid(RS, PSI, runaway, diverged=corner)}))
    assert "left: 0.50 rad/s against 8.10 without, over the cells that diverged in neither; diverged: 1 with, " \
           "1 without" in text


def test_lq_load_claims_follow_the_grids():
    lq, load = [-40.0, 0.0, 40.0], [0.0, 11.0, 22.0]
    grows = _grid(lq, load, np.zeros((3, 3)), angle=np.array([[0.01] * 3, [0.1] * 3, [0.3] * 3]), i_q=234.0)
    text = "\n".join(rdoc.lq_load_text({"sensorless": grows}))
    assert "**L_q mismatch (saturation) grows with the load**" in text
    assert f"Δθ ≈ ΔL_q i_q / ψ ({0.4 * MotorParams().L_q * 234.0 / MotorParams().psi:.2f} rad for −40 % at the 234 A" \
        .replace("−", "-") in text.replace("−", "-")
    assert "Unloaded it is harmless" in text and "rather than stability (no cell diverged)" in text
    assert "measured 0.30 rad RMS, of that size" in text
    flat = _grid(lq, load, np.array([[9.0, 0.0, 0.0], [0.0] * 3, [0.0] * 3]), angle=0.1, i_q=20.0,
                 diverged=[[False] * 3, [False] * 3, [True, False, False]])
    text = "\n".join(rdoc.lq_load_text({"sensorless": flat}))
    assert "does not grow 3 times with the load here" in text and "grows with the load**" not in text
    assert "measured 0.10 rad RMS, not of that size" in text
    assert "Even unloaded some cells are not stable" in text and "1 cells diverged" in text


def _dead(dead_time, comp, roll_back, slips=0, speed_rms=1.0, speed_max=5.0) -> DeadRun:
    run = DeadRun({"plant.dead_time": dead_time, "ctrl.dead_time_comp": comp, "status": "completed"}, {}, 1e-4, 4.0,
                  360.0)
    run.figures = {"speed_rms": speed_rms, "speed_error_max": speed_max, "angle_rms": 0.01, "roll_back": roll_back,
                   "slips": slips, "v_error": 360.0 * dead_time / 1e-4, "climb_bias": -1.5, "climb_voltage": 80.0,
                   "lead": 3.0}
    return run


def test_dead_time_claims_follow_the_runs():
    ideal = _dead(0.0, 0.0, 0.001)
    broken = [_dead(2e-6, 0.0, 3.0, slips=5), ideal, _dead(2e-6, 7.2, 0.001), _dead(0.0, 7.2, 2.0, slips=3)]
    text = "\n".join(rdoc.dead_time_text(broken, {}))
    assert "dead time of 2 µs at 10000 Hz takes 7.2 V from each phase" in text
    assert "4/π × 7.2 = 9.2 V less" in text and "that is 11.5 % of the voltage" in text  # 9.17 / 80
    assert "The back-EMF falls to the error at 20 rad/s" in text  # 7.2 / (4 x 0.08975)
    assert "the estimate slips 5 electrical turns, and the car rolls back 3 m" in text
    assert "With the compensation the run equals the ideal inverter's" in text
    assert "took it) breaks the run" in text
    held = [_dead(2e-6, 0.0, 0.002), ideal, _dead(2e-6, 7.2, 0.5, speed_rms=3.0), _dead(0.0, 7.2, 0.002)]
    text = "\n".join(rdoc.dead_time_text(held, {}))
    assert "the car is held all the same (roll-back 0.002 m)" in text and "rolls back" not in text
    assert "With the compensation the run differs from the ideal inverter's" in text
    assert "does no visible harm" in text and "breaks" not in text
