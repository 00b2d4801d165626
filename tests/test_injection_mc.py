"""The section of docs/robustness.md on the cycle Monte-Carlo with injection
(orchestrator/pmsm_cosim/app/report/robustness/injection_mc.py): the shipped design, and the section written
from made-up samples between its markers, judged by the cycle Monte-Carlo's one failure rule."""

from __future__ import annotations

from dataclasses import replace

from pmsm_cosim.app.report.robustness import injection_mc as im
from pmsm_cosim.app.studies import load_sweep
from pmsm_ev.params import MotorParams

COLUMNS = ("run", "status", "plant.m_v", "offset.delta", "inside_share", "slipped_turns", "fault_latched",
           "dc_Wh_per_km", "wall_time_s", "us_per_step")


def test_the_design_is_the_physically_consistent_one():
    d = load_sweep(im.SWEEP)
    assert str(d.system).endswith("wltc3b-sensorless") and d.samples >= 100
    for key in ("plant.L_d", "plant.L_q", "plant.flux_q_current", "plant.flux_d_current", "plant.R_s", "plant.psi",
                "plant.sensor_offset_a", "plant.sensor_gain_b", "ctrl.dead_time_comp"):
        assert key in d.random, key
    assert d.fixed["plant.dead_time"] == 2e-6


def test_the_section_counts_failures_by_the_rule_and_stays_between_its_markers(tmp_path):
    rows = [("0000_a", "completed", 900, 0.1, 1.0, 0, 0, 120.0, 75.0, 4.0),
            ("0001_b", "completed", 975, -0.3, 0.985, 0, 0, 130.0, 76.0, 4.1),  # left the band
            ("0002_c", "completed", 1050, 0.0, 1.0, 2, 0, 125.0, 74.0, 4.0),  # slipped
            ("0003_d", "not run", 900, 0.0, "", "", "", "", "", "")]  # a sweep stopped before it
    (tmp_path / "summary.csv").write_text(
        ",".join(COLUMNS) + "\n" + "\n".join(",".join(str(x) for x in r) for r in rows) + "\n", encoding="utf-8")
    page = tmp_path / "robustness.md"
    page.write_text("# Robustness\n\nbefore\n", encoding="utf-8")
    im.write(page, tmp_path, "a test machine")
    im.write(page, tmp_path, "a test machine")  # again: replaced, not added
    text = page.read_text(encoding="utf-8")
    assert text.count(im.BEGIN) == 1 and text.startswith("# Robustness\n\nbefore\n")
    assert "**3 samples run of the design's 100: 2 failed**" in text
    assert "| 0001_b | left the band |" in text and "| 0002_c | slipped a turn |" in text
    assert "0000_a" not in text.split("| sample |")[1]


def _summary(path, rows):
    path.mkdir(parents=True, exist_ok=True)
    (path / "summary.csv").write_text(
        ",".join(COLUMNS) + "\n" + "\n".join(",".join(str(x) for x in r) for r in rows) + "\n", encoding="utf-8")


def test_the_if_strategy_beside_on_the_samples_both_ran(tmp_path):
    """The I-f sweep is the same design with ``low_speed = "if"`` (the same draws); the section compares the
    samples both have run, by the same rule."""
    d, d_if = load_sweep(im.SWEEP), load_sweep(im.SWEEP_IF)
    assert d_if.random == d.random and d_if.system == d.system and d_if.fixed["ctrl.low_speed"] == "if"
    _summary(tmp_path / "inj", [("0000_a", "completed", 900, 0.1, 1.0, 0, 0, 120.0, 75.0, 4.0),
                                ("0001_b", "completed", 975, -0.3, 1.0, 0, 0, 130.0, 76.0, 4.1)])
    _summary(tmp_path / "if", [("0000_a", "completed", 900, 0.1, 1.0, 0, 0, 122.5, 75.0, 4.0),
                               ("0001_b", "completed", 975, -0.3, 1.0, 3, 0, 131.0, 76.0, 4.1),  # slipped
                               ("0002_c", "not run", 900, 0.0, "", "", "", "", "", "")])
    text = "\n".join(im.section(tmp_path / "inj", "a test machine", tmp_path / "if"))
    assert "**2 samples run with both: injection 0 failed, I-f 1 failed**" in text
    assert "| 0001_b | passed | slipped a turn |" in text
    assert "both passed (1)" in text and "I-f minus injection +2.5 … +2.5 Wh/km" in text


def test_a_fresh_draw_reported_with_its_own_seed(tmp_path):
    """A fresh draw is the shipped design with another seed (its sweep.toml copied beside its runs): the
    section names that seed and judges its samples by the same rule."""
    from pmsm_cosim.app.studies import packaged_sweep

    _summary(tmp_path / "inj", [("0000_a", "completed", 900, 0.1, 1.0, 0, 0, 120.0, 75.0, 4.0)])
    fresh = tmp_path / "fresh"
    _summary(fresh, [("0000_x", "completed", 900, 0.2, 1.0, 0, 0, 121.0, 75.0, 4.0),
                     ("0001_y", "completed", 975, -0.1, 0.97, 0, 0, 133.0, 76.0, 4.1)])  # left the band
    text = packaged_sweep(im.SWEEP).read_text(encoding="utf-8")
    (fresh / "sweep.toml").write_text(text.replace("seed = 36", "seed = 41").replace("samples = 100", "samples = 2"),
                                      encoding="utf-8")
    out = "\n".join(im.section(tmp_path / "inj", "a test machine", fresh=fresh))
    assert "drawn again with seed 41 (2 samples planned" in out
    assert "**2 samples run: 1 failed**" in out and "- 0001_y: left the band" in out


def test_the_design_sentence_is_the_sweep_files():
    """The section's account of the design (ranges, dead time, noise, seed) is computed from the sweep file it
    loads, not typed beside it: another seed or range in the file is another sentence."""
    d = load_sweep(im.SWEEP)
    text = im.design_text(d)
    assert f"seed {d.seed}" in text and "R_s 0 … +50 %, ψ −12 % … 0" in text and "L_d and L_q ±10 %" in text
    r_s = MotorParams().R_s
    other = replace(d, seed=d.seed + 1, random={**d.random, "plant.R_s": ("uniform", (r_s, 1.25 * r_s)),
                                                 "plant.L_q": ("uniform", (0.95 * MotorParams().L_q,
                                                                           1.05 * MotorParams().L_q))})
    text = im.design_text(other)
    assert f"seed {d.seed + 1}" in text and "R_s 0 … +25 %" in text and "L_d ±10 %, L_q ±5 % at zero current" in text
