"""Running a sweep: each run prepared and checked on the client, executed as one task on a
Dask cluster, its files written back beside the others.

:func:`prepare_runs` builds each run's :class:`~pmsm_cosim.engine.system.SystemSpec` on the
client and checks every variable against the FMUs before anything is launched;
:func:`run_sweep` executes the runs that are not already done on a Dask cluster (a
``LocalCluster`` of processes it starts and stops, or an existing scheduler) and writes
``OUT/runs/<run id>/`` (the normal ``results.csv`` and ``metrics.json``), ``OUT/summary.csv``
and ``OUT/summary.png``.

Each run is one task, :func:`execute_run`: the worker gets the run's system (already
resolved: signal tables loaded, paths fixed) and the bytes of its FMUs, writes the FMUs
once into its local directory (keyed by content hash), runs the engine's
:class:`~pmsm_cosim.engine.master.Master` into a scratch directory and returns the files,
which the client writes. Workers need this package installed (for the engine and the
application's hooks); the physics travels inside the FMUs. Each task measures its own wall
time (``sample_s``, in metrics.json and summary.csv); the client's line for a finished run
gives that cost and the time left for the rest at the pace so far.

Dask (``distributed``) is heavy: it is imported inside the functions that use it, when a
sweep runs, not when the package is imported.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import json
import logging
import math
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, replace
from importlib.metadata import version
from pathlib import Path

from ..engine.errors import CosimError, close_matches, one_line
from ..engine.fmu import FmuInstance, convert_start, variable_unit
from ..engine.master import Master
from ..engine.progress import CountBar
from ..engine.recording import write_metrics
from ..engine.system import SIGNAL_CONVERSIONS, SystemSpec, resolve_fmu_path
from .spec import RUNS_DIR, Param, RunPlan, SweepHooks, SweepSpec, parse_param, redrawn_text
from .summary import _row, plot_summary, write_summary

# --- the runs, prepared on the client -------------------------------------------------

@dataclass
class PreparedRun:
    plan: RunPlan
    spec: SystemSpec
    fmus: dict[str, str]  #: instance -> sha256 of its FMU file
    signature: str  #: sha256 of everything that determines the run's results


def _resolve_system(value: str, base_dir: Path, hooks: SweepHooks) -> str:
    """A shipped scenario name as it is; a path relative to the sweep file's directory."""
    path = Path(value).expanduser()
    if not path.is_absolute():
        path = base_dir / path
    if value in hooks.system_names or (path.suffix == "" and not path.exists()):
        return value  # hooks.load_system names its own systems (with close matches)
    return str(path.resolve())


