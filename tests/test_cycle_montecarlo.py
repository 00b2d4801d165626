"""The Monte-Carlo on a drive cycle (orchestrator/pmsm_cosim/app/sweeps/cycle_montecarlo_wltc3b.toml,
orchestrator/pmsm_cosim/app/report/robustness/cycle.py): the sweep engine's offset on a signal table and
whole-number draws, a cycle's figures in a sweep's metrics.json and summary.csv, the shipped sweep's design,
the failure rule and its interval on made-up figures, and one short sweep of 2 samples on a 2-worker Dask
cluster with its section of the page."""

from __future__ import annotations

import collections
import copy
import json
import math
import re
import statistics

import numpy as np
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app.drive import packaged_scenario
from pmsm_cosim.app.metrics.summary import SUMMARY_METRICS, summary_metrics
from pmsm_cosim.app.report import robustness as rr
from pmsm_cosim.app.report.robustness import cycle as rc
from pmsm_cosim.app.studies import load_sweep, packaged_sweep, parse_sweep
from pmsm_cosim.engine.errors import CosimError
from pmsm_cosim.engine.system import read_toml
from pmsm_cosim.sweeps import prepare_runs, read_summary, run_sweep
from pmsm_ev import cycles as pcycles
from pmsm_ev.params import MotorParams, PlantParams, VehicleParams

NAME = rr.CYCLE_MONTE_CARLO


def _data(**changes) -> dict:
    data = copy.deepcopy(read_toml(packaged_sweep(NAME), "sweep file"))
    for key, value in changes.items():
        if key in ("samples", "seed"):
            data["random"][key] = value
        else:
            data[key] = value
    return data


# --- the sweep engine: offset.SIGNAL, integers ------------------------------------------------------

def test_offset_adds_to_the_signal_table_and_r_w_resamples_the_cycle(tmp_path):
    project_fmus()
    base = packaged_scenario("wltc3b-if")
    path = tmp_path / "s.toml"
    path.write_text(f'system = "{base.as_posix()}"\nstop_time = 1.0\n[set]\n"plant.r_w" = 0.3\n'
                    '[grid]\n"offset.delta" = [-1.0, 0.5]\n', encoding="utf-8")
    runs = prepare_runs(load_sweep(path))
    for run, x in zip(runs, (-1.0, 0.5)):
        # the table [[0, 0]] in deg, plus x deg: the profile is in the input's unit, rad
        assert list(run.spec.signals["delta"].profile.values) == [math.radians(0.0 + x)]
    assert runs[0].signature != runs[1].signature
    # the cycle's omega_ref made with the run's r_w: omega = v n_g / r_w
    sig = runs[0].spec.signals["omega_ref"]
    ref = pcycles.speed_reference(pcycles.load("wltc3b"), 0.3, VehicleParams().n_g, sig.dt)
    assert list(sig.profile.values) == ref.omega.tolist()
    assert "r_w = 0.3 m" in sig.origin


def test_a_system_with_a_road_sweeps(tmp_path):
    """[road] (a RouteProfile component by position) and [cycle] in a sweep's system: each run carries the
    road component, its FMU shipped with the others, and the sweep's mass."""
    project_fmus()
    base = packaged_scenario("wltc3b-if").read_text(encoding="utf-8")
    with_road = base.replace("\n[cycle]", '\n[road]\nname = "hilly"\n\n[cycle]', 1)
    (tmp_path / "sys.toml").write_text(with_road, encoding="utf-8")
    (tmp_path / "s.toml").write_text('system = "sys.toml"\nstop_time = 1.0\n[grid]\n"plant.m_v" = [900.0, 1200.0]\n',
                                     encoding="utf-8")
    runs = prepare_runs(load_sweep(tmp_path / "s.toml"))
    for run, m_v in zip(runs, (900.0, 1200.0)):
        assert run.spec.component("road").start["road"] == "hilly" and "road" in run.fmus
        assert "delta" not in run.spec.signals  # the road drives plant.delta by position
        assert {(c.src, c.src_var, c.dst, c.dst_var) for c in run.spec.connections} >= {
            ("plant", "x_vehicle", "road", "x"), ("road", "delta", "plant", "delta")}
        assert run.spec.component("plant").start["m_v"] == m_v
        assert run.spec.signals["omega_ref"].cycle.name == "wltc3b"


