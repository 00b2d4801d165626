"""``pmsm-cosim``: run, sweep, build, inspect, plot and compare co-simulations; report; export a
system as an SSP package.

Every user error (missing file, bad system file, unknown variable, a value an FMU
refuses, ...) ends in one line ``error: ...`` on stderr and exit code 2.
Exit codes of ``run``: 0 completed, 1 failed during the steps, 130 interrupted (Ctrl-C);
of ``sweep``: 0 every run completed, 1 some run did not, 130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from pmsm_ev.params import ParameterError
from pmsm_ev.scenarios import ProfileError
from pmsm_ev_fmus import build as fmu_build
from pmsm_ev_fmus.build import OBSERVER_FMUS

from .. import __version__
from ..engine.errors import CosimError, one_line
from ..engine.fmu import read_description, variable_unit
from ..engine.master import LOOPS, Master
from ..engine.progress import ProgressBar
from ..engine.system import ALGORITHMS
from ..sweeps import prepare_runs, run_sweep
from . import bench, compare, cycles, report, thermal_metrics
from .drive import (
    PACKAGED_SCENARIOS,
    draw_figures,
    drive_metrics,
    ensure_fmus,
    export_ssp,
    fmu_dir_override,
    project_fmu_dir,
    with_fmi,
)
from .metrics.rows import T_FROM
from .metrics.verdicts import cycle_verdict, verdict_line
from .overrides import CONTROLLER_INSTANCE, PLANT_INSTANCE, apply_overrides, fmu_choices, resolve_fmu
from .studies import load_sweep

EXIT_USER_ERROR = 2
EXIT_FAILED = 1
EXIT_INTERRUPTED = 130


def _err(message: str) -> int:
    print(f"error: {one_line(message)}", file=sys.stderr)
    return EXIT_USER_ERROR


def _note(message: str, quiet: bool = False) -> None:
    if not quiet:
        print(f"note: {message}", file=sys.stderr)


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0 (got {text})")
    return value


def _whole_number(minimum: int):
    """An argparse type: a whole number >= ``minimum``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum} (got {text})")
        return value
    return parse


_count = _whole_number(1)  #: a count: >= 1
_seed = _whole_number(0)  #: a random generator's seed: >= 0


# --- commands --------------------------------------------------------------------------

def _load_with_overrides(a):
    """The system of ``a.system`` with the command line's overrides (the Python API's too:
    :func:`pmsm_cosim.app.overrides.apply_overrides`)."""
    return apply_overrides(a.system, plant=a.plant, controller=a.controller, fmus=a.fmu, stop_time=a.stop_time,
                           step_size=a.step, output_interval=a.output_interval, algorithm=a.algorithm, set=a.set,
                           profiles=a.profile, record=a.record, cycle=a.cycle, cli=True)


