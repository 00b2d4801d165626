"""The paper's figures 6-17 drawn from one run's ``results.csv``.

One run is one scenario, so a run gives one set of figures; ``scenario_label`` picks
the paper's numbering:

==================  ==========  ==========  =======================
content             scenario1   scenario2   other / None
==================  ==========  ==========  =======================
elevation           fig06       fig07       elevation.png
speed reference     fig08       fig08       speed_reference.png
speed               fig09       fig11       speed.png
speed zoom          fig10       fig12       speed_zoom.png
electrical angle    fig13       fig13       angle.png
currents            fig14       fig15       currents.png
load torque         fig16       fig17       load_torque.png
==================  ==========  ==========  =======================

Colours follow the paper's captions: speed reference blue, actual red, estimated green
(Figs 9-12); angle actual green, estimated blue (Fig 13); i_d blue, i_q green (Figs
14-15); T_L_hat of the EKF blue, T_L_mech of the vehicle green (Figs 16-17).

The overview plots thin their lines to a min/max envelope (every peak kept); the zooms
and the angle window use every recorded row. Usage::

    python -m pmsm_cosim.app.figures runs/ref1 --scenario scenario1
"""

from __future__ import annotations

import argparse
import gc
import math
import os
import sys
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from pmsm_ev.params import MotorParams

from ..engine.recording import read_results

#: figure size [in] and resolution [dpi]
FIGSIZE = (8.0, 4.5)
DPI = 110
#: min/max buckets per overview line (each bucket keeps its minimum and maximum)
OVERVIEW_BUCKETS = 2000
#: zoom window around each elevation change [s]
ZOOM_BEFORE = 2.0
ZOOM_AFTER = 12.0
#: at most this many zoom panels (the first changes of the run)
ZOOM_MAX_PANELS = 20
ZOOM_COLUMNS = 5
#: electrical periods shown in the angle window at the end of the run
ANGLE_PERIODS = 4

C_REF, C_ACT, C_EST = "tab:blue", "tab:red", "tab:green"  # Figs 9-12
C_THETA, C_THETA_HAT = "tab:green", "tab:blue"  # Fig 13
C_ID, C_IQ = "tab:blue", "tab:green"  # Figs 14-15
C_TL_HAT, C_TL_MECH = "tab:blue", "tab:green"  # Figs 16-17

#: columns the figures read
REQUIRED_COLUMNS = ("time", "delta_deg", "omega_ref", "omega_m", "omega_hat", "theta_e",
                    "theta_hat", "i_d", "i_q", "T_L_mech", "T_L_hat")

#: figure key -> (paper figure for scenario 1, for scenario 2, content title)
PAPER_FIGURES = {
    "elevation": (6, 7, "Road elevation angle"),
    "speed_reference": (8, 8, "Motor speed reference"),
    "speed": (9, 11, "Motor speed: reference, actual, estimated"),
    "speed_zoom": (10, 12, "Motor speed around the elevation changes"),
    "angle": (13, 13, "Electrical angle: actual vs estimated"),
    "currents": (14, 15, "Motor currents"),
    "load_torque": (16, 17, "Load torque: EKF estimate vs mechanical part"),
}


class FiguresError(ValueError):
    """results.csv is missing or cannot be plotted; the message names the file."""


def scenario_number(scenario_label) -> int | None:
    """1 or 2 for "scenario1"/"scenario2" (also "1", "Scenario 2", ...), else None."""
    if scenario_label is None:
        return None
    key = str(scenario_label).strip().lower().replace(" ", "").replace("_", "").replace("-", "")
    key = key.removeprefix("scenario")
    return int(key) if key in ("1", "2") else None


def figure_plan(scenario_label=None) -> dict[str, tuple[str, str]]:
    """{figure key: (file name, title)} for a run of ``scenario_label``."""
    n = scenario_number(scenario_label)
    plan = {}
    for key, (fig1, fig2, content) in PAPER_FIGURES.items():
        if n is None:
            name = f"{key}.png"
            title = content if scenario_label in (None, "") else f"{content} ({scenario_label})"
        else:
            num = fig1 if n == 1 else fig2
            name = f"fig{num:02d}_{key}.png"
            title = f"Fig. {num}, scenario {n}: {content}"
        plan[key] = (name, title)
    return plan


# --- data ---------------------------------------------------------------------------

