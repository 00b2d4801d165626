"""The section of docs/robustness.md on the cycle Monte-Carlo with injection
(orchestrator/pmsm_cosim/app/report/robustness/injection_mc.py): the shipped design, and the section written
from made-up samples between its markers, judged by the cycle Monte-Carlo's one failure rule."""

from __future__ import annotations

from pmsm_cosim.app.report.robustness import injection_mc as im
from pmsm_cosim.app.studies import load_sweep

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
