"""The report's section "Never lose the car": the synchronism test matrix.

Every case of ``pmsm_ev.scenarios.SYNC_MATRIX`` (references that do not wait for the start-up,
loads that change while the car creeps or stands, reversing) from each of the 8 initial angles
``SYNC_ANGLES`` with sigma = 1 A current noise, for the sensorless unit and, on the same angle
and noise, the sensored drive as the reference. The runs are the monolithic loop
(``pmsm_cosim.app.reference.run_reference``: the same kernels in the co-simulation's order; equal
to the FMUs under the master to 1e-9, ``tests/test_sensorless.py``), ``--jobs`` processes at a
time, into ``RUNS/sync/<case>-<controller>-<k>/``, a run reused by the report's one rule (``runs.reusable``:
completed, with the same settings and sources); the figures of merit are
``pmsm_cosim.app.metrics.synchronism.synchronism_metrics`` of each run's rows and the targets those of the issue that
asked for it.
"""

from __future__ import annotations

import hashlib
import json
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

from pmsm_ev.params import LOW_SPEED_STRATEGIES, SENSORLESS_EKF, DriveParams, InjectionParams, PlantParams
from pmsm_ev.scenarios import SYNC_ANGLES, SYNC_MATRIX, SyncCase
from pmsm_ev_fmus.build import source_hash

from ...engine.recording import read_results
from .. import reference
from ..metrics.synchronism import (
    RECOVERY_BAND,
    RECOVERY_LIMIT,
    ROLL_BACK_EXTRA,
    SPEED_EXTRA,
    SPIN_LIMIT,
    SYNC_BAND,
    SYNC_REL,
    synchronism_metrics,
)
from ..reference import run_reference
from .configs import OBSERVER_FMUS, PLANT_FMU
from .drawing import pyplot, save_figure
from .runs import KEY_FILE, reusable

#: current-sensor noise of every run [A] and the first seed (run k of a case has seed k + 1)
NOISE = 1.0
CONTROLLERS = ("sensorless", "sensored")
CASES = {c.name: c for c in SYNC_MATRIX}


def drive_params(controller: str, k: int, strategy: str = "if") -> DriveParams:
    """The parameters of a run of the matrix: angle ``SYNC_ANGLES[k]``, noise seed k + 1. ``strategy``: the
    sensorless unit's at and near zero speed (``InjectionParams.low_speed``); with "injection" both
    controllers drive the plant with the algebraic flux model (the magnet's asymmetry the polarity test
    needs), so that the sensored reference is on the same motor."""
    if strategy not in LOW_SPEED_STRATEGIES:
        raise ValueError(f"unknown low-speed strategy {strategy!r}: one of {', '.join(LOW_SPEED_STRATEGIES)}")
    base = DriveParams(ekf=SENSORLESS_EKF) if controller == "sensorless" else DriveParams()
    flux = "algebraic" if strategy == "injection" else "linear"
    plant = PlantParams(theta_e0=SYNC_ANGLES[k], sensor_noise=NOISE, sensor_seed=k + 1, flux_model=flux)
    return replace(base, plant=plant, injection=InjectionParams(low_speed=strategy))


def run_key(case: SyncCase, controller: str, k: int, strategy: str, sources: dict[str, str]) -> dict:
    """What a run of the matrix is made of, for ``runs.reusable``: the case, the angle, the strategy, the drive's
    parameters and the sources of the code that runs it (``sources``: ``matrix_sources``)."""
    return {"case": repr(case), "controller": controller, "k": k, "strategy": strategy,
            "params": repr(drive_params(controller, k, strategy)),
            "sources": {n: sources[n] for n in (OBSERVER_FMUS[controller], PLANT_FMU, "loop")}}


def matrix_sources() -> dict[str, str]:
    """The hashes of the units' sources (their physics, as their FMUs are built from them) and of the monolithic
    loop's module."""
    names = {OBSERVER_FMUS[c] for c in CONTROLLERS} | {PLANT_FMU}
    return {**{n: source_hash(n) for n in sorted(names)},
            "loop": hashlib.sha256(Path(reference.__file__).read_bytes()).hexdigest()}