def _resolve_fmu(value: str, base_dir: Path, hooks: SweepHooks) -> Path:
    """An FMU by name (``hooks.fmu_names``: FocEkf5, FocEkf4, ...), ``{fmus}/X.fmu`` or a path
    (relative to the sweep file)."""
    names = hooks.fmu_names
    name = value.strip()
    if name in names or name.removesuffix(".fmu") in names:
        return Path(hooks.fmu_dir) / f"{name.removesuffix('.fmu')}.fmu"
    if not name.endswith(".fmu") and "/" not in name and "\\" not in name:
        raise CosimError(f"unknown FMU {name!r}{close_matches(name, names)}; give a shipped FMU "
                         f"({', '.join(names)}) or the path of an .fmu file")
    return resolve_fmu_path(name, base_dir, fmu_dir=hooks.fmu_dir)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def run_signature(spec: SystemSpec, fmu_hashes: dict[str, str]) -> str:
    """sha256 of what determines a run's results: the FMUs' contents, start values, wiring,
    signal tables, time grid, algorithm and recorded columns (not the paths of files)."""
    obj = {
        "algorithm": spec.algorithm, "step_size": spec.step_size, "stop_time": spec.stop_time,
        "output_interval": spec.output_interval,
        "components": [[c.name, fmu_hashes[c.name], c.step_multiple, sorted(c.start.items())]
                       for c in spec.components],
        "connections": [str(c) for c in spec.connections],
        "signals": [[s.name, s.drives, s.unit, s.profile.interpolation, list(s.profile.times),
                     list(s.profile.values)] for s in spec.signals.values()],
        "columns": [[c.name, c.source] for c in spec.columns],
    }
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def _apply(spec: SystemSpec, param: Param, value, base_dir: Path, hooks: SweepHooks) -> None:
    if param.kind in ("scale", "offset"):  # every value of the signal's table times the factor, or plus
        sig = spec.signals.get(param.variable)
        if sig is None:
            raise CosimError(f"the system has no signal {param.variable!r}{close_matches(param.variable, spec.signals)}"
                             f"; its signals: {', '.join(spec.signals) or 'none'}")
        prof, x = sig.profile, float(value)
        if param.kind == "offset" and sig.written_unit in SIGNAL_CONVERSIONS:  # the offset is in the table's
            x = SIGNAL_CONVERSIONS[sig.written_unit][1](x)  # unit (deg), the profile in the input's (rad)
        values = tuple(x * v for v in prof.values) if param.kind == "scale" else tuple(v + x for v in prof.values)
        sig.profile = replace(prof, values=values)
        return
    comp = spec.component(param.instance)  # an unknown instance: close matches
    if param.kind == "fmu":
        comp.fmu, comp.fmu_text = _resolve_fmu(value, base_dir, hooks), value
    else:
        comp.start[param.variable] = value


def prepare_runs(sweep: SweepSpec, quiet: bool = True) -> list[PreparedRun]:
    """Each run's system, its FMUs built and checked: instances, variables (close matches),
    settable, values of the variable's type; FMU files readable. Nothing is launched."""
    hooks = sweep.hooks
    where = sweep.where
    bases: dict[str, SystemSpec] = {}
    hashes: dict[Path, str] = {}
    checked: dict[tuple, dict[str, FmuInstance]] = {}
    prepared = []
    built = False

    def origin(name: str) -> str:
        table = "set" if name in sweep.fixed else ("grid" if name in sweep.grid else "random")
        return f"{where}: {table}.{name}"

    for plan in sweep.runs:
        values = {**sweep.fixed, **plan.params}
        system = _resolve_system(values.get("system", sweep.system), sweep.base_dir, hooks)
        if system not in bases:
            try:
                bases[system] = hooks.load_system(system)
            except CosimError as exc:
                ctx = origin("system") if "system" in values else f"{where}: system"
                raise CosimError(f"{ctx}: {exc}") from None
        spec = copy.deepcopy(bases[system])
        if sweep.stop_time is not None:
            spec.stop_time = sweep.stop_time
        if sweep.output_interval is not None:
            spec.output_interval = sweep.output_interval
        params = {name: parse_param(name, where) for name in values if name != "system"}
        # start values and FMUs first, then what the application derives from them (hooks.adjust), then the
        # factors and offsets on signal tables (on the derived signals too)
        on_signals = [n for n, p in params.items() if p.kind in ("scale", "offset")]
        for names in ([n for n in params if n not in on_signals], on_signals):
            if names is on_signals and hooks.adjust is not None:
                try:
                    hooks.adjust(spec)
                except CosimError as exc:
                    raise CosimError(f"{where}: run {plan.id}: {exc}") from None
            for name in names:
                try:
                    _apply(spec, params[name], values[name], sweep.base_dir, hooks)
                except CosimError as exc:
                    raise CosimError(f"{origin(name)}: {exc}") from None
        key = (system, tuple((c.name, str(c.fmu)) for c in spec.components))
        if key not in checked:
            if hooks.prepare is not None and (not built or any(not c.fmu.is_file() for c in spec.components)):
                try:
                    hooks.prepare(spec, quiet)  # e.g. builds (or finds up to date) the application's FMUs
                except CosimError as exc:
                    raise CosimError(f"{where}: {exc}") from None
                built = built or any(c.fmu.parent == hooks.fmu_dir for c in spec.components)
            instances = {}
            for comp in spec.components:  # the model descriptions only
                ctx = next((origin(n) for n, p in params.items() if p.kind == "fmu" and p.instance == comp.name),
                           f"{where}: {system}")
                try:
                    instances[comp.name] = FmuInstance(comp.name, comp.fmu)
                except CosimError as exc:
                    raise CosimError(f"{ctx}: {exc}") from None
            for name, param in params.items():  # the sweep's variables, named where they are set
                if param.kind == "start":
                    sv = instances[param.instance].check_settable(param.variable, origin(name))
                    sweep.units.setdefault(name, variable_unit(sv))
            try:
                Master(spec).close()  # the system's own wiring and start values against its FMUs
            except CosimError as exc:
                raise CosimError(f"{where}: run {plan.id}: {exc}") from None
            checked[key] = instances
        instances = checked[key]
        for name, param in params.items():  # in the variable's type: 1 and 1.0 are one run
            if param.kind == "start":
                sv = instances[param.instance].variables[param.variable]
                spec.component(param.instance).start[param.variable] = convert_start(
                    sv, values[name], f"{origin(name)} = {values[name]!r}")
        for c in spec.components:
            if c.fmu not in hashes:
                hashes[c.fmu] = _sha256(c.fmu)
        fmus = {c.name: hashes[c.fmu] for c in spec.components}
        prepared.append(PreparedRun(plan, spec, fmus, run_signature(spec, fmus)))
    return prepared


