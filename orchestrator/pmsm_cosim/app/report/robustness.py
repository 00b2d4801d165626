"""The report "Robustness" (``docs/robustness.md``, figures in ``docs/robustness/``): where the
observers break when the motor is not its data sheet.

The plant's parameters are swept against the controller's nominal ones (``plant.R_s`` against
``ctrl.R_s``, ...: a model mismatch for the observer) by the shipped sweep files
(``orchestrator/pmsm_cosim/app/sweeps/robust_*.toml``) on a Dask cluster:

* map 1: R_s mismatch (-50 % .. +100 %) x psi mismatch (-20 % .. +20 %), 7 x 5, road step to 11 deg;
* map 2: L_q mismatch (-40 % .. +40 %) x load (road elevation 0 .. 22 deg), 5 x 5;

each for the sensorless unit from standstill, the stationary-frame EKF5 at a flying start and
the paper's EKF5 in its own mode (angle measured, for reference); a Monte-Carlo run of the
sensorless unit (200 samples of every mismatch at once plus sigma = 1 A sensor noise); and the
hill start with an inverter dead time, with and without the controller's compensation.

``generate`` runs the sweeps (a run already completed with the same settings and FMUs is
reused: the sweep engine's resume) and writes the page; every number in it comes from the
runs. ``small=True`` shrinks every grid to 3 x 3 and the Monte-Carlo run to a few samples (CI,
a quick look).
"""

from __future__ import annotations

import copy
import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pmsm_ev.params import DT_DEFAULT, MotorParams
from pmsm_ev.results import roll_back, row_timing_corrected_angle_error

from ...engine.recording import read_results
from ...engine.system import read_toml
from ...sweeps import local_cluster, read_summary, run_sweep
from ..studies import load_sweep, packaged_sweep, parse_sweep

#: the controllers of the maps: (key in the sweep names, label)
CONTROLLERS = (("sensorless", "sensorless unit, from standstill"),
               ("sensorless_adapt", "sensorless unit + ψ adaptation"),
               ("ekf5ab", "EKF5 αβ, flying start"),
               ("ekf5paper", "EKF5 paper mode (θ measured), flying start"))


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
        "plant ψ vs ctrl.psi [%]", "R_s × ψ mismatch, road step to 11°"),
    Map("lq_load", "plant.L_q", "scale.delta", _M.L_q, 0.0, "plant L_q vs ctrl.L_q [%]",
        "road elevation [°]", "L_q mismatch × load"),
)
MONTE_CARLO = "robust_montecarlo_sensorless"
MONTE_CARLO_ADAPT = "robust_montecarlo_sensorless_adapt"
DEAD_TIME = "robust_deadtime_hill"
SWEEPS = tuple(f"robust_{m.key}_{c}" for m in MAPS for c, _ in CONTROLLERS) + (MONTE_CARLO, MONTE_CARLO_ADAPT,
                                                                              DEAD_TIME)

T_FROM = 20.0  #: the metrics' window starts here [s] (past the start-up and the road step)
#: a run is **stable** if it did not diverge and its speed RMS error after T_FROM is below this
#: [rad/s] (2.5 % of 200 rad/s: a biased speed estimate makes a steady speed error)
SPEED_LIMIT = 5.0
#: a run **diverged** if it did not complete, or its estimate slipped an electrical turn after
#: T_FROM, or its speed RMS error after T_FROM is above this [rad/s] (25 % of 200 rad/s)
DIVERGED_LIMIT = 50.0
SMALL_SAMPLES = 6  #: Monte-Carlo samples of the small version


# --- the sweeps -----------------------------------------------------------------------------------

def sweep_spec(name: str, small: bool = False, stop_time: float | None = None):
    """The shipped sweep ``name``; ``small``: every grid axis cut to its first, middle and last
    value and the Monte-Carlo run to ``SMALL_SAMPLES``; ``stop_time`` overrides the file's."""
    path = packaged_sweep(name)
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


# --- figures of merit of a run ---------------------------------------------------------------------

