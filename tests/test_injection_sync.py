"""The section of docs/robustness.md on the synchronism matrix with injection
(orchestrator/pmsm_cosim/app/report/robustness/injection_sync.py): each case judged on the issue's targets
against the sensored drive on the same angle, the free roll of a parked car stated from its runs, the section
written between its markers."""

from __future__ import annotations

import math

import pytest

from pmsm_cosim.app.report.robustness import injection_sync as js
from pmsm_ev.params import VehicleParams
from pmsm_ev.scenarios import SYNC_MATRIX


def _result(case, controller, k, roll_back=0.0, slipped=0, episodes=0):
    return {"case": case, "controller": controller, "k": k, "roll_back_m": roll_back, "slipped_turns": slipped,
            "episodes": episodes, "fault_latched": False, "t_spin_standing": 0.0, "recovery_time": 0.5,
            "status": "completed", "wrong_way_speed": 0.0}


def _matrix(**bad):
    out = []
    for case in SYNC_MATRIX:
        for k in range(2):
            out.append(_result(case.name, "sensored", k, roll_back=0.10))
            out.append(_result(case.name, "sensorless", k, **bad.get(case.name, {"roll_back": 0.105})))
    return out


def test_each_case_judged_against_the_sensored_drive_on_the_same_angle(tmp_path):
    table = {r["case"].name: r for r in js.rows(_matrix(creep5={"roll_back": 0.10, "slipped": 1},
                                                          stand={"roll_back": 0.13}), tmp_path)}
    assert all(table["ramp20"]["ok"].values())
    assert table["ramp20"]["extra"] == pytest.approx(0.005)
    assert not table["creep5"]["ok"]["slip"] and table["creep5"]["ok"]["roll-back"]
    assert not table["stand"]["ok"]["roll-back"] and "free_roll" not in table["stand"]  # level at its start


def test_a_parked_car_gets_its_free_roll_from_the_runs_and_the_section_its_markers(tmp_path):
    for k in range(2):  # torque (mode 5) recorded from 0.3 s
        t, modes = [0.0, 0.1, 0.2, 0.3, 0.4], [3.0, 3.0, 4.0, 5.0, 5.0]
        run = tmp_path / f"park16-sensorless-{k}"
        run.mkdir()
        run.joinpath("results.csv").write_text("time,mode\n" + "".join(f"{a},{m}\n" for a, m in zip(t, modes)),
                                               encoding="ascii")
    results = _matrix(park16={"roll_back": 0.20})
    table = {r["case"].name: r for r in js.rows(results, tmp_path)}
    g = VehicleParams().g
    assert table["park16"]["free_roll"] == pytest.approx(0.5 * g * math.sin(math.radians(16)) * 0.3 ** 2)
    page = tmp_path / "robustness.md"
    page.write_text("# head\n\n" + js.BEGIN + "\nOLD-SECTION\n" + js.END + "\n\ntail\n", encoding="utf-8")
    js.write_between(page, js.section(results, tmp_path, "a test machine"), js.BEGIN, js.END)
    text = page.read_text(encoding="utf-8")
    assert text.startswith("# head") and text.rstrip().endswith("tail") and "OLD-SECTION" not in text
    assert "| park16 |" in text and "missed: roll-back" in text and f"{len(SYNC_MATRIX) - 1} of 12" in text
