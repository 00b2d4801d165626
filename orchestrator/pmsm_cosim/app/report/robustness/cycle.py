"""The robustness report's Monte-Carlo on a drive cycle (``cycle_montecarlo_wltc3b.toml``): each sample's
figures from its summary row and metrics.json, the failure rule, the counts with their interval, the Wh/km
distribution, what a sample costs, and its section of the page (its figure: ``figures.cycle_figure``).

**The failure rule** is ``pmsm_cosim.app.metrics.verdicts``' (``failure_reasons``, ``INSIDE_MIN``, ``REASONS``);
the page quotes it.
"""

from __future__ import annotations

import json
import math
import statistics
from dataclasses import dataclass, field
from pathlib import Path

from pmsm_ev import cycles as pcycles
from pmsm_ev import kernels
from pmsm_ev.params import MotorParams, VehicleParams

from ....sweeps import read_summary
from ...metrics.trace import TRACE_BAND_KMH, TRACE_WINDOW_S
from ...metrics.verdicts import INSIDE_MIN, REASONS, failure_reasons
from .interval import wilson

#: one occupant (driver or passenger) [kg] [chosen: the 75 kg of a person in EU 1230/2012's mass in running order]
OCCUPANT_KG = 75.0
#: the worker counts the page prices a thousand samples on
THOUSAND_ON = (2, 16, 64)
#: the sweep parameters of the design: vehicle mass, grade offset
MASS = "plant.m_v"
GRADE = "offset.delta"
_M = MotorParams()
#: the motor mismatches: sweep parameter -> (label, the controller's nominal value)
NOMINAL = {"plant.R_s": ("R_s", _M.R_s), "plant.psi": ("ψ", _M.psi), "plant.L_q": ("L_q", _M.L_q),
           "plant.L_d": ("L_d", _M.L_d)}


#: the sensorless unit's modes (``pmsm_ev.kernels`` MODE_*: metrics.json ``sensorless`` ``mode_changes``)
MODE_NAMES = {kernels.MODE_ALIGN: "alignment", kernels.MODE_IF: "I-f", kernels.MODE_EKF: "FOC on the EKF",
              kernels.MODE_ACQUIRE: "the injection's acquisition", kernels.MODE_POLARITY: "the polarity test",
              kernels.MODE_INJECTION: "FOC on the injection"}


def _num(x) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def occupants(m_v: float, base: float | None = None) -> float:
    """The occupants a vehicle mass stands for: (m_v - the plant's m_v) / OCCUPANT_KG."""
    base = VehicleParams().m_v if base is None else base
    return (m_v - base) / OCCUPANT_KG


def grade_pct(delta_deg: float) -> float:
    """A road angle [deg] as a grade [%]: 100 tan(delta)."""
    return 100.0 * math.tan(math.radians(delta_deg))


def cycle_rows(out: Path) -> list[dict]:
    """summary.csv of the cycle sweep's directory, each row with its numbers, ``occupants``, ``grade_pct``,
    ``reasons`` and ``failed``, and from metrics.json (completed runs) ``macro_steps``, ``init_time_s``,
    ``step_size``, ``stop_time``, ``t_end`` and ``cycle`` (of the trace) and ``t_fault`` [s] (the safe state
    latched; NaN: never)."""
    rows = []
    for row in read_summary(Path(out) / "summary.csv"):
        r = dict(row)
        for key in ("plant.m_v", "offset.delta", "inside_share", "slipped_turns", "fault_latched", "dc_Wh_per_km",
                    "wall_time_s", "us_per_step"):
            r[key] = _num(row.get(key))
        r["occupants"] = occupants(r[MASS]) if math.isfinite(r[MASS]) else math.nan
        r["grade_pct"] = grade_pct(r[GRADE]) if math.isfinite(r[GRADE]) else math.nan
        r["reasons"] = failure_reasons(r["status"], r["inside_share"], r["slipped_turns"], r["fault_latched"])
        r["failed"] = bool(r["reasons"])
        m = {}
        if r["status"] == "completed":
            try:
                m = json.loads((Path(out) / "runs" / r["run"] / "metrics.json").read_text(encoding="utf-8"))
            except (OSError, ValueError):
                m = {}
        trace, sync = m.get("trace") or {}, m.get("synchronism") or {}
        changes = (m.get("sensorless") or {}).get("mode_changes") or []
        r.update(macro_steps=_num(m.get("macro_steps")), init_time_s=_num(m.get("init_time_s")),
                 step_size=_num(m.get("step_size")), stop_time=_num(m.get("stop_time")),
                 t_end=_num(trace.get("t_end")), cycle=trace.get("cycle"), t_fault=_num(sync.get("t_fault")),
                 t_longest=_num(trace.get("t_longest_excursion")), longest_s=_num(trace.get("longest_excursion_s")),
                 episodes=_num(sync.get("episodes")),
                 last_mode=(_num(changes[-1][0]), _num(changes[-1][2])) if changes else (math.nan, math.nan))
        rows.append(r)
    return rows