def cmd_run(a) -> int:
    spec = with_fmi(_load_with_overrides(a), a.fmi)
    out = Path(a.out) if a.out else Path("runs") / spec.name
    ensure_fmus(spec, a.quiet)
    master = Master(spec, loop=a.loop, note=lambda line: _note(line, a.quiet), event_mode=not a.no_event_mode)
    if not a.quiet:
        for w in master.warnings:
            _note(w)
    progress = ProgressBar(spec.stop_time) if ProgressBar.wanted(a.quiet) else None
    m = master.run(out, progress=progress,
                   metrics_of=thermal_metrics.with_thermal_figures(cycles.with_trace_figures(drive_metrics, spec),
                                                                   spec),
                   extra_settings={"command_line": {"set": list(a.set or ()), "profile": list(a.profile or ()),
                                                     **({"cycle": a.cycle} if a.cycle else {})}})
    if "metrics_note" in m:
        _note(m["metrics_note"], a.quiet)
    if "metrics_error" in m:  # the run's rows are written; its figures of merit are not: said even with --quiet
        print(f"warning: the figures of merit could not be computed ({m['metrics_error']}); metrics.json holds the "
              f"run's bookkeeping only", file=sys.stderr)
    trace = m.get("trace")
    if isinstance(trace, dict):
        longest = (f", the longest {trace['longest_excursion_s']:.2f} s at {trace['t_longest_excursion']:.2f} s"
                   if trace["excursions"] else "")
        print(f"cycle {trace['cycle']}: inside the +-{trace['band_kmh']:g} km/h band "
              f"{100 * trace['inside_share']:.2f} % of {trace['t_end']:g} s, {trace['excursions']} excursions"
              f"{longest}; RMSE {trace['rmse_kmh']:.2f} km/h, largest deviation "
              f"{trace['max_deviation_kmh']:+.2f} km/h at {trace['t_max_deviation']:.2f} s")
        energy = m.get("energy")
        if isinstance(energy, dict) and energy.get("dc_Wh_per_km") is not None:
            share = energy["regen_Wh"] / energy["drawn_Wh"] if energy["drawn_Wh"] > 0 else 0.0
            print(f"energy: {energy['dc_Wh_per_km']:.1f} Wh/km at the DC link ({energy['dc_Wh']:.1f} Wh over "
                  f"{energy['distance_m'] / 1e3:.2f} km), {energy['regen_Wh']:.1f} Wh regenerated "
                  f"({100 * share:.1f} % of the {energy['drawn_Wh']:.1f} Wh drawn)")
            bat = energy.get("battery")
            if isinstance(bat, dict) and bat.get("chemical_Wh_per_km") is not None:
                print(f"battery: {bat['terminal_Wh_per_km']:.2f} Wh/km at the terminals, "
                      f"{bat['chemical_Wh_per_km']:.2f} from the chemistry; state of charge "
                      f"{100 * bat['soc_start']:.2f} -> {100 * bat['soc_end']:.2f} %, "
                      f"{bat['charge_Ah']:.3f} Ah drawn, {bat['losses_Wh']:.1f} Wh lost in the battery, terminal "
                      f"voltage {bat['v_bat_min']:.1f} .. {bat['v_bat_max']:.1f} V; {energy['brake_Wh']:.1f} Wh to the "
                      f"friction brake (regeneration refused or beyond the motor)")
    if isinstance(m.get("thermal"), dict):
        print(thermal_metrics.summary_line(m["thermal"]))
    figures = None
    if not a.no_figures and m["rows"] >= 2:
        figures = draw_figures(out, spec.name, a.quiet)
    fig_note = f", {len(figures)} figures" if figures else ""
    print(f"{m['status']}: {m['macro_steps']} steps in {m['wall_time_s']:.2f} s "
          f"({m['us_per_step']:.1f} us/step), {m['rows']} rows{fig_note}; results in {out}")
    sync = m.get("synchronism")
    if isinstance(sync, dict) and (sync.get("episodes") or sync.get("fault_latched")):
        latched = f"; safe state latched at {sync['t_fault']:.2f} s" if sync.get("fault_latched") else ""
        _note(f"the controller reported {sync['episodes']} loss-of-synchronism episode(s), the first at "
              f"{sync['t_first_episode']:.2f} s{latched} (output fault; metrics.json 'synchronism')", a.quiet)
    if m["status"] == "completed":
        return 0
    return EXIT_INTERRUPTED if m["status"] == "interrupted" else EXIT_FAILED


def cmd_export_ssp(a) -> int:
    spec = with_fmi(_load_with_overrides(a), a.fmi)
    if not a.output.lower().endswith(".ssp"):
        raise CosimError(f"-o {a.output}: an SSP package file name ends in .ssp")
    ensure_fmus(spec, a.quiet)
    summary = export_ssp(spec, Path(a.output), a.quiet)
    print(f"wrote {summary.path}: components {', '.join(summary.components)}; {summary.connections} connections; "
          f"{summary.parameters} parameter value{'' if summary.parameters == 1 else 's'}; "
          f"step {spec.step_size:g} s, stop {spec.stop_time:g} s, "
          f"{spec.algorithm}")
    return 0


