"""The report's sentences that state facts of the drive are computed from the parameters and runs they
describe (docs/architecture.md, "Physics and policy"): with the parameters as shipped each gives the text of
the generated page (docs/results.md as `pmsm-cosim report` wrote it, docs/robustness.md as `pmsm-cosim report
--robustness` did), and a changed parameter changes it. A whole report is ~70 runs, the robustness page
hundreds; these check the sentence-producing functions alone."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import pytest

from pmsm_cosim.app.drive import load_system
from pmsm_cosim.app.metrics.rows import T_FROM
from pmsm_cosim.app.report import cycles, document, speed_range, synchronism
from pmsm_cosim.app.report.robustness import cycle as robustness_cycle
from pmsm_cosim.app.report.robustness import injection_mc
from pmsm_cosim.app.studies import load_sweep
from pmsm_ev.params import ControllerParams, EkfParams, MotorParams, StartupParams, VehicleParams

ROOT = Path(__file__).resolve().parents[1]
PAGE = (ROOT / "docs" / "results.md").read_text(encoding="utf-8")


@pytest.mark.parametrize("name, text", [
    ("columns", lambda: document.columns_text(T_FROM)),
    ("parameters", lambda: "\n".join(document._param_lines(T_FROM))),
    ("EKF4 tuning", document.ekf4_tuning_text),
    ("realism", document.realism_text),
    ("what would change", document.what_would_change_text),
    ("scenario 1", lambda: f"## Scenario 1 ({document.elevation_text('scenario1')})\n"),
    ("scenario 2", lambda: f"## Scenario 2 ({document.elevation_text('scenario2')})\n"),
    ("synchronism", lambda: synchronism.intro(8)),
    ("acceleration route", lambda: speed_range.route_text(speed_range.route(load_system("acceleration"),
                                                                               VehicleParams()))),
])
def test_the_sentences_are_the_pages(name, text):
    """As shipped, each computed sentence is the generated page's, byte for byte."""
    assert text() in PAGE, name


def test_the_ekf_sentences_follow_its_covariances(monkeypatch):
    e = replace(EkfParams(), r_i=1.0, q_omega_ekf4=0.04)
    monkeypatch.setattr(document, "EkfParams", lambda: e)
    assert "R = 1 A² (σ = 1 A)" in document.realism_text()
    assert f"q_ω = 0.04 (rad/s)² per step, {0.04 / e.q_omega:g} times the EKF5's" in document.ekf4_tuning_text()


def test_the_variants_follow_their_system_files(monkeypatch):
    def changed(name):
        spec = load_system(name)
        if name == "scenario2-offset":
            spec.component("plant").start.update(sensor_offset_a=-0.5, sensor_offset_b=1.5)
        if name == "scenario2-angle-error":
            spec.component("ctrl").start["x0_theta"] = 0.25
        return spec

    monkeypatch.setattr(document, "load_system", changed)
    text = document.realism_text()
    assert "(−0.5 A on phase a, +1.5 A on phase b)" in text and "observers guessing 0.25)" in text


def test_the_elevation_headings_follow_the_tables(monkeypatch):
    def changed(name):
        spec = load_system(name)
        table = spec.signals["delta"].profile
        spec.signals["delta"] = replace(spec.signals["delta"], profile=replace(
            table, values=tuple(2 * v for v in table.values), times=tuple(2 * t for t in table.times)))
        return spec

    monkeypatch.setattr(document, "load_system", changed)
    assert document.elevation_text("scenario1") == "elevation 0 → 50 → 0° in 10° steps every 60 s"
    assert document.elevation_text("scenario2") == "0 / 44° alternating every 60 s from 100 s"


def test_the_cycle_settings_are_the_system_files(monkeypatch):
    scenarios = [scen for _, scen, _ in cycles.RUNS]
    assert cycles.setting_text(scenarios) == {"noise": "1", "rows": "0.05", "climb": "10",
                                              "low_speed": cycles.LOW_SPEED_TEXT["if"]}  # the -if scenarios
    assert cycles.setting_text(["udds-sensorless"])["low_speed"] == cycles.LOW_SPEED_TEXT["injection"]

    def changed(name):
        spec = load_system(name)
        if name == "udds":
            spec.component("plant").start["sensor_noise"] = 0.5
        return spec

    monkeypatch.setattr(cycles, "load_system", changed)
    assert cycles.setting_text(scenarios)["noise"] == "…"
    assert cycles.setting_text(["udds"])["noise"] == "0.5"


def test_the_columns_follow_the_friction_and_the_bands(monkeypatch):
    monkeypatch.setattr(document, "MotorParams", lambda: replace(MotorParams(), B_m=2e-3, T_m0=0.1))
    monkeypatch.setattr(document, "SETTLING_BAND", 2.0)
    monkeypatch.setattr(document, "PLATEAU_WINDOW", 3.0)
    text = document.columns_text(T_FROM)
    assert "B_m ω + T_m0 ≈ 0.5 N m" in text  # 2e-3 x 200 rad/s + 0.1
    assert "until it stays within 2 rad/s" in text and "the 3 s means" in text


