"""``pmsm-cosim compare``: overlay finished runs and tabulate their figures of merit.

Reads only the result contract (``pmsm_ev.results``): each run directory's
``results.csv`` and, when present, ``metrics.json``; it computes no figure itself, it
tabulates those of ``pmsm_ev.results``. Whole-run figures come from metrics.json
(``compute_metrics`` as the master wrote them; recomputed from results.csv when
metrics.json lacks them) and so do the steps' (``step_figures``); figures "after t_from"
are ``after_figures`` of the rows (``compute_metrics`` of the rows with ``time >= t_from``),
so that runs started from standstill (a 10 s speed ramp) and flying starts compare on the
same footing.

Writes ``OUT/metrics.md`` and ``OUT/metrics.csv`` (one row per run, the columns of
:data:`COLUMNS`) and ``OUT/compare_*.png`` (speed, angle error, torque estimate).
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pmsm_ev.results import CONTRACT_COLUMNS, angle_error_unwrapped

from ..engine.errors import CosimError, one_line
from ..engine.recording import read_results
from .metrics.rows import T_FROM
from .metrics.run import compute_metrics
from .metrics.windows import after_figures, step_figures

#: resolution of the overlay PNGs [dpi] and their size [in]
DPI = 80
FIGSIZE = (9.0, 3.6)
#: min/max buckets per overview line
BUCKETS = 1500

#: (key, Markdown header, format) of each table column, in order. Units in the headers.
COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("label", "run", "s"),
    ("scenario", "scenario", "s"),
    ("status", "status", "s"),
    ("stop_time", "stop [s]", ".0f"),
    ("speed_rms_error", "speed RMS err, whole run [rad/s]", ".3f"),
    ("speed_rms_after", "speed RMS err after t_from [rad/s]", ".3f"),
    ("step_dev_min", "step dip min [rad/s]", ".2f"),
    ("step_dev_max", "step dip max [rad/s]", ".2f"),
    ("settling_max", "settling max [s]", ".2f"),
    ("omega_hat_rms_after", "ω̂ RMS err after t_from [rad/s]", ".3f"),
    ("theta_rms_after", "θ̂ err RMS after t_from [rad]", ".3f"),
    ("theta_max_after", "θ̂ err max after t_from [rad]", ".3f"),
    ("theta_drift", "θ̂ drift t_from→end [rad]", ".2f"),
    ("T_L_err_max", "T̂_L − T_L,mech, max over plateaus [N m]", ".2f"),
    ("T_L_eq31_rms_after", "T̂_L − eq 31, RMS after t_from [N m]", ".2f"),
)


@dataclass
class Run:
    """One run directory: its label, metrics (metrics.json or recomputed) and columns."""

    label: str
    path: Path
    metrics: dict
    r: dict = field(repr=False)

    @property
    def scenario(self) -> str:
        return str(self.metrics.get("scenario") or self.path.name)


def load_run(path, label: str | None = None) -> Run:
    """A run directory -> :class:`Run`; CosimError (one line, naming the path) if unusable."""
    path = Path(path)
    if not path.is_dir():
        raise CosimError(f"{path}: no such run directory")
    csv_path = path / "results.csv"
    if not csv_path.is_file():
        raise CosimError(f"{path}: not a run directory (no results.csv)")
    try:
        r = read_results(csv_path)
    except (ValueError, UnicodeDecodeError, OSError) as exc:
        raise CosimError(f"{csv_path}: malformed results file ({one_line(exc)})") from None
    missing = [c for c in CONTRACT_COLUMNS if c not in r]
    if missing:
        raise CosimError(f"{csv_path}: not a result-contract file (missing columns: {', '.join(missing)})")
    if len(r["time"]) < 2:
        raise CosimError(f"{csv_path}: needs at least 2 data rows (has {len(r['time'])})")
    metrics: dict = {}
    mpath = path / "metrics.json"
    if mpath.is_file():
        try:
            metrics = json.loads(mpath.read_text(encoding="utf-8"))
        except (ValueError, OSError) as exc:
            raise CosimError(f"{mpath}: malformed metrics file ({one_line(exc)})") from None
        if not isinstance(metrics, dict):
            raise CosimError(f"{mpath}: malformed metrics file (not a JSON object)")
    if "speed_rms_error" not in metrics:  # no figures in metrics.json: compute them
        metrics = {**compute_metrics(r), **metrics}
        metrics.setdefault("status", "unknown (no metrics.json)")
    return Run(label or path.name, path, metrics, r)


def summarize(run: Run, t_from: float = T_FROM) -> dict:
    """One table row: the run's bookkeeping, the whole-run speed error from its metrics, the step
    figures of its metrics (``pmsm_cosim.app.metrics.windows.step_figures``) and the figures of its rows after
    ``t_from`` (``pmsm_cosim.app.metrics.windows.after_figures``)."""
    m, r = run.metrics, run.r
    speed = m.get("speed_rms_error")
    row = {
        "label": run.label,
        "scenario": run.scenario,
        "status": str(m.get("status", "unknown")),
        "stop_time": float(m.get("stop_time", r["time"][-1])),
        "speed_rms_error": None if isinstance(speed, float) and math.isnan(speed) else speed,
    }
    row.update(step_figures(m))
    row.update(after_figures(r, t_from))
    return row


def format_value(value, fmt: str) -> str:
    """A table cell: ``-`` for missing, ``never`` for an infinite settling time."""
    if value is None:
        return "-"
    if fmt == "s":
        return str(value)
    if isinstance(value, float) and math.isinf(value):
        return "never"
    return format(value, fmt)


def markdown_table(rows: list[dict], columns=COLUMNS, t_from: float | None = None) -> str:
    """Rows as a GitHub Markdown table (``t_from`` written into the headers)."""
    heads = [h.replace("t_from", f"{t_from:g} s") if t_from is not None else h for _, h, _ in columns]
    lines = ["| " + " | ".join(heads) + " |",
             "|" + "|".join("---" if f == "s" else "---:" for _, _, f in columns) + "|"]
    for row in rows:
        lines.append("| " + " | ".join(format_value(row.get(k), f) for k, _, f in columns) + " |")
    return "\n".join(lines) + "\n"


def write_csv(rows: list[dict], path: Path, columns=COLUMNS) -> Path:
    """Rows as CSV, full precision (``repr``); empty cell for missing, ``inf`` for never."""
    with open(path, "w", encoding="utf-8", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([k for k, _, _ in columns])
        for row in rows:
            w.writerow(["" if row.get(k) is None else (row[k] if f == "s" else repr(float(row[k])))
                        for k, _, f in columns])
    return path


# --- figures -------------------------------------------------------------------------

#: what each overlay shows: (y label, run's column or function, reference column, title)
PLOTS = {
    "speed": ("speed ω_m [rad/s]", "omega_m", "omega_ref", "rotor speed (dashed: reference)"),
    "speed_error": ("ω_ref − ω_m [rad/s]", None, None, "speed error"),
    "angle_error": ("θ̂ − θ, unwrapped [rad]", None, None, "angle error of the estimate (unwrapped)"),
    "torque": ("torque [N m]", "T_L_hat", "T_L_mech", "load-torque estimate T̂_L (dashed: T_L,mech)"),
}


def _series(run: Run, kind: str):
    r = run.r
    if kind == "speed_error":
        return r["omega_ref"] - r["omega_m"]
    if kind == "angle_error":
        return angle_error_unwrapped(r)
    return r[PLOTS[kind][1]]


def plot_overlay(runs: list[Run], kind: str, path: Path, window: tuple[float, float] | None = None,
                 title: str | None = None, size=FIGSIZE, skip_zero: bool = True, robust: bool | None = None) -> Path:
    """One PNG overlaying ``kind`` (a key of :data:`PLOTS`) of every run. ``window``
    restricts the time axis (all rows shown there, no thinning); references (dashed
    black) are drawn once per scenario. With ``skip_zero``, a run whose torque estimate
    is identically 0 (no load state) is left out of the torque plot. With ``robust``, the
    y axis spans the median of the runs' ranges (padded) when a run goes far beyond it (a
    diverged estimate would flatten every other line); that run is labelled "off scale".
    Default: robust, except for the angle error, whose slips of whole turns are the point."""
    from .figures import envelope, new_figure, save_png  # noqa: PLC0415 - matplotlib: heavy, only when drawing

    if robust is None:
        robust = kind != "angle_error"
    ylabel, _, ref_col, default_title = PLOTS[kind]
    fig, axes = new_figure(size=size, dpi=DPI)
    ax = axes[0, 0]
    refs_drawn: set[str] = set()
    lines = []
    for i, run in enumerate(runs):
        t = run.r["time"]
        y = _series(run, kind)
        if kind == "torque" and skip_zero and not np.any(y):
            continue
        sel = slice(None) if window is None else (t >= window[0]) & (t <= window[1])
        if window is not None and not np.any(sel):
            continue
        lines.append((i, run, t, y, sel))
    limits = None
    if robust and len(lines) >= 3:
        ranges = [(float(np.nanmin(y[sel])), float(np.nanmax(y[sel]))) for _, _, _, y, sel in lines]
        lo, hi = float(np.median([r[0] for r in ranges])), float(np.median([r[1] for r in ranges]))
        pad = 0.25 * max(hi - lo, 1e-9)
        lo, hi = lo - pad, hi + pad
        if any(r[0] < lo - 2 * (hi - lo) or r[1] > hi + 2 * (hi - lo) for r in ranges):
            limits = (lo, hi)
    for i, run, t, y, sel in lines:
        ts, ys = t[sel], y[sel]
        if window is None:
            ts, ys = envelope(ts, ys, BUCKETS)
        off = limits is not None and (np.nanmin(ys) < limits[0] or np.nanmax(ys) > limits[1])
        # the first runs on top: a hunting or diverged run drawn later does not hide them
        ax.plot(ts, ys, lw=1.0, color=f"C{i % 10}", label=run.label + (" (off scale)" if off else ""),
                zorder=2 + len(lines) - i)
        if ref_col and run.scenario not in refs_drawn:
            refs_drawn.add(run.scenario)
            tr, yr = t[sel], run.r[ref_col][sel]
            if window is None:
                tr, yr = envelope(tr, yr, BUCKETS)
            ax.plot(tr, yr, lw=1.0, ls="--", color="k", alpha=0.7, zorder=3 + len(lines))
    if window is not None:
        ax.set_xlim(*window)
    if limits is not None:
        ax.set_ylim(*limits)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title or default_title, fontsize=10)
    ax.grid(True, alpha=0.4)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize=7, ncol=2)
    return save_png(fig, path, DPI)


# --- the command ---------------------------------------------------------------------

def compare(run_dirs, out, labels=None, t_from: float = T_FROM, figures: bool = True) -> dict:
    """Load the runs, write ``OUT/metrics.md``, ``OUT/metrics.csv`` and the overlays.

    Returns {"rows": table rows, "markdown": path, "csv": path, "figures": [paths]}.
    """
    run_dirs = [Path(p) for p in run_dirs]
    if not run_dirs:
        raise CosimError("compare: give at least one run directory")
    if labels is not None and len(labels) != len(run_dirs):
        raise CosimError(f"--labels: {len(labels)} labels for {len(run_dirs)} run directories")
    runs = [load_run(p, labels[i] if labels else None) for i, p in enumerate(run_dirs)]
    rows = [summarize(run, t_from) for run in runs]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    md = out / "metrics.md"
    md.write_text(f"Figures after t_from = {t_from:g} s use the rows with time >= {t_from:g} s.\n\n"
                  + markdown_table(rows, t_from=t_from), encoding="utf-8")
    csv_path = write_csv(rows, out / "metrics.csv")
    paths = []
    if figures:
        for kind in ("speed", "angle_error", "torque"):
            paths.append(plot_overlay(runs, kind, out / f"compare_{kind}.png"))
    return {"rows": rows, "markdown": md, "csv": csv_path, "figures": paths}