def cmd_sweep(a) -> int:
    if a.workers is not None and a.scheduler:
        raise CosimError("--workers sizes the local cluster; with --scheduler the cluster's own workers are used")
    sweep = load_sweep(a.sweep, samples=a.samples, seed=a.seed)
    if a.stop_time is not None:
        sweep.stop_time = a.stop_time
    out = Path(a.out) if a.out else Path("runs") / sweep.name
    if a.dry_run:
        prepare_runs(sweep, a.quiet)  # every check, nothing launched
        names = sweep.swept
        print(f"{sweep.name}: {len(sweep.runs)} runs into {out / 'runs'}")
        for plan in sweep.runs:
            print(f"  {plan.id}: " + ", ".join(f"{n} = {plan.params[n]!r}" for n in names))
        return 0
    outcome = run_sweep(sweep, out, scheduler=a.scheduler, workers=a.workers, quiet=a.quiet)
    where = f"{outcome.summary}" + (f", {outcome.figure}" if outcome.figure else "")
    completed = sum(r["status"] == "completed" for r in outcome.rows)
    print(f"{'interrupted' if outcome.interrupted else 'done'}: {completed} of {len(outcome.rows)} runs completed "
          f"({outcome.ran} run now, {outcome.skipped} already done), {outcome.failed} not completed; {where}")
    verdict = cycle_verdict(outcome.rows)
    if verdict is not None:  # a cycle sweep: the failure rule on its samples
        print(verdict_line(verdict))
    if outcome.interrupted:
        return EXIT_INTERRUPTED
    return EXIT_FAILED if outcome.failed else 0


def cmd_build(a) -> int:
    kwargs = {"force": a.force, "out_dir": project_fmu_dir(), "fmi": a.fmi}  # --out/--fmu-dir DIR, else the default
    if a.names:
        kwargs["names"] = a.names
    try:
        paths = fmu_build.build_all(**kwargs)
    except (CosimError, ParameterError, ProfileError):
        raise
    except Exception as exc:
        raise CosimError(f"building the FMUs failed: {type(exc).__name__}: {exc}") from None
    for name, path in paths.items():
        print(f"{name}: {path}")
    return 0


def cmd_bench(a) -> int:
    return bench.run_from_args(a)


def cmd_info(a) -> int:
    fmu = Path(a.fmu)
    if a.fmu in fmu_choices():  # a shipped FMU by its name or its observer's: built first if needed
        fmu = resolve_fmu(a.fmu, f"info {a.fmu}")
        try:
            fmu_build.build_all(out_dir=fmu.parent, names=[fmu.stem])
        except Exception as exc:
            raise CosimError(f"building {fmu.name} failed: {type(exc).__name__}: {exc}") from None
    md = read_description(fmu)
    cs = md.coSimulation
    print(f"{md.modelName} (FMI {md.fmiVersion}, co-simulation, model identifier {cs.modelIdentifier})")
    if md.description:
        print(f"  {md.description}")
    print(f"  generated by {md.generationTool or '?'}; guid {md.guid}")
    if md.defaultExperiment is not None:
        de = md.defaultExperiment
        print(f"  default experiment: start {de.startTime}, stop {de.stopTime}, step {de.stepSize}")
    rows = [("name", "causality", "variability", "type", "unit", "start", "description")]
    order = {"input": 0, "output": 1, "parameter": 2, "calculatedParameter": 3, "local": 4, "independent": 5}
    variables = sorted(md.modelVariables, key=lambda v: (order.get(v.causality, 9), v.valueReference))
    if a.causality:
        variables = [v for v in variables if v.causality == a.causality]
    for v in variables:
        rows.append((v.name, v.causality, v.variability, v.type, variable_unit(v) or "-",
                     "-" if v.start is None else str(v.start), v.description or ""))
    widths = [max(len(r[i]) for r in rows) for i in range(6)]
    for r in rows:
        print("  " + "  ".join(r[i].ljust(widths[i]) for i in range(6)) + "  " + r[6])
    return 0