def figures_of(case: SyncCase, controller: str, k: int, out_dir: Path, strategy: str = "if") -> dict:
    """A run's ``synchronism_metrics`` from its rows, with the case, controller, angle and status; also written
    into the run's metrics.json as "synchronism"."""
    path = Path(out_dir) / "metrics.json"
    data = json.loads(path.read_text(encoding="utf-8"))
    sync = synchronism_metrics(read_results(out_dir), case.t_disturbance,
                               drive_params(controller, k, strategy).motor.N)
    sync.update({"case": case.name, "controller": controller, "k": k, "theta0": SYNC_ANGLES[k],
                 "status": data["status"]})
    data["synchronism"] = sync
    path.write_text(json.dumps(data, indent=1, default=str) + "\n", encoding="utf-8")
    return sync


def run_one(case: SyncCase, controller: str, k: int, out_dir: Path, strategy: str = "if",
            key: dict | None = None) -> dict:
    """One run of the matrix: ``case`` from angle ``SYNC_ANGLES[k]``, noise seed k + 1 (``drive_params``); its
    ``figures_of``. ``key``: written beside a completed run (``runs.KEY_FILE``), which makes it reusable."""
    (Path(out_dir) / KEY_FILE).unlink(missing_ok=True)  # a run cut short never looks reusable
    params = drive_params(controller, k, strategy)
    route = case.route()
    run_reference(out_dir, case.name, case.stop_time, controller, params=params, elevation=route["delta"],
                  omega_ref=route["omega_ref"], startup_columns=True)
    sync = figures_of(case, controller, k, out_dir, strategy)
    if key is not None and sync["status"] == "completed":
        (Path(out_dir) / KEY_FILE).write_text(json.dumps(key, indent=2) + "\n", encoding="utf-8")
    return sync


def _run(args) -> dict:
    name, controller, k, out, strategy, key = args
    return run_one(CASES[name], controller, k, Path(out), strategy, key)


def run_matrix(runs_dir, jobs: int = 2, cases=SYNC_MATRIX, angles=len(SYNC_ANGLES), log=print,
               strategy: str = "if", force: bool = False) -> list[dict]:
    """Every case x controller x angle, ``jobs`` at a time (``strategy``: ``drive_params``); the list of their
    figures. ``angles``: the first that many of ``SYNC_ANGLES``, or the indices of those to run. A run already in
    ``runs_dir`` is reused when ``runs.reusable`` (completed, the same ``run_key``), unless ``force``."""
    runs_dir = Path(runs_dir)
    indices = list(range(angles)) if isinstance(angles, int) else list(angles)
    sources = matrix_sources()
    plan = [(c.name, ctrl, k, str(runs_dir / f"{c.name}-{ctrl}-{k}"), strategy, run_key(c, ctrl, k, strategy, sources))
            for c in cases for ctrl in CONTROLLERS for k in indices]
    todo = [p for p in plan if force or not reusable(Path(p[3]), p[5])]
    log(f"synchronism matrix: {len(plan)} runs ({len(cases)} cases x {len(CONTROLLERS)} controllers x "
        f"{len(indices)} angles), {len(plan) - len(todo)} reused, {len(todo)} to run, {jobs} at a time, in {runs_dir}")
    if jobs > 1 and len(todo) > 1:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            made = dict(zip((p[3] for p in todo), pool.map(_run, todo)))
    else:
        made = {p[3]: _run(p) for p in todo}
    return [made[p[3]] if p[3] in made else figures_of(CASES[p[0]], p[1], p[2], Path(p[3]), strategy) for p in plan]


def load_matrix(runs_dir) -> list[dict]:
    """The figures of the matrix's runs already in ``runs_dir`` (their metrics.json)."""
    out = []
    for path in sorted(Path(runs_dir).glob("*/metrics.json")):
        sync = json.loads(path.read_text(encoding="utf-8")).get("synchronism")
        if isinstance(sync, dict) and sync.get("case") in CASES:
            out.append(sync)
    return out


def _worst(rows: list[dict], key: str, sign: float = 1.0):
    vals = [r[key] for r in rows]
    if any(v is None for v in vals):
        return None
    return max(vals, key=lambda v: sign * v)


