"""Sweep speed-up: the same runs on a LocalCluster of 2 worker processes vs 1.

    python benchmarks/sweep_speedup.py [--runs 4] [--stop-time 350] [--workers 2]

Each sweep is ``--runs`` equal runs of scenario 2 (stop time ``--stop-time``, by default the
whole scenario, 350 s: what a sweep runs; with short runs the fixed cost of a run, loading
its FMUs and kernels, weighs more and the speed-up is lower); only the
parameter that names the run differs, set to its default value, so every run does the
same work. The time measured is that of :func:`pmsm_cosim.sweeps.run_sweep` on an
already started cluster (submission, runs, files written, summary); the cluster's
start-up (about a second) is printed apart. The figure depends on how busy the machine
is: the load average is printed with it, and so is how the runs were spread (runs per
worker; "concurrency", the sum of the runs' own stepping times over the sweep's time: about
the number of workers when they ran side by side, even if a busy machine slowed each run).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

from distributed import Client

from pmsm_cosim.sweeps import load_sweep, local_cluster, run_sweep


def sweep_file(directory: Path, runs: int, stop_time: float) -> Path:
    # the default q_TL written differently in every run: equal runs, distinct run ids
    values = ", ".join(f'"{2.5e-3:.{4 + k}f}"' for k in range(runs))
    path = directory / "equal_runs.toml"
    path.write_text(f'name = "equal_runs"\nsystem = "scenario2"\nstop_time = {stop_time!r}\n\n'
                    f'[grid]\n"ctrl.q_TL" = [{values}]\n', encoding="utf-8")
    return path


def timed_sweep(path: Path, workers: int, out: Path) -> tuple[float, float, str]:
    """(seconds of the sweep, seconds of the cluster's start-up, how the runs were spread)."""
    t0 = time.perf_counter()
    with local_cluster(workers) as cluster, Client(cluster) as client:
        startup = time.perf_counter() - t0
        t1 = time.perf_counter()
        outcome = run_sweep(load_sweep(path), out, client=client, quiet=True)
        elapsed = time.perf_counter() - t1
    if outcome.failed or outcome.ran != len(outcome.rows):
        sys.exit(f"error: the sweep on {workers} worker(s) did not run every run: {outcome.rows}")
    per_worker: dict[str, int] = {}
    run_walls = 0.0
    for row in outcome.rows:
        m = json.loads((out / "runs" / row["run"] / "metrics.json").read_text(encoding="utf-8"))
        worker = m["settings"]["sweep"]["worker"]
        per_worker[worker] = per_worker.get(worker, 0) + 1
        run_walls += m["wall_time_s"]
    # runs in flight on average: the sum of the runs' own stepping times over the sweep's time
    spread = (f"runs per worker {sorted(per_worker.values(), reverse=True)}, "
              f"mean run {run_walls / len(outcome.rows):.2f} s, concurrency {run_walls / elapsed:.2f}")
    return elapsed, startup, spread


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=4)
    ap.add_argument("--stop-time", type=float, default=350.0, help="stop time of each run [s]")
    ap.add_argument("--workers", type=int, default=2, help="workers of the parallel sweep")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="sweep_speedup_") as tmp:
        tmp = Path(tmp)
        path = sweep_file(tmp, a.runs, a.stop_time)
        load = os.getloadavg()
        t1, s1, d1 = timed_sweep(path, 1, tmp / "one")
        tn, sn, dn = timed_sweep(path, a.workers, tmp / "many")
        load_after = os.getloadavg()
    print(f"{a.runs} equal runs of scenario 2 ({a.stop_time:g} s each, {a.stop_time / 1e-4:.0f} steps), "
          f"{os.cpu_count()} cores")
    print(f"  1 worker : {t1:7.2f} s  (cluster start-up {s1:.2f} s; {d1})")
    print(f"  {a.workers} workers: {tn:7.2f} s  (cluster start-up {sn:.2f} s; {dn})")
    print(f"  speed-up {t1 / tn:.2f} (target >= 1.9 with 2 workers on 2 free cores); "
          f"load average before {load[0]:.2f}, after {load_after[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