def test_integers_law_draws_whole_numbers_low_to_high_included():
    data = {"system": "scenario1", "random": {"samples": 400, "seed": 3, "plant.sensor_seed": {"integers": [0, 2]}}}
    values = [r.params["plant.sensor_seed"] for r in parse_sweep(data).runs]
    assert all(type(v) is int for v in values)
    assert set(values) == {0, 1, 2}
    assert min(collections.Counter(values).values()) > 400 / 3 - 4 * math.sqrt(400 * 2 / 9)
    for bad, msg in (([0.5, 2], "two whole numbers"), ([3, 2], "low must be <= high"), ([1], r"\[low, high\]")):
        data["random"]["plant.sensor_seed"] = {"integers": bad}
        with pytest.raises(CosimError, match=msg):
            parse_sweep(data)
    data["random"]["fmu.ctrl"] = {"integers": [0, 2]}
    data["random"]["plant.sensor_seed"] = {"integers": [0, 2]}
    with pytest.raises(CosimError, match="takes a choice of values, not a range"):
        parse_sweep(data)


def test_summary_metrics_of_a_cycle_run():
    m = {"trace": {"inside_share": 0.9925}, "synchronism": {"slipped_turns": 2, "fault_latched": True, "episodes": 3,
                                                            "roll_back_m": 0.004},
         "energy": {"dc_Wh_per_km": 131.5}, "identification": {"saliency": 1.069, "saliency_plant": 1.106,
                                                                 "blind": True}}
    s = summary_metrics(m)
    assert tuple(s) == SUMMARY_METRICS
    assert (s["inside_share"], s["slipped_turns"], s["episodes"], s["roll_back_m"], s["fault_latched"],
            s["dc_Wh_per_km"]) == (0.9925, 2.0, 3.0, 0.004, 1.0, 131.5)
    assert (s["saliency_id"], s["saliency_plant"], s["blind"]) == (1.069, 1.106, 1.0)
    s = summary_metrics({"synchronism": {"fault_latched": False}, "energy": {"dc_Wh_per_km": None}})
    assert s["fault_latched"] == 0.0
    assert all(math.isnan(s[k]) for k in ("inside_share", "slipped_turns", "episodes", "roll_back_m", "dc_Wh_per_km",
                                           "saliency_id", "saliency_plant", "blind"))


def test_the_wide_injection_sweep_draws_the_stated_design():
    """cycle_montecarlo_injection_wide: each sample on WLTC 3b and UDDS, the spread its file states (L_d, L_q
    +-15 % each, knees +-25 %, R_s 0..+60 %, psi -15..0 %, grade +-4 %, offsets +-1.5 A, gains +-2 %, the
    dead-time compensation +-30 % of the 7.2 V the 2 us dead time gives, sigma = 1.5 A)."""
    sweep = load_sweep("cycle_montecarlo_injection_wide")
    assert sweep.grid["system"] == ["wltc3b-sensorless", "udds-sensorless"]
    assert len(sweep.runs) == 2 * sweep.samples >= 200
    assert sweep.fixed == {"plant.sensor_noise": 1.5, "plant.dead_time": 2e-6}
    m, fm = MotorParams(), PlantParams()

    def spread(key, nominal):
        law, (lo, hi) = sweep.random[key]
        assert law == "uniform"
        return round(lo / nominal - 1.0, 4), round(hi / nominal - 1.0, 4)

    assert spread("plant.L_d", m.L_d) == spread("plant.L_q", m.L_q) == (-0.15, 0.15)
    assert spread("plant.flux_q_current", fm.flux_q_current) == spread("plant.flux_d_current", fm.flux_d_current) \
        == (-0.25, 0.25)
    assert spread("plant.R_s", m.R_s) == (0.0, 0.6) and spread("plant.psi", m.psi) == (-0.15, 0.0)
    assert spread("ctrl.dead_time_comp", 2e-6 * 360.0 / 1e-4) == (-0.3, 0.3)
    law, (lo, hi) = sweep.random["offset.delta"]
    assert rc.grade_pct(lo) == pytest.approx(-4.0, abs=1e-3) and rc.grade_pct(hi) == pytest.approx(4.0, abs=1e-3)
    assert sweep.random["plant.sensor_offset_a"] == ("uniform", (-1.5, 1.5))
    assert sweep.random["plant.sensor_gain_b"] == ("uniform", (0.98, 1.02))


