"""The report's section "Drive cycles": the shipped cycle scenarios (``wltc3b``, ``udds``, ``hwfet``, ``us06``,
sensored and truly sensorless from standstill, and ``wltc3b-hilly``), held to the regulatory tolerance band
(metrics.json's ``trace``, ``metrics.trace.trace_figures``), their synchronism (``synchronism``), and their
energy over the cycle and per WLTC phase (``metrics.cycle_energy``: Wh/km, regeneration, losses by kind, the
balance and the wheel energy against the trace's road-load integral). Every number in the text is computed from
the runs (docs/cycles.md, "The report's cycles")."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pmsm_ev import cycles, references
from pmsm_ev.params import InjectionParams
from pmsm_ev.results import row_timing_corrected_angle_error

from .. import envelope
from ..drive import load_system
from ..metrics import cycle_energy
from ..metrics.rows import KMH
from ..metrics.trace import TRACE_BAND_KMH, TRACE_WINDOW_S, trace_band
from ..metrics.verdicts import INSIDE_MIN
from ..metrics.windows import run_timing
from .configs import CYCLE_RUNS as RUNS
from .drawing import figure_links, pyplot, save_figure
from .drawing import num as _num
from .speed_range import SCENARIO_SETS, limits

#: a torque at least this share of the envelope's at its speed counts as at the drive's limit
AT_LIMIT = 0.98
#: the WLTC pair the phase tables and the figures compare
WLTC_PAIR = ("cyc-wltc3b", "cyc-wltc3b-if")
#: the angle error is drawn where the rotor turns faster than this [rad/s] (at standstill no back-EMF shows it)
ANGLE_FROM_SPEED = 20.0
#: the kinds of energy of the bars, in stacking order: (label, path in phase_energy's energy block); with the
#: stored energies' changes (0 for a phase from standstill to standstill) they add up to the DC link's net
KINDS = (("aero", ("road_Wh", "aero")), ("rolling", ("road_Wh", "rolling")), ("grade", ("road_Wh", "grade")),
         ("friction brake", ("brake_Wh",)), ("copper", ("losses_Wh", "copper")),
         ("inverter", ("losses_Wh", "inverter")), ("iron", ("losses_Wh", "iron")),
         ("motor friction", ("losses_Wh", "friction")), ("gear", ("losses_Wh", "gear")),
         ("kinetic energy gained", ("kinetic_change_Wh",)), ("magnetic energy gained", ("magnetic_change_Wh",)))
LOSS_KINDS = ("copper", "inverter", "iron", "friction", "gear")


def _pct(x, fmt=".2f") -> str:
    return "-" if x is None else f"{_num(100.0 * x, fmt)} %"


def figures_of(data, cid: str) -> dict | None:
    """One run's figures (None without the run): ``status``, ``trace`` (metrics.json's), ``synchronism``,
    ``cycle`` (``pmsm_ev.cycles.Cycle``, None if the run has no trace), ``whole`` (``cycle_energy.whole_run``),
    ``phases`` (``cycle_energy.phase_energy``). Computed once per run."""
    cache = data.__dict__.setdefault("_cycle_figures", {})
    if cid in cache:
        return cache[cid]
    run = data.runs.get(cid)
    if run is None:
        return None
    m = run.metrics
    trace = m.get("trace") or {}
    cycle = cycles.load(trace["cycle"]) if trace.get("cycle") else None
    _, vehicle = cycle_energy.plant_params(m)
    r = run.r
    has_energy = all(c in r for c in cycle_energy.ENERGY_COLUMNS)
    out = {"status": m.get("status"), "trace": trace, "synchronism": m.get("synchronism") or {}, "cycle": cycle,
           "whole": cycle_energy.whole_run(r, vehicle) if has_energy else None,
           "phases": cycle_energy.phase_energy(r, cycle, vehicle) if has_energy and cycle is not None else [],
           "t_end": float(r["time"][-1])}
    cache[cid] = out
    return out


def _phase_at(cycle, t: float) -> str:
    for w in cycle_energy.phase_windows(cycle, cycle.duration + 1.0):
        if w.start <= t <= w.end:
            return w.name
    return "-"


def excursions_by_phase(r: dict, cycle, trace: dict) -> str:
    """The excursions outside the band by the phase they start in, with their total time: "low 2 (3.10 s), ..."
    (the rows outside ``trace_band``, as ``pmsm_cosim.app.metrics.trace.trace_figures`` counts them)."""
    t = r["time"]
    keep = t <= trace["t_end"] + 1e-9
    t, v = t[keep], r["v_vehicle"][keep]
    lower, upper = trace_band(cycle.time, cycle.speed, trace["band_kmh"], trace["window_s"], t)
    outside = np.concatenate(([0], ((v < lower - 1e-9) | (v > upper + 1e-9)).astype(np.int8), [0]))
    starts, ends = np.nonzero(np.diff(outside) == 1)[0], np.nonzero(np.diff(outside) == -1)[0]
    dt_row = float(np.median(np.diff(t)))
    count: dict[str, list[float]] = {}
    for a, b in zip(starts, ends):
        count.setdefault(_phase_at(cycle, float(t[a])), []).append((b - a) * dt_row)
    return ", ".join(f"{name} {len(x)} ({sum(x):.2f} s)" for name, x in count.items())


def diagnosis(run, f: dict, lim) -> str:
    """Where and why a run left the band (or stopped), from its rows: the longest excursion's start, length,
    phase, the trace's speed there and the largest shortfall or excess in it, and what the drive was doing
    meanwhile: the share of it in alignment or I-f, at the torque envelope (|T_e| >= ``AT_LIMIT`` of the
    most the drive has at that speed), with the friction brake on, and the unit's loss-of-synchronism
    episodes and fault. "" when the run completed inside the band for ``INSIDE_MIN`` of the cycle."""
    tr, parts = f["trace"], []
    if f["status"] != "completed":
        parts.append(f"the run did not complete (status {f['status']}, last row at {f['t_end']:.2f} s)")
    share = tr.get("inside_share")
    if share is not None and share < INSIDE_MIN and tr.get("t_longest_excursion") is not None:
        cycle, r = f["cycle"], run.r
        t0, length = tr["t_longest_excursion"], tr["longest_excursion_s"]
        w = (r["time"] >= t0 - 1e-9) & (r["time"] < t0 + length - 1e-9)
        dev = (r["v_vehicle"][w] - np.interp(r["time"][w], cycle.time, cycle.speed)) * KMH
        worst = float(dev[int(np.argmax(np.abs(dev)))]) if dev.size else 0.0
        omega, torque = np.abs(r["omega_m"][w]), r["T_e"][w]
        motoring, braking, _ = references.torque_envelope(omega, lim)
        at_limit = np.where(torque >= 0, torque >= AT_LIMIT * motoring, torque <= AT_LIMIT * braking)
        what = [f"at the torque envelope {100 * float(np.mean(at_limit)):.0f} % of it"]
        if "mode" in r:
            mode = r["mode"][w]
            what.insert(0, f"in alignment {100 * float(np.mean(mode == 0)):.0f} % and in I-f "
                           f"{100 * float(np.mean(mode == 1)):.0f} % of it")
        if "T_brake" in r:
            what.append(f"the friction brake on {100 * float(np.mean(r['T_brake'][w] > 0)):.0f} % of it")
        s = f["synchronism"]
        if s:
            what.append(f"{s.get('episodes', 0)} loss-of-synchronism episodes in the run"
                        + (f", the fault latched at {s['t_fault']:.2f} s" if s.get("fault_latched") else ""))
        parts.append(
            f"inside the band only {100 * share:.2f} % of the time ({tr['excursions']} excursions: "
            f"{excursions_by_phase(r, cycle, tr)}); the longest, "
            f"{length:.2f} s from {t0:.2f} s (phase {_phase_at(cycle, t0)}, trace at "
            f"{float(np.interp(t0, cycle.time, cycle.speed)) * KMH:.1f} km/h), the car "
            f"{abs(worst):.2f} km/h {'behind' if worst < 0 else 'ahead of'} the trace at most; meanwhile the drive "
            f"was {', '.join(what)}")
    return "; ".join(parts)


def _cycle_table(data, rows: dict) -> list[str]:
    head = ("| cycle | controller | completed | inside the band | excursions | longest | RMSE | largest deviation | "
            "slipped turns | loss-of-sync episodes | Wh/km (DC) | regenerated / drawn | balance residual / "
            "throughput | road-load integral vs wheel (net, traction) |")
    L = [head, "|" + "---|" * (head.count("|") - 1)]
    for cid, scen, setup in RUNS:
        f = rows.get(cid)
        if f is None:
            L.append(f"| {scen} | {setup.label} | (no run) |" + " |" * (head.count("|") - 4))
            continue
        tr, s, wh = f["trace"], f["synchronism"], f["whole"] or {}
        e, bal, wc = wh.get("energy") or {}, wh.get("balance") or {}, wh.get("wheel") or {}
        share = tr.get("inside_share")
        mark = "" if share is None or share >= INSIDE_MIN else f" (< {100 * INSIDE_MIN:g} %)"
        longest = tr.get("longest_excursion_s")
        longest = "-" if longest is None else f"{longest:.2f} s at {tr['t_longest_excursion']:.1f} s"
        L.append(
            f"| {scen} | {setup.label} | {'yes' if f['status'] == 'completed' else f['status']} "
            f"({_num(tr.get('t_end'), '.0f')} s) | {_pct(share)}{mark} | {tr.get('excursions', '-')} | "
            f"{longest} | "
            f"{_num(tr.get('rmse_kmh'))} km/h | {_num(tr.get('max_deviation_kmh'), '+.2f')} km/h at "
            f"{_num(tr.get('t_max_deviation'), '.1f')} s | {s.get('slipped_turns', '-')} | {s.get('episodes', '-')} | "
            f"{_num(e.get('dc_Wh_per_km'))} | {_pct(wh.get('regen_share'), '.1f')} | "
            f"{_num(bal.get('relative'), '.2e')} | {_pct(wc.get('net_rel'), '.3f')}, "
            f"{_pct(wc.get('traction_rel'), '.3f')} |")
    return L + [""]


def _get(e: dict, path) -> float:
    x = e
    for k in path:
        x = (x or {}).get(k)
    return float(x or 0.0)


def _phase_table(pair: list[tuple[str, dict]]) -> list[str]:
    head = ("| phase | controller | distance | Wh/km (DC) | drawn | regenerated | regenerated / drawn | "
            "regenerated / braking at the wheels | copper | inverter | iron | motor friction | gear | friction brake | "
            "road (aero, rolling, grade) | residual / throughput |")
    L = [head, "|" + "---|" * (head.count("|") - 1)]
    names = [p["name"] for p in pair[0][1]["phases"]]
    for i, name in enumerate(names):
        for label, f in pair:
            if i >= len(f["phases"]):
                continue
            p = f["phases"][i]
            e, lo = p["energy"], p["energy"]["losses_Wh"]
            road = e["road_Wh"]
            L.append(
                f"| {name}{'' if p['complete'] else ' (to ' + format(p['end'], 'g') + ' s)'} | {label} | "
                f"{e['distance_m'] / 1000:.3f} km | {_num(e['dc_Wh_per_km'])} | {e['drawn_Wh']:.1f} Wh | "
                f"{e['regen_Wh']:.1f} Wh | {_pct(p['regen_share'], '.1f')} | {_pct(p['regen_of_braking'], '.1f')} | "
                + " | ".join(f"{lo[k]:.2f}" for k in LOSS_KINDS)
                + f" | {e['brake_Wh']:.2f} | {road['aero']:.1f}, {road['rolling']:.1f}, {road['grade']:.1f} | "
                f"{_num(p['residual_rel'], '.1e')} |")
    return L + ["", "(energies in Wh)", ""]


def _interval_index(t: np.ndarray, dt_row: float) -> np.ndarray:
    return np.rint(t[:-1] / dt_row).astype(np.int64)


def sensorless_cost(sensored, sensorless, fs: dict, fl: dict) -> list[dict]:
    """Per phase, what the sensorless run cost against the sensored one: the differences of Wh/km, DC energy
    and losses, its time in alignment and I-f, its copper loss over its I-f intervals and the sensored run's
    over the same intervals (rows at the same times), and their difference (``extra_copper_if_Wh``); the same for
    the inverter's losses (``inverter_if_Wh``, ``inverter_same_sensored_Wh``, ``extra_inverter_if_Wh``)."""
    rs, rl = sensored.r, sensorless.r
    dt_row = float(rl["time"][1] - rl["time"][0])
    out = []
    for ps, pl in zip(fs["phases"], fl["phases"]):
        es, el = ps["energy"], pl["energy"]
        ml = pl["modes"] or {}
        in_l = (rl["time"][:-1] >= pl["start"] - 1e-9) & (rl["time"][1:] <= pl["end"] + 1e-9) & (rl["mode"][:-1] == 1)
        if_idx = _interval_index(rl["time"], dt_row)[in_l]
        same = np.isin(_interval_index(rs["time"], dt_row), if_idx)
        if_losses = {k: (cycle_energy.interval_sum(rl, f"E_{k}", in_l), cycle_energy.interval_sum(rs, f"E_{k}", same))
                     for k in ("copper", "inverter")}
        out.append({
            "name": pl["name"], "complete": pl["complete"] and ps["complete"],
            "d_Wh_per_km": None if es["dc_Wh_per_km"] is None or el["dc_Wh_per_km"] is None
            else el["dc_Wh_per_km"] - es["dc_Wh_per_km"],
            "d_dc_Wh": el["dc_Wh"] - es["dc_Wh"],
            "d_losses_Wh": {k: el["losses_Wh"][k] - es["losses_Wh"][k] for k in LOSS_KINDS + ("total",)},
            "t_align": ml.get("align"), "t_if": ml.get("if"),
            **{f"{k}_if_Wh": a for k, (a, _) in if_losses.items()},
            **{f"{k}_same_sensored_Wh": b for k, (_, b) in if_losses.items()},
            **{f"extra_{k}_if_Wh": a - b for k, (a, b) in if_losses.items()},
        })
    return out