def run_metrics(r: dict, t_from: float = T_FROM, angle_used: bool = True) -> dict:
    """From a run's results: the speed RMS error and the angle RMS error (row timing removed)
    after ``t_from``; the electrical turns the estimate slipped after it reached the closed loop
    (``slips``) and after ``t_from`` (``slips_after``): whole turns of the unwrapped angle
    error's range; ``diverged`` and ``stable`` (see ``SPEED_LIMIT``, ``DIVERGED_LIMIT``). Slips
    count only where the control uses the estimated angle (``angle_used``): the paper's EKF5 in its
    own mode drives on the measured angle, its theta_hat is the integral of omega_hat."""
    t = r["time"]
    err = np.unwrap(row_timing_corrected_angle_error(r, DT_DEFAULT, _M.N))
    after = t >= t_from
    closed = np.nonzero(r["mode"] == 2.0)[0] if "mode" in r else np.array([0])
    start = int(closed[0]) if len(closed) else len(t)

    def turns(x) -> int:
        return int(math.floor((float(np.max(x)) - float(np.min(x))) / (2 * math.pi))) if len(x) else 0

    speed = float(np.sqrt(np.mean((r["omega_ref"][after] - r["omega_m"][after]) ** 2))) if after.any() else math.nan
    angle = float(np.sqrt(np.mean(np.square((err[after] + math.pi) % (2 * math.pi) - math.pi)))) \
        if after.any() else math.nan
    bias = float(np.mean(r["omega_m"][after] - r["omega_ref"][after])) if after.any() else math.nan
    m = {"speed_rms_after": speed, "speed_bias_after": bias, "angle_rms_after": angle, "slips": turns(err[start:]),
         "slips_after": turns(err[after]), "t_end": float(t[-1]) if len(t) else 0.0}
    m["diverged"] = bool(not math.isfinite(speed) or speed > DIVERGED_LIMIT or (angle_used and m["slips_after"] > 0))
    m["stable"] = bool(not m["diverged"] and speed < SPEED_LIMIT)
    return m


def sweep_results(out: Path, t_from: float = T_FROM, angle_used: bool = True) -> list[dict]:
    """summary.csv of a sweep directory, each row with its ``run_metrics`` (``stable`` False and
    NaN figures for a run that did not complete)."""
    rows = []
    for row in read_summary(out / "summary.csv"):
        row = dict(row)
        if row["status"] == "completed":
            row.update(run_metrics(read_results(out / "runs" / row["run"]), t_from, angle_used))
        else:
            row.update({"speed_rms_after": math.nan, "speed_bias_after": math.nan, "angle_rms_after": math.nan,
                        "slips": None,
                        "slips_after": None, "stable": False, "diverged": row["status"] == "failed"})
        rows.append(row)
    return rows