def where_text(r: dict) -> str:
    """Where a failed sample left the band and what the sensorless unit did: its longest excursion, its
    loss-of-synchronism episodes, and its last change of mode when that came before the excursion's end (a
    unit that never handed over to FOC again)."""
    parts = []
    if math.isfinite(r.get("t_longest", math.nan)):
        parts.append(f"longest excursion {r['longest_s']:.1f} s from {r['t_longest']:.1f} s")
    if math.isfinite(r.get("episodes", math.nan)):
        parts.append(f"{r['episodes']:g} loss-of-synchronism episodes")
    t_last, mode = r.get("last_mode", (math.nan, math.nan))
    if math.isfinite(t_last) and math.isfinite(r.get("t_longest", math.nan)) and mode in MODE_NAMES:
        if t_last <= r["t_longest"] + r["longest_s"]:
            parts.append(f"the unit's last change of mode: to {MODE_NAMES[mode]} at {t_last:.1f} s")
    return "; ".join(parts)


@dataclass
class CycleFindings:
    n: int
    failures: int
    interval: tuple[float, float]  #: Wilson 95 % of failures / n
    by_reason: dict  #: reason -> samples (a sample may have several)
    wh: dict  #: mean, median, min, max [Wh/km] of the completed samples with a figure, and their count
    cost: dict = field(default_factory=dict)


def _stats(values) -> dict:
    v = [x for x in values if math.isfinite(x)]
    if not v:
        return {"count": 0, "mean": math.nan, "median": math.nan, "min": math.nan, "max": math.nan}
    return {"count": len(v), "mean": statistics.fmean(v), "median": statistics.median(v), "min": min(v),
            "max": max(v)}


def sample_cost(rows: list[dict], cycle_duration: float | None) -> dict:
    """What one sample cost (medians over the completed samples: wall time [s], us/step, steps, stop time)
    and, for a whole cycle of ``cycle_duration`` [s], the steps, the wall time of one sample (its us/step times
    the steps, plus its initialisation) and of a thousand on each of ``THOUSAND_ON`` workers [h]."""
    done = [r for r in rows if r["status"] == "completed" and math.isfinite(r["us_per_step"])]
    if not done:
        return {}
    med = {k: statistics.median(r[k] for r in done) for k in ("wall_time_s", "us_per_step", "macro_steps",
                                                               "stop_time", "step_size", "init_time_s")}
    out = {"samples": len(done), **med}
    if cycle_duration and math.isfinite(med["step_size"]) and med["step_size"] > 0:
        steps = cycle_duration / med["step_size"]
        whole = med["us_per_step"] * 1e-6 * steps + (med["init_time_s"] if math.isfinite(med["init_time_s"]) else 0)
        out.update(cycle_duration=cycle_duration, cycle_steps=steps, cycle_wall_s=whole,
                   thousand_h={n: 1000.0 * whole / n / 3600.0 for n in THOUSAND_ON})
    return out


def findings(rows: list[dict], cycle_duration: float | None = None) -> CycleFindings:
    n = len(rows)
    fails = sum(r["failed"] for r in rows)
    by_reason = {reason: sum(reason in r["reasons"] for r in rows) for reason in REASONS}
    wh = _stats(r["dc_Wh_per_km"] for r in rows if r["status"] == "completed")
    return CycleFindings(n, fails, wilson(fails, n), by_reason, wh, sample_cost(rows, cycle_duration))


def cycle_duration_of(rows: list[dict]) -> float | None:
    """The duration [s] of the cycle the samples drove (named in their trace figures), None if unknown."""
    name = next((r["cycle"] for r in rows if r.get("cycle")), None)
    if name is None or name.lower() not in pcycles.names():
        return None
    return float(pcycles.load(name).duration)


# --- the section -----------------------------------------------------------------------------------

def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def _hours(h: float) -> str:
    return f"{h:.1f} h" if h >= 1 else f"{60 * h:.0f} min"


def design_text(design) -> str:
    """What the sweep draws, from its spec (``SweepSpec``)."""
    parts = []
    law = design.random.get(MASS)
    if law and law[0] == "choice":
        n_occ = sorted(occupants(float(v)) for v in law[1])
        parts.append(f"{len(law[1])} vehicle masses m_v = {', '.join(f'{float(v):g}' for v in law[1])} kg, "
                     f"equally likely ({n_occ[0]:g} to {n_occ[-1]:g} occupants of {OCCUPANT_KG:g} kg on the "
                     f"plant's {VehicleParams().m_v:g} kg)")
    law = design.random.get(GRADE)
    if law and law[0] == "uniform":
        a, b = law[1]
        parts.append(f"a grade offset, a constant road angle over the whole cycle, uniform over "
                     f"{grade_pct(a):+.2f} … {grade_pct(b):+.2f} % ({a:+.4g} … {b:+.4g}°)")
    mism = []
    for key, (label, nom) in NOMINAL.items():
        law = design.random.get(key)
        if law and law[0] == "uniform":
            a, b = law[1]
            mism.append(f"{label} {100 * (a / nom - 1):+.0f} … {100 * (b / nom - 1):+.0f} %")
    if mism:
        parts.append("the motor mismatches " + ", ".join(mism) + " (uniform)")
    noise = design.fixed.get("plant.sensor_noise")
    if noise:
        seeded = "plant.sensor_seed" in design.random
        parts.append(f"σ = {noise:g} A noise on each phase current" + (", its seed drawn for each sample"
                                                                          if seeded else ""))
    return "; ".join(parts)