def cmd_plot(a) -> int:
    run_dir = Path(a.dir)
    if not run_dir.exists():
        raise CosimError(f"{run_dir}: no such run directory")
    label = a.scenario
    if label is None:
        try:
            label = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8")).get("scenario")
        except (OSError, ValueError):
            label = None
    from .figures import make_figures  # noqa: PLC0415 - matplotlib: heavy, only when drawing

    try:
        paths = make_figures(run_dir, scenario_label=label)
    except ValueError as exc:  # FiguresError
        raise CosimError(str(exc)) from None
    for p in paths:
        print(p)
    return 0


def cmd_compare(a) -> int:
    out = Path(a.out)
    result = compare.compare(a.dirs, out, labels=a.labels, t_from=a.t_from, figures=not a.no_figures)
    print(result["markdown"].read_text(encoding="utf-8"), end="")
    print(f"table: {result['markdown']}, {result['csv']}"
          + (f"; figures: {', '.join(str(p) for p in result['figures'])}" if result["figures"] else ""))
    return 0


def cmd_envelope(a) -> int:
    from . import envelope  # noqa: PLC0415 - matplotlib and the map's losses: only for this command

    params = envelope.parameters(a.set)
    summary = envelope.draw(params, Path(a.out), runs=a.run or (), omega_max=a.speed_max,
                            efficiency=not a.no_efficiency)
    sp = summary["speeds"]

    def rad_s(x):
        return "none" if x is None else f"{x:.0f} rad/s"

    print(f"T_max {summary['limits']['T_max']:.1f} N m at I_max {summary['limits']['i_max']:g} A; base speed "
          f"{rad_s(sp['base_speed'])}, MTPV from {rad_s(sp['mtpv_speed'])}, max speed {rad_s(sp['max_speed'])}")
    for f in summary["figures"]:
        print(f)
    if a.published:
        from . import published  # noqa: PLC0415 - the measured map and its figure: only with --published

        c = published.write(params, Path(a.out))
        print(c["figure"])
        print(Path(a.out) / "efficiency_vs_published.md")
        print(c["table"], end="")
    print(Path(a.out) / "envelope.json")
    return 0


def cmd_report(a) -> int:
    if a.list:
        for c in report.CONFIGS:
            print(f"{c.id}: {c.scenario}, {c.label}" + (f", {c.description}" if c.description else ""))
        return 0
    if a.jobs < 1:
        raise CosimError(f"--jobs must be >= 1 (got {a.jobs})")
    if a.robustness:
        command = "pmsm-cosim report --robustness" + (" --small" if a.small else "") + (
            f" --stop-time {a.stop_time:g}" if a.stop_time else "") + (f" --only {' '.join(a.only)}" if a.only else "")
        report.robustness.generate(out=a.out, runs_dir=a.runs or "runs/robustness", workers=a.jobs,
                                   small=a.small, stop_time=a.stop_time, run=not a.no_run, command=command,
                                   log=lambda msg: print(msg, file=sys.stderr, flush=True), only=a.only)
        return 0
    if a.small or a.no_run:
        raise CosimError("--small and --no-run go with --robustness")
    command = "pmsm-cosim report" + (f" --stop-time {a.stop_time:g}" if a.stop_time else "")
    report.generate(out=a.out, runs_dir=a.runs or "runs/report", jobs=a.jobs, stop_time=a.stop_time, only=a.only,
                    force=a.force, log=lambda msg: print(msg, file=sys.stderr, flush=True), command=command)
    return 0


# --- parser ------------------------------------------------------------------------------

class _Parser(argparse.ArgumentParser):
    """argparse with the project's error format: one line ``error: ...``, exit code 2."""

    def error(self, message):
        self.exit(EXIT_USER_ERROR, f"error: {one_line(message)} (see {self.prog} --help)\n")