def load_run(run_dir) -> tuple[Path, dict[str, np.ndarray]]:
    """(path of results.csv, columns); FiguresError naming the file if unusable."""
    path = Path(run_dir)
    if path.is_dir() or path.suffix.lower() != ".csv":
        path = path / "results.csv"
    if not path.is_file():
        raise FiguresError(f"{path}: results file not found")
    if path.stat().st_size == 0:
        raise FiguresError(f"{path}: malformed results file (empty, no header row)")
    try:
        r = read_results(path, columns=REQUIRED_COLUMNS)  # the figures' columns only: a cycle's run is long
    except (ValueError, UnicodeDecodeError, OSError) as exc:
        raise FiguresError(f"{path}: malformed results file ({type(exc).__name__}: {exc})") from None
    missing = [c for c in REQUIRED_COLUMNS if c not in r]
    if missing:
        raise FiguresError(f"{path}: malformed results file (missing columns: {', '.join(missing)})")
    if len(r["time"]) < 2:
        raise FiguresError(f"{path}: malformed results file (needs at least 2 data rows, "
                           f"has {len(r['time'])})")
    if not np.all(np.diff(r["time"]) > 0):
        raise FiguresError(f"{path}: malformed results file (time does not increase)")
    return path, r


def _wrap(x):
    """Angle to [-pi, pi), the convention of the recorded angles."""
    return (np.asarray(x) + math.pi) % (2 * math.pi) - math.pi


def envelope(t, y, buckets: int = OVERVIEW_BUCKETS):
    """Thin (t, y) for an overview line: the min and max of each of ``buckets`` runs of
    rows, in time order, plus the last row; short series come back unchanged."""
    n = len(y)
    if n <= 2 * buckets:
        return t, y
    size = -(-n // buckets)
    pad = size * buckets - n
    yy = np.concatenate([y, np.full(pad, y[-1])]).reshape(buckets, size)
    lo = np.argmin(np.where(np.isnan(yy), np.inf, yy), axis=1)
    hi = np.argmax(np.where(np.isnan(yy), -np.inf, yy), axis=1)
    base = np.arange(buckets) * size
    idx = np.unique(np.concatenate([base + lo, base + hi, [n - 1]]))
    idx = idx[idx < n]
    return t[idx], y[idx]


def elevation_changes(r) -> list[tuple[float, float, float]]:
    """(time, angle before, angle after) [s, deg, deg] of each recorded elevation change."""
    d = r["delta_deg"]
    idx = np.nonzero(d[1:] != d[:-1])[0] + 1
    return [(float(r["time"][i]), float(d[i - 1]), float(d[i])) for i in idx]


def _break_at_wraps(t, a):
    """Wrapped angle with NaN inserted where it jumps by 2 pi (no vertical lines)."""
    w = _wrap(a)
    jumps = np.nonzero(np.abs(np.diff(w)) > math.pi)[0] + 1
    return np.insert(np.asarray(t, float), jumps, np.nan), np.insert(w, jumps, np.nan)


def unwrap_with_speed(t, theta, omega_e):
    """Continuous angle from samples wrapped to 2 pi: each increment is the one nearest
    the integral of ``omega_e`` (trapezoid), so it holds even when a sample interval
    spans more than half an electrical period."""
    expected = 0.5 * (omega_e[1:] + omega_e[:-1]) * np.diff(t)
    inc = expected + _wrap(np.diff(theta) - expected)
    return theta[0] + np.concatenate([[0.0], np.cumsum(inc)])


# --- drawing ------------------------------------------------------------------------

def new_figure(nrows=1, ncols=1, size=FIGSIZE, dpi=DPI, **kw):
    """A figure (no pyplot: freed with its last reference) and its grid of axes, ``axes[row, column]``."""
    fig = Figure(figsize=size, dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False, **kw)
    return fig, axes


def _finish(ax, xlabel="time [s]", ylabel=None, legend=True):
    ax.set_xlabel(xlabel)
    if ylabel:
        ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.4)
    if legend and ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize=8)


