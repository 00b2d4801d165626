"""The section of docs/robustness.md on the physically consistent cycle Monte-Carlo with injection
(``cycle_montecarlo_wltc3b_injection.toml``): the samples run so far, each judged by the cycle
Monte-Carlo's one failure rule (``cycle.failure_reasons``), the failures with their 95 % interval, the
Wh/km, what a sample cost. Written between the page's markers, the rest of the page left as it is:

    python -m pmsm_cosim.app.report.robustness.injection_mc runs/robustness/cycle_montecarlo_wltc3b_injection
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from pmsm_ev.params import InjectionParams, MotorParams, PlantParams

from ....engine.recording import read_results
from ...drive import load_system
from ...metrics.synchronism import slipped_turns
from ...metrics.trace import TRACE_BAND_KMH
from ...studies import load_sweep
from .cycle import (
    INSIDE_MIN,
    REASONS,
    cycle_duration_of,
    cycle_rows,
    failure_reasons,
    findings,
    grade_pct,
    where_text,
)
from .interval import wilson
from .pages import write_between

SWEEP = "cycle_montecarlo_wltc3b_injection"
SWEEP_IF = "cycle_montecarlo_wltc3b_injection_if"  #: the same samples with the I-f strategy
NOT_RUN = "not run"  #: summary.csv's status of a sample a stopped sweep has not run
BEGIN, END = "<!-- injection-mc: generated -->", "<!-- /injection-mc -->"


def _span(lo: float, hi: float, unit: str = "%") -> str:
    """A drawn range as the page writes it: ±hi when symmetric, else its ends (the unit beside the one not 0)."""
    def signed(x):
        return f"{x:+g}".replace("-", "−")

    if lo == -hi:
        return f"±{hi:g} {unit}"
    if lo == 0:
        return f"0 … {signed(hi)} {unit}"
    return f"{signed(lo)} {unit} … 0" if hi == 0 else f"{signed(lo)} … {signed(hi)} {unit}"


def design_text(design) -> str:
    """What the sweep draws (``design``: its spec), in the page's words: each uniform range in % of the plant's
    nominal value (the motor's, its flux model's knees, the sensors' unit gain, the dead-time compensation's
    v_dc t_d / T_s) or in its own unit, the fixed dead time and noise, the seed."""
    r, fixed, m, p = design.random, design.fixed, MotorParams(), PlantParams()
    spec = load_system(design.system)
    v_dc, dead = spec.component("plant").start.get("v_dc", p.v_dc), fixed.get("plant.dead_time", p.dead_time)

    def pct(key, nominal):
        return _span(*(round(100.0 * (x / nominal - 1.0), 1) for x in r[key][1]))

    def both(a, b, text_a, text_b, what):
        return f"{a} and {b} {text_a}{what}" if text_a == text_b else f"{a} {text_a}, {b} {text_b}{what}"

    grade = [round(grade_pct(x), 1) for x in r["offset.delta"][1]]
    offsets = " / ".join(dict.fromkeys(_span(*r[f"plant.sensor_offset_{ph}"][1], unit="A") for ph in "ab"))
    gains = " / ".join(dict.fromkeys(pct(f"plant.sensor_gain_{ph}", 1.0) for ph in "ab"))
    knees = (pct("plant.flux_q_current", p.flux_q_current), pct("plant.flux_d_current", p.flux_d_current))
    return ("the plant's flux model off the controller's, "
            + both("L_d", "L_q", pct("plant.L_d", m.L_d), pct("plant.L_q", m.L_q), " at zero current")
            + f", the saturation's knees {knees[0] if knees[0] == knees[1] else ' (q), '.join(knees) + ' (d)'}"
            + f"; a hot motor, R_s {pct('plant.R_s', m.R_s)}, ψ {pct('plant.psi', m.psi)}; occupants; a grade offset "
            f"{_span(*grade)}; current-sensor offsets {offsets} and gains {gains}; "
            f"{dead * 1e6:g} µs of dead time, its compensation off by "
            f"{pct('ctrl.dead_time_comp', v_dc * dead / spec.step_size)}; "
            f"{fixed.get('plant.sensor_noise', p.sensor_noise):g} A of noise; seed {design.seed}")


def judged_rows(out: Path) -> list[dict]:
    """``cycle_rows``, each completed sample's slipped turns counted again from its results.csv by
    ``metrics.synchronism.slipped_turns`` as it is now (a sample's metrics.json keeps the count of the code that
    ran it), its failure reasons with them; the samples not run yet (a sweep stopped and to be resumed) left out."""
    rows = [r for r in cycle_rows(out) if r["status"] != NOT_RUN]
    for r in rows:
        path = Path(out) / "runs" / r["run"]
        if r["status"] == "completed" and (path / "results.csv").is_file():
            r["slipped_turns"] = float(slipped_turns(read_results(path), MotorParams().N))
            r["reasons"] = failure_reasons(r["status"], r["inside_share"], r["slipped_turns"], r["fault_latched"])
            r["failed"] = bool(r["reasons"])
    return rows


def beside_lines(rows: list[dict], beside: Path) -> list[str]:
    """The I-f strategy on the same samples (``SWEEP_IF``'s runs in ``beside``): the samples both have run,
    the failures of each by the same rule, the samples where they differ, the Wh/km of each."""
    other = {r["run"]: r for r in judged_rows(beside)}
    both = [(r, other[r["run"]]) for r in rows if r["run"] in other]
    lines = ["### The I-f strategy on the same samples", "",
             f"`pmsm-cosim sweep {SWEEP_IF}` (the same system and draws, `low_speed = \"if\"`: alignment, I-f, "
             "handover), judged by the same rule."]
    if not both:
        return lines + ["", "No sample has run in both yet."]
    f_inj = sum(a["failed"] for a, _ in both)
    f_if = sum(b["failed"] for _, b in both)
    lo, hi = wilson(f_if, len(both))
    lines += ["", f"**{len(both)} samples run with both: injection {f_inj} failed, I-f {f_if} failed** (I-f's 95 % "
              f"interval {100 * lo:.1f} … {100 * hi:.1f} %, Wilson)."]
    differ = [(a, b) for a, b in both if a["failed"] != b["failed"]]
    if differ:
        lines += ["", "| sample | injection | I-f | I-f: where |", "|---|---|---|---|"]
        for a, b in differ:
            inj, i_f = ", ".join(a["reasons"]) or "passed", ", ".join(b["reasons"]) or "passed"
            lines.append(f"| {a['run']} | {inj} | {i_f} | {where_text(b) if b['failed'] else ''} |")
    wh = [(a["dc_Wh_per_km"], b["dc_Wh_per_km"]) for a, b in both
          if not a["failed"] and not b["failed"] and math.isfinite(a["dc_Wh_per_km"] + b["dc_Wh_per_km"])]
    if wh:
        d = [y - x for x, y in wh]
        lines += ["", f"Energy at the DC link on the samples both passed ({len(wh)}): injection "
                  f"{sum(x for x, _ in wh) / len(wh):.1f} Wh/km mean, I-f {sum(y for _, y in wh) / len(wh):.1f}; I-f "
                  f"minus injection {min(d):+.1f} … {max(d):+.1f} Wh/km."]
    return lines


def sample_facts(rows: list[dict], f, median: bool) -> list[str]:
    """The samples' facts beside the failures: the least share inside the band, the loss-of-synchronism
    episodes, the Wh/km at the DC link (``f``: their ``findings``; with its median or not)."""
    inside = [r["inside_share"] for r in rows if math.isfinite(r["inside_share"])]
    episodes = [r["episodes"] for r in rows if math.isfinite(r.get("episodes", math.nan))]
    wh = f.wh
    facts = []
    if inside:
        facts.append(f"Inside the band: the least {100 * min(inside):.2f} % of the cycle.")
    if episodes:
        facts.append(f"Loss-of-synchronism episodes: {sum(episodes):g} over {len(episodes)} samples (in "
                     f"{sum(e > 0 for e in episodes)} of them).")
    if wh["count"]:
        mid = f"{wh['median']:.1f} median, " if median else ""
        facts.append(f"Energy at the DC link: {wh['mean']:.1f} Wh/km mean, {mid}{wh['min']:.1f} … {wh['max']:.1f} "
                     f"over {wh['count']} samples.")
    return facts


def fresh_lines(fresh: Path) -> list[str]:
    """A fresh draw of the same design (the sweep file's copy in ``fresh``, ``sweep.toml``: another seed, maybe
    fewer samples), run with the unit as it is now, judged by the same rule."""
    rows = judged_rows(fresh)
    design = load_sweep(Path(fresh) / "sweep.toml")
    lines = ["### A fresh draw", "",
             f"The same design drawn again with seed {design.seed} ({design.samples} samples planned; "
             f"`{Path(fresh).name}/sweep.toml`, the design above with its `seed` and `samples` changed), the unit "
             "as shipped now (with the hill hold at enable: docs/sensorless.md, \"The hill hold\"; the samples "
             "above ran before it), judged by the same rule."]
    if not rows:
        return lines + ["", "No sample has run yet."]
    f = findings(rows, cycle_duration_of(rows))
    lo, hi = f.interval
    lines += ["", f"**{f.n} samples run: {f.failures} failed** (95 % interval of the failure rate "
              f"{100 * lo:.1f} … {100 * hi:.1f} %, Wilson)."]
    for r in rows:
        if r["failed"]:
            lines.append(f"- {r['run']}: {', '.join(r['reasons'])}; {where_text(r)}")
    for fact in sample_facts(rows, f, median=False):
        lines += ["", fact]
    return lines


def section(out: Path, machine: str, beside: Path | None = None, fresh: Path | None = None) -> list[str]:
    rows = judged_rows(out)
    design = load_sweep(SWEEP)
    planned = design.samples
    f = findings(rows, cycle_duration_of(rows))
    lo, hi = f.interval
    low_speed = load_system(design.system).component("ctrl").start.get("low_speed", InjectionParams().low_speed)
    lines = [BEGIN, "", "## The cycle Monte-Carlo with injection, physically consistent", "",
             f"`pmsm-cosim sweep {SWEEP}` (orchestrator/pmsm_cosim/app/sweeps/{SWEEP}.toml: {design_text(design)}, "
             f"a draw no earlier study used), the unit with `low_speed = \"{low_speed}\"` through the whole WLTC 3b. "
             "A sample fails if "
             f"it did not complete, or was inside the ±{TRACE_BAND_KMH:g} km/h band for less than "
             f"{100 * INSIDE_MIN:.0f} % of the "
             "cycle, or slipped an electrical turn, or latched the safe state.", ""]
    if not rows:
        return lines + ["No sample has run yet.", "", END]
    total = f" of the design's {planned}" if planned else ""
    lines += [f"**{f.n} samples run{total}: {f.failures} failed** (95 % interval of the failure rate "
              f"{100 * lo:.1f} … {100 * hi:.1f} %, Wilson).", ""]
    if f.failures:
        lines += ["| sample | why | where |", "|---|---|---|"]
        for r in rows:
            if r["failed"]:
                lines.append(f"| {r['run']} | {', '.join(r['reasons'])} | {where_text(r)} |")
    else:
        lines.append(f"None: {', '.join(REASONS)}: 0 each.")
    facts = sample_facts(rows, f, median=True)
    cost = f.cost
    if cost:
        facts.append(f"A sample cost {cost['wall_time_s']:.0f} s of wall time ({cost['us_per_step']:.1f} us/step, "
                     f"median) on {machine}, two samples at a time.")
    lines += [""] + [x for fact in facts for x in (fact, "")]
    if beside is not None:
        lines += beside_lines(rows, beside) + [""]
    if fresh is not None:
        lines += fresh_lines(fresh) + [""]
    return lines + [END]


def write(page: Path, out: Path, machine: str, beside: Path | None = None, fresh: Path | None = None) -> None:
    write_between(page, section(out, machine, beside, fresh), BEGIN, END)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m pmsm_cosim.app.report.robustness.injection_mc",
                                description=__doc__.split("\n")[0])
    p.add_argument("runs", help="the sweep's output directory")
    p.add_argument("--page", default="docs/robustness.md", help="the page to write the section into")
    p.add_argument("--machine", default="this machine", help="the machine the samples ran on, for the page")
    p.add_argument("--beside", metavar="RUNS_IF", help=f"the output directory of {SWEEP_IF}: the I-f strategy on "
                                                       "the same samples, reported beside")
    p.add_argument("--fresh", metavar="RUNS_FRESH", help="the output directory of a fresh draw of the same design "
                                                         "(its sweep.toml with another seed), reported after")
    a = p.parse_args(argv)
    beside = Path(a.beside) if a.beside else None
    fresh = Path(a.fresh) if a.fresh else None
    write(Path(a.page), Path(a.runs), a.machine, beside, fresh)
    print("\n".join(section(Path(a.runs), a.machine, beside, fresh)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
