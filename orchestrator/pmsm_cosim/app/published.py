"""This model's motor + inverter efficiency map set beside a published, measured one (``pmsm-cosim envelope
--published``): the 2004 Toyota Prius's traction motor and inverter on ORNL's dynamometer, Table B-1 of
ORNL/TM-2006/423 (``data/ornl_prius2004_table_b1.csv``, its source and conditions in its header).

The two motors differ in size (the Prius's 50 kW and 400 N m on a ~500 V link; this model's ~56 kW and
153 N m on 360 V), so both are put in per-unit: speed over the corner speed (this model's base speed, where
MTPA at its torque limit meets the voltage limit; the Prius's rated power over its rated torque) and torque
over the peak torque. The figures compared are the peak efficiency and where it sits, and the extent of the
90 % contour: the share of the measured operating points at or above it (this model at the same per-unit
points), the speeds and torques it spans, and at each speed of the measurement the torques where it is
entered and left. Everything is computed here from the table and the model; nothing is typed in.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from pmsm_ev import losses, references

from . import envelope

#: Table B-1 of ORNL/TM-2006/423, as the file's header says
DATA = Path(__file__).with_name("data") / "ornl_prius2004_table_b1.csv"
#: the 2004 Prius motor's ratings: 50 kW, 400 N m, 6000 rpm (ORNL/TM-2010/253, Burress et al., "Evaluation of
#: the 2010 Toyota Prius Hybrid Synergy Drive System", Table 2.1, p. 5, its 2004 Prius column, as
#: jonelay/heat-sweep's data/ornl_hev_benchmarking/design_comparison.csv transcribes it); ORNL/TM-2006/423's
#: abstract: "a peak-power output of 50 kW over the speed range of 1200-1540 rpm", so the corner speed
#: P / T = 125 rad/s (1194 rpm) is where that range starts
PRIUS_2004 = {"name": "2004 Prius MG2 + inverter (ORNL/TM-2006/423, Table B-1)", "P_peak": 50.0e3, "T_peak": 400.0,
              "n_max_rpm": 6000.0}
#: the efficiency level whose contour is compared
LEVEL = 0.9
#: the contour levels of the figure (those of ``pmsm-cosim envelope``'s map)
LEVELS = (0.5, 0.7, 0.8, 0.85, 0.9, 0.92, 0.94, 0.95, 0.96, 0.97, 0.98, 0.99)
#: torques of the model's line at each measured speed (``level_crossings``) [-]
LINE_TORQUES = 400
#: where the losses are split (``loss_split``): the measured points nearest these (speed, torque) per-unit
#: points: low speed at half torque, about the corner at 0.7 of the peak torque, the measured peak's
#: neighbourhood, top speed at light load
SPLIT_AT_PU = ((0.25, 0.5), (1.1, 0.7), (1.9, 0.28), (5.0, 0.1))


def load(path: Path = DATA) -> dict:
    """The table's columns as arrays (``#`` lines are its header), with omega [rad/s], the combined efficiency
    recomputed from the powers (``eta`` = P_mech / P_dc; the table's ``eta_total`` kept beside it) and ``group``:
    the nominal speed of the test [rpm], the speed rounded to 100 rpm (each of the table's speeds lies within
    7 % of its test's)."""
    with Path(path).open(encoding="utf-8") as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    if not rows:
        raise ValueError(f"{path}: no rows")
    out = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    out["omega"] = out["speed_rpm"] * math.pi / 30.0
    out["eta"] = out["p_mech_W"] / out["p_dc_W"]
    out["group"] = np.round(out["speed_rpm"] / 100.0) * 100.0
    return out


def corner_speed(rating: dict) -> float:
    """The corner speed of a rating [rad/s]: its peak power over its peak torque."""
    return rating["P_peak"] / rating["T_peak"]


def level_crossings(T, eta, level: float = LEVEL) -> dict:
    """Along one speed: the lowest torque at which the efficiency reaches ``level`` (``T_from``) and the highest
    at which it still holds it (``T_to``), each interpolated linearly between the neighbouring torques (the
    end torque where it holds at the end: ``from_edge`` / ``to_edge`` say so), None where it never does; and the
    best efficiency there. NaN efficiencies (outside the envelope) are left out."""
    T = np.asarray(T, dtype=float)
    eta = np.asarray(eta, dtype=float)
    ok = np.isfinite(eta)
    order = np.argsort(T[ok])
    t, e = T[ok][order], eta[ok][order]
    out = {"T_from": None, "T_to": None, "from_edge": False, "to_edge": False,
           "best": float(e.max()) if e.size else None}
    above = np.flatnonzero(e >= level)
    if not above.size:
        return out
    i, j = int(above[0]), int(above[-1])

    def cross(a, b):
        return float(t[a] + (level - e[a]) / (e[b] - e[a]) * (t[b] - t[a]))

    out["T_from"] = float(t[0]) if i == 0 else cross(i - 1, i)
    out["T_to"] = float(t[-1]) if j == t.size - 1 else cross(j, j + 1)
    out["from_edge"], out["to_edge"] = i == 0, j == t.size - 1
    return out


def point_summary(omega, T, eta, omega_c: float, T_pk: float, level: float = LEVEL) -> dict:
    """The figures a map on a set of operating points is compared by: the peak efficiency and where it sits
    ([rad/s], [N m] and per-unit of ``omega_c``, ``T_pk``), the share of the points at or above ``level`` (of
    those with an efficiency), and the per-unit speeds and torques those points span."""
    omega, T, eta = (np.asarray(x, dtype=float) for x in (omega, T, eta))
    ok = np.isfinite(eta)
    k = int(np.nanargmax(np.where(ok, eta, -np.inf)))
    above = ok & (eta >= level)
    out = {"max": float(eta[k]), "at_omega": float(omega[k]), "at_T": float(T[k]),
           "at_pu": [float(omega[k] / omega_c), float(T[k] / T_pk)], "level": level, "points": int(ok.sum()),
           "share_above": float(above.sum() / ok.sum()), "omega_above_pu": None, "T_above_pu": None}
    if np.any(above):
        out["omega_above_pu"] = [float(omega[above].min() / omega_c), float(omega[above].max() / omega_c)]
        out["T_above_pu"] = [float(T[above].min() / T_pk), float(T[above].max() / T_pk)]
    return out


def efficiency_at(p: dict, lim, omega, T) -> np.ndarray:
    """This model's motor + inverter efficiency at the motoring operating points (omega [rad/s], T [N m]) (pairs),
    as ``envelope.efficiency_map`` has it at each (the generator's references, the plant's steady-state
    losses, P_shaft / P_dc); NaN outside the envelope and where no power flows."""
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    t = np.atleast_1d(np.asarray(T, dtype=float))
    speeds, where = np.unique(w, return_inverse=True)
    motoring, _, _ = references.torque_envelope(speeds, replace(lim, P_regen_max=0.0))
    out = np.full(w.size, np.nan)
    for k in range(w.size):
        if not 0.0 < t[k] <= motoring[where[k]] * (1 + 1e-9):
            continue
        ops = references.operating_points(t[k:k + 1], w[k:k + 1], lim)
        s = losses.steady_state(p["motor"], p["plant"], p["vehicle"], float(ops.i_d[0, 0]), float(ops.i_q[0, 0]),
                                float(w[k]))
        if s["mode"] != "idle" and s["efficiency"] > 0.0:
            out[k] = s["efficiency"]
    return out


def loss_split(p: dict, lim, pub: dict, omega_c: float, T_pk: float, at_pu=SPLIT_AT_PU) -> list:
    """At the measured points nearest each of ``at_pu`` (speed, torque per-unit; the torque's distance counts
    three times the speed's, the table's grid being finer in torque): the measured losses, the motor's
    (P_ac - P_mech) and the inverter's (P_dc - P_ac), and this model's at the same per-unit point (its copper,
    iron, friction and windage, inverter), each as a share of P_dc; and the current, as a share of the largest
    (the measured phase current over the largest in the table; the model's |i| over its I_max)."""
    x, y = pub["omega"] / omega_c, pub["torque_Nm"] / T_pk
    w_b = references.region_speeds(lim)["base_speed"]
    out = []
    for xs, ys in at_pu:
        k = int(np.argmin(np.hypot(x - xs, 3.0 * (y - ys))))
        w, t = float(x[k] * w_b), float(y[k] * lim.T_max)
        row = {"rpm": float(pub["speed_rpm"][k]), "T": float(pub["torque_Nm"][k]), "pu": [float(x[k]), float(y[k])],
               "measured": {"eta": float(pub["eta"][k]),
                            "motor": float((pub["p_ac_W"][k] - pub["p_mech_W"][k]) / pub["p_dc_W"][k]),
                            "inverter": float((pub["p_dc_W"][k] - pub["p_ac_W"][k]) / pub["p_dc_W"][k]),
                            "t_stator_C": float(pub["t_stator_C"][k]),
                            "current": float(pub["i_ac_A"][k] / pub["i_ac_A"].max())},
               "model": None}
        if np.isfinite(efficiency_at(p, lim, w, t)[0]):
            ops = references.operating_points(np.array([t]), np.array([w]), lim)
            st = losses.steady_state(p["motor"], p["plant"], p["vehicle"], float(ops.i_d[0, 0]),
                                     float(ops.i_q[0, 0]), w)
            row["model"] = {"eta": float(st["efficiency"]), "omega": w, "T": t,
                            "current": float(math.hypot(ops.i_d[0, 0], ops.i_q[0, 0]) / lim.i_max),
                            **{k: float(st[f"P_{k}"] / st["P_dc"]) for k in ("copper", "iron", "friction", "inverter")}}
        out.append(row)
    return out


def compare(p: dict, pub: dict | None = None, rating: dict = PRIUS_2004, level: float = LEVEL,
            line_torques: int = LINE_TORQUES) -> dict:
    """The comparison (what ``envelope.json``'s ``published`` block holds): the per-unit bases of both, the
    published points' ``point_summary``, this model's at the same per-unit points, and at each measured speed
    the published and this model's ``level_crossings`` (in per-unit; the model's on ``line_torques`` torques
    up to its envelope)."""
    pub = load() if pub is None else pub
    lim = references.limits(p["controller"], p["motor"])
    w_b = references.region_speeds(lim)["base_speed"]
    t_b = lim.T_max
    w_c, t_c = corner_speed(rating), rating["T_peak"]
    x, y = pub["omega"] / w_c, pub["torque_Nm"] / t_c
    model_eta = efficiency_at(p, lim, x * w_b, y * t_b)
    out = {"published": {"name": rating["name"], "omega_corner": w_c, "T_peak": t_c, "P_peak": rating["P_peak"],
                         "v_dc": [float(pub["v_dc_V"].min()), float(pub["v_dc_V"].max())],
                         "eta_vs_table": float(np.max(np.abs(pub["eta"] - pub["eta_total"]))),
                         "motor_max": float(pub["eta_motor"].max()), "inverter_max": float(pub["eta_inverter"].max()),
                         **point_summary(pub["omega"], pub["torque_Nm"], pub["eta"], w_c, t_c, level)},
           "model": {"omega_corner": w_b, "T_peak": t_b, "P_corner": w_b * t_b, "v_dc": p["plant"].v_dc,
                     **point_summary(x * w_b, y * t_b, model_eta, w_b, t_b, level)},
           "by_speed": [], "loss_split": loss_split(p, lim, pub, w_c, t_c)}
    motoring, _, _ = references.torque_envelope(np.unique(pub["group"]) * math.pi / 30.0 / w_c * w_b, lim)
    for g, t_edge in zip(np.unique(pub["group"]), motoring, strict=True):
        sel = pub["group"] == g
        x_g = float(np.mean(x[sel]))
        measured = level_crossings(y[sel], pub["eta"][sel], level)
        t_line = np.linspace(t_edge / line_torques, t_edge, line_torques)
        line = efficiency_at(p, lim, np.full(t_line.size, x_g * w_b), t_line)
        model = level_crossings(t_line / t_b, line, level)
        out["by_speed"].append({"rpm": float(g), "omega_pu": x_g, "T_measured_pu": [float(y[sel].min()),
                                                                                     float(y[sel].max())],
                                "published": measured, "model": model})
    return out


def _fmt_span(span, fmt="{:.2f}"):
    return "none" if span is None else f"{fmt.format(span[0])}-{fmt.format(span[1])}"


def table(c: dict, speeds_rpm=(300, 700, 1300, 2300, 3000, 3800, 5000, 6000)) -> str:
    """The comparison as markdown: the figures of each map, then where the 90 % contour is at some measured
    speeds."""
    pub, mod = c["published"], c["model"]
    lvl = f"{100 * pub['level']:.0f} %"
    lines = [f"| map | peak | where: rad/s, N m (per-unit) | points at >= {lvl} | >= {lvl} spans: speed, torque "
             f"(per-unit) |", "|---|---|---|---|---|"]
    for label, s in ((f"{pub['name']}, measured, {pub['v_dc'][0]:.0f}-{pub['v_dc'][1]:.0f} V", pub),
                     (f"this model at the same per-unit points, {mod['v_dc']:.0f} V", mod)):
        lines.append(f"| {label} | {100 * s['max']:.1f} % | {s['at_omega']:.0f}, {s['at_T']:.1f} "
                     f"({s['at_pu'][0]:.2f}, {s['at_pu'][1]:.2f}) | {100 * s['share_above']:.1f} % of "
                     f"{s['points']} | {_fmt_span(s['omega_above_pu'])}, {_fmt_span(s['T_above_pu'])} |")
    lines += ["", f"| speed (per-unit) | measured torques | >= {lvl} from-to, measured (best) | this model (best) |",
              "|---|---|---|---|"]

    def span(m):
        if m["T_from"] is None:
            return f"none ({100 * m['best']:.1f} %)"
        lo = ("<= " if m["from_edge"] else "") + f"{m['T_from']:.2f}"
        hi = (">= " if m["to_edge"] else "") + f"{m['T_to']:.2f}"
        return f"{lo}-{hi} ({100 * m['best']:.1f} %)"

    for row in c["by_speed"]:
        if row["rpm"] in speeds_rpm:
            lines.append(f"| {row['rpm']:.0f} rpm ({row['omega_pu']:.2f}) | {_fmt_span(row['T_measured_pu'])} | "
                         f"{span(row['published'])} | {span(row['model'])} |")
    lines += ["", "| measured point: rpm, N m (per-unit) | measured: efficiency; motor, inverter losses (of P_dc); "
              "current (of the largest) | this model: efficiency; copper, iron, friction and windage, inverter losses "
              "(of P_dc); current (of I_max) |",
              "|---|---|---|"]
    for r in c["loss_split"]:
        m, mo = r["measured"], r["model"]
        model = "outside its envelope" if mo is None else (
            f"{100 * mo['eta']:.1f} %; {100 * mo['copper']:.1f}, {100 * mo['iron']:.1f}, {100 * mo['friction']:.2f}, "
            f"{100 * mo['inverter']:.1f} %; {mo['current']:.2f}")
        lines.append(f"| {r['rpm']:.0f}, {r['T']:.1f} ({r['pu'][0]:.2f}, {r['pu'][1]:.2f}) | {100 * m['eta']:.1f} %; "
                     f"{100 * m['motor']:.1f}, {100 * m['inverter']:.1f} %; {m['current']:.2f} | {model} |")
    return "\n".join(lines) + "\n"


def draw(p: dict, c: dict, out: Path, pub: dict | None = None, rating: dict = PRIUS_2004) -> Path:
    """``efficiency_vs_published.png`` in ``out``: in per-unit of each motor's corner speed and peak torque, the
    measured map (contours over the triangulated points, the region measured) and this model's (motoring),
    each with the other's 90 % contour dashed and both peaks marked."""
    import matplotlib  # noqa: PLC0415 - matplotlib: heavy, only when drawing

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - matplotlib: heavy, only when drawing
    from matplotlib.tri import Triangulation  # noqa: PLC0415 - as above

    pub = load() if pub is None else pub
    w_c, t_c = corner_speed(rating), rating["T_peak"]
    x, y = pub["omega"] / w_c, pub["torque_Nm"] / t_c
    tri = Triangulation(x, y)
    # the region measured: under the largest torque measured at each speed (the envelope's concave side)
    groups = np.unique(pub["group"])
    gx = np.array([np.mean(x[pub["group"] == g]) for g in groups])
    top = np.array([y[pub["group"] == g].max() for g in groups])
    cx, cy = x[tri.triangles].mean(axis=1), y[tri.triangles].mean(axis=1)
    tri.set_mask(cy > np.interp(cx, gx, top) + 1e-3)

    lim = references.limits(p["controller"], p["motor"])
    w_b, t_b = c["model"]["omega_corner"], c["model"]["T_peak"]
    x_max = 1.05 * float(x.max())
    em = envelope.efficiency_map(p, lim, x_max * w_b, n_speeds=60, n_torques=80)
    mot = em["T"] > 0.0
    mx, my, me = em["omega"] / w_b, em["T"][mot] / t_b, em["efficiency"][mot]
    w_line = np.linspace(0.0, x_max * w_b, 300)
    edge, _, _ = references.torque_envelope(w_line, lim)

    fig, axes = plt.subplots(1, 2, figsize=(12.0, 5.2), sharex=True, sharey=True, layout="constrained")
    ax_p, ax_m = axes
    filled = ax_p.tricontourf(tri, pub["eta"], levels=LEVELS, cmap="viridis", extend="both")
    ax_p.tricontour(tri, pub["eta"], levels=LEVELS, colors="k", linewidths=0.4)
    ax_p.tricontour(tri, pub["eta"], levels=[LEVEL], colors="r", linewidths=1.6)
    ax_p.plot(x, y, "k.", ms=1.5)
    ax_p.contour(mx, my, me, levels=[LEVEL], colors="w", linewidths=1.4, linestyles="--")
    ax_m.contourf(mx, my, me, levels=LEVELS, cmap="viridis", extend="both")
    lines = ax_m.contour(mx, my, me, levels=LEVELS, colors="k", linewidths=0.4)
    ax_m.clabel(lines, fmt="%.2f", fontsize=6)
    ax_m.contour(mx, my, me, levels=[LEVEL], colors="w", linewidths=1.6)
    ax_m.tricontour(tri, pub["eta"], levels=[LEVEL], colors="r", linewidths=1.4, linestyles="--")
    ax_m.plot(w_line / w_b, edge / t_b, "k-", lw=0.8)
    for ax in axes:
        for s, colour in ((c["published"], "r"), (c["model"], "w")):
            ax.plot(*s["at_pu"], marker="*", ms=11, color=colour, mec="k", mew=0.6)
        ax.set_xlabel("speed / corner speed [-]")
        ax.grid(True, lw=0.3)
        ax.set_xlim(0.0, x_max)
        ax.set_ylim(0.0, 1.05)
    pp, mm = c["published"], c["model"]
    ax_p.set_ylabel("torque / peak torque [-]")
    ax_p.set_title(f"measured: {pp['name']}\nP_mech / P_dc, {pp['v_dc'][0]:.0f}-{pp['v_dc'][1]:.0f} V; corner "
                   f"{pp['omega_corner']:.0f} rad/s, peak {pp['T_peak']:.0f} N m\nred: its 90 %; white dashed: "
                   "the model's 90 %; dots: the points measured", fontsize=8)
    ax_m.set_title(f"this model (the sourced losses), P_shaft / P_dc, {mm['v_dc']:.0f} V\ncorner (base) "
                   f"{mm['omega_corner']:.0f} rad/s, peak {mm['T_peak']:.1f} N m\nwhite: its 90 %; red dashed: the "
                   "measured 90 %; stars: the peaks (red measured)", fontsize=8)
    fig.colorbar(filled, ax=list(axes), label="motor + inverter efficiency [-]", shrink=0.9, pad=0.01)
    Path(out).mkdir(parents=True, exist_ok=True)
    path = Path(out) / "efficiency_vs_published.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def write(p: dict, out: Path) -> dict:
    """``pmsm-cosim envelope --published``: the comparison into ``out``: the figure (``draw``), the tables
    (``efficiency_vs_published.md``) and ``envelope.json``'s ``published`` block (the file's other blocks kept);
    returns the comparison with ``figure`` and ``table`` (the markdown) added."""
    out = Path(out)
    c = compare(p)
    fig = draw(p, c, out)
    md = table(c)
    (out / "efficiency_vs_published.md").write_text(md, encoding="utf-8")
    path = out / "envelope.json"
    doc = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    doc["published"] = c
    doc["figures"] = sorted({*doc.get("figures", []), str(fig)})
    path.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return {**c, "figure": str(fig), "table": md}