def _system_options(p: argparse.ArgumentParser) -> None:
    """The options that change a system before it is run or exported."""
    p.add_argument("--plant", metavar="FMU", help=f"FMU of the instance '{PLANT_INSTANCE}': an .fmu file or a "
                                                  f"shipped FMU's name (PmsmEvPlant)")
    p.add_argument("--controller", metavar="FMU",
                   help=f"FMU of the instance '{CONTROLLER_INSTANCE}': an observer ({', '.join(OBSERVER_FMUS)}: "
                        f"e.g. ekf4 swaps the observer), a shipped FMU's name or an .fmu file")
    p.add_argument("--fmu", action="append", metavar="INSTANCE=FMU",
                   help="FMU of any instance, as --controller (repeatable)")
    p.add_argument("--stop-time", type=_positive, metavar="S", help="stop time [s] (default: the system file's)")
    p.add_argument("--step", type=_positive, metavar="S", help="base communication step [s]")
    p.add_argument("--algorithm", choices=ALGORITHMS, help="coupling (default: the system file's, gauss-seidel)")
    p.add_argument("--output-interval", type=_positive, metavar="S", help="recording interval [s]")
    p.add_argument("--set", action="extend", nargs="+", metavar="INSTANCE.VAR=VALUE",
                   help="start value of an FMU variable, e.g. ctrl.angle_source=estimated plant.omega_m0=200")
    p.add_argument("--profile", action="append", metavar="SIGNAL=CSV",
                   help="take a scenario signal from a (time, value) CSV file in the signal's unit, "
                        "e.g. delta=route.csv (repeatable)")
    p.add_argument("--cycle", metavar="NAME|CSV",
                   help="drive the speed reference omega_ref by a drive cycle: a shipped one (wltc3b, udds, hwfet, "
                        "us06) or a CSV file (time_s, speed_kmh|speed_mps|speed_mph); the stop time is the cycle's "
                        "duration unless --stop-time (docs/cycles.md)")
    p.add_argument("--record", action="extend", nargs="+", metavar="COLUMN",
                   help="record only these columns (and time): the system's (omega_m) or a variable "
                        "(plant.omega_m, the column named as written)")
    _fmu_dir_option(p)


def _fmu_dir_option(p: argparse.ArgumentParser, *names: str) -> None:
    p.add_argument(*(names or ("--fmu-dir",)), dest="fmu_dir", metavar="DIR",
                   help="the folder of the project's FMUs, built there if needed (default: $PMSM_COSIM_FMU_DIR, "
                        "else the user's cache, e.g. ~/.cache/pmsm-ev-cosim/fmus/<content key>/)")


def _fmi_option(p) -> None:
    p.add_argument("--fmi", type=int, choices=fmu_build.FMI_VERSIONS, default=None,
                   help="the project's FMUs of the system as FMI 2.0 units (2) or FMI 3.0 units (3: built into "
                        f"DIR/{fmu_build.FMI3_FOLDER}/ from the same FMI 2.0 stack); default: as the system names them "
                        "({fmus}/X.fmu, {fmus}/fmi3/X.fmu: one system may mix both)")


