"""``pmsm-cosim envelope``: where the drive can go, for any motor and limits given with ``--set``.

Two figures and a JSON file into OUT:

* ``envelope.png``: the torque-speed envelope (the most motoring and braking torque at each speed,
  ``pmsm_ev.references.torque_envelope``), coloured by the reference generator's region (MTPA, field
  weakening, MTPV, the current and voltage limits), with the base, MTPV and maximum speeds
  (``region_speeds``); beside it the current plane: the current limit's circle, the MTPA and MTPV
  trajectories and the voltage limit's ellipses at a few speeds; with ``--run DIR`` the run's operating
  points (omega_m, T_e and i_d, i_q of its results.csv) over both;
* ``efficiency.png``: the motor + inverter efficiency over torque and speed within the envelope: at each
  point the generator's references (the least current for the torque, ``operating_points``) and the
  plant's steady-state losses there (``pmsm_ev.losses.steady_state``: copper, friction, the inverter's
  conduction and switching losses when ``inverter_losses`` is on; motoring P_shaft / P_dc, generating
  P_dc / P_shaft);
* ``envelope.json``: the limits and the region speeds.

With ``--published``, ``published.py`` sets the map beside a measured one (the 2004 Prius motor and inverter,
ORNL/TM-2006/423 Table B-1) in per-unit: ``efficiency_vs_published.png`` and ``.md``, ``envelope.json``'s
``published``.

The parameters are the package's defaults with the reference generator in field weakening on a 360 V DC
link (``reference = "fw"``, ``v_dc = 360``); ``--set NAME=VALUE`` changes any field of ``MotorParams``,
``ControllerParams``, ``PlantParams`` or ``VehicleParams`` (a name in several groups changes it in each:
``v_dc`` is the controller's and the plant's DC link). The motor is one: the controller's model and the
plant's motor are the same here.
"""

from __future__ import annotations

import json
import math
from dataclasses import fields, replace
from pathlib import Path

import numpy as np

from pmsm_ev import kernels, losses, references
from pmsm_ev.params import (
    SOURCED_IRON,
    SOURCED_K_WIND,
    SOURCED_T_M0,
    ControllerParams,
    MotorParams,
    ParameterError,
    PlantParams,
    VehicleParams,
)

from ..engine.errors import CosimError, close_matches
from ..engine.recording import read_results

#: the groups ``--set`` reaches, and the defaults of the envelope (field weakening on a 360 V DC link)
GROUPS = {"motor": MotorParams, "controller": ControllerParams, "plant": PlantParams, "vehicle": VehicleParams}
#: and the drive-cycle scenarios' sourced losses (docs/speed-range.md, "The losses"): the bearings and windage
#: instead of eq 8's B_m, T_m0, the iron losses, the data sheet's inverter
DEFAULTS = {"controller": {"reference": "fw", "v_dc": 360.0},
            "motor": {"B_m": 0.0, "T_m0": SOURCED_T_M0, "k_wind": SOURCED_K_WIND},
            "plant": {"v_dc": 360.0, "inverter_losses": True, "iron_c_h": SOURCED_IRON[0], "iron_c_e": SOURCED_IRON[1]}}
#: the speed axis reaches at least this vehicle speed [km/h] (where the motor can): an EV's top speed
AXIS_KMH = 150.0
#: the region colours of the figures, by region code (``pmsm_ev.references.REGIONS``)
REGION_COLOURS = ("C0", "C1", "C3", "C2", "C4", "0.6")
#: the speeds of the voltage ellipses in the current plane, as fractions of the envelope's speed range
ELLIPSE_FRACTIONS = (0.25, 0.5, 1.0)
#: the efficiency map's grid: speeds x torques [-]
MAP_SPEEDS, MAP_TORQUES = 48, 40  # an even number of torques: none at 0, where no power flows