def _cost_table(cost: list[dict]) -> list[str]:
    L = ["| phase | Δ Wh/km (DC) | Δ DC energy | Δ copper | Δ inverter | Δ iron | Δ losses, all | alignment | I-f | "
         "copper in I-f, sensorless (sensored, same intervals) | extra copper in I-f | inverter in I-f, sensorless "
         "(sensored) | extra inverter in I-f |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in cost:
        d = c["d_losses_Wh"]
        L.append(f"| {c['name']} | {_num(c['d_Wh_per_km'], '+.2f')} | {c['d_dc_Wh']:+.2f} Wh | {d['copper']:+.2f} | "
                 f"{d['inverter']:+.2f} | {d['iron']:+.2f} | {d['total']:+.2f} | {_num(c['t_align'], '.2f')} s | "
                 f"{_num(c['t_if'], '.2f')} s | {c['copper_if_Wh']:.3f} ({c['copper_same_sensored_Wh']:.3f}) Wh | "
                 f"{c['extra_copper_if_Wh']:+.3f} Wh | {c['inverter_if_Wh']:.3f} "
                 f"({c['inverter_same_sensored_Wh']:.3f}) Wh | {c['extra_inverter_if_Wh']:+.3f} Wh |")
    return L + ["", "(Δ: sensorless minus sensored; energies in Wh)", ""]


#: what the sensorless unit does at and near zero speed, by its ``low_speed`` (default ``InjectionParams``')
LOW_SPEED_TEXT = {"injection": "high-frequency injection at and near zero speed: the acquisition, the polarity "
                               "test and FOC on the injection, the stationary-frame EKF5 above",
                  "if": "alignment, I-f, the stationary-frame EKF5, back to I-f at every stop"}


def setting_text(scenarios) -> dict[str, str]:
    """What the cycle scenarios' system files set alike, as text: ``noise`` (the plant's current-sensor noise
    [A]) and ``rows`` (the output interval [s]), each "…" where they differ, ``low_speed`` (the sensorless
    scenarios' strategy at and near zero speed, ``LOW_SPEED_TEXT``) and ``climb`` (the steepest grade of the road
    ``hilly`` [%])."""
    specs = [load_system(s) for s in scenarios]
    strategies = {s.component("ctrl").start.get("low_speed", InjectionParams().low_speed) for s in specs
                  if s.component("ctrl").fmu.name == "FocSensorless.fmu"}

    def alike(values, fmt):
        values = set(values)
        return format(values.pop(), fmt) if len(values) == 1 else "…"

    return {"noise": alike((s.component("plant").start.get("sensor_noise", 0.0) for s in specs), "g"),
            "rows": alike((s.output_interval for s in specs), "g"),
            "low_speed": LOW_SPEED_TEXT[strategies.pop()] if len(strategies) == 1 else "…",
            "climb": f"{100 * float(np.max(cycles.load_road('hilly').grade)):g}"}


def render(data, fig_names) -> list[str]:
    """The section's lines, every figure computed from the runs."""
    L = ["## Drive cycles: WLTC, UDDS, HWFET and US06, sensored and truly sensorless\n"]
    rows = {cid: figures_of(data, cid) for cid, _, _ in RUNS}
    if not any(rows.values()):
        return L + ["(no runs)\n"]
    lim = limits()
    st = setting_text(scen for _, scen, _ in RUNS)
    suffix = {scen.rsplit("-", 1)[-1] for _, scen, setup in RUNS if setup.key == "sensorless"}
    descr = []
    for name in cycles.names():
        c = cycles.load(name)
        descr.append(f"`{name}` ({c.duration:.0f} s, {c.distance / 1000:.2f} km, {c.top_speed * KMH:.1f} km/h, "
                     f"{c.stops} stop{'' if c.stops == 1 else 's'})")
    L.append(
        "The shipped cycle scenarios (docs/cycles.md): " + ", ".join(descr) + ", each with the sensored drive "
        "(`FocSensored`, the reference) and truly sensorless from standstill at an unknown angle "
        f"(`-{suffix.pop() if len(suffix) == 1 else '…'}`, `FocSensorless`: {st['low_speed']}), and "
        f"`wltc3b-hilly` (sensored, the road `hilly` by position: a stop and restart on its {st['climb']} % climb). "
        f"All with σ = {st['noise']} A current noise, the speed loop's feedforward (inertia and road load), the "
        "reference generator in "
        f"field weakening on the {envelope.parameters(SCENARIO_SETS)['controller'].v_dc:g} V DC link (T_max "
        f"{lim.T_max:.1f} N m, regeneration up to "
        f"{lim.P_regen_max / 1e3:g} kW, the friction brake for the rest), rows every {st['rows']} s. *Inside the "
        "band*: "
        f"the share of the cycle the car's speed is within ±{TRACE_BAND_KMH:g} km/h of the trace taken over "
        f"±{TRACE_WINDOW_S:g} s "
        f"(GTR No. 15; issue 24 requires {100 * INSIDE_MIN:g} %); *RMSE* and *largest deviation* against the "
        "trace; *slipped turns* and *loss-of-sync episodes* from metrics.json's `synchronism`; *Wh/km (DC)* the "
        "net DC-link energy per km driven; *regenerated / drawn* the DC energy returned as a share of the DC energy "
        "drawn; *balance residual / throughput* the energy balance's residual over the DC throughput "
        f"(∫|P_dc| dt; required ≤ {cycle_energy.BALANCE_TOL:g} over a WLTC); *road-load integral vs wheel*: "
        "the integral of (m_v a + f_f + f_a + f_g) v dt from the recorded speed and grade (eqs 1-5) against the "
        "wheel energy of the plant's accumulators (what the drive delivers through the gear minus the friction "
        f"brake), relative, net and the traction part (required within {100 * cycle_energy.WHEEL_TOL:g} %). "
        "What a run costs is the bench's (docs/performance.md): a report's runs share the machine with one another, "
        "and their wall times say more of that than of the drive.\n")
    L += _cycle_table(data, rows)
    # the requirements, computed
    fails = []
    for cid, scen, setup in RUNS:
        f = rows.get(cid)
        if f is None:
            continue
        why = diagnosis(data.runs[cid], f, lim)
        if why:
            fails.append(f"- **{scen}, {setup.label}**: {why}.")
    cut = [f"{scen} ({f['t_end']:g} s)" for cid, scen, _ in RUNS if (f := rows.get(cid)) and f["cycle"] is not None
           and f["t_end"] < f["cycle"].duration - 1e-6]
    if cut:
        L.append("Runs shorter than their cycle (the report's stop time), measured up to their end: "
                 + ", ".join(cut) + ".\n")
    ok = [f for f in rows.values() if f is not None]
    slipped = sum(int(f["synchronism"].get("slipped_turns") or 0) for f in ok)
    if fails:
        L.append(f"Runs that miss the {100 * INSIDE_MIN:g} % of the band or did not complete, where and why:\n")
        L += fails + [""]
    else:
        L.append(f"Every run completed inside the band for at least {100 * INSIDE_MIN:g} % of its cycle.\n")
    L.append(f"Electrical turns slipped, all runs together: {slipped}.\n")
    checks = []
    for cid, scen, setup in RUNS:
        f = rows.get(cid)
        if f is None or f["whole"] is None:
            continue
        bal, wc = f["whole"]["balance"], f["whole"]["wheel"]
        checks.append((scen, setup.label, bal, wc))
    if checks:
        def where(failed) -> str:
            return "in every run" if not failed else "in every run except " + "; ".join(failed)

        bal_bad = [f"{sc}, {lb} ({_num(b.get('relative'), '.2e')})" for sc, lb, b, _ in checks if not b.get("passed")]
        wc_bad = [f"{sc}, {lb} (net {_pct(w.get('net_rel'), '.2f')}, traction {_pct(w.get('traction_rel'), '.2f')})"
                  for sc, lb, _, w in checks if not w.get("passed")]
        worst_b = max(checks, key=lambda c: abs(c[2].get("relative") or 0.0))
        worst_w = max(checks, key=lambda c: max(abs(c[3].get("net_rel") or 0.0), abs(c[3].get("traction_rel") or 0.0)))
        wl = [c for c in checks if c[0] == "wltc3b"]
        L.append(
            f"The energy balance closes to {cycle_energy.BALANCE_TOL:g} of the DC throughput {where(bal_bad)} "
            f"(the largest: {worst_b[0]}, {worst_b[1]}, {_num(worst_b[2].get('relative'), '.2e')}, "
            f"{_num(worst_b[2].get('residual_Wh'), '.2e')} Wh of {_num(worst_b[2].get('throughput_Wh'), '.1f')} Wh)"
            + (f"; over the sensored WLTC {_num(wl[0][2].get('relative'), '.2e')}" if wl else "")
            + f". The wheel energy agrees with the road-load integral within {100 * cycle_energy.WHEEL_TOL:g} % "
            f"{where(wc_bad)} (the largest difference: {worst_w[0]}, {worst_w[1]}, "
            f"net {_pct(worst_w[3].get('net_rel'), '.4f')}, traction {_pct(worst_w[3].get('traction_rel'), '.4f')})"
            + (f"; the sensored WLTC's wheels took {wl[0][3]['wheel']['traction_Wh']:.1f} Wh in traction and gave "
               f"{wl[0][3]['wheel']['braking_Wh']:.1f} Wh in braking ({wl[0][3]['brake_Wh']:.2f} Wh of it to the "
               f"friction brake), the road-load integral {wl[0][3]['road_load']['traction_Wh']:.1f} and "
               f"{wl[0][3]['road_load']['braking_Wh']:.1f} Wh" if wl and wl[0][3].get("wheel") else "")
            + ".\n")
    hilly, level = rows.get("cyc-wltc3b-hilly"), rows.get("cyc-wltc3b")
    if hilly and hilly["whole"]:
        e = hilly["whole"]["energy"]
        r = data.runs["cyc-wltc3b-hilly"].r
        climb = r["x_vehicle"][r["delta_deg"] > 0.0]
        lv = (level or {}).get("whole") or {}
        L.append(
            f"On the hilly road (`wltc3b-hilly`, sensored): the grade took {e['road_Wh']['grade']:.1f} Wh net "
            f"(the potential energy at the end against the start), "
            + (f"the car was on the climb from {float(climb[0]):.0f} m to {float(climb[-1]):.0f} m, " if climb.size
               else "")
            + f"rolled back at most {_num(hilly['synchronism'].get('roll_back_m'), '.3f')} m, and drew "
            f"{_num(e.get('dc_Wh_per_km'))} Wh/km at the DC link"
            + (f" against {_num(lv['energy'].get('dc_Wh_per_km'))} on the level road" if lv.get("energy") else "")
            + f", {_pct(hilly['whole'].get('regen_share'), '.1f')} of the drawn energy regenerated"
            + (f" ({_pct(lv.get('regen_share'), '.1f')} level)" if lv else "") + ".\n")
    L += figure_links(("cyc_wltc3b_trace", "cyc_envelope"), fig_names)
    # per WLTC phase, sensored against sensorless
    fs, fl = rows.get(WLTC_PAIR[0]), rows.get(WLTC_PAIR[1])
    if fs and fl and fs["phases"] and fl["phases"]:
        L.append("### WLTC class 3b by phase, sensored against sensorless\n")
        phases = ", ".join(f"{ph.name.replace('_', ' ')} {ph.start:g}-{ph.end:g} s" for ph in fs["cycle"].phases)
        L.append(f"Per phase (GTR No. 15: {phases}; "
                 "the plant's cumulative energies differenced from the phase's first row to its last). "
                 "*Regenerated / braking at the wheels*: the DC energy regenerated as a share of the wheels' "
                 "braking work (regeneration through the gear plus the friction brake).\n")
        L += _phase_table([(data.runs[WLTC_PAIR[0]].label, fs), (data.runs[WLTC_PAIR[1]].label, fl)])
        cost = sensorless_cost(data.runs[WLTC_PAIR[0]], data.runs[WLTC_PAIR[1]], fs, fl)
        L.append("What the sensorless start-up and low-speed strategy cost: the sensorless run minus the sensored "
                 "one per phase, the time the unit spent aligning and in I-f (open-loop current at a commanded "
                 "frequency, below the EKF's handover speed), its copper loss in those I-f intervals and the "
                 "sensored run's in the same intervals.\n")
        L += _cost_table(cost)
        tot_if = sum(c["t_if"] or 0.0 for c in cost)
        extra = sum(c["extra_copper_if_Wh"] for c in cost)
        extra_inv = sum(c["extra_inverter_if_Wh"] for c in cost)
        rl = data.runs[WLTC_PAIR[1]].r
        standing_if = (np.abs(rl["v_vehicle"][:-1]) * KMH < cycles.STANDSTILL_KMH) & (rl["mode"][:-1] == 1)
        t_still = float(np.sum(np.diff(rl["time"])[standing_if]))
        d_dc = sum(c["d_dc_Wh"] for c in cost)
        dist = sum(p["energy"]["distance_m"] for p in fl["phases"]) / 1000.0
        L.append(f"Over the cycle the sensorless unit spent {tot_if:.1f} s in I-f ({t_still:.1f} s of it with the car "
                 f"standing, below {cycles.STANDSTILL_KMH:g} km/h, where I-f holds its current); its copper and "
                 "inverter losses there "
                 f"exceeded the sensored drive's by {extra:.2f} and {extra_inv:.2f} Wh, of a DC energy difference of "
                 f"{d_dc:+.2f} Wh "
                 f"({d_dc / dist if dist > 0 else float('nan'):+.2f} Wh/km).\n")
    L += figure_links(("cyc_energy_phases", "cyc_wltc3b_angle_mode", "cyc_wltc3b_stop_zoom"), fig_names)
    return L


# -- figures ------------------------------------------------------------------------------------------------

def zoom_window(cycle, t_end: float) -> tuple[float, float, tuple[float, float]] | None:
    """A window of about 15 s around a stop and restart within the run: the shortest stop of at least 2 s whose
    restart is at least 8 s before the run's end (if none, the first restart within the run, to its end);
    (t0, t1, (stop start, stop end)), None if there is none.
    A stop of up to 5 s: from 5 s before it to 8 s after; a longer one: its last 7 s and 8 s after."""
    stops = [(a, b) for a, b in cycle.stop_periods if b - a >= 2.0 and b + 8.0 <= t_end and b < cycle.duration]
    if not stops:  # a run shorter than the cycle: the first restart it has, up to its end
        stops = [(a, b) for a, b in cycle.stop_periods if b - a >= 2.0 and b < min(t_end, cycle.duration)][:1]
    if not stops:
        return None
    a, b = min(stops, key=lambda ab: (ab[1] - ab[0], ab[0]))
    t0 = a - 5.0 if b - a <= 5.0 else b - 7.0
    return max(0.0, t0), min(b + 8.0, t_end), (a, b)


def figures(data, fig_dir: Path) -> list[Path]:
    """The section's figures into ``fig_dir``: the WLTC trace, band and speeds; the operating points on the
    envelope; the energy by phase and kind; the sensorless run's angle error and mode; a stop and restart."""
    plt = pyplot()

    made = []

    def save(fig, name):
        made.append(save_figure(fig, fig_dir / f"{name}.png"))

    pair = [(cid, data.runs[cid]) for cid in WLTC_PAIR if cid in data.runs]
    fig_dir.mkdir(parents=True, exist_ok=True)
    if pair:
        cycle = figures_of(data, pair[0][0])["cycle"]
        t_end = max(float(run.r["time"][-1]) for _, run in pair)
        tt = np.arange(0.0, min(t_end, cycle.duration) + 1e-9, 0.05)
        lower, upper = trace_band(cycle.time, cycle.speed, time=tt)
        v_tr = np.interp(tt, cycle.time, cycle.speed)
        fig, axes = plt.subplots(2, 1, figsize=(9.0, 6.0), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
        axes[0].fill_between(tt, lower * KMH, upper * KMH, color="0.85",
                             label=f"band ±{TRACE_BAND_KMH:g} km/h, ±{TRACE_WINDOW_S:g} s")
        axes[0].plot(tt, v_tr * KMH, "k-", lw=0.6, label="trace")
        axes[1].fill_between(tt, (lower - v_tr) * KMH, (upper - v_tr) * KMH, color="0.85")
        for i, (cid, run) in enumerate(pair):
            r = run.r
            axes[0].plot(r["time"], r["v_vehicle"] * KMH, lw=0.7, color=f"C{i}", label=run.label)
            axes[1].plot(r["time"], (r["v_vehicle"] - np.interp(r["time"], cycle.time, cycle.speed)) * KMH, lw=0.6,
                         color=f"C{i}")
        for w in cycle_energy.phase_windows(cycle, t_end)[1:]:
            for ax in axes:
                ax.axvline(w.start, color="0.5", ls=":", lw=0.7)
        axes[0].set_ylabel("v [km/h]")
        axes[0].set_title("WLTC class 3b: trace, tolerance band and the car's speed")
        axes[0].legend(fontsize=7, loc="upper left")
        axes[1].set_ylabel("v − trace [km/h]\n(grey: the band)")
        axes[1].set_xlabel("time [s]")
        for ax in axes:
            ax.grid(True, lw=0.3)
        save(fig, "cyc_wltc3b_trace")

    pts = [(cid, data.runs[cid]) for cid in (*WLTC_PAIR, "cyc-us06") if cid in data.runs]
    if pts:
        lim = limits()
        speeds = references.region_speeds(lim)
        w = np.linspace(0.0, 1.15 * max(float(np.max(run.r["omega_m"])) for _, run in pts), 300)
        motoring, braking, region = references.torque_envelope(w, lim)
        fig, ax = plt.subplots(figsize=(7.5, 4.5))
        points = [(Path(f"{run.scenario}, {run.label}"), {"omega_m": run.r["omega_m"], "T_e": run.r["T_e"]})
                  for _, run in pts]
        envelope.plot_envelope(ax, lim, speeds, w, motoring, braking, region, points)
        save(fig, "cyc_envelope")

    fs, fl = (figures_of(data, cid) if cid in data.runs else None for cid in WLTC_PAIR)
    bars = [(data.runs[cid].label, f) for cid, f in zip(WLTC_PAIR, (fs, fl)) if f and f["phases"]]
    if bars:
        names = [p["name"] for p in bars[0][1]["phases"]]
        fig, ax = plt.subplots(figsize=(8.0, 4.5))
        width = 0.8 / len(bars)
        for j, (label, f) in enumerate(bars):
            x = np.arange(len(f["phases"])) + (j - (len(bars) - 1) / 2) * width
            km = np.array([max(p["energy"]["distance_m"], 1.0) / 1000.0 for p in f["phases"]])
            pos, neg = np.zeros(len(x)), np.zeros(len(x))
            for k, (kind, path) in enumerate(KINDS):
                val = np.array([_get(p["energy"], path) for p in f["phases"]]) / km
                bottom = np.where(val >= 0, pos, neg)
                ax.bar(x, val, width * 0.95, bottom=bottom, color=plt.get_cmap("tab20")(k),
                       label=kind if j == 0 else None, hatch="//" if j else None, edgecolor="k", lw=0.3)
                pos, neg = pos + np.maximum(val, 0), neg + np.minimum(val, 0)
            dc = np.array([p["energy"]["dc_Wh"] for p in f["phases"]]) / km
            ax.plot(x, dc, "kD", ms=4, label="DC link, net" if j == 0 else None)
            for xi in x:
                ax.text(xi, 0, label.split()[0], rotation=90, fontsize=6, ha="center", va="bottom", color="w")
        ax.set_xticks(np.arange(len(names)), names)
        ax.set_ylabel("Wh/km")
        ax.set_title("WLTC class 3b: where the energy went, by phase and kind (left: "
                     + ", right: ".join(lb for lb, _ in bars) + ")", fontsize=8)
        ax.legend(fontsize=6, ncol=2)
        ax.grid(True, axis="y", lw=0.3)
        save(fig, "cyc_energy_phases")

    if WLTC_PAIR[1] in data.runs:
        run = data.runs[WLTC_PAIR[1]]
        r = run.r
        e = row_timing_corrected_angle_error(r, *run_timing(run.metrics))
        fast = np.abs(r["omega_m"]) > ANGLE_FROM_SPEED
        fig, axes = plt.subplots(3, 1, figsize=(9.0, 6.5), sharex=True)
        axes[0].plot(r["time"][fast], e[fast], ".", ms=0.8, color="C1")
        axes[0].set_ylabel(f"θ̂ − θ [rad]\n(row timing removed,\n|ω_m| > {ANGLE_FROM_SPEED:g} rad/s)")
        if "mode" in r:
            axes[1].plot(r["time"], r["mode"], lw=0.7, color="C1")
        axes[1].set_ylabel("mode\n(0 align, 1 I-f, 2 EKF)")
        axes[2].plot(r["time"], r["v_vehicle"] * KMH, lw=0.7, color="C1")
        axes[2].set_ylabel("v [km/h]")
        axes[2].set_xlabel("time [s]")
        axes[0].set_title(f"WLTC class 3b, {run.label}: angle error and controller mode")
        for ax in axes:
            ax.grid(True, lw=0.3)
        save(fig, "cyc_wltc3b_angle_mode")

    if pair:
        cycle = figures_of(data, pair[0][0])["cycle"]
        t_end = min(float(run.r["time"][-1]) for _, run in pair)
        win = zoom_window(cycle, t_end)
        if win is not None:
            t0, t1, (a, b) = win
            fig, axes = plt.subplots(4, 1, figsize=(8.0, 8.0), sharex=True)
            tt = np.arange(t0, t1 + 1e-9, 0.01)
            lower, upper = trace_band(cycle.time, cycle.speed, time=tt)
            axes[0].fill_between(tt, lower * KMH, upper * KMH, color="0.85", label="band")
            axes[0].plot(tt, np.interp(tt, cycle.time, cycle.speed) * KMH, "k-", lw=0.6, label="trace")
            for i, (cid, run) in enumerate(pair):
                r = run.r
                w = (r["time"] >= t0) & (r["time"] <= t1)
                t = r["time"][w]
                ratio = cycle_energy.plant_params(run.metrics)[1]
                axes[0].plot(t, r["v_vehicle"][w] * KMH, lw=0.9, color=f"C{i}", label=run.label)
                if i == 0:
                    axes[0].plot(t, r["omega_ref"][w] * ratio.r_w / ratio.n_g * KMH, "k--", lw=0.6,
                                 label="speed reference")
                if "mode" in r:
                    axes[1].plot(t, r["mode"][w], lw=0.9, color=f"C{i}")
                if cid == WLTC_PAIR[1]:
                    e = row_timing_corrected_angle_error(r, *run_timing(run.metrics))
                    axes[2].plot(t, e[w], lw=0.8, color=f"C{i}", label=run.label)
                ls = "-" if cid == WLTC_PAIR[1] else "--"
                axes[3].plot(t, r["i_d"][w], ls, lw=0.8, color="C2", label=f"i_d, {run.label}")
                axes[3].plot(t, r["i_q"][w], ls, lw=0.8, color="C3", label=f"i_q, {run.label}")
            axes[0].set_title(f"WLTC class 3b: the stop at {a:g}-{b:g} s and the restart")
            axes[0].set_ylabel("v [km/h]")
            axes[0].legend(fontsize=6)
            axes[1].set_ylabel("mode\n(0 align, 1 I-f, 2 EKF)")
            axes[2].set_ylabel("θ̂ − θ [rad]\n(row timing removed)")
            axes[3].set_ylabel("current [A]")
            axes[3].legend(fontsize=6, ncol=2)
            axes[3].set_xlabel("time [s]")
            for ax in axes:
                ax.grid(True, lw=0.3)
            save(fig, "cyc_wltc3b_stop_zoom")
    return made
