"""Parameter sweeps and Monte-Carlo studies of a system on Dask distributed, on top of the engine.

``spec`` (sweep files: parsing, checks, the list of runs; :class:`SweepHooks`, what an
application adds), ``execute`` (runs prepared on the client, executed on Dask workers),
``summary`` (summary.csv and summary.png). Knows no motor: the figures of merit, the
scenarios by name and the FMUs by name come from the application's hooks.
"""

from .execute import (
    SweepOutcome,
    cpu_count,
    dask_client,
    execute_run,
    is_done,
    local_cluster,
    prepare_runs,
    run_signature,
    run_sweep,
)
from .spec import Param, RunPlan, SweepHooks, SweepSpec, load_sweep, parse_param, parse_sweep, redraw, run_id
from .summary import plot_summary, read_summary, write_summary

__all__ = ["Param", "RunPlan", "SweepHooks", "SweepOutcome", "SweepSpec", "cpu_count", "dask_client", "execute_run",
           "is_done", "load_sweep", "local_cluster", "parse_param", "parse_sweep", "plot_summary", "prepare_runs",
           "read_summary", "redraw", "run_id", "run_signature", "run_sweep", "write_summary"]