def verdicts(results: list[dict]) -> list[dict]:
    """Per case: the worst figures over the angles for each controller, and each target met or
    not (sensorless against the sensored drive on the same angle and noise)."""
    out = []
    for case in SYNC_MATRIX:
        rows = {ctrl: sorted((r for r in results if r["case"] == case.name and r["controller"] == ctrl),
                             key=lambda r: r["k"]) for ctrl in CONTROLLERS}
        sl, sd = rows["sensorless"], rows["sensored"]
        if not sl or not sd or len(sl) != len(sd):
            continue
        pairs = list(zip(sl, sd))
        rec = [r["recovery_time"] for r in sl]
        out.append({
            "case": case, "n": len(sl),
            "roll_back": max(r["roll_back_m"] for r in sl), "roll_back_sensored": max(r["roll_back_m"] for r in sd),
            "roll_back_ok": all(a["roll_back_m"] <= b["roll_back_m"] + ROLL_BACK_EXTRA["if"] for a, b in pairs),
            "wrong_speed": max(r["wrong_way_speed"] for r in sl),
            "wrong_speed_sensored": max(r["wrong_way_speed"] for r in sd),
            "wrong_speed_ok": all(a["wrong_way_speed"] <= b["wrong_way_speed"] + SPEED_EXTRA for a, b in pairs),
            "out_of_sync": max(r["t_out_of_sync"] for r in sl),
            "slipped": max(r["slipped_turns"] for r in sl),
            "spin": max(r["t_spin_standing"] for r in sl),
            "spin_ok": all(r["t_spin_standing"] <= SPIN_LIMIT for r in sl),
            "recovery": None if any(v is None for v in rec) else max(rec),
            "recovery_sensored": _worst(sd, "recovery_time"),
            "recovery_ok": all(v is not None and v <= RECOVERY_LIMIT for v in rec),
            "speed_rms_after": _worst(sl, "speed_rms_after"),
            "episodes": sum(r["episodes"] for r in sl), "faults": sum(r["fault_latched"] for r in sl),
            "completed": all(r["status"] == "completed" for r in sl + sd),
        })
    return out


def figures(results: list[dict], runs_dir, fig_dir: Path) -> list[Path]:
    """Speed and position of the creeping and standing cases, sensorless against sensored (angle k = 0)."""
    plt = pyplot()

    runs_dir = Path(runs_dir)
    names = [n for n in ("step200", "creep10", "stand") if (runs_dir / f"{n}-sensorless-0").is_dir()]
    if not names:
        return []
    fig, axes = plt.subplots(3, len(names), figsize=(4.2 * len(names), 7.0), sharex="col", squeeze=False)
    for j, name in enumerate(names):
        for ctrl, style in (("sensored", "--"), ("sensorless", "-")):
            r = read_results(runs_dir / f"{name}-{ctrl}-0")
            t = r["time"]
            axes[0][j].plot(t, r["omega_m"], style, lw=0.9, label=f"ω_m, {ctrl}")
            axes[1][j].plot(t, 100.0 * (r["x_vehicle"] - r["x_vehicle"][0]), style, lw=0.9, label=ctrl)
            if ctrl == "sensorless":
                axes[0][j].plot(t, r["omega_ref"], ":", lw=0.8, color="k", label="ω_ref")
                axes[2][j].plot(t, r["mode"], lw=0.9, label="mode")
                axes[2][j].plot(t, r["fault"], lw=0.9, label="fault")
        axes[0][j].set_title(CASES[name].description, fontsize=8)
        axes[0][j].set_ylabel("speed [rad/s]")
        axes[1][j].set_ylabel("x − x(0) [cm]")
        axes[2][j].set_ylabel("mode, fault")
        axes[2][j].set_xlabel("time [s]")
        for ax in (axes[0][j], axes[1][j], axes[2][j]):
            ax.grid(True, lw=0.3)
            ax.legend(fontsize=6)
    return [save_figure(fig, fig_dir / "sync_matrix.png")]


def _n(x, fmt=".2f") -> str:
    return "never" if x is None else format(x, fmt)


def _ok(ok: bool) -> str:
    return "✓" if ok else "✗"


