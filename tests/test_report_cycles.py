"""The report's section "Drive cycles" (pmsm_cosim.app.report.cycles) built from the first 30 s of wltc3b and
wltc3b-if: its table holds the runs' metrics, its per-phase tables pmsm_cosim.app.metrics.cycle_energy's figures,
the text flags a run inside the band for less than 99 % of the time (and says where and why), and the
figures are written."""

from __future__ import annotations

import csv
import json
import shutil

import numpy as np
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app.cli import main
from pmsm_cosim.app.drive import load_system
from pmsm_cosim.app.metrics import cycle_energy
from pmsm_cosim.app.metrics.rows import KMH
from pmsm_cosim.app.metrics.trace import trace_figures
from pmsm_cosim.app.report import CONFIGS, Data, cycles, select
from pmsm_cosim.engine.recording import read_results
from pmsm_ev import cycles as pcycles

CYCLE_IDS = ["cyc-wltc3b", "cyc-wltc3b-if", "cyc-udds", "cyc-udds-if", "cyc-hwfet",
             "cyc-hwfet-if", "cyc-us06", "cyc-us06-if", "cyc-wltc3b-hilly"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    project_fmus()
    base = tmp_path_factory.mktemp("cyc")
    out = {}
    for cid, scenario in (("cyc-wltc3b", "wltc3b"), ("cyc-wltc3b-if", "wltc3b-if")):
        d = base / cid
        assert main(["run", scenario, "--stop-time", "30", "--out", str(d), "--quiet", "--no-figures"]) == 0
        out[cid] = d
    return out


def cycle_configs():
    return [c for c in CONFIGS if c.section == "cycles"]


def test_the_cycle_configurations_and_only_cyc():
    assert [c.id for c in cycle_configs()] == CYCLE_IDS
    assert [c.id for c in select(CONFIGS, ["cyc"])] == CYCLE_IDS  # --only cyc: just these
    by_id = {c.id: c for c in cycle_configs()}
    assert by_id["cyc-us06-if"].run_args(None, None)[:3] == ["us06-if", "--controller", "sensorless"]
    assert by_id["cyc-wltc3b-hilly"].run_args(60.0, None) == ["wltc3b-hilly", "--controller", "sensored",
                                                              "--stop-time", "60.0"]


def test_the_sensorless_cycle_runs_are_the_if_strategys():
    """The section's sensorless runs are the ``-if`` scenarios, whose system files set the I-f strategy the
    section's cost paragraph measures (alignment and I-f); the ``-sensorless`` ones run the injection."""
    for _, scen, setup in cycles.RUNS:
        strategy = load_system(scen).component("ctrl").start.get("low_speed")
        if setup.key == "sensorless":
            assert scen.endswith("-if") and strategy == "if", scen
            assert load_system(scen.replace("-if", "-sensorless")).component("ctrl").start["low_speed"] == "injection"


def cell(lines: list[str], first: str, second: str) -> list[str]:
    """The cells of the table row starting with ``| first | second |``."""
    row = next(x for x in lines if x.startswith(f"| {first} | {second} |"))
    return [c.strip() for c in row.strip("|").split("|")]


def test_the_section_holds_the_runs_figures_and_writes_its_figures(runs, tmp_path):
    data = Data(cycle_configs(), runs)
    figs = cycles.figures(data, tmp_path / "results")
    names = sorted(p.stem for p in figs)
    assert names == ["cyc_energy_phases", "cyc_envelope", "cyc_wltc3b_angle_mode", "cyc_wltc3b_trace"]
    assert all(p.is_file() and p.stat().st_size > 10_000 for p in figs)
    lines = cycles.render(data, names)
    text = "\n".join(lines)
    # the drive the table shows, named as its scenarios run it: the -if scenarios, the I-f strategy
    assert f"(`-if`, `FocSensorless`: {cycles.LOW_SPEED_TEXT['if']})" in text and "`-sensorless`" not in text
    for cid, scen, label in (("cyc-wltc3b", "wltc3b", "sensored"),
                             ("cyc-wltc3b-if", "wltc3b-if", "sensorless from standstill")):
        m = json.loads((runs[cid] / "metrics.json").read_text())
        r = read_results(runs[cid])
        _, vehicle = cycle_energy.plant_params(m)
        whole = cycle_energy.whole_run(r, vehicle)
        c = cell(lines, scen, label)
        assert c[2] == "yes (30 s)"
        assert c[3] == f"{100 * m['trace']['inside_share']:.2f} %"
        assert c[4] == str(m["trace"]["excursions"])
        assert c[6] == f"{m['trace']['rmse_kmh']:.2f} km/h"
        assert c[8] == str(m["synchronism"]["slipped_turns"]) and c[9] == str(m["synchronism"]["episodes"])
        assert c[10] == f"{m['energy']['dc_Wh_per_km']:.2f}" == f"{whole['energy']['dc_Wh_per_km']:.2f}"
        assert c[11] == f"{100 * whole['regen_share']:.1f} %"
        assert c[12] == f"{whole['balance']['relative']:.2e}"
        assert len(c) == 14  # no wall time: what a run costs is the bench's
        (low,) = cycle_energy.phase_energy(r, pcycles.load("wltc3b"), vehicle)
        p = cell(lines, "low (to 30 s)", label)
        assert p[3] == f"{low['energy']['dc_Wh_per_km']:.2f}"
        assert p[8] == f"{low['energy']['losses_Wh']['copper']:.2f}"
    assert "Every run completed inside the band for at least 99 % of its cycle." in text
    assert "measured up to their end: wltc3b (30 s), wltc3b-if (30 s)" in text
    # what the sensorless start costs: its I-f time is the mode column's
    rl = read_results(runs["cyc-wltc3b-if"])
    t_if = float(np.sum(np.diff(rl["time"])[rl["mode"][:-1] == 1]))
    i = next(k for k, x in enumerate(lines) if x.startswith("| phase | Δ Wh/km"))
    cost = [x.strip() for x in lines[i + 2].strip("|").split("|")]
    assert cost[0] == "low"
    assert cost[8] == f"{t_if:.2f} s" and t_if > 1.0
    for name in names:
        assert f"![{name}](results/{name}.png)" in text


def test_a_run_outside_the_band_is_flagged_with_where_and_why(runs, tmp_path):
    """The sensored run made 3 km/h too fast from 20 to 25 s (its results.csv edited, metrics.json's trace
    recomputed): below 99 %, the longest excursion there, in phase low, ahead of the trace."""
    bad = tmp_path / "cyc-wltc3b"
    shutil.copytree(runs["cyc-wltc3b"], bad)
    with open(bad / "results.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    head = rows[0]
    iv, it = head.index("v_vehicle"), head.index("time")
    for row in rows[1:]:
        if 20.0 - 1e-9 <= float(row[it]) < 25.0 - 1e-9:
            row[iv] = repr(float(row[iv]) + 3.0 / KMH)
    with open(bad / "results.csv", "w", newline="") as fh:
        csv.writer(fh, lineterminator="\n").writerows(rows)
    r = read_results(bad)
    m = json.loads((bad / "metrics.json").read_text())
    m["trace"] = {"cycle": "wltc3b", **trace_figures(r["time"], r["v_vehicle"], pcycles.load("wltc3b"))}
    (bad / "metrics.json").write_text(json.dumps(m))
    assert m["trace"]["inside_share"] < 0.99
    data = Data(cycle_configs(), {"cyc-wltc3b": bad, "cyc-wltc3b-if": runs["cyc-wltc3b-if"]})
    text = "\n".join(cycles.render(data, []))
    share = 100 * m["trace"]["inside_share"]
    assert f"| {share:.2f} % (< 99 %) |" in text
    assert "Runs that miss the 99 % of the band or did not complete, where and why:" in text
    line = next(x for x in text.splitlines() if x.startswith("- **wltc3b, sensored**"))
    t0, length = m["trace"]["t_longest_excursion"], m["trace"]["longest_excursion_s"]
    assert 19.0 <= t0 <= 21.0 and 3.0 <= length <= 6.0
    assert f"inside the band only {share:.2f} % of the time ({m['trace']['excursions']} excursions: low " in line
    assert f"the longest, {length:.2f} s from {t0:.2f} s (phase low" in line and "ahead of the trace" in line
    assert "wltc3b-if" not in text.split("where and why:")[1].split("\n\n")[0]
    # the edited speed no longer matches the plant's wheel energy: the check says so
    assert "within 1 % in every run except wltc3b, sensored (net" in text
    # a run that stopped early says so, with its last row
    m["status"] = "diverged"
    (bad / "metrics.json").write_text(json.dumps(m))
    data = Data(cycle_configs(), {"cyc-wltc3b": bad})
    text = "\n".join(cycles.render(data, []))
    assert "| wltc3b | sensored | diverged (30 s) |" in text
    assert f"the run did not complete (status diverged, last row at {r['time'][-1]:.2f} s)" in text


def test_the_zoom_window_is_a_stop_and_restart_within_the_run():
    c = pcycles.load("wltc3b")
    assert cycles.zoom_window(c, 1800.0) == (525.0, 540.0, (530.0, 532.0))  # the shortest stop, 2 s
    assert cycles.zoom_window(c, 140.0) == (130.0, 140.0, (99.0, 137.0))  # a short run: its first restart
    assert cycles.zoom_window(c, 90.0) is None