def save_png(fig, path: Path, dpi=DPI) -> Path:
    """Write ``fig`` to ``path`` whole or not at all (a temporary file renamed); its folder made if need be."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    # no "Software" entry: the same data give the same bytes, whatever the version
    fig.savefig(tmp, format="png", dpi=dpi, metadata={"Software": None})
    os.replace(tmp, path)
    return path


def _panel():
    """A figure of one panel: (figure, its axes)."""
    fig, axes = new_figure()
    return fig, axes[0, 0]


def _over_the_run(fig, ax, t, title, ylabel, legend=None):
    """Finish a panel drawn against the run's time ``t``: its span, title, labels (and the legend at ``legend``)."""
    ax.set_xlim(t[0], t[-1])
    ax.set_title(title)
    _finish(ax, ylabel=ylabel)
    if legend:
        ax.legend(loc=legend, fontsize=8)
    return fig


def _line(ax, t, y, thin, **kw):
    if thin:
        t, y = envelope(t, y)
    ax.plot(t, y, **kw)


def plot_elevation(r, title):
    fig, ax = _panel()
    ax.plot(r["time"], r["delta_deg"], color="tab:blue", lw=1.5, drawstyle="steps-post",
            label="elevation angle δ")
    lo, hi = float(np.min(r["delta_deg"])), float(np.max(r["delta_deg"]))
    pad = max(1.0, 0.1 * (hi - lo))
    ax.set_ylim(lo - pad, hi + pad)
    return _over_the_run(fig, ax, r["time"], title, "δ [deg]")


def plot_speed_reference(r, title):
    fig, ax = _panel()
    _line(ax, r["time"], r["omega_ref"], True, color=C_REF, lw=1.5, label="reference ω_ref")
    return _over_the_run(fig, ax, r["time"], title, "speed [rad/s]")


def plot_speed(r, title):
    fig, ax = _panel()
    t = r["time"]
    _line(ax, t, r["omega_ref"], True, color=C_REF, lw=1.4, label="reference ω_ref")
    _line(ax, t, r["omega_m"], True, color=C_ACT, lw=1.6, label="actual ω_m")
    _line(ax, t, r["omega_hat"], True, color=C_EST, lw=0.9, ls="--", label="estimated ω̂ (EKF)")
    return _over_the_run(fig, ax, t, title, "speed [rad/s]", legend="lower right")