def wilson(failures: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The Wilson score interval of a proportion failures / n (95 % by default)."""
    if n == 0:
        return math.nan, math.nan
    p = failures / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


def _axis(values, nominal):
    """Axis values: the mismatch in % of the nominal value, or the values as they are."""
    return [100.0 * (v / nominal - 1.0) for v in values] if nominal else list(values)


def grid_of(rows: list[dict], m: Map) -> dict:
    """The map's cells: x and y values (sorted), and per metric an array [y, x]."""
    xs = sorted({float(r[m.x]) for r in rows})
    ys = sorted({float(r[m.y]) for r in rows})
    shape = (len(ys), len(xs))
    g = {"x": _axis(xs, m.x_nominal), "y": _axis(ys, m.y_nominal),
         "speed": np.full(shape, np.nan), "bias": np.full(shape, np.nan), "angle": np.full(shape, np.nan),
         "slips": np.zeros(shape, int), "stable": np.zeros(shape, bool), "diverged": np.zeros(shape, bool),
         "status": np.full(shape, "not run", dtype=object)}
    for r in rows:
        i, j = ys.index(float(r[m.y])), xs.index(float(r[m.x]))
        g["speed"][i, j] = r["speed_rms_after"]
        g["bias"][i, j] = r["speed_bias_after"]
        g["angle"][i, j] = r["angle_rms_after"]
        g["slips"][i, j] = r["slips"] or 0
        g["stable"][i, j] = r["stable"]
        g["diverged"][i, j] = r["diverged"]
        g["status"][i, j] = r["status"]
    return g


# --- figures -----------------------------------------------------------------------------------

def _plt():
    import matplotlib  # noqa: PLC0415 - matplotlib: heavy, only when drawing

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - matplotlib: heavy, only when drawing

    return plt


def _outline(ax, stable: np.ndarray) -> None:
    """Outline the stable cells' region (cell edges between stable and not)."""
    ny, nx = stable.shape
    for i in range(ny):
        for j in range(nx):
            if not stable[i, j]:
                continue
            for di, dj, seg in ((-1, 0, ((j - .5, j + .5), (i - .5, i - .5))),
                                (1, 0, ((j - .5, j + .5), (i + .5, i + .5))),
                                (0, -1, ((j - .5, j - .5), (i - .5, i + .5))),
                                (0, 1, ((j + .5, j + .5), (i - .5, i + .5)))):
                a, b = i + di, j + dj
                if not (0 <= a < ny and 0 <= b < nx) or not stable[a, b]:
                    ax.plot(*seg, color="k", lw=2.2)


def map_figure(m: Map, grids: dict, path: Path) -> Path:
    """Heat maps (one column per controller) of the speed RMS error and the angle RMS error after
    T_FROM; cells annotated, runs that did not complete crossed, the stable region outlined."""
    from matplotlib.colors import LogNorm  # noqa: PLC0415 - matplotlib: heavy, only when drawing

    plt = _plt()
    keys = [k for k, _ in CONTROLLERS if k in grids]
    fig, axes = plt.subplots(2, len(keys), figsize=(4.3 * len(keys), 7.2), squeeze=False)
    for col, key in enumerate(keys):
        g = grids[key]
        for row, (metric, unit, lo, hi) in enumerate((("speed", "rad/s", 1e-2, 1e2), ("angle", "rad", 1e-3, 2.0))):
            ax = axes[row, col]
            data = np.clip(np.where(np.isfinite(g[metric]), g[metric], hi), lo, hi)
            im = ax.imshow(data, origin="lower", cmap="viridis", norm=LogNorm(lo, hi), aspect="auto")
            for i in range(data.shape[0]):
                for j in range(data.shape[1]):
                    if g["status"][i, j] != "completed":
                        ax.text(j, i, "✗" if g["status"][i, j] == "failed" else "–", ha="center", va="center",
                                color="r", fontsize=14)
                        continue
                    v = g[metric][i, j]
                    txt = f"{v:.2g}" + (f"\n{g['slips'][i, j]}↻" if g["slips"][i, j] else "") + (
                        "\n✗" if g["diverged"][i, j] else "")
                    ax.text(j, i, txt, ha="center", va="center", fontsize=6.5,
                            color="w" if data[i, j] < math.sqrt(lo * hi) else "k")
            _outline(ax, g["stable"])
            ax.set_xticks(range(len(g["x"])), [f"{v:+.0f}" if m.x_nominal else f"{v:g}" for v in g["x"]],
                          fontsize=7)
            ax.set_yticks(range(len(g["y"])), [f"{v:+.0f}" if m.y_nominal else f"{v:g}" for v in g["y"]],
                          fontsize=7)
            ax.set_xlabel(m.x_label, fontsize=8)
            ax.set_ylabel(m.y_label, fontsize=8)
            name = "speed RMS error" if metric == "speed" else "angle RMS error"
            ax.set_title(f"{dict(CONTROLLERS)[key]}\n{name} after {T_FROM:g} s [{unit}]", fontsize=8)
            fig.colorbar(im, ax=ax, shrink=0.8)
    fig.suptitle(f"{m.title}: black outline = stable (speed RMS error < {SPEED_LIMIT:g} rad/s); ✗ = diverged "
                 f"(failed, slipping after {T_FROM:g} s or > {DIVERGED_LIMIT:g} rad/s); n↻ = electrical turns slipped\n"
                 "(paper mode: the control runs on the measured angle; θ̂, the integral of ω̂, may slip harmlessly)",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def monte_carlo_figure(rows: list[dict], path: Path, label: str = "sensorless unit") -> Path:
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(13.0, 4.0))
    ok = [r for r in rows if r["stable"]]
    bad = [r for r in rows if not r["stable"]]

    def pct(r, key, nominal):
        return 100.0 * (float(r[key]) / nominal - 1.0)

    for ax, (kx, nx, ky, ny, lx, ly) in zip(axes[:2], (
            ("plant.R_s", _M.R_s, "plant.psi", _M.psi, "R_s mismatch [%]", "ψ mismatch [%]"),
            ("plant.L_q", _M.L_q, "plant.L_d", _M.L_d, "L_q mismatch [%]", "L_d mismatch [%]"))):
        ax.scatter([pct(r, kx, nx) for r in ok], [pct(r, ky, ny) for r in ok], s=12, c="tab:green",
                   label=f"stable ({len(ok)})")
        ax.scatter([pct(r, kx, nx) for r in bad], [pct(r, ky, ny) for r in bad], s=30, c="tab:red", marker="x",
                   label=f"failed ({len(bad)})")
        ax.set_xlabel(lx)
        ax.set_ylabel(ly)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    speeds = np.array([r["speed_rms_after"] for r in rows], float)
    finite = speeds[np.isfinite(speeds)]
    if len(finite):
        bins = np.logspace(math.log10(max(finite.min(), 1e-3)), math.log10(max(finite.max(), 1e-2)) + 0.01, 30)
        axes[2].hist(np.clip(finite, bins[0], None), bins=bins, color="tab:blue")
        axes[2].set_xscale("log")
    axes[2].axvline(SPEED_LIMIT, color="r", ls="--", lw=1, label=f"limit {SPEED_LIMIT:g} rad/s")
    axes[2].set_xlabel(f"speed RMS error after {T_FROM:g} s [rad/s]")
    axes[2].set_ylabel("runs")
    axes[2].legend(fontsize=7)
    fig.suptitle(f"Monte-Carlo, {label}: {len(rows)} samples of every mismatch at once, σ = 1 A noise",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def dead_time_label(row: dict) -> str:
    td, comp = float(row["plant.dead_time"]), float(row["ctrl.dead_time_comp"])
    return (f"dead time {td * 1e6:g} µs" if td else "ideal inverter") + (f", compensation {comp:g} V" if comp else "")


def dead_time_figure(runs: list[tuple[dict, dict]], path: Path) -> Path:
    plt = _plt()
    fig, axes = plt.subplots(3, 1, figsize=(8.0, 7.5), sharex=True)
    for row, r in runs:
        label = dead_time_label(row)
        axes[0].plot(r["time"], r["omega_m"], lw=0.9, label=label)
        axes[1].plot(r["time"], np.unwrap(row_timing_corrected_angle_error(r, DT_DEFAULT, _M.N)), lw=0.9)
        axes[2].plot(r["time"], r["x_vehicle"], lw=0.9)
    if runs:
        r = runs[0][1]
        axes[0].plot(r["time"], r["omega_ref"], "k--", lw=0.8, label="ω_ref")
    axes[0].set_ylabel("ω_m [rad/s]")
    axes[0].legend(fontsize=7)
    axes[1].set_ylabel("θ̂ − θ [rad]\n(unwrapped)")
    axes[2].set_ylabel("x_vehicle [m]")
    axes[2].set_xlabel("time [s]")
    axes[0].set_title("Hill start (stop on 22°, stand, restart), sensorless unit, 360 V DC link")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


# --- the page -----------------------------------------------------------------------------------

def _cells(g: dict, m: Map, mask: np.ndarray) -> str:
    """The (x, y) of the cells in ``mask``, with the speed RMS error, or "none"."""
    fmt = (lambda v: f"{v:+.0f} %") if m.x_nominal else (lambda v: f"{v:g}°")
    fmty = (lambda v: f"{v:+.0f} %") if m.y_nominal else (lambda v: f"{v:g}°")
    cells = [f"({fmt(g['x'][j])}, {fmty(g['y'][i])}" + (f": {g['speed'][i, j]:.3g}" if math.isfinite(g['speed'][i, j])
                                                         else "") + ")"
             for i in range(len(g["y"])) for j in range(len(g["x"])) if mask[i, j]]
    return ", ".join(cells) if cells else "none"


def render(grids: dict, mc: list[dict], dead: list[tuple[dict, dict]], figs: dict, timing: dict | None,
           command: str, small: bool) -> str:
    L = ["# Robustness: a motor that is not its data sheet", "",
         f"Generated by `{command}` from the sweeps in `orchestrator/pmsm_cosim/app/sweeps/robust_*.toml` "
         "(`orchestrator/pmsm_cosim/app/report/robustness.py`); every number below comes from those runs."
         + (" **Small version** (3 × 3 grids, a few Monte-Carlo samples, short runs): a check of the "
            "pipeline, not the maps." if small else ""), "",
         "The plant's parameters are swept, the controllers keep their nominal ones (`ctrl.R_s`, "
         "`ctrl.psi`, `ctrl.L_q`, ...): a plant value that differs from the controller's is the model "
         "mismatch the observer meets on a real motor (a hot winding, a hot magnet, saturation). "
         "`pmsm-cosim run ... --set plant.R_s=0.0121` expresses the same for one run. "
         f"A run is **stable** if it completed, its speed RMS error after {T_FROM:g} s is below "
         f"{SPEED_LIMIT:g} rad/s and its angle estimate slipped no electrical turn after {T_FROM:g} s. "
         "The maps' runs are 30 s: the sensorless unit starts from standstill (alignment, I-f, "
         "handover to the stationary-frame EKF5; reference 0 → 200 rad/s over 2.5-12.5 s, road step "
         "at 15 s); the EKF5 runs are flying starts at 200 rad/s (road step at 5 s), the stationary-frame "
         "EKF5 truly sensorless, the paper's EKF5 in its own mode (frame angle measured; its angle "
         "estimate is not used by the control) for reference.", ""]
    for m in MAPS:
        gs = grids.get(m.key, {})
        if not gs:
            continue
        L += [f"## {m.title}", "", f"![{m.key}](robustness/{figs[m.key].name})", ""]
        L.append("| controller | stable cells | diverged cells (x, y) | biased cells: completed, speed RMS error "
                 f"> {SPEED_LIMIT:g} rad/s (x, y) | largest angle RMS error [rad] |")
        L.append("|---|---|---|---|---|")
        for key, label in CONTROLLERS:
            if key not in gs:
                continue
            g = gs[key]
            biased = ~g["stable"] & ~g["diverged"] & (g["status"] == "completed")
            L.append(f"| {label} | {int(g['stable'].sum())} of {g['stable'].size} | {_cells(g, m, g['diverged'])} | "
                     f"{_cells(g, m, biased)} | {np.nanmax(g['angle']):.3g} |")
        L.append("")
    L += _why(grids)
    if mc:
        L += ["## Monte-Carlo: every mismatch at once", "",
              f"Samples of `{MONTE_CARLO}.toml`: R_s −10 … +50 %, ψ −12 … +3 %, L_q −35 … +10 %, "
              "L_d ±10 % (uniform, all at once: hot copper, hot magnet, saturation and tolerances) with "
              "σ = 1 A noise on each phase current, road step to 11° after the start; the same samples "
              f"with the EKF's ψ adaptation (`{MONTE_CARLO_ADAPT}.toml`).", "",
              "| controller | samples | failure rate (not stable) | 95 % interval (Wilson) | diverged "
              "| 95 % interval | "
              "did not complete |", "|---|---|---|---|---|---|---|"]
        for k, (label, rows) in enumerate(mc.items()):
            n = len(rows)
            fails = sum(1 for r in rows if not r["stable"])
            div = sum(1 for r in rows if r["diverged"])
            lo, hi = wilson(fails, n)
            dlo, dhi = wilson(div, n)
            L.append(f"| {label} | {n} | **{fails}/{n} = {100 * fails / n:.1f} %** | "
                     f"{100 * lo:.1f} … {100 * hi:.1f} % | "
                     f"{div}/{n} = {100 * div / n:.1f} % | {100 * dlo:.1f} … {100 * dhi:.1f} % | "
                     f"{sum(1 for r in rows if r['status'] != 'completed')} |")
        L.append("")
        for k, (label, rows) in enumerate(mc.items()):
            L += [f"![Monte-Carlo, {label}](robustness/{figs[f'mc{k}'].name})", ""]
            bad = sorted((r for r in rows if not r["stable"]),
                         key=lambda r: -np.nan_to_num(r["speed_rms_after"], nan=1e9))
            if bad:
                L.append(f"{label}, failed samples (mismatch of R_s, ψ, L_q, L_d: speed RMS error after "
                         f"{T_FROM:g} s, steady error ω_m − ω_ref), worst first:")
                L.append("")
                for r in bad[:8]:
                    L.append(f"- {_pct(r, 'plant.R_s', _M.R_s)}, {_pct(r, 'plant.psi', _M.psi)}, "
                             f"{_pct(r, 'plant.L_q', _M.L_q)}, {_pct(r, 'plant.L_d', _M.L_d)}: "
                             f"{r['speed_rms_after']:.3g} rad/s, {r['speed_bias_after']:+.3g} rad/s"
                             f"{', diverged' if r['diverged'] else ''} ({r['status']})")
                L.append("")
    if dead:
        L += ["## Dead time at low speed: the hill start", "",
              f"![dead time](robustness/{figs['dead'].name})", "",
              "`hill-start` (stop on 22°, stand 10 s, restart) with the sensorless unit and a 360 V DC link "
              "(`robust_deadtime_hill.toml`): the inverter's dead time of 2 µs at 10 kHz takes 7.2 V from "
              "each phase in the sign of its current (`plant.dead_time`); `ctrl.dead_time_comp` = 7.2 V "
              "adds it back from the measured currents.", "",
              "| inverter | completed | speed RMS error, whole run [rad/s] | largest speed error 30-70 s [rad/s] | "
              "roll-back after 20 s [m] | angle RMS error 30-70 s [rad] | turns slipped |",
              "|---|---|---|---|---|---|---|"]
        for row, r in dead:
            t = r["time"]
            w = (t >= 30.0) & (t <= 70.0)
            err = (row_timing_corrected_angle_error(r, DT_DEFAULT, _M.N))
            met = run_metrics(r)
            L.append(f"| {dead_time_label(row)} | {row['status']} | "
                     f"{float(np.sqrt(np.mean((r['omega_ref'] - r['omega_m']) ** 2))):.3g} | "
                     f"{float(np.max(np.abs(r['omega_ref'][w] - r['omega_m'][w]))) if w.any() else math.nan:.3g} | "
                     f"{roll_back(r['x_vehicle'][t > 20.0]):.3g} | "
                     f"{float(np.sqrt(np.mean(err[w] ** 2))) if w.any() else math.nan:.3g} | {met['slips']} |")
        L.append("")
        by = {(float(row["plant.dead_time"]) > 0, float(row["ctrl.dead_time_comp"]) > 0): r for row, r in dead}
        raw = by.get((True, False))
        if raw is not None:
            t = raw["time"]
            climb = (t >= 25.0) & (t <= 30.0)
            bias = float(np.mean(raw["omega_m"][climb] - raw["omega_ref"][climb])) if climb.any() else math.nan
            k = int(np.searchsorted(t, 38.0))
            lead = float(raw["omega_hat"][k] - raw["omega_m"][k]) if k < len(t) else math.nan
            L += [f"Without compensation the observer is fed the commanded voltage, while the motor gets "
                  f"about 4/π × 7.2 = {4 / math.pi * 7.2:.1f} V less, against the current: at 200 rad/s on the "
                  f"slope (25-30 s) that is a few % of the voltage, and the speed runs {bias:+.1f} rad/s off. On "
                  "the way down to the stop the back-EMF falls towards the error (7.2 V at 20 rad/s): at 38 s "
                  f"the speed estimate runs {lead:+.1f} rad/s ahead of the rotor, the rotor falls out of step "
                  "before the handover to I-f, the I-f vector placed from the estimate does not hold the load, and "
                  f"the car rolls back {roll_back(raw['x_vehicle'][t > 20.0]):.0f} m. With the compensation the run "
                  "equals the ideal inverter's; over-compensating an ideal inverter (7.2 V added where no dead "
                  "time took it) breaks the start-up just as surely: the compensation must match the inverter.", ""]
    if timing:
        L += ["## Cost", "",
              f"{timing['runs']} runs made by the last generation that ran any in {timing['elapsed']:.0f} s on "
              f"{timing['workers']} Dask worker(s) ({timing.get('cores', os.cpu_count())} cores, "
              f"load average at the end "
              f"{timing['load']}); the runs' own wall times add up to {timing['run_walls']:.0f} s: a "
              f"speed-up of {timing['run_walls'] / max(timing['elapsed'], 1e-9):.2f} over running them one "
              "after the other (`benchmarks/sweep_speedup.py` measures it on equal runs).", ""]
    return "\n".join(L) + "\n"


def _near(values, target) -> int | None:
    k = int(np.argmin([abs(v - target) for v in values])) if len(values) else None
    return k if k is not None and abs(values[k] - target) < 1e-6 else None


def _why(grids: dict) -> list[str]:
    """Where the maps break, with the mechanism; numbers from the grids."""
    L = []
    gs = grids.get("rs_psi", {})
    lines = []
    for key, label in CONTROLLERS:
        g = gs.get(key)
        if g is None:
            continue
        j0, i0 = _near(g["x"], 0.0), _near(g["y"], 0.0)
        if j0 is None or i0 is None:
            continue
        psi = ", ".join(f"ψ {g['y'][i]:+.0f} %: {g['bias'][i, j0]:+.2f}" for i in range(len(g["y"])) if i != i0)
        rs = np.nanmax(np.abs(g["bias"][i0, :]))
        angle = f" (angle RMS error ≤ {np.nanmax(g['angle'][i0, :]):.3f} rad)" if key != "ekf5paper" else ""
        lines.append(f"- {label}: steady speed error ω_m − ω_ref after {T_FROM:g} s at the nominal R_s: {psi} rad/s; "
                     f"over the whole R_s range at the nominal ψ at most {rs:.2f} rad/s{angle}; "
                     f"{int(g['diverged'].sum())} of {g['diverged'].size} cells diverged.")
    if lines:
        L += ["## Where and why the drive breaks", "",
              "**ψ mismatch biases the speed, R_s mismatch hardly matters at speed.** At 200 rad/s the "
              "back-EMF N ω ψ (72 V) dominates the stator voltage; the resistive drop R_s i_q is 1 V at the "
              "11° load, so even +100 % R_s is a 1-2 % voltage error, taken up by a small angle error. A wrong "
              "ψ, though, is a back-EMF the model can match only with a wrong speed: the EKF settles where "
              "its innovation is balanced between ω̂ (the model's back-EMF ω̂ ψ̂), a rotated θ̂ and T̂_L, "
              "and the speed loop, which holds ω̂ at the reference, drives the rotor off by the rest: a steady "
              "speed error of roughly the sign of −Δψ, not a divergence. A hot magnet (−10 %) alone takes "
              "the drive out of the 2.5 % speed tolerance:", ""] + lines + [""]
        if "sensorless" in gs and "sensorless_adapt" in gs:
            a, b = gs["sensorless"], gs["sensorless_adapt"]
            L += [f"**The magnet-flux adaptation widens the stable region from {int(a['stable'].sum())} to "
                  f"{int(b['stable'].sum())} of {b['stable'].size} cells** (`ctrl.psi_adapt` = 1/s, "
                  "`EkfParams.psi_adapt`, `pmsm_ev.kernels.adapt_psi`): the estimated angle must turn at the "
                  "rotor's speed on average, so the mean of the EKF's angle corrections, N (ω − ω̂) dt per step, "
                  "measures the speed error a wrong ψ causes; the EKF's ψ is moved until it vanishes (largest "
                  f"|ω_m − ω_ref| left: {np.nanmax(np.abs(b['bias'])):.2f} rad/s against "
                  f"{np.nanmax(np.abs(a['bias'])):.1f} without). It needs speed (it runs above 30 rad/s) and "
                  "identifies ψ, not R_s: at 200 rad/s R_s hardly matters, at low speed it is the dead time and "
                  "R_s that count (below).", ""]
    gl = grids.get("lq_load", {})
    lines = []
    for key, label in CONTROLLERS:
        g = gl.get(key)
        if g is None:
            continue
        lines.append(f"- {label}: {int(g['stable'].sum())} of {g['stable'].size} stable; diverged "
                     f"{_cells(g, MAPS[1], g['diverged'])}; biased "
                     f"{_cells(g, MAPS[1], ~g['stable'] & ~g['diverged'] & (g['status'] == 'completed'))}.")
    if lines:
        g = gl.get("sensorless")
        measured = ""
        if g is not None:
            i, j = _near(g["y"], 22.0), _near(g["x"], -40.0)
            if i is not None and j is not None:
                measured = f"; the sensorless unit's angle RMS error there: {g['angle'][i, j]:.2f} rad"
        dtheta = 0.4 * _M.L_q * 234.0 / _M.psi
        L += ["**L_q mismatch (saturation) grows with the load.** L_q enters the model through the "
              "cross-coupling ω L_q i_q of eq 10 and the q-current dynamics (eq 11): a wrong L_q is a d-axis "
              "voltage error proportional to the load current, ω ΔL_q i_q, which the EKF takes as a rotated "
              f"back-EMF, an angle error Δθ ≈ ΔL_q i_q / ψ ({dtheta:.2f} rad for −40 % at the 234 A of 22°"
              f"{measured}) and, through the torque it then mis-attributes, a small speed error. Unloaded it is "
              "harmless; the angle error costs torque per ampere (cos Δθ) rather than stability:", ""] + lines + [""]
    return L


def _pct(r: dict, key: str, nominal: float) -> str:
    return f"{100.0 * (float(r[key]) / nominal - 1.0):+.0f} %"


def collect(runs_dir: Path, t_from: float = T_FROM) -> tuple[dict, list, list]:
    """(map grids {map key: {controller: grid}}, Monte-Carlo rows, [(dead-time row, results)])
    from the sweep directories present in ``runs_dir``."""
    grids: dict = {}
    for m in MAPS:
        for key, _ in CONTROLLERS:
            out = runs_dir / f"robust_{m.key}_{key}"
            if (out / "summary.csv").is_file():
                grids.setdefault(m.key, {})[key] = grid_of(sweep_results(out, t_from, key != "ekf5paper"), m)
    mc = {}
    for name, label in ((MONTE_CARLO, "sensorless unit"), (MONTE_CARLO_ADAPT, "sensorless unit + ψ adaptation")):
        if (runs_dir / name / "summary.csv").is_file():
            mc[label] = sweep_results(runs_dir / name, t_from)
    dead = []
    dead_dir = runs_dir / DEAD_TIME
    if (dead_dir / "summary.csv").is_file():
        for row in read_summary(dead_dir / "summary.csv"):
            if row["status"] == "completed":
                dead.append((row, read_results(dead_dir / "runs" / row["run"])))
    return grids, mc, dead


def generate(out: Path | str = "docs", runs_dir: Path | str = "runs/robustness", workers: int = 2,
             small: bool = False, stop_time: float | None = None, run: bool = True,
             command: str = "pmsm-cosim report --robustness", log=print) -> Path:
    """Run the sweeps (unless ``run`` is False: then the runs in ``runs_dir`` as they are) and write
    ``out/robustness.md`` with its figures in ``out/robustness/``. Returns the page's path."""
    out, runs_dir = Path(out), Path(runs_dir)
    timing = None
    record = runs_dir / "generation.json"  # the cost of the last generation that made runs
    if run:
        timing = run_sweeps(runs_dir, workers, small, stop_time, log=log)
        timing.update(workers=workers, load=" ".join(f"{x:.2f}" for x in os.getloadavg()), cores=os.cpu_count())
        if timing["runs"]:
            record.write_text(json.dumps(timing, indent=1) + "\n", encoding="utf-8")
    if (timing is None or not timing["runs"]) and record.is_file():
        timing = json.loads(record.read_text(encoding="utf-8"))
    t_from = T_FROM if stop_time is None or stop_time > 1.5 * T_FROM else stop_time / 2.0
    grids, mc, dead = collect(runs_dir, t_from)
    fig_dir = out / "robustness"
    fig_dir.mkdir(parents=True, exist_ok=True)
    figs = {}
    for m in MAPS:
        if grids.get(m.key):
            figs[m.key] = map_figure(m, grids[m.key], fig_dir / f"map_{m.key}.png")
    for k, (label, rows) in enumerate(mc.items()):
        figs[f"mc{k}"] = monte_carlo_figure(rows, fig_dir / f"monte_carlo{'_adapt' if k else ''}.png", label)
    if dead:
        figs["dead"] = dead_time_figure(dead, fig_dir / "dead_time_hill.png")
    page = out / "robustness.md"
    page.write_text(render(grids, mc, dead, figs, timing, command, small),
                    encoding="utf-8")
    log(f"wrote {page} and {len(figs)} figures in {fig_dir}")
    return page
