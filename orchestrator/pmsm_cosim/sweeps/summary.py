"""A sweep's summary: one row per run (its parameters, figures of merit, bookkeeping) in
``summary.csv``, and the chosen metrics against the swept parameters in ``summary.png``."""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

from .spec import BOOKKEEPING, RunPlan, SweepSpec, _label


def _row(sweep: SweepSpec, plan: RunPlan, status: str, error: str, metrics: dict | None) -> dict:
    row = {"run": plan.id, "index": plan.index, "status": status, "error": error}
    row.update({name: plan.params[name] for name in sweep.swept})
    hooks = sweep.hooks
    figures = hooks.summary_of(metrics or {}) if hooks.summary_of is not None else {}
    row.update({name: figures.get(name, math.nan) for name in hooks.summary_metrics})
    for key in BOOKKEEPING:
        value = (metrics or {}).get(key)
        row[key] = float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else math.nan
    return row


def _format(value) -> str:
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    return str(value)


def write_summary(sweep: SweepSpec, rows: list[dict], out: Path) -> Path:
    """summary.csv: one row per run in index order (written atomically)."""
    columns = ["run", "index", "status", "error", *sweep.swept, *sweep.hooks.summary_metrics, *BOOKKEEPING]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for row in sorted(rows, key=lambda r: r["index"]):
        w.writerow([_format(row[c]) for c in columns])
    path = out / "summary.csv"
    tmp = path.with_suffix(".csv.tmp")
    tmp.write_text(buf.getvalue(), encoding="utf-8")
    os.replace(tmp, path)
    return path


def read_summary(path) -> list[dict]:
    with open(path, encoding="utf-8", newline="") as fh:
        return list(csv.DictReader(fh))


def plot_summary(sweep: SweepSpec, rows: list[dict], path: Path) -> Path | None:
    """Each chosen metric (rows of panels) against each swept parameter (columns); failed
    runs as red crosses on the x axis. None when matplotlib is missing."""
    try:  # optional for the sweep engine
        import matplotlib  # noqa: PLC0415 - matplotlib: heavy, only when drawing
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # noqa: PLC0415 - matplotlib: heavy, only when drawing
        from matplotlib.transforms import blended_transform_factory  # noqa: PLC0415 - matplotlib: heavy, only when drawing
    except ImportError:
        return None
    params, metrics = sweep.swept, sweep.metrics
    fig, axes = plt.subplots(len(metrics), len(params), squeeze=False, sharex="col",
                             figsize=(max(4.5, 4.0 * len(params)), 0.6 + 2.8 * len(metrics)))
    n_failed = sum(r["status"] != "completed" for r in rows)
    for j, name in enumerate(params):
        values = [r[name] for r in rows]
        numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
        cats = [] if numeric else sorted({_label(v) for v in values}, key=str)
        for i, metric in enumerate(metrics):
            ax = axes[i][j]
            ok = [r for r in rows if r["status"] == "completed" and math.isfinite(r[metric])]
            bad = [r for r in rows if r["status"] != "completed"]

            def xs(rs):
                return [r[name] for r in rs] if numeric else [cats.index(_label(r[name])) for r in rs]

            ax.plot(xs(ok), [r[metric] for r in ok], "o", color="C0", ms=5)
            if not ok:
                ax.text(0.5, 0.5, "no finite values", ha="center", va="center", transform=ax.transAxes,
                        color="0.4")
            if bad:
                tr = blended_transform_factory(ax.transData, ax.transAxes)
                ax.plot(xs(bad), [0.02] * len(bad), "x", color="C3", ms=7, transform=tr, clip_on=False)
            if numeric and sweep.log_scale.get(name) and all(v > 0 for v in values):
                ax.set_xscale("log")
            if ok and all(r[metric] > 0 for r in ok) and max(r[metric] for r in ok) > 30 * min(
                    r[metric] for r in ok):
                ax.set_yscale("log")
            if not numeric:
                ax.set_xticks(range(len(cats)), cats, rotation=20)
            ax.grid(True, which="major", alpha=0.4)
            if j == 0:
                unit = sweep.hooks.summary_units.get(metric) or ("s" if metric == "wall_time_s" else "")
                ax.set_ylabel(f"{metric} [{unit}]" if unit and metric != "wall_time_s" else metric)
            if i == len(metrics) - 1:
                unit = sweep.units.get(name)
                ax.set_xlabel(f"{name} [{unit}]" if unit else name)
    title = f"{sweep.name}: {len(rows)} runs"
    if sweep.stop_time is not None:
        title += f" of {sweep.stop_time:g} s"
    if n_failed:
        title += f", {n_failed} not completed (x)"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