def _parse(field, text: str):
    """``text`` as the type of a dataclass field (bool, int, float or str)."""
    kind = type(field.default)
    if kind is bool:
        low = text.strip().lower()
        if low in ("1", "true", "yes", "on"):
            return True
        if low in ("0", "false", "no", "off"):
            return False
        raise ParameterError(f"--set {field.name}={text}: not a boolean (true/false)")
    if kind in (int, float):
        try:
            value = float(text)
        except ValueError:
            raise ParameterError(f"--set {field.name}={text}: not a number") from None
        return int(value) if kind is int and value.is_integer() else value
    return text


def parameters(assignments=()) -> dict:
    """{group: params} with ``DEFAULTS`` and the ``NAME=VALUE`` assignments applied (each validated);
    ``ParameterError`` names an unknown name or a bad value."""
    changes = {g: dict(DEFAULTS.get(g, {})) for g in GROUPS}
    known = {}
    for g, cls in GROUPS.items():
        for f in fields(cls):
            known.setdefault(f.name, []).append((g, f))
    for item in assignments or ():
        name, sep, text = str(item).partition("=")
        name = name.strip()
        if not sep or not name:
            raise ParameterError(f"--set {item}: expected NAME=VALUE")
        if name not in known:
            raise ParameterError(f"--set {name}: no such parameter{close_matches(name, sorted(known))}")
        for g, f in known[name]:
            changes[g][name] = _parse(f, text)
    out = {}
    for g, cls in GROUPS.items():
        p = replace(cls(), **changes[g])
        p.validate()
        out[g] = p
    return out


def _run_points(run_dir: Path) -> dict:
    """omega_m, T_e, i_d, i_q of a run's results.csv (the columns it has)."""
    if not (run_dir / "results.csv").is_file():
        raise CosimError(f"--run {run_dir}: no results.csv there")
    r = read_results(run_dir)
    missing = [c for c in ("omega_m", "T_e") if c not in r]
    if missing:
        raise CosimError(f"--run {run_dir}: results.csv has no {', '.join(missing)} column")
    return {k: r[k] for k in ("omega_m", "T_e", "i_d", "i_q") if k in r}


def speed_range(speeds: dict, vehicle: VehicleParams, omega_max: float | None) -> float:
    """The envelope's speed axis [rad/s]: ``omega_max``, else the larger of 2.5 x the base speed and the motor
    speed of ``AXIS_KMH`` at the wheels (eqs 1, 6), but no more than 1.15 x the maximum speed."""
    if omega_max:
        return float(omega_max)
    w_axis = AXIS_KMH / 3.6 * vehicle.n_g / vehicle.r_w
    base, top = speeds["base_speed"], speeds["max_speed"]
    w = max(2.5 * base, w_axis) if math.isfinite(base) else w_axis
    return min(w, 1.15 * top) if math.isfinite(top) else w


def efficiency_map(p: dict, lim, omega_max: float, n_speeds: int = MAP_SPEEDS, n_torques: int = MAP_TORQUES) -> dict:
    """Motor + inverter efficiency on a grid of speeds (0, omega_max] x torques [-T_max, T_max] (NaN outside
    the envelope and where no power flows): {"omega", "T", "efficiency", "P_loss"} (arrays; rows: torques)."""
    w = np.linspace(omega_max / n_speeds, omega_max, n_speeds)
    t = np.linspace(-lim.T_max, lim.T_max, n_torques)
    motoring, braking, _ = references.torque_envelope(w, replace(lim, P_regen_max=0.0))
    eff = np.full((n_torques, n_speeds), np.nan)
    loss = np.full((n_torques, n_speeds), np.nan)
    ops = references.operating_points(t, w, lim)
    for a, ta in enumerate(t):
        for b, wb in enumerate(w):
            if not (braking[b] * (1 + 1e-9) <= ta <= motoring[b] * (1 + 1e-9)) or ta == 0.0:
                continue
            s = losses.steady_state(p["motor"], p["plant"], p["vehicle"], float(ops.i_d[a, b]), float(ops.i_q[a, b]),
                                    float(wb))
            if s["mode"] != "idle" and s["efficiency"] > 0.0:
                eff[a, b] = s["efficiency"]
            loss[a, b] = s["P_loss"]
    return {"omega": w, "T": t, "efficiency": eff, "P_loss": loss}