def test_what_would_change_follows_the_inertia_and_the_rate(monkeypatch):
    m, v = MotorParams(), VehicleParams()
    monkeypatch.setattr(document, "MotorParams", lambda: replace(m, J_m=2 * m.J_m))
    monkeypatch.setattr(document, "ControllerParams", lambda: replace(ControllerParams(), omega_n=5.0))
    monkeypatch.setattr(document, "DT_DEFAULT", 5e-5)
    text = document.what_would_change_text()
    ratio = (2 * m.J_m + v.reflected_inertia) / (2 * m.J_m)
    assert f"J_m = J_eq/{ratio:.0f} (eqs 30-31)" in text
    assert "ω_n = 5 rad/s in every run here" in text and "at 20 kHz" in text


def test_the_synchronism_sentence_follows_its_bands_and_the_alignment(monkeypatch):
    monkeypatch.setattr(synchronism, "SYNC_BAND", 12.0)
    monkeypatch.setattr(synchronism, "SYNC_REL", 0.2)
    monkeypatch.setattr(synchronism, "RECOVERY_BAND", 25.0)
    base = synchronism.drive_params

    def slower(controller, k, strategy="if"):
        p = base(controller, k, strategy)
        return replace(p, startup=replace(StartupParams(), t_sweep=2.0))

    monkeypatch.setattr(synchronism, "drive_params", slower)
    text = synchronism.intro(8)
    assert "more than 12 rad/s + 20 %" in text and "|ω_m − ω_ref| ≤ 25 rad/s" in text
    assert "the unit's 3.3 s alignment" in text


def test_the_acceleration_route_follows_the_wheel():
    v = VehicleParams()
    rt = speed_range.route(load_system("acceleration"), replace(v, r_w=2 * v.r_w))
    base = speed_range.route(load_system("acceleration"), v)
    assert math.isclose(rt["top_kmh"], 2 * base["top_kmh"]) and math.isclose(rt["decel"], 2 * base["decel"])
    assert rt["t_brake"] == base["t_brake"] == 22.5


ROBUSTNESS = (ROOT / "docs" / "robustness.md").read_text(encoding="utf-8")
SUMMARY = ("run,status,plant.m_v,offset.delta,inside_share,slipped_turns,fault_latched,dc_Wh_per_km,wall_time_s,"
           "us_per_step\n0000_a,completed,900,0.1,1.0,0,0,120.0,75.0,4.0\n")


def _failure_rule(lines: list[str]) -> str:
    text = "\n".join(lines)
    start = text.index("A sample **fails**")
    return text[start:text.index(".", text.index("latched", start)) + 1]


def test_the_monte_carlo_failure_rules_are_the_pages(tmp_path):
    """docs/robustness.md (hundreds of whole-cycle runs): its failure rules as the generators state them, the
    trace band's from ``metrics.trace``, are the page's."""
    (tmp_path / "summary.csv").write_text(SUMMARY, encoding="utf-8")
    rule = _failure_rule(robustness_cycle.cycle_text(robustness_cycle.cycle_rows(tmp_path),
                                                     load_sweep("cycle_montecarlo_wltc3b"), None))
    assert "±2 km/h / ±1 s tolerance band" in rule and rule in ROBUSTNESS
    intro = injection_mc.section(tmp_path, "a test machine")[4]
    assert "inside the ±2 km/h band" in intro and intro in ROBUSTNESS


def test_the_monte_carlo_failure_rules_follow_the_band(tmp_path, monkeypatch):
    (tmp_path / "summary.csv").write_text(SUMMARY, encoding="utf-8")
    monkeypatch.setattr(robustness_cycle, "TRACE_BAND_KMH", 3.2)
    monkeypatch.setattr(robustness_cycle, "TRACE_WINDOW_S", 2.0)
    monkeypatch.setattr(injection_mc, "TRACE_BAND_KMH", 3.2)
    rule = _failure_rule(robustness_cycle.cycle_text(robustness_cycle.cycle_rows(tmp_path),
                                                     load_sweep("cycle_montecarlo_wltc3b"), None))
    assert "±3.2 km/h / ±2 s tolerance band" in rule
    assert "inside the ±3.2 km/h band" in injection_mc.section(tmp_path, "a test machine")[4]


def test_the_hill_start_route_is_its_system_files(monkeypatch):
    """The sensorless section's hill start (its grade, stop, stand and restart: the figure, the windows of its
    figures and the text) is read from hill-start-if's system file, not typed beside it."""
    from pmsm_cosim.app.report import sensorless

    assert sensorless.hill_route() == {"grade": 22.0, "grade_at": 20.0, "stop": (30.0, 40.0), "stand": (40.0, 50.0),
                                       "restart": (50.0, 60.0)}

    def later(name):
        spec = load_system(name)
        for sig in ("delta", "omega_ref"):
            table = spec.signals[sig].profile
            spec.signals[sig].profile = replace(table, times=tuple(t + 10.0 if t >= 20.0 else t for t in table.times))
        return spec

    monkeypatch.setattr(sensorless, "load_system", later)
    assert sensorless.hill_route() == {"grade": 22.0, "grade_at": 30.0, "stop": (40.0, 50.0), "stand": (50.0, 60.0),
                                       "restart": (60.0, 70.0)}
