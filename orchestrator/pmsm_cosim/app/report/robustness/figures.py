"""The robustness report's figures: the maps' heat maps, the Monte-Carlo scatter and histogram,
the Monte-Carlo on a drive cycle (Wh/km), the dead-time runs on the hill start (matplotlib, loaded
only when drawing)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from pmsm_ev.params import MotorParams
from pmsm_ev.results import row_timing_corrected_angle_error

from ..drawing import pyplot, save_figure
from .cycle import MASS
from .metrics import DIVERGED_LIMIT, SPEED_LIMIT, T_FROM, DeadRun
from .runs import CONTROLLERS, Map

_M = MotorParams()


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


def map_figure(m: Map, grids: dict, path: Path, t_from: float = T_FROM) -> Path:
    """Heat maps (one column per controller) of the speed RMS error and the angle RMS error after
    ``t_from``; cells annotated, runs that did not complete crossed, the stable region outlined."""
    from matplotlib.colors import LogNorm  # noqa: PLC0415 - matplotlib: heavy, only when drawing

    plt = pyplot()
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
            ax.set_title(f"{dict(CONTROLLERS)[key]}\n{name} after {t_from:g} s [{unit}]", fontsize=8)
            fig.colorbar(im, ax=ax, shrink=0.8)
    fig.suptitle(f"{m.title}: black outline = stable (speed RMS error < {SPEED_LIMIT:g} rad/s); ✗ = diverged "
                 f"(failed, slipping after {t_from:g} s or > {DIVERGED_LIMIT:g} rad/s); n↻ = electrical turns slipped\n"
                 "(paper mode: the control runs on the measured angle; θ̂, the integral of ω̂, may slip harmlessly)",
                 fontsize=9)
    return save_figure(fig, path)


def monte_carlo_figure(rows: list[dict], path: Path, label: str = "sensorless unit", t_from: float = T_FROM) -> Path:
    plt = pyplot()
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
    axes[2].set_xlabel(f"speed RMS error after {t_from:g} s [rad/s]")
    axes[2].set_ylabel("runs")
    axes[2].legend(fontsize=7)
    fig.suptitle(f"Monte-Carlo, {label}: {len(rows)} samples of every mismatch at once, σ = 1 A noise",
                 fontsize=10)
    return save_figure(fig, path)


def dead_time_label(run: DeadRun) -> str:
    td, comp = run.dead_time, run.compensation
    return (f"dead time {td * 1e6:g} µs" if td else "ideal inverter") + (f", compensation {comp:g} V" if comp else "")


def dead_time_figure(runs: list[DeadRun], path: Path) -> Path:
    plt = pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(8.0, 7.5), sharex=True)
    for run in runs:
        r = run.r
        axes[0].plot(r["time"], r["omega_m"], lw=0.9, label=dead_time_label(run))
        axes[1].plot(r["time"], np.unwrap(row_timing_corrected_angle_error(r, run.dt, run.pole_pairs)), lw=0.9)
        axes[2].plot(r["time"], r["x_vehicle"], lw=0.9)
    if runs:
        r = runs[0].r
        axes[0].plot(r["time"], r["omega_ref"], "k--", lw=0.8, label="ω_ref")
    axes[0].set_ylabel("ω_m [rad/s]")
    axes[0].legend(fontsize=7)
    axes[1].set_ylabel("θ̂ − θ [rad]\n(unwrapped)")
    axes[2].set_ylabel("x_vehicle [m]")
    axes[2].set_xlabel("time [s]")
    v_dc = {run.v_dc for run in runs}
    axes[0].set_title("Hill start (stop on 22°, stand, restart), sensorless unit"
                      + (f", {v_dc.pop():g} V DC link" if len(v_dc) == 1 else ""))
    for ax in axes:
        ax.grid(alpha=0.3)
    return save_figure(fig, path)


# --- the Monte-Carlo on a drive cycle ------------------------------------------------------------

def cycle_figure(rows: list[dict], path: Path, label: str) -> Path:
    """The Wh/km histogram (passed and failed samples stacked) and Wh/km against the vehicle mass (colour:
    the grade offset; failures crossed, a sample without a Wh/km figure on the axis)."""
    plt = pyplot()
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11.0, 4.0))
    ok = [r["dc_Wh_per_km"] for r in rows if not r["failed"] and math.isfinite(r["dc_Wh_per_km"])]
    bad = [r["dc_Wh_per_km"] for r in rows if r["failed"] and math.isfinite(r["dc_Wh_per_km"])]
    both = ok + bad
    if both:
        lo, hi = min(both), max(both)
        bins = np.linspace(lo - 0.5, hi + 0.5, 16) if hi - lo < 1e-9 else np.linspace(lo, hi, 16)
        ax0.hist([ok, bad], bins=bins, stacked=True, color=["tab:blue", "tab:red"],
                 label=[f"passed ({len(ok)})", f"failed, with a Wh/km figure ({len(bad)})"])
    ax0.set_xlabel("energy at the DC link [Wh/km]")
    ax0.set_ylabel("samples")
    ax0.legend(fontsize=7)
    ax0.grid(alpha=0.3)
    fin = [r for r in rows if math.isfinite(r["dc_Wh_per_km"])]
    if fin:
        grades = [r["grade_pct"] for r in fin]
        lim = max(1e-9, max(abs(g) for g in grades if math.isfinite(g)) if any(map(math.isfinite, grades)) else 1.0)
        sc = ax1.scatter([r[MASS] for r in fin], [r["dc_Wh_per_km"] for r in fin], c=grades, cmap="coolwarm",
                         vmin=-lim, vmax=lim, s=28, edgecolors="k", linewidths=0.4)
        fig.colorbar(sc, ax=ax1, label="grade offset [%]")
    failed = [r for r in fin if r["failed"]]
    if failed:
        ax1.scatter([r[MASS] for r in failed], [r["dc_Wh_per_km"] for r in failed], marker="x", s=70,
                    c="tab:red", label=f"failed ({sum(r['failed'] for r in rows)})")
    no_fig = [r for r in rows if not math.isfinite(r["dc_Wh_per_km"]) and math.isfinite(r[MASS])]
    if no_fig:
        from matplotlib.transforms import blended_transform_factory  # noqa: PLC0415 - matplotlib: only drawing

        tr = blended_transform_factory(ax1.transData, ax1.transAxes)
        ax1.plot([r[MASS] for r in no_fig], [0.03] * len(no_fig), "x", color="tab:red", ms=8, transform=tr,
                 clip_on=False, label=f"no Wh/km figure ({len(no_fig)})")
    masses = sorted({r[MASS] for r in rows if math.isfinite(r[MASS])})
    if masses:
        ax1.set_xticks(masses)
    ax1.set_xlabel("vehicle mass m_v [kg] (plant; 75 kg an occupant)")
    ax1.set_ylabel("energy at the DC link [Wh/km]")
    if failed or no_fig:
        ax1.legend(fontsize=7)
    ax1.grid(alpha=0.3)
    fig.suptitle(label, fontsize=10)
    return save_figure(fig, path)