def efficiency_summary(em: dict, level: float = 0.9) -> dict:
    """The figures a published efficiency map is compared by (docs/speed-range.md): the peak and where it sits
    (omega_m [rad/s], T [N m], motoring), and the extent of the ``level`` contour on the motoring side: the
    share of the motoring points at or above it, and the speeds and torques it spans."""
    e = em["efficiency"]
    mot = np.isfinite(e) & (em["T"][:, None] > 0.0)
    out = {"max": None, "grid": [len(em["omega"]), len(em["T"])]}
    if not np.any(mot):
        return out
    em_mot = np.where(mot, e, -np.inf)
    a, b = np.unravel_index(int(np.argmax(em_mot)), e.shape)
    above = mot & (e >= level)
    out.update({"max": float(e[a, b]), "at_omega": float(em["omega"][b]), "at_T": float(em["T"][a]),
                "level": level, "share_above": float(above.sum() / mot.sum())})
    if np.any(above):
        rows, cols = np.nonzero(above)
        out.update({"omega_above": [float(em["omega"][cols.min()]), float(em["omega"][cols.max()])],
                    "T_above": [float(em["T"][rows.min()]), float(em["T"][rows.max()])]})
    return out


#: the speeds [rad/s] at which ``level_torques`` gives where the efficiency contour starts (docs/speed-range.md)
LEVEL_SPEEDS = (150.0, 300.0, 600.0, 1000.0, 1500.0)


def level_torques(p: dict, lim, speeds=LEVEL_SPEEDS, level: float = 0.9, n_torques: int = 400) -> list:
    """Where the motoring efficiency reaches ``level`` at each of ``speeds``: the lowest motoring torque T_from
    [N m] at which it does (``efficiency_map`` on that one speed and ``n_torques`` torques, the crossing
    interpolated linearly; None where it never does) and the best efficiency there, [{"omega", "T_from",
    "best"}]: the figures a published map's contour is read at."""
    out = []
    for w in speeds:
        em = efficiency_map(p, lim, float(w), n_speeds=1, n_torques=n_torques)
        mot = em["T"] > 0.0
        t, e = em["T"][mot], em["efficiency"][mot, 0]
        ok = np.flatnonzero(np.isfinite(e) & (e >= level))
        t_from = None
        if ok.size:
            i = int(ok[0])
            t_from = float(t[i]) if i == 0 or not np.isfinite(e[i - 1]) else float(
                t[i - 1] + (level - e[i - 1]) / (e[i] - e[i - 1]) * (t[i] - t[i - 1]))
        best = float(np.nanmax(e)) if np.any(np.isfinite(e)) else None
        out.append({"omega": float(w), "T_from": t_from, "best": best})
    return out


def mtpv_line(lim, n: int = 200):
    """The MTPV trajectory inside the current circle, (i_d, i_q >= 0) arrays [A] (``kernels.mtpv_angle`` on
    the flux circles up to psi); None where it lies outside the circle (psi / L_d > I_max)."""
    lam = np.linspace(lim.psi / n, lim.psi, n)
    d = np.array([kernels.mtpv_angle(x, lim.psi, lim.L_d, lim.L_q) for x in lam])
    i_d = (lam * np.cos(d) - lim.psi) / lim.L_d
    i_q = lam * np.sin(d) / lim.L_q
    inside = np.hypot(i_d, i_q) <= lim.i_max
    return (i_d[inside], i_q[inside]) if np.any(inside) else None