def intro(n_angles: int) -> str:
    """The section's first paragraph: what was run and how it is judged, every number from what the matrix
    ran (its angles, its noise, the sensorless unit's alignment in ``drive_params``) and from the bands and
    targets that judge it (``metrics.synchronism``'s, this module's)."""
    s = drive_params("sensorless", 0).startup
    t_align = s.t_ramp + s.t_hold + s.t_sweep + s.t_settle
    return (
        f"Each case from {n_angles} initial rotor angles ({', '.join(f'{a:.2f}' for a in SYNC_ANGLES[:n_angles])} rad) "
        f"with σ = {NOISE:g} A current noise, the sensorless unit (`FocSensorless`) and, on the same angle and noise, "
        f"the sensored drive (`FocSensored`). No case waits for the unit's {t_align:g} s alignment. Worst over the "
        "angles; roll-back is the largest travel against the driver's direction, 'out of sync' the time the control "
        "frame's speed and the rotor's differ by more than "
        f"{SYNC_BAND:g} rad/s + {100 * SYNC_REL:g} %, 'spin' the longest time the frame turned while the rotor stood, "
        "'recovered' the time after the disturbance (the reference's start, or the grade's change) from which "
        f"|ω_m − ω_ref| ≤ {RECOVERY_BAND:g} rad/s "
        "to the end, and 'episodes' the unit's own loss-of-synchronism detections (output `fault` = 1), "
        "'faults' the latched safe states (`fault` = 2). Targets (✓/✗): roll-back within the sensored drive's "
        f"+ {100 * ROLL_BACK_EXTRA['if']:g} cm and wrong-way speed within its + {SPEED_EXTRA:g} rad/s, run by run; "
        f"spin ≤ "
        f"{SPIN_LIMIT:g} s; recovered within {RECOVERY_LIMIT:g} s. Generated from `pmsm_ev.scenarios.SYNC_MATRIX` "
        "by `pmsm-cosim report` (monolithic loop, `pmsm_cosim.app.report.synchronism`).\n")


def render(results: list[dict] | None, fig_names) -> list[str]:
    """The section's markdown (nothing without results)."""
    if not results:
        return []
    rows = verdicts(results)
    n_angles = rows[0]["n"] if rows else 0
    L = ["## Never lose the car: the synchronism matrix\n"]
    L.append(intro(n_angles))
    L.append("| case | roll-back [cm], sensored | wrong-way speed [rad/s], sensored | out of sync [s] | turns slipped "
             "| spin [s] | recovered [s], sensored | speed RMS after [rad/s] | episodes | faults |\n"
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for v in rows:
        L.append(
            f"| {v['case'].name}: {v['case'].description} | {100 * v['roll_back']:.1f}, "
            f"{100 * v['roll_back_sensored']:.1f} {_ok(v['roll_back_ok'])} | {v['wrong_speed']:.1f}, "
            f"{v['wrong_speed_sensored']:.1f} {_ok(v['wrong_speed_ok'])} | {v['out_of_sync']:.2f} | {v['slipped']} | "
            f"{v['spin']:.2f} {_ok(v['spin_ok'])} | {_n(v['recovery'])}, {_n(v['recovery_sensored'])} "
            f"{_ok(v['recovery_ok'])} | {_n(v['speed_rms_after'])} | {v['episodes']} | {v['faults']} |")
    met = all(v["roll_back_ok"] and v["wrong_speed_ok"] and v["spin_ok"] and v["recovery_ok"] and v["completed"]
              for v in rows)
    L.append("")
    less = [v for v in rows if v["roll_back"] < v["roll_back_sensored"]]
    worst_rb = max(rows, key=lambda v: v["roll_back"] - v["roll_back_sensored"])
    L.append(
        f"{'Every target is met' if met else 'Not every target is met (✗ above)'} in the {len(rows)} cases × "
        f"{n_angles} angles. The sensorless unit's worst roll-back is smaller than the sensored drive's in "
        f"{len(less)} of the {len(rows)} cases; the largest excess is in {worst_rb['case'].name} "
        f"({100 * worst_rb['roll_back']:.1f} cm against {100 * worst_rb['roll_back_sensored']:.1f} cm). "
        f"Loss-of-synchronism episodes detected: {sum(v['episodes'] for v in rows)}; safe states latched: "
        f"{sum(v['faults'] for v in rows)}.\n")
    if "sync_matrix" in fig_names:
        L.append("![sync_matrix](results/sync_matrix.png)\n")
    return L
