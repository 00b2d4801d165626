"""The section of docs/robustness.md on the synchronism matrix with injection: every case of
``pmsm_ev.scenarios.SYNC_MATRIX`` from its 8 angles, the sensorless unit with ``low_speed = "injection"``
against the sensored drive on the same plant (the algebraic flux model), angle and noise
(``report.synchronism.run_matrix(strategy="injection")``). Each case judged on the issue's targets: the
roll-back within the sensored drive's + ``ROLL_BACK_EXTRA["injection"]``, no turn slipped, no episode, no fault, the
frame never spinning past a standing rotor, back on the reference within ``RECOVERY_LIMIT``.
Where a car parked on a slope rolls back more, the section states the free roll before the unit gives
torque, 1/2 g sin(delta) t^2 with t measured from the runs (an upper bound: no rolling resistance, no
rotating inertia). Written between the page's markers, the rest of the page left as it is:

    python -m pmsm_cosim.app.report.robustness.injection_sync RUNS [--run] [--jobs 2]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from pmsm_ev.kernels import MODE_INJECTION
from pmsm_ev.params import InjectionParams, VehicleParams
from pmsm_ev.scenarios import SYNC_ANGLES, SYNC_MATRIX

from ....engine.recording import read_results
from ...metrics.synchronism import RECOVERY_LIMIT, ROLL_BACK_EXTRA, SPIN_LIMIT
from .. import synchronism
from .pages import write_between

BEGIN, END = "<!-- injection-sync: generated -->", "<!-- /injection-sync -->"
#: the injection's roll-back target [m] (``metrics.synchronism.ROLL_BACK_EXTRA``: within the sensored drive's + 1 cm)
EXTRA = ROLL_BACK_EXTRA["injection"]


def torque_time(run_dir: Path) -> float:
    """The first recorded time [s] with the unit giving torque on the injection (``MODE_INJECTION``); nan if
    never."""
    r = read_results(run_dir)
    hit = np.nonzero(r["mode"] == MODE_INJECTION)[0]
    return float(r["time"][hit[0]]) if len(hit) else math.nan


def rows(results: list[dict], runs_dir: Path) -> list[dict]:
    """Per case: the worst figures over the angles and each target met or not."""
    out = []
    for case in SYNC_MATRIX:
        sl = sorted((r for r in results if r["case"] == case.name and r["controller"] == "sensorless"),
                    key=lambda r: r["k"])
        sd = sorted((r for r in results if r["case"] == case.name and r["controller"] == "sensored"),
                    key=lambda r: r["k"])
        if not sl or len(sl) != len(sd):
            continue
        extra = max(a["roll_back_m"] - b["roll_back_m"] for a, b in zip(sl, sd))
        rec = [r["recovery_time"] for r in sl]
        row = {
            "case": case, "n": len(sl), "roll_back": max(r["roll_back_m"] for r in sl),
            "roll_back_sensored": max(r["roll_back_m"] for r in sd), "extra": extra,
            "slipped": max(r["slipped_turns"] for r in sl), "episodes": sum(r["episodes"] for r in sl),
            "faults": sum(r["fault_latched"] for r in sl), "spin": max(r["t_spin_standing"] for r in sl),
            "recovery": None if any(v is None for v in rec) else max(rec),
            "completed": all(r["status"] == "completed" for r in sl + sd),
        }
        row["ok"] = {
            "roll-back": extra <= EXTRA, "slip": row["slipped"] == 0, "episodes": row["episodes"] == 0,
            "fault": row["faults"] == 0, "spin": row["spin"] <= SPIN_LIMIT,
            "recovery": row["recovery"] is not None and row["recovery"] <= RECOVERY_LIMIT,
            "completed": row["completed"],
        }
        delta = math.radians(case.grade_deg[0][1])
        if not row["ok"]["roll-back"] and delta > 0.0:
            t_torque = max(torque_time(runs_dir / f"{case.name}-sensorless-{k}") for k in range(len(sl)))
            row["free_roll"] = 0.5 * VehicleParams().g * math.sin(delta) * t_torque ** 2
            row["t_torque"] = t_torque
        out.append(row)
    return out


def section(results: list[dict], runs_dir: Path, machine: str) -> list[str]:
    table = rows(results, Path(runs_dir))
    lines = [BEGIN, "", "## The synchronism matrix with injection", "",
             f"Every case of the synchronism matrix (docs/sensorless.md, \"Never lose the car\") from its "
             f"{len(SYNC_ANGLES)} angles, σ = {synchronism.NOISE:g} A: the unit with `low_speed = \"injection\"` "
             "against the sensored drive on the same plant (the algebraic flux model), angle and noise "
             "(`python -m pmsm_cosim.app.report.robustness.injection_sync RUNS --run`, on "
             f"{machine}). Targets: the roll-back within the sensored drive's + {100 * EXTRA:.0f} cm, "
             f"no turn slipped, no episode, no fault, the frame never spinning past a standing rotor for more than "
             f"{SPIN_LIMIT:g} s, back within the recovery band by {RECOVERY_LIMIT:g} s. "
             f"From enable until it first gives torque the unit holds the car with the friction brake "
             f"(`hold_brake` = {InjectionParams().hold_brake:g}: docs/sensorless.md, \"The hill hold\"); the sensored "
             "drive has torque from t = 0 and no hold.", "",
             "| case | roll-back [cm] | sensored [cm] | worst extra [cm] | turns slipped | episodes | faults | "
             "recovery [s] | targets |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in table:
        missed = [name for name, ok in r["ok"].items() if not ok]
        rec = "never" if r["recovery"] is None else f"{r['recovery']:.2f}"
        lines.append(f"| {r['case'].name} | {100 * r['roll_back']:.1f} | {100 * r['roll_back_sensored']:.1f} | "
                     f"{100 * r['extra']:+.1f} | {r['slipped']} | {r['episodes']} | {r['faults']} | {rec} | "
                     f"{'met' if not missed else 'missed: ' + ', '.join(missed)} |")
    met = sum(not [1 for ok in r["ok"].values() if not ok] for r in table)
    lines += ["", f"{met} of {len(table)} cases meet every target."]
    for r in table:
        if "free_roll" in r:
            lines += ["", f"{r['case'].name}: the car stands on {r['case'].grade_deg[0][1]:g}° with no brake from "
                      f"enable, and the unit gives torque only once it has the angle and the magnet's polarity (at "
                      f"{r['t_torque']:.2f} s at the latest here): rolling free that long is "
                      f"{100 * r['free_roll']:.1f} cm (1/2 g sin δ t², an upper bound), of its "
                      f"{100 * r['extra']:+.1f} cm beyond the sensored drive, which has torque from t = 0. A car holds "
                      f"its brake until the drive reports torque (the unit's `mode` output: {MODE_INJECTION:g})."]
    return lines + ["", END]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m pmsm_cosim.app.report.robustness.injection_sync",
                                description=__doc__.split("\n")[0])
    p.add_argument("runs", help="the matrix's run directory")
    p.add_argument("--run", action="store_true", help="run the matrix first (else read the runs there)")
    p.add_argument("--jobs", type=int, default=2, help="runs at a time")
    p.add_argument("--page", default="docs/robustness.md", help="the page to write the section into")
    p.add_argument("--machine", default="this machine", help="the machine the runs ran on, for the page")
    a = p.parse_args(argv)
    runs = Path(a.runs)
    results = (synchronism.run_matrix(runs, jobs=a.jobs, strategy="injection") if a.run
               else synchronism.load_matrix(runs))
    lines = section(results, runs, a.machine)
    write_between(Path(a.page), lines, BEGIN, END)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
