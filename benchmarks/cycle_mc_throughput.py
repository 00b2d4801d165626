"""The cycle Monte-Carlo's throughput: samples an hour on N workers.

    python benchmarks/cycle_mc_throughput.py [--samples 4] [--workers 2] [--sweep NAME] [--seed 901]

Runs ``--samples`` samples of a shipped cycle Monte-Carlo (by default ``cycle_montecarlo_wltc3b_injection``: the
shipped sensorless drive, injection at and near zero speed, through the whole WLTC 3b on a plant whose flux model
is not the controller's) on a local Dask cluster of ``--workers`` worker processes, as ``pmsm-cosim sweep`` runs
them (each sample the whole cycle, its results.csv and metrics.json written, no figures), with its own seed
(``--seed``: not the shipped design's, so that the figure is not of hand-picked samples). It prints each sample's
wall time on its worker and its stepping loop's cost a step, then

* the sweep's throughput: samples / the sweep's wall time x 3600 (the cluster's start-up apart), what a user of
  ``pmsm-cosim sweep`` gets for this many samples (the last samples leave a worker idle when the samples do not
  divide among the workers);
* the steady throughput: workers x 3600 / the mean sample's wall time, what a long study approaches when the
  workers run side by side (on a machine with a free core per worker).

The machine's load average is printed before and after: the workers share the cores with whatever else runs.
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

from pmsm_cosim.app.studies import packaged_sweep, parse_sweep
from pmsm_cosim.engine.system import read_toml
from pmsm_cosim.sweeps import local_cluster, redraw, run_sweep

DEFAULT_SWEEP = "cycle_montecarlo_wltc3b_injection"


def sweep_of(name: str, samples: int, seed: int):
    """The shipped sweep ``name`` drawn again: ``samples`` random samples with ``seed`` (as ``pmsm-cosim sweep NAME
    --samples N --seed S``), named ``..._throughput``."""
    path = packaged_sweep(name)
    data = read_toml(path, "sweep file")
    if "random" not in data:
        sys.exit(f"error: {name} is not a Monte-Carlo sweep (it has no [random] table)")
    data = redraw(data, samples, seed, path)
    data["name"] = f"{data['name']}_throughput"
    return parse_sweep(data, None, path.parent)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=4, help="samples to run (default 4)")
    ap.add_argument("--workers", type=int, default=2, help="worker processes of the local cluster (default 2)")
    ap.add_argument("--sweep", default=DEFAULT_SWEEP, help=f"a shipped Monte-Carlo sweep (default {DEFAULT_SWEEP})")
    ap.add_argument("--seed", type=int, default=901, help="the samples' seed (default 901)")
    a = ap.parse_args(argv)
    if a.samples < 1 or a.workers < 1:
        ap.error("--samples and --workers must be >= 1")
    sweep = sweep_of(a.sweep, a.samples, a.seed)
    load = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="cycle_mc_throughput_") as tmp:
        out = Path(tmp)
        t0 = time.perf_counter()
        with local_cluster(a.workers) as cluster, Client(cluster) as client:
            startup = time.perf_counter() - t0
            t1 = time.perf_counter()
            outcome = run_sweep(sweep, out, client=client, quiet=True)
            elapsed = time.perf_counter() - t1
        samples = []
        for row in outcome.rows:
            m = json.loads((out / "runs" / row["run"] / "metrics.json").read_text(encoding="utf-8"))
            samples.append((row["run"], row["status"], row.get("sample_s"), m.get("us_per_step"),
                            m["settings"]["sweep"]["worker"]))
    load_after = os.getloadavg()
    print(f"{sweep.name}: {a.samples} samples (seed {a.seed}) of {sweep.system} on {a.workers} worker(s), "
          f"{os.cpu_count()} cores; load average before {load[0]:.2f}, after {load_after[0]:.2f}")
    walls = []
    for run, status, wall, us, worker in samples:
        walls.append(wall)
        print(f"  {run}: {status}, {wall:.1f} s on its worker, {us:.2f} us/step ({worker})")
    failed = [run for run, status, *_ in samples if status != "completed"]
    mean = sum(walls) / len(walls)
    print(f"  the sweep: {elapsed:.1f} s (cluster start-up {startup:.1f} s apart): "
          f"{a.samples / elapsed * 3600:.0f} samples an hour")
    print(f"  steady: mean sample {mean:.1f} s: {a.workers} x 3600 / {mean:.1f} = "
          f"{a.workers * 3600 / mean:.0f} samples an hour on {a.workers} workers")
    if failed:
        print(f"  not completed: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
