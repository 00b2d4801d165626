"""The report "Robustness" (``docs/robustness.md``, figures in ``docs/robustness/``): where the
observers break when the motor is not its data sheet.

The plant's parameters are swept against the controller's nominal ones (``plant.R_s`` against
``ctrl.R_s``, ...: a model mismatch for the observer) by the shipped sweep files
(``orchestrator/pmsm_cosim/app/sweeps/robust_*.toml``) on a Dask cluster:

* map 1: R_s mismatch (-50 % .. +100 %) x psi mismatch (-20 % .. +20 %), 7 x 5, road step to 11 deg;
* map 2: L_q mismatch (-40 % .. +40 %) x load (road elevation 0 .. 22 deg), 5 x 5;

each for the sensorless unit from standstill (with and without the EKF's psi adaptation), the
stationary-frame EKF5 at a flying start and the paper's EKF5 in its own mode (angle measured, for
reference); a Monte-Carlo run of the sensorless unit (200 samples of every mismatch at once plus
sigma = 1 A sensor noise, with and without the adaptation); the hill start with an inverter
dead time, with and without the controller's compensation; and a Monte-Carlo run on a drive cycle
(WLTC 3b, the sensorless unit: occupants, a grade offset, the mismatches and the noise; :mod:`.cycle`).

In four parts: :mod:`.runs` (the sweeps and running them), :mod:`.metrics` (each run's figures,
the stability rule, the grids and the findings the text states), :mod:`.figures` and
:mod:`.document` (the page). ``generate`` runs the sweeps (a run already completed with the same
settings and FMUs is reused: the sweep engine's resume) and writes the page; every number in it
comes from the runs. ``small=True`` shrinks every grid to 3 x 3 and the Monte-Carlo runs to a few
samples (the drive cycle's to its first seconds; CI, a quick look); ``only`` runs only the sweeps it
names (``runs.select_sweeps``) and takes the others from ``runs_dir`` as they are.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from .cycle import INSIDE_MIN, cycle_rows, failure_reasons, findings
from .document import render
from .figures import cycle_figure, dead_time_figure, map_figure, monte_carlo_figure
from .metrics import (
    DIVERGED_LIMIT,
    SPEED_LIMIT,
    T_FROM,
    Collected,
    classify,
    collect,
    grid_of,
    run_metrics,
    sweep_results,
    wilson,
)
from .runs import (
    CONTROLLERS,
    CYCLE_MONTE_CARLO,
    DEAD_TIME,
    MAPS,
    MONTE_CARLO,
    MONTE_CARLO_ADAPT,
    SMALL_SAMPLES,
    SWEEPS,
    Map,
    run_sweeps,
    select_sweeps,
    sweep_spec,
)

__all__ = ["CONTROLLERS", "CYCLE_MONTE_CARLO", "DEAD_TIME", "DIVERGED_LIMIT", "INSIDE_MIN", "MAPS", "MONTE_CARLO",
           "MONTE_CARLO_ADAPT", "SMALL_SAMPLES", "SPEED_LIMIT", "SWEEPS", "T_FROM", "Collected", "Map", "classify",
           "collect", "cycle_figure", "cycle_rows", "failure_reasons", "findings", "generate", "grid_of", "render",
           "run_metrics", "run_sweeps", "select_sweeps", "sweep_results", "sweep_spec", "wilson"]


def generate(out: Path | str = "docs", runs_dir: Path | str = "runs/robustness", workers: int = 2,
             small: bool = False, stop_time: float | None = None, run: bool = True,
             command: str = "pmsm-cosim report --robustness", log=print, only=None) -> Path:
    """Run the sweeps (unless ``run`` is False: then the runs in ``runs_dir`` as they are) and write
    ``out/robustness.md`` with its figures in ``out/robustness/``. Returns the page's path."""
    out, runs_dir = Path(out), Path(runs_dir)
    timing = None
    record = runs_dir / "generation.json"  # the cost of the last generation that made runs
    if run:
        names = select_sweeps(only) if only else SWEEPS
        timing = run_sweeps(runs_dir, workers, small, stop_time, names=names, log=log)
        timing.update(workers=workers, load=" ".join(f"{x:.2f}" for x in os.getloadavg()), cores=os.cpu_count())
        if timing["runs"]:
            record.write_text(json.dumps(timing, indent=1) + "\n", encoding="utf-8")
    if (timing is None or not timing["runs"]) and record.is_file():
        timing = json.loads(record.read_text(encoding="utf-8"))
    t_from = T_FROM if stop_time is None or stop_time > 1.5 * T_FROM else stop_time / 2.0
    c = collect(runs_dir, t_from)
    fig_dir = out / "robustness"
    fig_dir.mkdir(parents=True, exist_ok=True)
    figs = {}
    for m in MAPS:
        if c.grids.get(m.key):
            figs[m.key] = map_figure(m, c.grids[m.key], fig_dir / f"map_{m.key}.png", t_from)
    for k, (label, rows) in enumerate(c.mc.items()):
        figs[f"mc{k}"] = monte_carlo_figure(rows, fig_dir / f"monte_carlo{'_adapt' if k else ''}.png", label, t_from)
    if c.dead:
        figs["dead"] = dead_time_figure(c.dead, fig_dir / "dead_time_hill.png")
    if c.cycle:
        figs["cycle"] = cycle_figure(c.cycle, fig_dir / "cycle_monte_carlo.png",
                                     f"Monte-Carlo on a drive cycle ({CYCLE_MONTE_CARLO}): {len(c.cycle)} samples, "
                                     f"{sum(r['failed'] for r in c.cycle)} failed")
    page = out / "robustness.md"
    page.write_text(render(c, figs, timing, command, small), encoding="utf-8")
    log(f"wrote {page} and {len(figs)} figures in {fig_dir}")
    return page