# --- one run, on a worker ---------------------------------------------------------------

def _scratch_root() -> Path:
    """The worker's local directory (removed by Dask with the worker), else the temp dir."""
    from distributed import get_worker  # noqa: PLC0415 - dask: heavy, loaded when a sweep runs

    try:
        return Path(get_worker().local_directory) / "pmsm-cosim"
    except (ValueError, AttributeError):  # called outside a Dask worker
        global _SCRATCH
        if _SCRATCH is None:
            _SCRATCH = tempfile.TemporaryDirectory(prefix="pmsm-cosim-sweep-")  # removed at exit
        return Path(_SCRATCH.name)


_SCRATCH: tempfile.TemporaryDirectory | None = None


def _worker_address() -> str | None:
    from distributed import get_worker  # noqa: PLC0415 - dask: heavy, loaded when a sweep runs

    try:
        return get_worker().address
    except (ValueError, AttributeError):
        return None


def _local_fmu(sha: str, filename: str, blob: bytes) -> Path:
    """The FMU written once per worker, under its content hash."""
    path = _scratch_root() / "fmus" / sha[:16] / filename
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_bytes(blob)
        os.replace(tmp, path)
    return path


def execute_run(task: dict, blobs: dict[str, bytes]) -> dict:
    """Run one co-simulation (a Dask task): returns {"id", "status", "error", "files"}, where
    ``files`` maps the run directory's relative paths to their bytes. Never raises for a
    failed run: a refusal at load or initialization is a failed status with its reason.
    ``sample_s``: the task's wall time [s] from its start to its files read (also in metrics.json)."""
    t0 = time.perf_counter()
    spec: SystemSpec = task["spec"]
    hooks: SweepHooks = task["hooks"]
    client_paths = {c.name: str(c.fmu) for c in spec.components}
    for c in spec.components:
        sha = task["fmus"][c.name]
        c.fmu = _local_fmu(sha, c.fmu.name, blobs[sha])
    scratch = _scratch_root() / "runs"
    scratch.mkdir(parents=True, exist_ok=True)
    out = Path(tempfile.mkdtemp(prefix=f"{task['id'][:40]}-", dir=scratch))
    result = {"id": task["id"], "status": "failed", "error": "", "files": {}}
    try:
        try:
            master = Master(spec)
            metrics_of = hooks.metrics_of
            if hooks.metrics_for is not None:
                metrics_of = hooks.metrics_for(metrics_of, spec)
            metrics = master.run(out, extra_settings={"sweep": task["sweep"]}, catch_sigint=False,
                                 metrics_of=metrics_of)
        except (CosimError, *hooks.run_errors) as exc:
            result["error"] = one_line(exc)
        except Exception as exc:  # noqa: BLE001 - any failure is the run's, not the sweep's
            result["error"] = one_line(f"{type(exc).__name__}: {exc}")
        else:
            # the run's settings name the client's FMU files, as a single run would
            settings = metrics.get("settings", {})
            for comp in settings.get("components", []):
                comp["fmu"] = client_paths.get(comp["name"], comp["fmu"])
            settings.get("sweep", {})["worker"] = _worker_address()
            write_metrics(out, metrics)
            status = metrics["status"]
            result["status"], _, result["error"] = status.partition(": ")
            if task["figures"] and hooks.figures is not None and metrics.get("rows", 0) >= 2:
                hooks.figures(out, spec.name, True)
            metrics["sample_s"] = time.perf_counter() - t0  # the sample's cost, the figures included
            write_metrics(out, metrics)
        for p in sorted(out.rglob("*")):
            if p.is_file():
                result["files"][p.relative_to(out).as_posix()] = p.read_bytes()
    finally:
        shutil.rmtree(out, ignore_errors=True)
    result["sample_s"] = time.perf_counter() - t0
    return result