# --- the shipped sweep --------------------------------------------------------------------------------

def test_the_shipped_sweep_draws_the_stated_design():
    sweep = load_sweep(NAME)
    assert NAME in rr.SWEEPS
    assert len(sweep.runs) == sweep.samples >= 30 and sweep.seed == 24
    assert sweep.fixed == {"plant.sensor_noise": 1.0}
    # occupants: 0..4 x 75 kg on the plant's m_v, each equally likely
    m0 = VehicleParams().m_v
    law, masses = sweep.random["plant.m_v"]
    assert law == "choice" and list(masses) == [m0 + 75.0 * k for k in range(5)]
    assert [rc.occupants(m) for m in masses] == [0, 1, 2, 3, 4]
    # the grade offset: +-2 % as a road angle [deg]
    law, (lo, hi) = sweep.random["offset.delta"]
    assert law == "uniform" and rc.grade_pct(lo) == pytest.approx(-2.0, abs=1e-3) and rc.grade_pct(hi) == \
        pytest.approx(2.0, abs=1e-3)
    # the motor mismatches of the robustness Monte-Carlo, the same laws
    mc = load_sweep(rr.MONTE_CARLO)
    for key in ("plant.R_s", "plant.psi", "plant.L_q", "plant.L_d"):
        assert sweep.random[key] == mc.random[key]
    assert mc.fixed["plant.sensor_noise"] == sweep.fixed["plant.sensor_noise"]
    # every sample in its ranges, a noise seed of its own
    for r in sweep.runs:
        p = r.params
        assert p["plant.m_v"] in masses and lo <= p["offset.delta"] <= hi
        for key in ("plant.R_s", "plant.psi", "plant.L_q", "plant.L_d"):
            a, b = sweep.random[key][1]
            assert a <= p[key] <= b
    assert len({r.params["plant.sensor_seed"] for r in sweep.runs}) == len(sweep.runs)
    # the base system: the sensorless unit on WLTC 3b, 1 A noise, a level road the offset shifts
    assert sweep.system == "wltc3b-if"
    spec = sweep.hooks.load_system(sweep.system)
    assert spec.signals["omega_ref"].cycle.name == "wltc3b" and spec.stop_time == 1800.0
    assert spec.component("ctrl").fmu.name == "FocSensorless.fmu"
    assert spec.component("plant").start["sensor_noise"] == 1.0 and "m_v" not in spec.component("plant").start
    assert list(spec.signals["delta"].profile.values) == [0.0]


def test_occupants_are_equally_likely_over_many_draws():
    values = [r.params["plant.m_v"] for r in parse_sweep(_data(samples=2000)).runs]
    counts = collections.Counter(rc.occupants(v) for v in values)
    assert sorted(counts) == [0, 1, 2, 3, 4]
    sd = math.sqrt(2000 * 0.2 * 0.8)
    assert all(abs(n - 400) < 4 * sd for n in counts.values()), counts