def cycle_text(rows: list[dict], design, fig: Path | None, timing: dict | None = None) -> list[str]:
    """The section of the page: the design, the failure rule, the table of counts and Wh/km, the failed
    samples, the figure and what a sample costs."""
    if not rows:
        return []
    duration = cycle_duration_of(rows)
    f = findings(rows, duration)
    cycle = next((r["cycle"] for r in rows if r.get("cycle")), "the cycle")
    stop = f.cost.get("stop_time", math.nan)
    short = duration is not None and math.isfinite(stop) and stop < duration - 1e-9
    L = ["## Monte-Carlo on a drive cycle", "",
         f"{f.n} samples (of the file's {design.samples}) of `{design.name}.toml` on `{design.system}`, "
         f"the sensorless unit from standstill through {cycle}"
         + (f" **cut to its first {stop:g} s** (of {duration:g} s): the figures are of that part only"
            if short else "") + ": " + design_text(design) + ", all drawn at once. "
         f"A sample **fails** if it did not complete, its speed was inside the ±{TRACE_BAND_KMH:g} km/h / "
         f"±{TRACE_WINDOW_S:g} s tolerance band for "
         f"less than {100 * INSIDE_MIN:g} % of the cycle, it slipped an electrical turn, or the safe state "
         "latched (`robustness/cycle.py`).", "",
         "| samples | failures | failure rate | 95 % interval (Wilson) | "
         + " | ".join(REASONS) + " | Wh/km mean | median | range |",
         "|---" * (7 + len(REASONS)) + "|"]
    lo, hi = f.interval
    wh = f.wh
    wh_cells = (f"{wh['mean']:.1f} | {wh['median']:.1f} | {wh['min']:.1f} … {wh['max']:.1f}" if wh["count"]
                else "– | – | –")
    L.append(f"| {f.n} | {f.failures} | **{f.failures}/{f.n} = {_pct(f.failures / f.n)}** | "
             f"{_pct(lo)} … {_pct(hi)} | " + " | ".join(str(f.by_reason[k]) for k in REASONS) + f" | {wh_cells} |")
    L += ["", f"Wh/km: the DC link's energy over the distance driven (metrics.json `energy` `dc_Wh_per_km`), of "
              f"the {wh['count']} completed samples with a distance; the reasons add up to more than the failures "
              "where a sample failed for several.", ""]
    if fig is not None:
        L += [f"![Monte-Carlo on {cycle}](robustness/{fig.name})", ""]
    bad = [r for r in rows if r["failed"]]
    if bad:
        L += ["Failed samples (vehicle mass, grade offset, share of the cycle inside the band, turns slipped):", ""]
        for r in bad[:10]:
            inside = _pct(r["inside_share"]) if math.isfinite(r["inside_share"]) else "–"
            fault = f" (at {r['t_fault']:g} s)" if math.isfinite(r.get("t_fault", math.nan)) else ""
            L.append(f"- `{r['run']}`: m_v {r[MASS]:g} kg ({r['occupants']:g} × {OCCUPANT_KG:g} kg), grade "
                     f"{r['grade_pct']:+.2f} %, inside {inside}, {r['slipped_turns']:g} turns slipped: "
                     + ", ".join(r["reasons"]).replace(REASONS[3], REASONS[3] + fault)
                     + (f" ({r['error']})" if r.get("error") else "")
                     + (f"; {w}" if (w := where_text(r)) else ""))
        if len(bad) > 10:
            L.append(f"- and {len(bad) - 10} more (summary.csv)")
        L.append("")
    c = f.cost
    if c:
        text = (f"**What a sample costs.** Median over the {c['samples']} completed samples: {c['macro_steps']:.0f} "
                f"steps of {c['step_size'] * 1e6:g} µs ({c['stop_time']:g} s) in {c['wall_time_s']:.1f} s of wall "
                f"time, {c['us_per_step']:.1f} µs per step (metrics.json `wall_time_s`, `us_per_step`, each "
                f"sample on one Dask worker process")
        if timing and timing.get("workers"):
            text += f"; {timing['workers']} workers on {timing.get('cores', '?')} cores, load average {timing['load']}"
        text += ")."
        if "cycle_wall_s" in c:
            text += (f" At that rate a whole {cycle} of {c['cycle_duration']:g} s is {c['cycle_steps']:.3g} steps, "
                     f"{c['cycle_wall_s'] / 60:.1f} min a sample; a thousand samples take "
                     + ", ".join(f"{_hours(h)} on {n} workers" for n, h in c["thousand_h"].items())
                     + " (one sample per worker process, one per core; the sweep engine resumes an interrupted "
                       "sweep).")
        L += [text, ""]
    return L