def _shade_regions(ax, w, t, region):
    for code in np.unique(region):
        sel = region == code
        ax.scatter(w[sel], t[sel], s=4, color=REGION_COLOURS[int(code) % len(REGION_COLOURS)],
                   label=references.REGIONS[int(code)], zorder=3)


def plot_envelope(ax, lim, speeds: dict, w, motoring, braking, region, points=()) -> None:
    """The torque-speed envelope on ``ax``: the most motoring and braking torque at the speeds ``w``
    (``references.torque_envelope``), coloured by region, the region speeds, and the operating points
    (omega_m, T_e) of ``points`` ((run directory, columns) pairs)."""
    w_top = float(w[-1])
    ax.plot(w, motoring, "k-", lw=0.8)
    ax.plot(w, braking, "k-", lw=0.8)
    _shade_regions(ax, w, motoring, region)
    ax.fill_between(w, braking, motoring, color="0.93", zorder=0)
    for key, label in (("base_speed", "base"), ("mtpv_speed", "MTPV"), ("max_speed", "max")):
        x = speeds[key]
        if math.isfinite(x) and x <= w_top:
            ax.axvline(x, color="0.4", ls=":", lw=0.8)
            ax.text(x, lim.T_max * 1.02, f"{label} {x:.0f}", fontsize=7, ha="center", va="bottom")
    if lim.P_regen_max > 0:
        ax.text(0.98 * w_top, braking[-1], f"regen limit {lim.P_regen_max / 1e3:g} kW", fontsize=7, ha="right",
                va="top")
    for i, (d, r) in enumerate(points):
        ax.plot(r["omega_m"], r["T_e"], ".", ms=1.5, color=f"C{5 + i}", alpha=0.5, label=f"run {d.name}", zorder=4)
    ax.set_xlabel("ω_m [rad/s]")
    ax.set_ylabel("torque [N m]")
    voltage = f"u {lim.u_fw:.0f} V" if lim.u_fw else "no voltage limit"
    ax.set_title(f"torque-speed envelope: I_max {lim.i_max:g} A, T_max {lim.T_max:.1f} N m, {voltage}", fontsize=9)
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=6, loc="lower left", markerscale=3)