def test_only_selects_sweeps_by_name():
    assert rr.select_sweeps(["cycle_montecarlo_wltc3b"]) == (NAME,)
    assert rr.select_sweeps(["montecarlo"]) == (rr.MONTE_CARLO, rr.MONTE_CARLO_ADAPT, NAME)
    assert rr.select_sweeps(["robust_rs_psi_*"]) == tuple(f"robust_rs_psi_{k}" for k, _ in rr.CONTROLLERS)
    with pytest.raises(CosimError, match="matches no robustness sweep"):
        rr.select_sweeps(["hwfet"])


def test_report_only_runs_the_named_sweeps(tmp_path, monkeypatch):
    from pmsm_cosim.app import cli

    seen = {}

    def fake_run_sweeps(runs_dir, workers, small, stop_time, names, log):
        seen.update(names=names, workers=workers, stop_time=stop_time)
        return {"runs": 0, "elapsed": 0.0, "run_walls": 0.0}

    monkeypatch.setattr(rr, "run_sweeps", fake_run_sweeps)
    assert cli.main(["report", "--robustness", "--only", "cycle_montecarlo", "--runs", str(tmp_path / "runs"),
                     "--out", str(tmp_path / "docs"), "--jobs", "3"]) == 0
    assert seen == {"names": (NAME,), "workers": 3, "stop_time": None}
    text = (tmp_path / "docs" / "robustness.md").read_text(encoding="utf-8")
    assert "`pmsm-cosim report --robustness --only cycle_montecarlo`" in text
    assert cli.main(["report", "--robustness", "--only", "hwfet", "--runs", str(tmp_path / "runs"),
                     "--out", str(tmp_path / "docs")]) == 2


# --- the failure rule and its interval on made-up figures ----------------------------------------------

def test_failure_reasons():
    f = rc.failure_reasons
    assert f("completed", 0.99, 0, 0) == []
    assert f("completed", 1.0, math.nan, math.nan) == []  # a controller without the synchronism figures
    assert f("completed", 0.9899, 0, 0) == ["left the band"]
    assert f("completed", math.nan, 0, 0) == ["left the band"]  # no trace figures: not shown to follow
    assert f("completed", 0.995, 1, 0) == ["slipped a turn"]
    assert f("completed", 0.5, 3, 1) == ["left the band", "slipped a turn", "fault latched"]
    assert f("failed", 1.0, 0, 0) == ["did not complete"]
    assert f("not run", math.nan, math.nan, math.nan) == ["did not complete"]


def test_an_unseen_slip_and_the_verdict_on_a_cycle_sweeps_rows():
    from pmsm_cosim.app.metrics.verdicts import cycle_verdict, unseen_slip, verdict_line

    assert unseen_slip(1.0, 0.0) and unseen_slip(302.0, 0.0)
    assert not unseen_slip(1.0, 1.0) and not unseen_slip(0.0, 0.0) and not unseen_slip(math.nan, math.nan)
    rows = [{"status": "completed", "inside_share": 1.0, "slipped_turns": 0.0, "fault_latched": 0.0, "episodes": 0.0},
            {"status": "completed", "inside_share": "0.9965", "slipped_turns": "302", "fault_latched": "0",
             "episodes": "0"},
            {"status": "completed", "inside_share": 0.98, "slipped_turns": 2.0, "fault_latched": 1.0, "episodes": 3.0},
            {"status": "failed: x", "inside_share": "", "slipped_turns": "", "fault_latched": "", "episodes": ""}]
    v = cycle_verdict(rows)
    assert v == {"samples": 4, "failed": 3, "unseen_slips": 1,
                 "by_reason": {"did not complete": 1, "left the band": 1, "slipped a turn": 2, "fault latched": 1}}
    assert verdict_line(v).startswith("cycle verdict: 3 of 4 samples failed (did not complete 1, left the band 1, ")
    assert cycle_verdict([{"status": "completed", "speed_rms_error": 1.0}]) is None  # not a cycle sweep


def _row(k, status="completed", inside=1.0, slips=0.0, fault=0.0, wh=150.0):
    reasons = rc.failure_reasons(status, inside, slips, fault)
    return {"run": f"{k:04d}", "status": status, "error": "", "inside_share": inside, "slipped_turns": slips,
            "fault_latched": fault, "dc_Wh_per_km": wh if status == "completed" else math.nan,
            "plant.m_v": 900.0 + 75 * (k % 5), "offset.delta": 0.0, "occupants": k % 5, "grade_pct": 0.0,
            "reasons": reasons, "failed": bool(reasons), "wall_time_s": 10.0 + k, "us_per_step": 40.0 + k,
            "macro_steps": 300000.0, "init_time_s": 2.0, "step_size": 1e-4, "stop_time": 30.0, "t_end": 30.0,
            "cycle": "wltc3b"}


def test_where_a_failed_sample_left_the_band():
    """A failed sample's line says where: its longest excursion, its episodes and, when the unit's last change
    of mode came before the excursion ended, that one (a unit that never handed over to FOC again)."""
    stuck = {"t_longest": 141.25, "longest_s": 38.8, "episodes": 0.0, "last_mode": (98.25, 1.0)}
    assert rc.where_text(stuck) == ("longest excursion 38.8 s from 141.2 s; 0 loss-of-synchronism episodes; "
                                    "the unit's last change of mode: to I-f at 98.2 s")
    later = dict(stuck, last_mode=(1794.6, 1.0))  # the last change after the excursion: not the cause
    assert rc.where_text(later) == "longest excursion 38.8 s from 141.2 s; 0 loss-of-synchronism episodes"
    assert rc.where_text({"last_mode": (math.nan, math.nan)}) == ""


def test_findings_on_made_up_samples():
    rows = [_row(k, wh=140.0 + k) for k in range(26)]
    rows += [_row(26, inside=0.98, wh=170.0), _row(27, slips=1.0, fault=1.0, wh=175.0), _row(28, status="failed"),
             _row(29, inside=0.95, slips=2.0, wh=180.0)]
    f = rc.findings(rows, 1800.0)
    assert (f.n, f.failures) == (30, 4)
    assert f.interval == pytest.approx((0.053, 0.297), abs=5e-4)  # Wilson, 4/30
    assert f.interval == rr.wilson(4, 30)
    assert f.by_reason == {"did not complete": 1, "left the band": 2, "slipped a turn": 2, "fault latched": 1}
    wh = [140.0 + k for k in range(26)] + [170.0, 175.0, 180.0]
    assert f.wh == {"count": 29, "mean": pytest.approx(statistics.fmean(wh)), "median": 154.0, "min": 140.0,
                    "max": 180.0}
    c = f.cost  # medians of the 29 completed: wall 10..37 s without 38 -> 24 s, us/step 54
    assert c["samples"] == 29 and c["wall_time_s"] == 24.0 and c["us_per_step"] == 54.0
    assert c["cycle_steps"] == pytest.approx(18e6)
    assert c["cycle_wall_s"] == pytest.approx(54e-6 * 18e6 + 2.0)
    assert c["thousand_h"][16] == pytest.approx(1000 * (54e-6 * 18e6 + 2.0) / 16 / 3600)
    assert rr.wilson(3, 30) == pytest.approx((0.0346, 0.2562), abs=1e-4)


# --- one short sweep on Dask, and its section of the page --------------------------------------------------

STOP = 30.0  #: [s] of WLTC 3b: standing to 11 s (the alignment, I-f), then accelerating to 41.3 km/h at 30 s


def test_two_samples_on_a_two_worker_cluster_and_the_page(tmp_path):
    pytest.importorskip("distributed")
    project_fmus()
    runs = tmp_path / "runs"
    sweep = parse_sweep(_data(samples=2, stop_time=STOP), packaged_sweep(NAME))
    outcome = run_sweep(sweep, runs / NAME, workers=2, quiet=True)
    assert outcome.ran == 2 and [r["status"] for r in outcome.rows] == ["completed", "completed"]
    summary = read_summary(runs / NAME / "summary.csv")
    for row in summary:  # each run's cycle figures in its metrics.json and its summary row, the same numbers
        m = json.loads((runs / NAME / "runs" / row["run"] / "metrics.json").read_text(encoding="utf-8"))
        assert m["trace"]["cycle"] == "wltc3b" and m["trace"]["t_end"] == STOP
        assert float(row["inside_share"]) == m["trace"]["inside_share"]
        assert float(row["slipped_turns"]) == m["synchronism"]["slipped_turns"]
        assert float(row["fault_latched"]) == float(m["synchronism"]["fault_latched"])
        wh = m["energy"]["dc_Wh_per_km"]  # None: no distance driven (a car that did not move forward)
        assert _f(row["dc_Wh_per_km"]) == wh if wh is not None else math.isnan(_f(row["dc_Wh_per_km"]))
        assert m["macro_steps"] == round(STOP / 1e-4)
        start = {c["name"]: c["start"] for c in m["settings"]["components"]}["plant"]
        assert start["m_v"] == float(row["plant.m_v"]) and start["sensor_seed"] == int(row["plant.sensor_seed"])
        assert start["sensor_noise"] == 1.0
    page = rr.generate(out=tmp_path / "docs", runs_dir=runs, stop_time=STOP, run=False, log=lambda msg: None)
    text = page.read_text(encoding="utf-8")
    assert (tmp_path / "docs" / "robustness" / "cycle_monte_carlo.png").stat().st_size > 5000
    assert f"**cut to its first {STOP:g} s** (of 1800 s)" in text
    # the table, from summary.csv by the failure rule
    fails = [float(r["inside_share"]) < 0.99 or float(r["slipped_turns"]) > 0 or float(r["fault_latched"]) > 0
             for r in summary]
    n_fail = sum(fails)
    lo, hi = rr.wilson(n_fail, 2)
    wh = [_f(r["dc_Wh_per_km"]) for r in summary if math.isfinite(_f(r["dc_Wh_per_km"]))]
    line = next(ln for ln in text.splitlines() if ln.startswith("| 2 |"))
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[:4] == ["2", str(n_fail), f"**{n_fail}/2 = {100 * n_fail / 2:.1f} %**",
                         f"{100 * lo:.1f} % … {100 * hi:.1f} %"]
    assert cells[4] == "0"  # none did not complete
    assert cells[5] == str(sum(float(r["inside_share"]) < 0.99 for r in summary))
    assert cells[6] == str(sum(float(r["slipped_turns"]) > 0 for r in summary))
    assert cells[8:] == ([f"{np.mean(wh):.1f}", f"{np.median(wh):.1f}", f"{min(wh):.1f} … {max(wh):.1f}"] if wh
                         else ["–", "–", "–"])
    # what a sample costs: the medians of the runs' own timing
    us = statistics.median(float(r["us_per_step"]) for r in summary)
    wall = statistics.median(float(r["wall_time_s"]) for r in summary)
    cost = re.search(r"(\d+) steps of 100 µs \(30 s\) in ([\d.]+) s of wall time, ([\d.]+) µs per step", text)
    assert cost and cost.group(1) == "300000"
    assert float(cost.group(2)) == pytest.approx(wall, abs=0.05) and float(cost.group(3)) == pytest.approx(us, abs=0.05)
    assert f"1.8e+07 steps, {(us * 18.0 + statistics.median(_init(runs, summary))) / 60:.1f} min a sample" in text


def _f(text: str) -> float:
    """A number of summary.csv (empty: NaN)."""
    return float(text) if text else math.nan


def _init(runs, summary):
    for row in summary:
        m = json.loads((runs / NAME / "runs" / row["run"] / "metrics.json").read_text(encoding="utf-8"))
        yield m["init_time_s"]
