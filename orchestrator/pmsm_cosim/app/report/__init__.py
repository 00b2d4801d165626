"""``pmsm-cosim report``: the observer comparison, from fresh co-simulations, as
``docs/results.md`` with small PNG figures in ``docs/results/``.

Every configuration (:data:`CONFIGS`) is one ``pmsm-cosim run`` of a shipped scenario in
its own process (``--jobs`` at a time), into ``RUNS/<config id>/``. A run is reused, not
rerun, when its ``metrics.json`` says ``completed`` and its ``report-run.json`` holds the
same settings: the command-line arguments, the stop time, and the build hashes of the
FMUs it used. A change to one FMU's sources therefore reruns only the configurations
that use it; ``--only`` restricts (re)running to some configurations and takes the
others from RUNS as they are (same settings, any FMU build).

The tables are :func:`pmsm_cosim.app.compare.summarize` of each run (``compute_metrics``
of ``results.csv``, whole run and after ``T_FROM``); the text around them quotes those
same numbers.
"""

from __future__ import annotations

from pathlib import Path

from ..metrics.rows import T_FROM
from . import cycles, robustness, sensorless, synchronism
from .configs import CONFIGS, OBSERVER_FMUS, SETUPS, Config, select
from .document import RECOVERED, TABLE_KEYS, Data, _figures, load_split, recovery, render
from .runs import _fmu_hashes, _key, reusable, run_configs

__all__ = ["CONFIGS", "OBSERVER_FMUS", "RECOVERED", "SETUPS", "TABLE_KEYS", "T_FROM", "Config", "Data", "generate",
           "load_split", "recovery", "render", "reusable", "robustness", "run_configs", "select", "sensorless",
           "synchronism", "cycles",
           "_fmu_hashes", "_key"]


def generate(out="docs", runs_dir="runs/report", jobs: int = 2, stop_time: float | None = None,
             only=None, force: bool = False, configs: list[Config] | None = None, log=print,
             command: str = "pmsm-cosim report", t_from: float = T_FROM, sync: bool | None = None) -> Path:
    """Run (or reuse) the configurations and the synchronism matrix (``sync``: run the matrix's runs that are not
    up to date, ``force``: all of them; else take its runs in RUNS/sync as they are; default: run it for the whole
    report unless ``only`` names no pattern of "sync"), then write ``OUT/results.md`` and ``OUT/results/*.png``."""
    if sync is None:  # the whole report reruns it; a report of chosen configurations or --only does not
        sync = configs is None and (not only or any(p in "sync" or "sync" in p for p in only))
    configs = list(configs or CONFIGS)
    run_dirs = run_configs(configs, Path(runs_dir), jobs=jobs, stop_time=stop_time, only=only, force=force,
                           log=log)
    data = Data(configs, run_dirs, t_from)
    # the synchronism matrix (its own short runs, in-process): rerun unless --only leaves it out
    sync_dir = Path(runs_dir) / "sync"
    data.sync = (synchronism.run_matrix(sync_dir, jobs=jobs, log=log, force=force) if sync
                 else synchronism.load_matrix(sync_dir))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    figs = _figures(data, out / "results")
    figs += synchronism.figures(data.sync, sync_dir, out / "results") if data.sync else []
    text = render(data, [p.stem for p in figs], stop_time, command)
    path = out / "results.md"
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)
    log(f"report: {path}, {len(figs)} figures in {out / 'results'}")
    return path