def draw(p: dict, out: Path, runs=(), omega_max: float | None = None, efficiency: bool = True) -> dict:
    """The figures and envelope.json into ``out`` (see the module doc); returns what envelope.json holds."""
    import matplotlib  # noqa: PLC0415 - matplotlib: heavy, only when drawing

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - matplotlib: heavy, only when drawing

    lim = references.limits(p["controller"], p["motor"])
    speeds = references.region_speeds(lim)
    w_top = speed_range(speeds, p["vehicle"], omega_max)
    w = np.linspace(0.0, w_top, 400)
    motoring, braking, region = references.torque_envelope(w, lim)
    points = [(Path(d), _run_points(Path(d))) for d in runs]
    out.mkdir(parents=True, exist_ok=True)

    fig, (ax, axi) = plt.subplots(1, 2, figsize=(12.0, 4.8))
    plot_envelope(ax, lim, speeds, w, motoring, braking, region, points)

    # the current plane: the current circle, MTPA, the voltage ellipses, the MTPV line
    phi = np.linspace(0.0, 2.0 * math.pi, 361)
    axi.plot(lim.i_max * np.cos(phi), lim.i_max * np.sin(phi), "k-", lw=0.8, label=f"|i| = {lim.i_max:g} A")
    i_q = np.linspace(-lim.i_max, lim.i_max, 201)
    mtpa = np.array([kernels.mtpa_d_current(q, lim.psi, lim.L_d, lim.L_q) for q in i_q])
    inside = np.hypot(mtpa, i_q) <= lim.i_max * (1 + 1e-9)
    axi.plot(mtpa[inside], i_q[inside], "C0-", lw=1.2, label="MTPA")
    if lim.u_fw:
        for frac in ELLIPSE_FRACTIONS:
            we = lim.N * frac * w_top
            lam = lim.u_fw / we
            axi.plot((lam * np.cos(phi) - lim.psi) / lim.L_d, lam * np.sin(phi) / lim.L_q, "--", lw=0.7,
                     color="0.5")
            x_text = (lam - lim.psi) / lim.L_d
            if x_text < 0.25 * lim.i_max:
                axi.text(x_text, 0.0, f" {frac * w_top:.0f} rad/s", fontsize=6, color="0.4")
        mtpv = mtpv_line(lim)
        if mtpv is not None:
            axi.plot(mtpv[0], mtpv[1], "C3-", lw=1.0, label="MTPV")
            axi.plot(mtpv[0], -mtpv[1], "C3-", lw=1.0)
    for i, (d, r) in enumerate(points):
        if "i_d" in r and "i_q" in r:
            axi.plot(r["i_d"], r["i_q"], ".", ms=1.5, color=f"C{5 + i}", alpha=0.5)
    axi.set_xlim(-1.3 * lim.i_max, 0.3 * lim.i_max)
    axi.set_ylim(-1.15 * lim.i_max, 1.15 * lim.i_max)
    axi.set_aspect("equal")
    axi.set_xlabel("i_d [A]")
    axi.set_ylabel("i_q [A]")
    axi.set_title("current plane (dashed: voltage limit at the speeds named)", fontsize=9)
    axi.grid(True, lw=0.3)
    axi.legend(fontsize=6, loc="upper left")
    fig.tight_layout()
    made = [out / "envelope.png"]
    fig.savefig(made[0], dpi=100)
    plt.close(fig)

    summary = {"limits": {"i_max": lim.i_max, "T_max": lim.T_max, "u_fw": lim.u_fw, "P_regen_max": lim.P_regen_max,
                          "k_dq": p["motor"].k_dq, "N": lim.N, "psi": lim.psi, "L_d": lim.L_d, "L_q": lim.L_q},
               "speeds": {k: (v if math.isfinite(v) else None) for k, v in speeds.items()},
               "omega_axis": w_top, "figures": [str(m) for m in made]}
    if efficiency:
        em = efficiency_map(p, lim, w_top)
        fig, ax = plt.subplots(figsize=(7.5, 5.0))
        levels = [0.5, 0.7, 0.8, 0.85, 0.9, 0.92, 0.94, 0.95, 0.96, 0.97, 0.98, 0.99]
        filled = ax.contourf(em["omega"], em["T"], em["efficiency"], levels=levels, cmap="viridis", extend="both")
        lines = ax.contour(em["omega"], em["T"], em["efficiency"], levels=levels, colors="k", linewidths=0.4)
        ax.clabel(lines, fmt="%.2f", fontsize=6)
        fig.colorbar(filled, ax=ax, label="motor + inverter efficiency [-]")
        ax.plot(w, motoring, "k-", lw=0.8)
        ax.plot(w, braking, "k-", lw=0.8)
        for i, (d, r) in enumerate(points):
            ax.plot(r["omega_m"], r["T_e"], ".", ms=1.0, color="w", alpha=0.4)
        pl = p["plant"]
        kinds = ["copper", "friction"] + (["windage"] if p["motor"].k_wind else []) + (
            ["inverter"] if pl.inverter_losses else []) + (["iron"] if (pl.iron_c_h or pl.iron_c_e) else [])
        ax.set_title(f"motor + inverter efficiency, losses: {', '.join(kinds)} (generating: P_dc / P_shaft)",
                     fontsize=9)
        ax.set_xlabel("ω_m [rad/s]")
        ax.set_ylabel("torque [N m]")
        fig.tight_layout()
        made.append(out / "efficiency.png")
        fig.savefig(made[-1], dpi=100)
        plt.close(fig)
        summary["efficiency"] = efficiency_summary(em)
        summary["efficiency"]["level_from"] = level_torques(p, lim)
        summary["figures"] = [str(m) for m in made]
    (out / "envelope.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary
