"""pmsm-cosim sweep: sweep files (expansion, one-line errors checked against the FMUs),
runs on a Dask LocalCluster equal to single runs byte for byte, failed runs recorded,
resume, the summary."""

from __future__ import annotations

import json
import math
import textwrap

import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app.cli import main
from pmsm_cosim.app.studies import load_sweep, parse_sweep
from pmsm_cosim.engine.errors import CosimError
from pmsm_cosim.sweeps import read_summary, run_sweep

STOP = 0.5  # [s] short runs: the start-up ramp, 5000 steps


def write_sweep(tmp_path, body: str, name: str = "sw", header: str | None = None):
    header = header if header is not None else f'system = "scenario2"\nstop_time = {STOP}\n'
    path = tmp_path / f"{name}.toml"
    path.write_text(header + textwrap.dedent(body), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def client():
    """One LocalCluster of two single-threaded worker processes for the module."""
    distributed = pytest.importorskip("distributed")
    from pmsm_cosim.sweeps import local_cluster

    project_fmus()  # build the FMUs once, before any sweep
    with local_cluster(2) as cluster, distributed.Client(cluster) as cl:
        assert len(cl.scheduler_info()["workers"]) == 2
        yield cl


def single_run(tmp_path, name: str, *args) -> bytes:
    out = tmp_path / "single" / name
    assert main(["run", "scenario2", "--stop-time", str(STOP), "--no-figures", "-q", "--out", str(out),
                 *args]) == 0
    return out


# --- the sweep file ------------------------------------------------------------------

def test_grid_log_range_and_cross_product(tmp_path):
    sweep = load_sweep(write_sweep(tmp_path, """
        [grid]
        ctrl.q_TL = { from = 1e-6, to = 1e-1, num = 6, scale = "log" }
        "plant.omega_m0" = { from = 0, to = 10, num = 3 }
        "fmu.ctrl" = ["FocEkf5", "FocEkf4"]
    """))
    assert sweep.grid["ctrl.q_TL"] == [1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1]  # exact decades
    assert sweep.grid["plant.omega_m0"] == [0.0, 5.0, 10.0]
    assert sweep.log_scale == {"ctrl.q_TL": True, "plant.omega_m0": False, "fmu.ctrl": False}
    assert len(sweep.runs) == 6 * 3 * 2
    # the last parameter varies fastest; ids are unique, ordered and name the values
    assert [r.params["fmu.ctrl"] for r in sweep.runs[:2]] == ["FocEkf5", "FocEkf4"]
    assert sweep.runs[0].params == {"ctrl.q_TL": 1e-6, "plant.omega_m0": 0.0, "fmu.ctrl": "FocEkf5"}
    assert sweep.runs[-1].params == {"ctrl.q_TL": 0.1, "plant.omega_m0": 10.0, "fmu.ctrl": "FocEkf4"}
    assert sweep.runs[1].id == "0001_q_TL=1e-06_omega_m0=0_ctrl=FocEkf4"
    assert len({r.id for r in sweep.runs}) == len(sweep.runs)


def test_random_samples_are_seeded_and_in_range(tmp_path):
    body = """
        [grid]
        "ctrl.angle_source" = ["measured", "estimated"]
        [random]
        samples = 50
        seed = 7
        "ctrl.q_TL" = { log_uniform = [1e-6, 1e-2] }
        "plant.omega_m0" = { uniform = [-5, 5] }
        "fmu.ctrl" = { choice = ["FocEkf5", "FocEkf5AB"] }
    """
    a = load_sweep(write_sweep(tmp_path, body))
    b = load_sweep(write_sweep(tmp_path, body.replace("seed = 7", "seed = 7"), name="again"))
    c = load_sweep(write_sweep(tmp_path, body.replace("seed = 7", "seed = 8"), name="other"))
    assert len(a.runs) == 2 * 50
    assert [r.params for r in a.runs] == [r.params for r in b.runs]
    assert [r.params for r in a.runs] != [r.params for r in c.runs]
    first = [r.params for r in a.runs[:50]]
    # the same samples at every grid point
    assert [{k: v for k, v in p.items() if k != "ctrl.angle_source"} for p in first] == \
        [{k: v for k, v in r.params.items() if k != "ctrl.angle_source"} for r in a.runs[50:]]
    q = [p["ctrl.q_TL"] for p in first]
    w = [p["plant.omega_m0"] for p in first]
    assert all(1e-6 <= x <= 1e-2 for x in q) and all(-5 <= x <= 5 for x in w)
    # log-uniform: about as many samples in each decade (50 samples, 4 decades)
    per_decade = [sum(10.0 ** (-6 + d) <= x < 10.0 ** (-5 + d) for x in q) for d in range(4)]
    assert min(per_decade) >= 5, per_decade
    assert {p["fmu.ctrl"] for p in first} == {"FocEkf5", "FocEkf5AB"}


@pytest.mark.parametrize("body, message", [
    ('stoptime = 3\n[grid]\n"ctrl.q_TL" = [1]\n', "unknown key 'stoptime' (did you mean: stop_time?)"),
    ('[grid]\n"ctrl.q_tl" = [1e-3]\n', "has no variable 'q_tl' (did you mean: q_TL"),
    ('[grid]\n"ctl.q_TL" = [1e-3]\n', "unknown instance 'ctl' (did you mean: ctrl?)"),
    ('[grid]\n"ctrl.zoh_compensation" = [true, "maybe"]\n', "'maybe' is not a valid Boolean value"),
    ('[grid]\n"ctrl.q_TL" = ["much"]\n', "'much' is not a valid Real value"),
    ('[grid]\n"ctrl.q_TL" = { from = 0, to = 1, num = 3, scale = "log" }\n', "a log range needs from > 0"),
    ('[grid]\n"ctrl.q_TL" = { from = 1, to = 2, num = 0 }\n', "num must be a whole number >= 1"),
    ('[grid]\n"ctrl.q_TL" = { from = 1, to = 2 }\n', "a range needs from, to and num (missing num)"),
    ('[grid]\n"ctrl.q_TL" = { from = 1, to = 2, num = 3, scale = "ln" }\n', "scale must be one of linear, log"),
    ('[grid]\n"ctrl.q_TL" = { form = 1, to = 2, num = 3 }\n', "unknown key 'form' (did you mean: from?)"),
    ('[grid]\n"ctrl.q_TL" = []\n', "the list of values is empty"),
    ('[grid]\n"fmu.ctrl" = ["FocEkf6"]\n', "unknown FMU 'FocEkf6' (did you mean: FocEkf5"),
    ('[grid]\n"fmu.ctrl" = ["nowhere/X.fmu"]\n', "FMU not found"),
    ('[grid]\n"system" = ["scenario3"]\n', "no scenario or system file 'scenario3'"),
    ('[random]\nsamples = 3\n"ctrl.q_TL" = { uniform = [2, 1] }\n', "low must be < high"),
    ('[random]\nsamples = 3\n"ctrl.q_TL" = { log_uniform = [0, 1] }\n', "low must be > 0"),
    ('[random]\nsamples = 3\n"ctrl.q_TL" = { normal = [0, 1] }\n', "unknown key 'normal'"),
    ('[random]\nsamples = 0\n"ctrl.q_TL" = { uniform = [0, 1] }\n', "random.samples must be a whole number >= 1"),
    ('[random]\nsamples = 2\n', "[random] has samples but no parameter"),
    ('[grid]\n"ctrl.q_TL" = [1]\n[random]\nsamples = 2\n"ctrl.q_TL" = { uniform = [0, 1] }\n',
     "ctrl.q_TL is both in [grid] and in [random]"),
    ('metric = "speed_rms"\n[grid]\n"ctrl.q_TL" = [1]\n', "unknown metric 'speed_rms' (did you mean: speed_rms_error"),
    ('[set]\n"ctrl.q_TL" = 1e-3\n', "nothing to sweep"),
    ('[grid]\n"scale.deltaa" = [1.0]\n', "grid.scale.deltaa: the system has no signal 'deltaa' (did you mean: delta"),
    ('[grid]\n"scale.delta" = ["big"]\n', "scale.delta (a factor on the signal's values) must be a finite number"),
    ('[set]\n"ctrl.q_TLL" = 1e-3\n[grid]\n"ctrl.q_i" = [1]\n',
     "set.ctrl.q_TLL: ctrl (FocEkf5.fmu) has no variable 'q_TLL' (did you mean: q_TL"),
])
def test_sweep_file_errors_are_one_line(tmp_path, capsys, body, message):
    path = write_sweep(tmp_path, body)
    assert main(["sweep", str(path), "--dry-run", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    assert message in err[0]
    assert str(path) in err[0]
    assert not (tmp_path / "out").exists()


def test_unknown_shipped_sweep(capsys):
    assert main(["sweep", "ekf5_load_nosie", "--dry-run"]) == 2
    assert "did you mean: ekf5_load_noise?" in capsys.readouterr().err


def test_shipped_sweep_lists_its_runs(capsys):
    assert main(["sweep", "ekf5_load_noise", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "ekf5_load_noise: 7 runs" in out and "ctrl.q_TL = 1e-07" in out and "ctrl.q_TL = 0.1" in out


MC_BODY = """
    [random]
    samples = 4
    seed = 7
    "ctrl.q_TL" = { log_uniform = [1e-6, 1e-1] }
    "plant.R_s" = { uniform = [0.05, 0.07] }
"""


def test_a_monte_carlo_sweep_drawn_again_is_the_file_with_that_seed_and_samples(tmp_path):
    """--seed, --samples: the same design with another draw, as the file edited to that seed and count would
    give; a name of its own (the default output directory)."""
    again = load_sweep(write_sweep(tmp_path, MC_BODY), samples=3, seed=11)
    edited = load_sweep(write_sweep(tmp_path, MC_BODY.replace("samples = 4", "samples = 3")
                                    .replace("seed = 7", "seed = 11"), name="edited"))
    assert again.name == "sw_seed11_n3" and (again.seed, again.samples) == (11, 3)
    assert [r.params for r in again.runs] == [r.params for r in edited.runs]
    assert [r.params for r in again.runs] != [r.params for r in load_sweep(write_sweep(tmp_path, MC_BODY)).runs][:3]
    # the copy beside the results is the sweep that was run: the file's text with its name, samples and seed
    from pmsm_cosim.sweeps.spec import redrawn_text

    copy = tmp_path / "copy" / "sweep.toml"
    copy.parent.mkdir()
    copy.write_text(redrawn_text((tmp_path / "sw.toml").read_text(), again))
    rerun = load_sweep(copy)
    assert (rerun.name, rerun.seed, rerun.samples) == ("sw_seed11_n3", 11, 3)
    assert [r.params for r in rerun.runs] == [r.params for r in again.runs]
    assert "# drawn again" in copy.read_text() and 'log_uniform = [1e-6, 1e-1]' in copy.read_text()


def test_seed_and_samples_on_a_sweep_without_random_are_one_line(tmp_path, capsys):
    path = write_sweep(tmp_path, '[grid]\n"ctrl.q_TL" = [1e-3, 1e-2]\n')
    assert main(["sweep", str(path), "--seed", "3", "--dry-run", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and "this sweep has no [random] table" in err[0], err
    assert main(["sweep", "cycle_montecarlo_wltc3b", "--samples", "2", "--seed", "5", "--dry-run"]) == 0
    assert capsys.readouterr().out.startswith("cycle_montecarlo_wltc3b_seed5_n2: 2 runs into "
                                              "runs/cycle_montecarlo_wltc3b_seed5_n2/runs")


def test_parse_needs_a_system():
    with pytest.raises(CosimError, match="needs system ="):
        parse_sweep({"grid": {"ctrl.q_TL": [1]}})


# --- runs on the cluster --------------------------------------------------------------

Q_VALUES = (1e-4, 1e-3, 1e-2, 1e-1)


def test_sweep_equals_single_runs(tmp_path, client):
    path = write_sweep(tmp_path, f'[grid]\n"ctrl.q_TL" = {list(Q_VALUES)}\n')
    outcome = run_sweep(load_sweep(path), tmp_path / "sweep", client=client, quiet=True)
    assert (outcome.ran, outcome.skipped, outcome.failed) == (4, 0, 0)
    rows = read_summary(tmp_path / "sweep" / "summary.csv")
    assert [float(r["ctrl.q_TL"]) for r in rows] == list(Q_VALUES)
    workers = set(client.scheduler_info()["workers"])
    csvs = []
    for q, row in zip(Q_VALUES, rows):
        run_dir = tmp_path / "sweep" / "runs" / row["run"]
        single = single_run(tmp_path, row["run"], "--set", f"ctrl.q_TL={q!r}")
        mine = (run_dir / "results.csv").read_bytes()
        assert mine == (single / "results.csv").read_bytes()
        csvs.append(mine)
        m_sweep = json.loads((run_dir / "metrics.json").read_text())
        m_single = json.loads((single / "metrics.json").read_text())
        assert m_sweep["status"] == "completed" and m_sweep["macro_steps"] == round(STOP / 1e-4)
        assert [c["fmu"] for c in m_sweep["settings"]["components"]] == \
            [c["fmu"] for c in m_single["settings"]["components"]]
        assert m_sweep["settings"]["components"][0]["start"]["q_TL"] == q  # --set keeps the text "0.0001"
        assert m_sweep["settings"]["sweep"]["parameters"] == {"ctrl.q_TL": q}
        assert m_sweep["settings"]["sweep"]["worker"] in workers
        # summary.csv carries the run's own figures, exactly
        for key in ("speed_rms_error", "omega_hat_rms_error", "theta_error_rms"):
            assert float(row[key]) == m_single[key]
    # the parameter reached the FMU: a noisier load model makes omega_hat follow omega_m
    # more closely during the ramp
    assert len(set(csvs)) == 4
    errs = [float(r["omega_hat_rms_error"]) for r in rows]
    assert errs == sorted(errs, reverse=True)
    assert (tmp_path / "sweep" / "summary.png").stat().st_size > 1000


def failing_sweep(tmp_path, bad: float = -1.0):
    return write_sweep(tmp_path, f'[grid]\n"ctrl.q_TL" = [1e-3, {bad!r}, 1e-2, 1e-1]\n', name="failing")


def test_failed_run_is_recorded_and_resume_skips_completed_runs(tmp_path, client, capsys):
    out = tmp_path / "out"
    # through the command line, on the running cluster (--scheduler): exit code 1, one line per run
    assert main(["sweep", str(failing_sweep(tmp_path)), "--scheduler", client.scheduler.address,
                 "--out", str(out)]) == 1
    lines = capsys.readouterr().out.strip().splitlines()
    assert "0001_q_TL=-1: failed: ctrl (FocEkf5.fmu): fmi2ExitInitializationMode (start values) refused: " \
           "q_TL must be finite and >= 0 (got -1.0)" in "\n".join(lines)
    assert lines[-1].startswith("done: 3 of 4 runs completed (4 run now, 0 already done), 1 not completed")
    rows = read_summary(out / "summary.csv")
    assert [r["status"] for r in rows] == ["completed", "failed", "completed", "completed"]
    assert "q_TL must be finite and >= 0" in rows[1]["error"] and rows[1]["speed_rms_error"] == ""
    assert all(r["error"] == "" and math.isfinite(float(r["speed_rms_error"])) for r in rows[::2])
    assert not (out / "runs" / rows[1]["run"]).exists()  # refused at initialization: nothing written
    done = {r["run"]: (out / "runs" / r["run"] / "results.csv").stat().st_mtime_ns
            for r in rows if r["status"] == "completed"}

    # the same sweep again: only the failed run is tried again
    outcome = run_sweep(load_sweep(failing_sweep(tmp_path)), out, client=client, quiet=True)
    assert (outcome.ran, outcome.skipped, outcome.failed) == (1, 3, 1)
    assert {r: (out / "runs" / r / "results.csv").stat().st_mtime_ns for r in done} == done

    # the bad value corrected: that run (a new id) runs, the other three are still skipped
    outcome = run_sweep(load_sweep(failing_sweep(tmp_path, bad=1e-4)), out, client=client, quiet=True)
    assert (outcome.ran, outcome.skipped, outcome.failed) == (1, 3, 0)
    assert {r: (out / "runs" / r / "results.csv").stat().st_mtime_ns for r in done} == done
    rows = read_summary(out / "summary.csv")
    assert [r["status"] for r in rows] == ["completed"] * 4 and rows[1]["run"] == "0001_q_TL=0.0001"

    # a completed run whose settings changed (another stop time) is run again
    sweep = load_sweep(failing_sweep(tmp_path, bad=1e-4))
    sweep.stop_time = 2 * STOP
    outcome = run_sweep(sweep, out, client=client, quiet=True)
    assert (outcome.ran, outcome.skipped) == (4, 0)


@pytest.mark.slow
def test_local_cluster_of_the_command_and_fmu_choice(tmp_path, capsys):
    """Without --scheduler the command starts (and stops) its own LocalCluster; fmu.ctrl
    takes the shipped controller names."""
    project_fmus()
    path = write_sweep(tmp_path, '[grid]\n"fmu.ctrl" = ["FocEkf5", "FocEkf4"]\n', name="observers")
    assert main(["sweep", str(path), "--workers", "1", "--out", str(tmp_path / "out"), "-q"]) == 0
    rows = read_summary(tmp_path / "out" / "summary.csv")
    assert [r["fmu.ctrl"] for r in rows] == ["FocEkf5", "FocEkf4"]
    ekf4 = single_run(tmp_path, "ekf4", "--controller", str(project_fmus()["FocEkf4"]))
    assert (tmp_path / "out" / "runs" / rows[1]["run"] / "results.csv").read_bytes() == \
        (ekf4 / "results.csv").read_bytes()
    assert (tmp_path / "out" / "sweep.toml").read_text() == path.read_text()


# --- pieces ----------------------------------------------------------------------------

def test_sweep_help(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["sweep", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "--scheduler" in out and "--workers" in out and "docs/sweeps.md" in out


def test_workers_only_for_the_local_cluster(tmp_path, capsys):
    path = write_sweep(tmp_path, '[grid]\n"ctrl.q_TL" = [1e-3]\n')
    assert main(["sweep", str(path), "--scheduler", "tcp://127.0.0.1:1", "--workers", "2"]) == 2
    assert "--workers sizes the local cluster" in capsys.readouterr().err


def test_summary_metrics_of_steps_and_plateaus():
    from pmsm_cosim.app.metrics.summary import SUMMARY_METRICS, summary_metrics

    m = {"speed_rms_error": 0.5, "omega_hat_rms_error": 0.1, "theta_error_rms": 0.01, "theta_error_max": 0.02,
         "steps": [{"max_speed_deviation": 3.0, "settling_time": 1.5},
                   {"max_speed_deviation": 4.0, "settling_time": 2.5}],
         "plateaus": [{"T_L_hat_mean": 10.0, "T_L_mech_mean": 10.5}, {"T_L_hat_mean": 80.0, "T_L_mech_mean": 79.0}]}
    s = summary_metrics(m)
    assert tuple(s) == SUMMARY_METRICS
    assert (s["speed_rms_error"], s["max_speed_deviation"], s["max_settling_time"], s["T_L_hat_error_max"]) == \
        (0.5, 4.0, 2.5, 1.0)
    m["steps"][0]["settling_time"] = None  # never settled
    assert summary_metrics(m)["max_settling_time"] == math.inf
    empty = summary_metrics({"status": "failed: x"})
    assert all(math.isnan(v) for v in empty.values())


def test_count_bar():
    import io

    from pmsm_cosim.engine.progress import CountBar

    class Tty(io.StringIO):
        def isatty(self):
            return True

    stream = Tty()
    bar = CountBar(8, stream=stream)
    bar.update(0, force=True)
    bar.update(3)  # rate-limited: not drawn
    bar.update(3, force=True)
    text = stream.getvalue()
    assert text.count("\r[") == 2 and "3/8 runs" in text and "0/8 runs" in text
    bar.close()
    assert stream.getvalue().endswith("\r")


def test_sigterm_stops_the_sweep_keeping_finished_runs(tmp_path):
    """SIGTERM (like Ctrl-C) ends the sweep: exit code 130, the finished runs and the
    summary kept, the rest 'not run' (and run by the next call)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    project_fmus()
    path = write_sweep(tmp_path, '[grid]\n"ctrl.q_TL" = [1e-3, 1e-2, 1e-1]\n', name="long",
                       header='system = "scenario2"\nstop_time = 5.0\n')
    log = tmp_path / "log.txt"
    with open(log, "w") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "pmsm_cosim.app.cli", "sweep", str(path), "--workers", "1",
                                 "--out", str(tmp_path / "out")], stdout=fh, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 120
        while "[1/3]" not in log.read_text() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGTERM)
        assert proc.wait(timeout=60) == 130, log.read_text()
    finally:
        if proc.poll() is None:
            proc.kill()
    rows = read_summary(tmp_path / "out" / "summary.csv")
    assert [r["status"] for r in rows] == ["completed", "not run", "not run"], log.read_text()
    assert "interrupted: 2 runs not run" in log.read_text()
    assert sorted(p.name for p in (tmp_path / "out" / "runs").iterdir()) == [rows[0]["run"]]


def test_run_signature_follows_values_not_spelling(tmp_path):
    from pmsm_cosim.sweeps import prepare_runs

    project_fmus()
    a = prepare_runs(load_sweep(write_sweep(tmp_path, '[grid]\n"ctrl.q_i" = [1, 2]\n', name="a")))
    b = prepare_runs(load_sweep(write_sweep(tmp_path, '[grid]\n"ctrl.q_i" = [1.0, 2e0]\n', name="b")))
    c = prepare_runs(load_sweep(write_sweep(tmp_path, '[grid]\n"ctrl.q_i" = [1.0, 2.0000001]\n', name="c")))
    assert [r.signature for r in a] == [r.signature for r in b]
    assert a[0].signature == c[0].signature and a[1].signature != c[1].signature
    assert a[0].spec.component("ctrl").start["q_i"] == 1.0 and isinstance(a[0].spec.component("ctrl").start["q_i"],
                                                                           float)


def test_each_sample_reports_its_cost_and_an_eta(tmp_path, client):
    """As each run finishes: its cost (wall seconds on the worker, the loop's us/step) and the time left for
    the rest; summary.csv and metrics.json carry the cost (``sample_s``). Sane values, not exact timings."""
    import io
    import re

    path = write_sweep(tmp_path, '[grid]\n"ctrl.q_TL" = [1e-4, 1e-3, 1e-2]\n', name="cost",
                       header='system = "scenario2"\nstop_time = 0.05\nfigures = false\n')
    stream = io.StringIO()
    outcome = run_sweep(load_sweep(path), tmp_path / "out", client=client, stream=stream)
    assert (outcome.ran, outcome.failed) == (3, 0)
    lines = [line for line in stream.getvalue().splitlines() if line.startswith("[")]
    assert len(lines) == 3
    pattern = (r"^\[(\d)/3\] (\S+): completed, \S+ = \S+; (\d+\.\d) s, (\d+\.\d\d) us/step"
               r"(?:; (\d) left, ETA (\d+\.\d) (s|min|h))?$")
    rows = {r["run"]: r for r in read_summary(tmp_path / "out" / "summary.csv")}
    for k, line in enumerate(lines, start=1):
        m = re.match(pattern, line)
        assert m, line
        assert int(m[1]) == k
        assert (m[5] is None) == (k == 3)  # an ETA while samples are left, none after the last
        if k < 3:
            assert int(m[5]) == 3 - k and float(m[6]) >= 0  # (two workers: a sample may finish with another)
        row = rows[m[2]]
        sample_s, wall, us = float(row["sample_s"]), float(row["wall_time_s"]), float(row["us_per_step"])
        assert 0 < wall <= sample_s < 600 and us > 0
        assert float(m[3]) == round(sample_s, 1) and float(m[4]) == round(us, 2)
        metrics = json.loads((tmp_path / "out" / "runs" / m[2] / "metrics.json").read_text())
        assert metrics["sample_s"] == sample_s
    assert list(read_summary(tmp_path / "out" / "summary.csv")[0])[-3:] == ["wall_time_s", "us_per_step",
                                                                            "sample_s"]