def build_parser() -> argparse.ArgumentParser:
    ap = _Parser(
        prog="pmsm-cosim",
        description="Co-simulate the PMSM EV drive FMUs (FMI 2.0) with a fixed-step master.",
        epilog="Run 'pmsm-cosim COMMAND --help' for the options of a command.")
    ap.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=_Parser)

    r = sub.add_parser("run", help="co-simulate a scenario, a system file or an SSP package",
                       description="Co-simulate a shipped scenario (scenario1, scenario2), a system file "
                                   "(TOML, see docs/system-file.md) or an SSP 1.0 package (.ssp); write "
                                   "OUT/results.csv, OUT/metrics.json and OUT/figures/*.png. Missing project "
                                   "FMUs are built first.")
    r.add_argument("system", metavar="SCENARIO_OR_SYSTEM",
                   help=f"{' or '.join(PACKAGED_SCENARIOS)}, or the path of a system file or .ssp package")
    _system_options(r)
    r.add_argument("--out", metavar="DIR", help="output directory (default: runs/<scenario name>)")
    r.add_argument("--no-figures", action="store_true", help="do not draw figures")
    r.add_argument("--loop", choices=LOOPS, default=None,
                   help="the stepping loop (same results): compiled (machine code, the default; a system it "
                        "cannot step runs the plain one, with a note saying why) or plain (Python for a "
                        "debugger); also: PMSM_COSIM_LOOP=...")
    r.add_argument("--plain-loop", action="store_const", const="plain", dest="loop",
                   help="the same as --loop plain")
    _fmi_option(r)
    r.add_argument("--no-event-mode", action="store_true",
                   help="FMI 3.0 units with clocks (the controllers' sample clock) instantiated without event mode: "
                        "not ticked by the master, they sample at their own period (the same results)")
    r.add_argument("--quiet", "-q", action="store_true", help="no progress bar, no notes")
    r.set_defaults(func=cmd_run)

    e = sub.add_parser("export-ssp", help="write a system as an SSP 1.0 package for other tools",
                       description="Write a scenario or system file as an SSP 1.0 package: SystemStructure.ssd, "
                                   "the FMUs (the signals as a RouteProfile FMU carrying the system's route) and "
                                   "the start values as .ssv parameter sets. libcosim, fmpy and other SSP "
                                   "tools run it; so does 'pmsm-cosim run FILE.ssp'.")
    e.add_argument("system", metavar="SCENARIO_OR_SYSTEM",
                   help=f"{' or '.join(PACKAGED_SCENARIOS)}, or the path of a system file or .ssp package")
    e.add_argument("-o", "--output", required=True, metavar="FILE.ssp", help="the package to write")
    _system_options(e)
    _fmi_option(e)
    e.add_argument("--quiet", "-q", action="store_true", help="no notes")
    e.set_defaults(func=cmd_export_ssp)

    w = sub.add_parser("sweep", help="run a parameter sweep or Monte-Carlo study on Dask",
                       description="Run the runs of a sweep file (TOML, see docs/sweeps.md; or a shipped sweep: "
                                   "ekf5_load_noise) on a Dask cluster: OUT/runs/<run>/ (results.csv, "
                                   "metrics.json), OUT/summary.csv, OUT/summary.png. Completed runs of the same "
                                   "parameters already in OUT are skipped. Exit code 1 if a run did not complete.")
    w.add_argument("sweep", metavar="SWEEP_FILE", help="a sweep file, or the name of a shipped sweep")
    w.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="use this Dask scheduler (its workers need pmsm-ev-cosim installed) instead of a local "
                        "cluster")
    w.add_argument("--workers", type=_count, metavar="N",
                   help="worker processes of the local cluster (default: one per core, at most one per run)")
    w.add_argument("--out", metavar="DIR", help="output directory (default: runs/<sweep name>)")
    w.add_argument("--stop-time", type=_positive, metavar="S", help="stop time of every run [s] (overrides the file)")
    w.add_argument("--samples", type=_count, metavar="N",
                   help="a Monte-Carlo sweep: draw N samples instead of the file's (its name, and so the default "
                        "output directory, get _nN)")
    w.add_argument("--seed", type=_seed, metavar="N",
                   help="a Monte-Carlo sweep: draw with the seed N instead of the file's, new samples of the same "
                        "design (its name, and so the default output directory, get _seedN)")
    w.add_argument("--dry-run", action="store_true", help="check the sweep against the FMUs and list its runs")
    w.add_argument("--quiet", "-q", action="store_true", help="no progress bar, no per-run lines")
    _fmu_dir_option(w)
    w.set_defaults(func=cmd_sweep)

    b = sub.add_parser("build", help="build the project's FMUs (into the user's cache, or --out DIR)",
                       description="Build the project's FMUs (pmsm_ev_fmus.build.build_all) into DIR, else "
                                   "$PMSM_COSIM_FMU_DIR, else the user's cache (a folder per content of the "
                                   "sources, ~/.cache/pmsm-ev-cosim/fmus/<key>/ on Linux), where runs find them; "
                                   "only those whose sources changed unless --force. Prints each FMU's path.")
    b.add_argument("--force", action="store_true", help="rebuild even when up to date")
    b.add_argument("--fmi", type=int, choices=fmu_build.FMI_VERSIONS, default=2,
                   help="FMI version of the units: 2 (default) or 3, FMI 3.0 co-simulation units made from the "
                        f"FMI 2.0 ones (built too), into DIR/{fmu_build.FMI3_FOLDER}/")
    _fmu_dir_option(b, "--out", "--fmu-dir")
    b.add_argument("names", nargs="*", metavar="NAME", help="build only these FMUs (default: all)")
    b.set_defaults(func=cmd_build)


    bn = sub.add_parser("bench", help="measure the co-simulation's cost per step",
                        description="Measure the wall time per macro step on a slice of scenario 1: "
                                    "(a) the master with the project's FMUs, (b) with pass-through FMUs "
                                    "that compute nothing, (c) the monolithic reference, (d) libcosim "
                                    "with the same FMUs; (e)-(g) the sensorless cycle drive on WLTC 3b; (h), (i) the "
                                    "whole compiled loop (no FMI) of the systems of (e) and (a); then the peak "
                                    "memory of 100 s and 350 s runs.")
    bench.add_arguments(bn)
    _fmu_dir_option(bn)
    bn.set_defaults(func=cmd_bench)

    i = sub.add_parser("info", help="list an FMU's variables",
                       description="Print an FMU's model information and its variables with causality, "
                                   "variability, type, unit, start value and description.")
    i.add_argument("fmu", metavar="FMU", help="the .fmu file, or a shipped FMU's name (PmsmEvPlant, FocEkf4) or "
                                             "an observer's (ekf4)")
    _fmu_dir_option(i)
    i.add_argument("--causality", choices=("input", "output", "parameter", "calculatedParameter", "local"),
                   help="only variables of this causality")
    i.set_defaults(func=cmd_info)

    p = sub.add_parser("plot", help="draw the figures of an existing run",
                       description="Draw the figures of a run directory (DIR/results.csv) into DIR/figures.")
    p.add_argument("dir", metavar="DIR", help="run directory")
    p.add_argument("--scenario", metavar="LABEL",
                   help="scenario1/scenario2 names the figures after the paper's (default: from metrics.json)")
    p.set_defaults(func=cmd_plot)

    c = sub.add_parser("compare", help="overlay runs and tabulate their metrics",
                       description="Overlay finished runs (speed, angle error, torque estimate vs T_L_mech) "
                                   "as OUT/compare_*.png and write one metrics table across them as "
                                   "OUT/metrics.md and OUT/metrics.csv.")
    c.add_argument("dirs", nargs="+", metavar="RUN_DIR", help="run directories (results.csv, metrics.json)")
    c.add_argument("--out", metavar="DIR", default="runs/compare", help="output directory (default: runs/compare)")
    c.add_argument("--labels", nargs="+", metavar="LABEL", help="one label per run (default: directory names)")
    c.add_argument("--from", dest="t_from", type=float, default=T_FROM, metavar="S",
                   help=f"start of the window of the 'after' figures [s] (default: {T_FROM:g}, past the start-up ramp)")
    c.add_argument("--no-figures", action="store_true", help="only the table")
    c.set_defaults(func=cmd_compare)

    ev = sub.add_parser("envelope", help="draw the torque-speed envelope and the efficiency map",
                        description="Draw where the drive can go: the torque-speed envelope of the reference "
                                    "generator (MTPA, field weakening, MTPV; the current and voltage limits) with the "
                                    "current plane, and the motor + inverter efficiency map from the plant's loss "
                                    "model, into OUT/envelope.png, OUT/efficiency.png, OUT/envelope.json. Defaults: "
                                    "the package's motor, field weakening on a 360 V DC link.")
    ev.add_argument("--set", nargs="+", metavar="NAME=VALUE", default=[],
                    help="any motor, controller, plant or vehicle parameter, e.g. L_d=0.3e-3 i_max=450 "
                         "inverter_losses=true (a name of several groups changes each)")
    ev.add_argument("--run", nargs="+", metavar="RUN_DIR", help="overlay the operating points of these runs")
    ev.add_argument("--speed-max", type=_positive, metavar="RAD_S", help="the speed axis's end [rad/s]")
    ev.add_argument("--no-efficiency", action="store_true", help="only the envelope (the map takes ~10 s)")
    ev.add_argument("--published", action="store_true",
                    help="set the map beside a measured one (the 2004 Prius motor and inverter, ORNL/TM-2006/423 "
                         "Table B-1) in per-unit: OUT/efficiency_vs_published.png and .md, envelope.json's "
                         "'published' (~10 s more)")
    ev.add_argument("--out", metavar="DIR", default="runs/envelope", help="output directory (default: runs/envelope)")
    ev.set_defaults(func=cmd_envelope)

    rp = sub.add_parser("report", help="run the observer comparison and write docs/results.md",
                        description="Co-simulate every configuration of the observer comparison (both paper "
                                    "scenarios x EKF5 paper mode / sensorless, stationary-frame EKF5, EKF4 paper "
                                    "mode / sensorless, sensored; scenario 2 under sensor noise, offsets and an "
                                    "initial angle error; the sensorless unit from standstill; the synchronism matrix, "
                                    "in-process), JOBS runs at a time, and write OUT/results.md with "
                                    "its figures in OUT/results/. A run in RUNS whose metrics.json is "
                                    "'completed' with the same settings and FMU builds is reused.")
    rp.add_argument("--out", metavar="DIR", default="docs", help="where results.md goes (default: docs)")
    rp.add_argument("--runs", "--reuse", dest="runs", metavar="DIR", default=None,
                    help="run directories, reused when up to date (default: runs/report; with --robustness: "
                         "runs/robustness)")
    rp.add_argument("--jobs", "-j", type=int, default=2, metavar="N", help="runs at a time (default: 2)")
    rp.add_argument("--stop-time", type=_positive, metavar="S",
                    help="stop time of every run [s] (default: the scenarios' 350 s); short for a quick look")
    rp.add_argument("--only", nargs="+", metavar="PATTERN",
                    help="(re)run only the configurations whose id contains PATTERN (or matches it as a "
                         "glob), e.g. ekf5ab; with --robustness the sweeps whose name does, e.g. "
                         "cycle_montecarlo_wltc3b; the others are taken from RUNS as they are")
    rp.add_argument("--force", action="store_true", help="rerun the (selected) configurations even when up to date")
    rp.add_argument("--list", action="store_true", help="list the configuration ids and exit")
    rp.add_argument("--robustness", action="store_true",
                    help="instead: run the robustness sweeps (orchestrator/pmsm_cosim/app/sweeps/robust_*.toml) "
                         "on a local Dask "
                         "cluster of --jobs workers and write OUT/robustness.md and OUT/robustness/*.png")
    rp.add_argument("--small", action="store_true",
                    help="with --robustness: 3 x 3 grids and a few Monte-Carlo samples (a quick check)")
    rp.add_argument("--no-run", action="store_true",
                    help="with --robustness: write the page from the runs in RUNS as they are")
    _fmu_dir_option(rp)
    rp.set_defaults(func=cmd_report)
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        with fmu_dir_override(getattr(args, "fmu_dir", None)):
            return args.func(args)
    except (CosimError, ParameterError, ProfileError) as exc:
        return _err(str(exc))
    except OSError as exc:
        return _err(f"{exc.filename + ': ' if getattr(exc, 'filename', None) else ''}{exc.strerror or exc}")
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def entry_point() -> None:
    """The ``pmsm-cosim`` command: ``main``, its return value the exit code."""
    sys.exit(main())


if __name__ == "__main__":
    entry_point()
