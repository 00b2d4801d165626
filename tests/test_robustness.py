"""Robustness maps (orchestrator/pmsm_cosim/app/report/robustness.py,
orchestrator/pmsm_cosim/app/sweeps/robust_*.toml): the
sweep engine's signal factor, the figures of merit of a run, the failure-rate interval, and a
small version of every map (3 x 3, short runs) on a 2-worker local cluster, page included."""

from __future__ import annotations

import math

import numpy as np
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app.report import robustness as rr
from pmsm_cosim.app.studies import PACKAGED_SWEEPS, load_sweep
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
            "theta_hat": theta - 4 * (w + speed_offset) * 1e-4 - drift, "mode": np.full_like(t, 2.0)}


def test_run_metrics_count_slips_and_classify():
    ok = rr.run_metrics(_synthetic(0.0, 0.5))
    assert ok["speed_rms_after"] == pytest.approx(0.5) and ok["angle_rms_after"] < 1e-9
    assert (ok["slips"], ok["stable"], ok["diverged"]) == (0, True, False)
    biased = rr.run_metrics(_synthetic(0.0, -12.0))
    assert (biased["stable"], biased["diverged"]) == (False, False)
    slipping = rr.run_metrics(_synthetic(2 * np.pi * 1.5, 0.0))  # 1.5 electrical turns per second, 8 s
    assert slipping["slips"] == 12 and slipping["slips_after"] == 12
    assert (slipping["stable"], slipping["diverged"]) == (False, True)


def test_wilson_interval():
    lo, hi = rr.wilson(10, 200)
    assert (lo, hi) == (pytest.approx(0.0274, abs=2e-4), pytest.approx(0.0896, abs=2e-4))
    lo, hi = rr.wilson(0, 200)
    assert lo == 0.0 and hi == pytest.approx(0.0188, abs=2e-4)


def test_small_maps_on_a_two_worker_cluster(tmp_path):
    """Every map 3 x 3 with 1.2 s runs (the sensorless unit is still aligning; the EKF5 flying
    starts hold 200 rad/s), the Monte-Carlo run with a few samples and the dead-time runs, on a
    LocalCluster of 2 workers; then the page with its figures."""
    pytest.importorskip("distributed")
    project_fmus()
    runs = tmp_path / "runs"
    timing = rr.run_sweeps(runs, workers=2, small=True, stop_time=1.2, log=lambda msg: None)
    n_maps = len(rr.MAPS) * len(rr.CONTROLLERS)
    assert timing["runs"] == n_maps * 9 + 2 * rr.SMALL_SAMPLES + 4
    page = rr.generate(out=tmp_path / "docs", runs_dir=runs, small=True, stop_time=1.2, run=False,
                       log=lambda msg: None)
    grids, mc, dead = rr.collect(runs, t_from=0.6)
    for m in rr.MAPS:
        for key, _ in rr.CONTROLLERS:
            g = grids[m.key][key]
            assert g["speed"].shape == (3, 3) and (g["status"] == "completed").all()
            assert g["x"][1] == pytest.approx(0.0)  # the nominal value in the middle
    # the paper's EKF5 on the measured angle, nominal motor, level road: holds 200 rad/s
    g = grids["lq_load"]["ekf5paper"]
    assert g["stable"][0, 1] and g["speed"][0, 1] < 2.0  # 1 % of 200 rad/s, 0.6 s after the flying start
    # the sensorless unit is aligning at standstill (reference 0 until 2.5 s): the rotor swings on
    # the alignment vector by well under 1 rad/s, and does not turn
    assert np.nanmax(grids["rs_psi"]["sensorless"]["speed"]) < 1.0
    assert [len(rows) for rows in mc.values()] == [rr.SMALL_SAMPLES] * 2 and len(dead) == 4
    text = page.read_text(encoding="utf-8")
    assert "Small version" in text and "failure rate" in text and "95 % interval" in text
    for name in ("map_rs_psi.png", "map_lq_load.png", "monte_carlo.png", "monte_carlo_adapt.png",
                 "dead_time_hill.png"):
        assert (tmp_path / "docs" / "robustness" / name).stat().st_size > 5000