def plot_speed_zoom(r, title):
    """One panel per elevation change, [-ZOOM_BEFORE, +ZOOM_AFTER] s around it, all rows."""
    changes = elevation_changes(r)
    if not changes:
        return None
    shown = changes[:ZOOM_MAX_PANELS]
    n = len(shown)
    ncols = min(n, ZOOM_COLUMNS)
    nrows = -(-n // ncols)
    t = r["time"]
    windows, refs, dev = [], [], 0.0
    for tc, _, _ in shown:
        w = (t >= tc - ZOOM_BEFORE) & (t <= tc + ZOOM_AFTER)
        ref = float(np.interp(tc, t, r["omega_ref"]))
        windows.append(w)
        refs.append(ref)
        for k in ("omega_ref", "omega_m", "omega_hat"):
            v = r[k][w]
            v = v[np.isfinite(v)]
            if len(v):
                dev = max(dev, float(np.max(np.abs(v - ref))))
    # the same half-span in every panel, so the dips compare at a glance
    span = max(5.0, 1.15 * dev)
    span = float(np.ceil(span / 5.0) * 5.0) if span < 100 else float(np.ceil(span / 20.0) * 20.0)
    same_ref = max(refs) - min(refs) < 1e-9
    fig, axes = new_figure(nrows, ncols, size=(FIGSIZE[0], max(FIGSIZE[1], 0.4 + 2.3 * nrows)),
                        sharex=True, sharey=same_ref)
    for i, ((tc, d0, d1), w, ref) in enumerate(zip(shown, windows, refs)):
        ax = axes[i // ncols, i % ncols]
        x = t[w] - tc
        ax.plot(x, r["omega_ref"][w], color=C_REF, lw=1.2, label="reference")
        ax.plot(x, r["omega_m"][w], color=C_ACT, lw=1.6, label="actual")
        ax.plot(x, r["omega_hat"][w], color=C_EST, lw=0.9, ls="--", label="estimated")
        ax.axvline(0.0, color="0.5", lw=0.8, ls=":")
        ax.set_xlim(-ZOOM_BEFORE, ZOOM_AFTER)
        ax.set_ylim(ref - span, ref + span)
        ax.set_title(f"t = {tc:g} s: {d0:g}° → {d1:g}°", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.4)
        if i // ncols == nrows - 1 or i + ncols >= n:
            ax.set_xlabel("t − t_change [s]", fontsize=8)
            ax.xaxis.set_tick_params(labelbottom=True)
        if i % ncols == 0:
            ax.set_ylabel("speed [rad/s]", fontsize=8)
    for j in range(n, nrows * ncols):
        axes[j // ncols, j % ncols].set_visible(False)
    axes[0, 0].legend(loc="lower right", fontsize=6)
    more = f" (first {n} of {len(changes)} changes)" if len(changes) > n else ""
    fig.suptitle(title + more, fontsize=11)
    return fig


def plot_angle(r, title, pole_pairs: int):
    """Top: theta_e and theta_hat over the last ANGLE_PERIODS electrical periods. Bottom:
    the wrapped error theta_hat - theta_e over the whole run."""
    t = r["time"]
    fig, axes = new_figure(2, 1, size=(FIGSIZE[0], 6.0))
    ax, ax_err = axes[0, 0], axes[1, 0]
    dt = float(np.median(np.diff(t)))
    omega_e = pole_pairs * r["omega_m"]
    omega_e_hat = pole_pairs * r["omega_hat"]
    w_end = abs(float(omega_e[-1])) if math.isfinite(omega_e[-1]) else 0.0
    length = ANGLE_PERIODS * 2 * math.pi / w_end if w_end > 1.0 else 20 * dt
    length = max(length, 3 * dt)
    t1 = float(t[-1])
    t0 = max(float(t[0]), t1 - length)
    win = t >= t0 - 1e-12
    if w_end * dt < math.pi / 8:
        # at least 16 rows per electrical period: draw the rows themselves
        for key, colour, label, lw in (("theta_e", C_THETA, "actual θ_e", 1.6),
                                       ("theta_hat", C_THETA_HAT, "estimated θ̂ (EKF)", 1.0)):
            ax.plot(*_break_at_wraps(t[win], r[key][win]), color=colour, lw=lw, label=label)
        note = ""
    else:
        # rows are further apart than 1/16 of an electrical period: unwrap the rows with
        # the recorded speeds, draw the angle between them at that speed, mark the rows
        lead = max(0, int(np.argmax(win)) - 5)
        sel = slice(lead, len(t))
        tf = np.linspace(t0, t1, 64 * ANGLE_PERIODS + 1)
        for key, om, colour, label, lw in (("theta_e", omega_e, C_THETA, "actual θ_e", 1.6),
                                           ("theta_hat", omega_e_hat, C_THETA_HAT, "estimated θ̂ (EKF)", 1.0)):
            cont = unwrap_with_speed(t[sel], r[key][sel], om[sel])
            ax.plot(*_break_at_wraps(tf, np.interp(tf, t[sel], cont)), color=colour, lw=lw, label=label)
            ax.plot(t[win], _wrap(r[key][win]), "o", color=colour, ms=4 if key == "theta_e" else 2.5,
                    mfc="none" if key == "theta_e" else colour)
        note = (f"\ndots: rows recorded every {dt * 1e3:.3g} ms; lines: rows unwrapped "
                f"with N·ω (N = {pole_pairs}) and interpolated")
    ax.set_xlim(t0, t1)
    ax.ticklabel_format(axis="x", useOffset=False)
    ax.set_ylim(-math.pi * 1.05, math.pi * 1.25)
    ax.set_yticks([-math.pi, -math.pi / 2, 0, math.pi / 2, math.pi])
    ax.set_yticklabels(["−π", "−π/2", "0", "π/2", "π"])
    ax.set_title(f"last {(t1 - t0) * 1e3:.3g} ms of the run (~{ANGLE_PERIODS} electrical periods)"
                 + note, fontsize=8)
    _finish(ax, ylabel="electrical angle [rad]", legend=False)
    ax.legend(loc="upper right", fontsize=8, ncol=2)

    err = _wrap(r["theta_hat"] - r["theta_e"])
    _line(ax_err, t, err, True, color="tab:purple", lw=0.8, label="wrap(θ̂ − θ_e)")
    ax_err.set_xlim(t[0], t[-1])
    sec = ax_err.secondary_yaxis("right", functions=(np.degrees, np.radians))
    sec.set_ylabel("[deg]")
    ax_err.set_title("angle estimation error, whole run", fontsize=9)
    _finish(ax_err, ylabel="error [rad]")
    fig.suptitle(title, fontsize=11)
    return fig


def plot_currents(r, title):
    """Top: i_d and i_q on one axis as in the paper. Bottom: i_d on its own scale."""
    t = r["time"]
    fig, axes = new_figure(2, 1, size=(FIGSIZE[0], 5.5), sharex=True, height_ratios=(3, 2))
    ax, ax_d = axes[0, 0], axes[1, 0]
    _line(ax, t, r["i_q"], True, color=C_IQ, lw=1.0, label="i_q")
    _line(ax, t, r["i_d"], True, color=C_ID, lw=1.0, label="i_d")
    _finish(ax, xlabel="", ylabel="current [A]")
    ax.set_xlim(t[0], t[-1])
    _line(ax_d, t, r["i_d"], True, color=C_ID, lw=0.8, label="i_d (own scale)")
    _finish(ax_d, ylabel="i_d [A]")
    fig.suptitle(title, fontsize=11)
    return fig


def plot_load_torque(r, title):
    fig, ax = _panel()
    t = r["time"]
    _line(ax, t, r["T_L_mech"], True, color=C_TL_MECH, lw=1.4, label="T_L_mech, mechanical part (eq 29)")
    _line(ax, t, r["T_L_hat"], True, color=C_TL_HAT, lw=1.0, label="T̂_L, fifth-order EKF (eq 31)")
    return _over_the_run(fig, ax, t, title, "torque [N m]", legend="upper left")


def make_figures(run_dir, out_dir=None, scenario_label=None, pole_pairs: int | None = None) -> list[Path]:
    """Draw the figures of one run; return the PNG paths written.

    ``run_dir`` holds ``results.csv`` (or is that file). PNGs go to ``run_dir/figures``
    unless ``out_dir`` is given. ``scenario_label`` "scenario1"/"scenario2" names them
    after the paper's figures, anything else gives generic names (see the module doc).
    ``pole_pairs`` (default: the motor's, Table I) converts the speed to electrical for
    the angle window. The speed zoom is left out when the elevation never changes.
    """
    csv_path, r = load_run(run_dir)
    out = Path(out_dir) if out_dir is not None else csv_path.parent / "figures"
    out.mkdir(parents=True, exist_ok=True)
    n_poles = int(pole_pairs if pole_pairs is not None else MotorParams().N)
    plan = figure_plan(scenario_label)
    drawers = {
        "elevation": lambda title: plot_elevation(r, title),
        "speed_reference": lambda title: plot_speed_reference(r, title),
        "speed": lambda title: plot_speed(r, title),
        "speed_zoom": lambda title: plot_speed_zoom(r, title),
        "angle": lambda title: plot_angle(r, title, n_poles),
        "currents": lambda title: plot_currents(r, title),
        "load_torque": lambda title: plot_load_torque(r, title),
    }
    written = []
    # a figure's artists refer to each other (cycles): each is freed once saved rather than at the collector's
    # next pass, so that a long run's figures do not pile up (15 MB over a whole WLTC's six). What was alive
    # before the figures (the modules, numba's and matplotlib's objects, the run's arrays) is set aside while they
    # are drawn (gc.freeze), so that each of those collections looks at the figure's objects only: 6 x 0.1 s
    # of full collections over a process of a few hundred thousand objects otherwise.
    gc.freeze()
    try:
        for key, (name, title) in plan.items():
            fig = drawers[key](title)
            if fig is not None:
                written.append(save_png(fig, out / name))
                fig.clear()
                del fig
                gc.collect()
    finally:
        gc.unfreeze()
    return written


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m pmsm_cosim.app.figures",
        description="Draw the paper's figures 6-17 from RUN_DIR/results.csv into RUN_DIR/figures.")
    ap.add_argument("run_dir", metavar="RUN_DIR", help="directory holding results.csv (or the file)")
    ap.add_argument("--scenario", default=None, metavar="LABEL",
                    help="scenario1 or scenario2 names the files after the paper's figures "
                         "(fig06..fig17); anything else, or none, gives generic names")
    ap.add_argument("--out", default=None, metavar="DIR", help="output directory (default RUN_DIR/figures)")
    a = ap.parse_args(argv)
    try:
        paths = make_figures(a.run_dir, a.out, a.scenario)
    except FiguresError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for p in paths:
        print(p)
    return 0


if __name__ == "__main__":
    sys.exit(main())
