"""The robustness report's runs: the sweeps it is made of (the maps, the Monte-Carlo runs, the dead
time on the hill start), as the shipped sweep files define them, and running them on Dask."""

from __future__ import annotations

import copy
import fnmatch
import json
import time
from dataclasses import dataclass
from pathlib import Path

from pmsm_ev.params import MotorParams

from ....engine.errors import CosimError
from ....engine.system import read_toml
from ....sweeps import local_cluster, run_sweep
from ...studies import load_sweep, packaged_sweep, parse_sweep

#: the controllers of the maps: (key in the sweep names, label)
CONTROLLERS = (("sensorless", "sensorless unit, from standstill"),
               ("sensorless_adapt", "sensorless unit + ψ adaptation"),
               ("ekf5ab", "EKF5 αβ, flying start"),
               ("ekf5paper", "EKF5 paper mode (θ measured), flying start"))
#: the controllers whose control runs on the estimated angle (the paper's EKF5 in its own mode
#: drives on the measured angle: its theta_hat, the integral of omega_hat, may slip harmlessly)
ANGLE_USED = {key: key != "ekf5paper" for key, _ in CONTROLLERS}


@dataclass(frozen=True)
class Map:
    key: str  #: robust_<key>_<controller>
    x: str  #: swept parameter on the x axis
    y: str  #: ... on the y axis
    x_nominal: float  #: the controller's value: the axis is the mismatch in % of it (0: absolute)
    y_nominal: float
    x_label: str
    y_label: str
    title: str


_M = MotorParams()
MAPS = (
    Map("rs_psi", "plant.R_s", "plant.psi", _M.R_s, _M.psi, "plant R_s vs ctrl.R_s [%]",
        "plant ψ vs ctrl.psi [%]", "R_s × ψ mismatch"),
    Map("lq_load", "plant.L_q", "scale.delta", _M.L_q, 0.0, "plant L_q vs ctrl.L_q [%]",
        "road elevation [°]", "L_q mismatch × load"),
)
MONTE_CARLO = "robust_montecarlo_sensorless"
MONTE_CARLO_ADAPT = "robust_montecarlo_sensorless_adapt"
#: the Monte-Carlo sweeps and their labels
MONTE_CARLOS = ((MONTE_CARLO, "sensorless unit"), (MONTE_CARLO_ADAPT, "sensorless unit + ψ adaptation"))
DEAD_TIME = "robust_deadtime_hill"
#: the Monte-Carlo on a drive cycle (WLTC 3b, the sensorless unit; ``cycle.py``)
CYCLE_MONTE_CARLO = "cycle_montecarlo_wltc3b"
SWEEPS = tuple(f"robust_{m.key}_{c}" for m in MAPS for c, _ in CONTROLLERS) + (MONTE_CARLO, MONTE_CARLO_ADAPT,
                                                                              DEAD_TIME, CYCLE_MONTE_CARLO)
SMALL_SAMPLES = 6  #: Monte-Carlo samples of the small version
#: the small version's drive cycle runs stop here [s] (unless a stop time is given): a check, not the cycle
SMALL_CYCLE_STOP_TIME = 30.0


def select_sweeps(patterns, names=SWEEPS) -> tuple[str, ...]:
    """The sweeps whose name matches one of the patterns (fnmatch; a plain word matches any name containing
    it, as the report's ``--only``), in ``names``' order; none matching is an error naming them."""
    pats = [p if any(ch in p for ch in "*?[") else f"*{p}*" for p in patterns]
    chosen = tuple(n for n in names if any(fnmatch.fnmatchcase(n, p) for p in pats))
    if not chosen:
        raise CosimError(f"--only {' '.join(patterns)}: matches no robustness sweep; sweeps: {', '.join(names)}")
    return chosen


def sweep_spec(name: str, small: bool = False, stop_time: float | None = None):
    """The shipped sweep ``name``; ``small``: every grid axis cut to its first, middle and last
    value, the Monte-Carlo run to ``SMALL_SAMPLES`` and the drive cycle's runs to
    ``SMALL_CYCLE_STOP_TIME``; ``stop_time`` overrides the file's."""
    path = packaged_sweep(name)
    if small and stop_time is None and name == CYCLE_MONTE_CARLO:
        stop_time = SMALL_CYCLE_STOP_TIME
    if not small and stop_time is None:
        return load_sweep(path)
    data = copy.deepcopy(read_toml(path, "sweep file"))
    if small:
        full = load_sweep(path).grid  # ranges expanded
        for key in list(data.get("grid", {})):
            values = full[key]
            if len(values) > 3:
                data["grid"][key] = [values[0], values[len(values) // 2], values[-1]]
        if "random" in data:
            data["random"]["samples"] = min(data["random"]["samples"], SMALL_SAMPLES)
    if stop_time is not None:
        data["stop_time"] = float(stop_time)
    return parse_sweep(data, path)


def run_sweeps(runs_dir: Path, workers: int = 2, small: bool = False, stop_time: float | None = None,
               names=SWEEPS, client=None, log=print) -> dict:
    """Run the sweeps ``names`` into ``runs_dir/<name>`` on one local cluster of ``workers``
    processes (or ``client``). Returns {"runs": runs made now, "elapsed": s, "run_walls": s}:
    the sum of the runs' own wall times over the elapsed time is the parallel speed-up seen."""
    from distributed import Client  # noqa: PLC0415 - dask: heavy, only when the sweeps run

    specs = [(name, sweep_spec(name, small, stop_time)) for name in names]
    made, walls = 0, 0.0
    t0 = time.perf_counter()

    def go(c):
        nonlocal made, walls
        for name, spec in specs:
            out = runs_dir / name
            t = time.perf_counter()
            outcome = run_sweep(spec, out, client=c, quiet=True)
            made += outcome.ran
            walls += sum(_wall(out, row["run"]) for row in outcome.rows) if outcome.ran else 0.0
            log(f"{name}: {len(outcome.rows)} runs ({outcome.ran} run now, {outcome.failed} not completed) "
                f"in {time.perf_counter() - t:.1f} s")

    if client is not None:
        go(client)
    else:
        with local_cluster(workers) as cluster, Client(cluster) as c:
            go(c)
    return {"runs": made, "elapsed": time.perf_counter() - t0, "run_walls": walls}


def _wall(out: Path, run: str) -> float:
    try:
        m = json.loads((out / "runs" / run / "metrics.json").read_text(encoding="utf-8"))
        return float(m.get("wall_time_s") or 0.0)
    except (OSError, ValueError):
        return 0.0