# --- the sweep, on the client -----------------------------------------------------------

def _read_metrics(run_dir: Path) -> dict | None:
    try:
        return json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def is_done(run_dir: Path, signature: str) -> bool:
    """A completed run of the same parameters, system and FMUs is in ``run_dir``."""
    m = _read_metrics(run_dir)
    if not m or m.get("status") != "completed":
        return False
    sweep = (m.get("settings") or {}).get("sweep") or {}
    return sweep.get("signature") == signature and (run_dir / "results.csv").is_file()


@dataclass
class SweepOutcome:
    rows: list[dict]
    ran: int  #: runs executed now
    skipped: int  #: completed runs found in the output directory
    summary: Path
    figure: Path | None
    interrupted: bool = False

    @property
    def failed(self) -> int:
        return sum(r["status"] != "completed" for r in self.rows)


def cpu_count() -> int:
    """The cores this process may use."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None):
    """A distributed Client: of a LocalCluster of ``workers`` single-threaded processes
    (default one per core) that is stopped on exit, or of the scheduler at ``scheduler``."""
    from distributed import Client  # noqa: PLC0415 - dask: heavy, loaded when a sweep runs

    if scheduler:
        try:
            client = Client(scheduler, timeout=30)
        except (OSError, TimeoutError, ValueError) as exc:
            raise CosimError(f"cannot connect to the Dask scheduler at {scheduler}: {one_line(exc)}") from None
        try:
            yield client
        finally:
            client.close()
        return
    with local_cluster(workers) as cluster, Client(cluster) as client:
        yield client


def local_cluster(workers: int | None = None):
    """A distributed LocalCluster of ``workers`` (default: one per core) worker processes of
    one thread each (a run holds the GIL), without a dashboard (its HTTP server on a free
    port), silent: a failed run is reported through its task; what the cluster itself
    logs (e.g. a heartbeat missed while it shuts down) is noise to the sweep."""
    from distributed import LocalCluster  # noqa: PLC0415 - dask: heavy, loaded when a sweep runs

    return LocalCluster(n_workers=workers or cpu_count(), threads_per_worker=1, processes=True,
                        dashboard_address=None, scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"},
                        silence_logs=logging.CRITICAL)


def _check_workers(client) -> None:
    """Every worker can import this package (the tasks run the orchestrator there)."""
    if not client.scheduler_info().get("workers"):
        client.wait_for_workers(1, timeout=60)
    try:
        found = client.run(lambda: __import__("importlib.metadata").metadata.version("pmsm-ev-cosim"))
    except Exception as exc:  # noqa: BLE001 - whatever the worker raised
        raise CosimError(f"a Dask worker cannot import pmsm-ev-cosim (install the package on every worker): "
                         f"{type(exc).__name__}: {one_line(exc)}") from None
    mine = version("pmsm-ev-cosim")
    other = {w: v for w, v in found.items() if v != mine}
    if other:
        print(f"note: workers run pmsm-ev-cosim {', '.join(sorted(set(other.values())))}, this client {mine}",
              file=sys.stderr)


def _submit(client, sweep: SweepSpec, todo: list[PreparedRun]) -> dict:
    """Ship the FMUs (once per worker) and submit one task per run: {future: run}."""
    _check_workers(client)
    blobs: dict[str, bytes] = {}
    for run in todo:
        for c in run.spec.components:
            if run.fmus[c.name] not in blobs:
                blobs[run.fmus[c.name]] = c.fmu.read_bytes()
    shipped = client.scatter(blobs, broadcast=True, hash=False)
    futures = {}
    for run in todo:
        task = {"id": run.plan.id, "spec": run.spec, "fmus": run.fmus, "figures": sweep.figures, "hooks": sweep.hooks,
                "sweep": {"name": sweep.name, "run": run.plan.id, "index": run.plan.index,
                          "parameters": run.plan.params, "signature": run.signature}}
        needed = {sha: shipped[sha] for sha in set(run.fmus.values())}
        key = f"pmsm-cosim-run-{run.plan.id}-{run.signature[:8]}-{time.time_ns()}"
        futures[client.submit(execute_run, task, needed, pure=False, key=key)] = run
    return futures


def _collect(futures: dict, finished) -> None:
    """``finished(run, result)`` for each run as it completes; a task that raised (a worker
    that died, a task that could not be sent, ...) is a failed run."""
    from distributed import as_completed  # noqa: PLC0415 - dask: heavy, loaded when a sweep runs

    for fut in as_completed(list(futures)):
        run = futures[fut]
        try:
            res = fut.result()
        except Exception as exc:  # noqa: BLE001
            res = {"id": run.plan.id, "status": "failed", "error": one_line(f"{type(exc).__name__}: {exc}"),
                   "files": {}}
        finished(run, res)
        fut.release()


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt


def duration(seconds: float) -> str:
    """A duration for the console: 12.3 s, 4.5 min, 2.1 h."""
    if seconds < 120:
        return f"{seconds:.1f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def cost_text(row: dict) -> str:
    """A sample's cost as the console line gives it: its wall time on the worker and the stepping loop's cost
    a step, each if known ("" if neither)."""
    parts = []
    if math.isfinite(row.get("sample_s", math.nan)):
        parts.append(duration(row["sample_s"]))
    if math.isfinite(row.get("us_per_step", math.nan)) and row["us_per_step"] > 0:
        parts.append(f"{row['us_per_step']:.2f} us/step")
    return "; " + ", ".join(parts) if parts else ""


def eta_text(left: int, finished: int, elapsed: float) -> str:
    """The time left for ``left`` samples at the pace so far (``finished`` samples in ``elapsed`` seconds of
    the sweep, whatever the number of workers), "" when nothing is left or nothing finished yet."""
    if left <= 0 or finished <= 0:
        return ""
    return f"; {left} left, ETA {duration(elapsed / finished * left)}"


def run_sweep(sweep: SweepSpec, out, *, scheduler: str | None = None, workers: int | None = None,
              client=None, quiet: bool = False, stream=None) -> SweepOutcome:
    """Run the sweep's runs that are not done yet into ``out``; write summary.csv and summary.png.

    ``client``: an existing distributed Client (then ``scheduler``/``workers`` are unused).
    A failed run is recorded (status and error in summary.csv, its files kept) and the
    sweep goes on; a completed run of the same signature already in ``out`` is skipped.
    """
    stream = stream if stream is not None else sys.stdout
    out = Path(out)
    prepared = prepare_runs(sweep, quiet)
    out.mkdir(parents=True, exist_ok=True)
    if sweep.path is not None and sweep.path.resolve() != (out / "sweep.toml").resolve():
        if sweep.redrawn:  # what was run: the file with the name, samples and seed it was drawn with
            (out / "sweep.toml").write_text(redrawn_text(sweep.path.read_text(encoding="utf-8"), sweep),
                                            encoding="utf-8")
        else:
            shutil.copyfile(sweep.path, out / "sweep.toml")  # what was run, beside its results
    runs_dir = out / RUNS_DIR
    rows: dict[int, dict] = {}
    todo: list[PreparedRun] = []
    for run in prepared:
        run_dir = runs_dir / run.plan.id
        if is_done(run_dir, run.signature):
            rows[run.plan.index] = _row(sweep, run.plan, "completed", "", _read_metrics(run_dir))
        else:
            todo.append(run)
            rows[run.plan.index] = _row(sweep, run.plan, "not run", "", None)
    skipped = len(prepared) - len(todo)
    total = len(prepared)
    say = (lambda text: None) if quiet else (lambda text: print(text, file=stream, flush=True))
    if skipped:
        say(f"{skipped} of {total} runs already completed in {out}; running {len(todo)}")
    interrupted = False
    done = skipped

    def finished(run: PreparedRun, res: dict) -> None:
        """Write a run's files and its summary row (the summary after every run)."""
        nonlocal done
        run_dir = runs_dir / run.plan.id
        if res["files"]:  # written beside, then put in place: never half a run in run_dir
            staging = runs_dir / f".{run.plan.id}.partial"
            shutil.rmtree(staging, ignore_errors=True)
            for rel, data in res["files"].items():
                target = staging / rel
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_bytes(data)
            if run_dir.exists():
                shutil.rmtree(run_dir)
            os.replace(staging, run_dir)
        row = _row(sweep, run.plan, res["status"], res["error"], _read_metrics(run_dir) if res["files"] else None)
        if not math.isfinite(row["sample_s"]) and "sample_s" in res:  # a run refused before its metrics.json
            row["sample_s"] = float(res["sample_s"])
        rows[run.plan.index] = row
        done += 1
        write_summary(sweep, list(rows.values()), out)
        if res["status"] == "completed":
            tail = f", {sweep.metrics[0]} = {row[sweep.metrics[0]]:.6g}"
        else:
            tail = f": {res['error']}" if res["error"] else ""
        if bar:
            bar.close()
        eta = eta_text(total - done, done - skipped, time.perf_counter() - started)
        say(f"[{done}/{total}] {run.plan.id}: {res['status']}{tail}{cost_text(row)}{eta}")
        if bar:
            bar.update(done, force=True)

    bar = CountBar(total) if todo and CountBar.wanted(quiet) else None
    started = time.perf_counter()  # the pace of the samples run now: their ETA
    old_term = None
    if todo and threading.current_thread() is threading.main_thread():  # SIGTERM stops the sweep like Ctrl-C
        old_term = signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        if todo:
            n_workers = workers or min(len(todo), cpu_count())  # no idle processes for a short sweep
            ctx = contextlib.nullcontext(client) if client is not None else dask_client(scheduler, n_workers)
            with ctx as cl:
                futures = _submit(cl, sweep, todo)
                started = time.perf_counter()  # (the cluster up, the FMUs shipped)
                if bar:
                    bar.update(done, force=True)
                try:
                    _collect(futures, finished)
                except KeyboardInterrupt:
                    interrupted = True
                    with contextlib.suppress(Exception):
                        cl.cancel(list(futures))
    except KeyboardInterrupt:  # while the cluster starts or stops
        interrupted = True
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
        if bar:
            bar.close()
    if interrupted:
        say(f"interrupted: {sum(r['status'] == 'not run' for r in rows.values())} runs not run; "
            f"run the same sweep again to complete them")
    summary = write_summary(sweep, list(rows.values()), out)
    figure = plot_summary(sweep, sorted(rows.values(), key=lambda r: r["index"]), out / "summary.png")
    return SweepOutcome(sorted(rows.values(), key=lambda r: r["index"]), done - skipped, skipped, summary, figure,
                        interrupted)
