"""Parameter sweeps and Monte-Carlo runs of a system on Dask distributed.

A *sweep file* (TOML, ``docs/sweeps.md``) names a base system or scenario, the values
fixed for every run and the swept parameters: a grid (a list of values or a linear/log
range per parameter, crossed) and/or random samples (uniform, log-uniform or a choice,
drawn with a seed). A parameter is a start value ``INSTANCE.VAR`` (as ``--set``), the
FMU of an instance ``fmu.INSTANCE`` (as ``--fmu``), or the ``system`` itself.

:func:`load_sweep` parses and checks the file and lists the runs; :func:`prepare_runs`
builds each run's :class:`~orchestrator.system.SystemSpec` on the client and checks every
variable against the FMUs before anything is launched; :func:`run_sweep` executes the
runs that are not already done on a Dask cluster (a ``LocalCluster`` of processes it
starts and stops, or an existing scheduler) and writes ``OUT/runs/<run id>/`` (the normal
``results.csv`` and ``metrics.json``), ``OUT/summary.csv`` and ``OUT/summary.png``.

Each run is one task, :func:`execute_run`: the worker gets the run's system (already
resolved: signal tables loaded, paths fixed) and the bytes of its FMUs, writes the FMUs
once into its local directory (keyed by content hash), runs the orchestrator's
:class:`~orchestrator.master.Master` into a scratch directory and returns the files,
which the client writes. Workers need this package installed (for the orchestrator);
the physics travels inside the FMUs.
"""

from __future__ import annotations

import contextlib
import copy
import csv
import hashlib
import io
import itertools
import json
import math
import os
import re
import shutil
import signal
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

from pmsm_ev.params import ParameterError
from pmsm_ev.results import SUMMARY_METRICS, SUMMARY_UNITS, summary_metrics
from pmsm_ev.scenarios import ProfileError

from .errors import CosimError, close_matches, one_line
from .system import (PACKAGED_SCENARIOS, SystemSpec, load_system, project_fmu_dir, read_toml, resolve_fmu_path,
                     split_reference)

#: the sweeps shipped with the package (``orchestrator/sweeps/<name>.toml``)
PACKAGED_SWEEPS = ("ekf5_load_noise",
                   "robust_rs_psi_sensorless", "robust_rs_psi_ekf5ab", "robust_rs_psi_ekf5paper",
                   "robust_lq_load_sensorless", "robust_lq_load_ekf5ab", "robust_lq_load_ekf5paper",
                   "robust_rs_psi_sensorless_adapt", "robust_lq_load_sensorless_adapt",
                   "robust_montecarlo_sensorless", "robust_montecarlo_sensorless_adapt", "robust_deadtime_hill")
TOP_KEYS = ("name", "description", "system", "stop_time", "output_interval", "metric", "figures", "set",
            "grid", "random")
GRID_KEYS = ("values", "from", "to", "num", "scale")
SCALES = ("linear", "log")
RANDOM_KEYS = ("uniform", "log_uniform", "choice")
RANDOM_SETTINGS = ("samples", "seed")
#: numbers in summary.csv besides the figures of merit
BOOKKEEPING = ("wall_time_s", "us_per_step")
DEFAULT_METRIC = "speed_rms_error"
#: run directories live in OUT/runs/
RUNS_DIR = "runs"
MAX_ID_LENGTH = 80


# --- the sweep file -------------------------------------------------------------

@dataclass(frozen=True)
class Param:
    """A swept or fixed parameter: ``kind`` "start" (INSTANCE.VAR), "fmu" (fmu.INSTANCE), "scale"
    (scale.SIGNAL: a factor on the values of one of the system's signal tables) or "system"."""

    name: str
    kind: str
    instance: str = ""
    variable: str = ""


@dataclass
class RunPlan:
    index: int
    id: str
    params: dict[str, Any]  #: swept parameter name -> value


@dataclass
class SweepSpec:
    name: str
    path: Path | None
    base_dir: Path
    system: str  #: the base scenario or system file, as written
    stop_time: float | None = None
    output_interval: float | None = None
    metrics: list[str] = field(default_factory=lambda: [DEFAULT_METRIC])
    figures: bool = False
    description: str = ""
    fixed: dict[str, Any] = field(default_factory=dict)  #: [set]: name -> value
    grid: dict[str, list] = field(default_factory=dict)  #: name -> values
    random: dict[str, tuple] = field(default_factory=dict)  #: name -> (law, args)
    samples: int = 0
    seed: int = 0
    log_scale: dict[str, bool] = field(default_factory=dict)  #: for the summary figure
    units: dict[str, str] = field(default_factory=dict)  #: of the swept variables (from the FMUs)
    runs: list[RunPlan] = field(default_factory=list)

    @property
    def swept(self) -> list[str]:
        return list(self.grid) + list(self.random)

    @property
    def where(self) -> str:
        return str(self.path) if self.path else "sweep"


def packaged_sweep(name: str) -> Path:
    return Path(str(resources.files("orchestrator") / "sweeps" / f"{name}.toml"))


def parse_param(name: str, where: str) -> Param:
    """``system``, ``fmu.INSTANCE``, ``scale.SIGNAL`` or ``INSTANCE.VAR``."""
    if name == "system":
        return Param(name, "system")
    inst, var = split_reference(name, f"{where}: {name!r}")
    if inst == "fmu":
        return Param(name, "fmu", instance=var)
    if inst == "scale":
        return Param(name, "scale", variable=var)
    return Param(name, "start", inst, var)


def _scalar(value) -> bool:
    return isinstance(value, (bool, int, float, str))


def _finite(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CosimError(f"{where} must be a finite number (got {value!r})")
    return float(value)


def _flatten(table: dict, spec_keys, skip=()) -> dict:
    """``{"ctrl": {"q_TL": spec}}`` (TOML's unquoted dotted key ctrl.q_TL) -> ``{"ctrl.q_TL": spec}``."""
    out = {}
    for key, value in table.items():
        if key in skip:
            continue
        if isinstance(value, dict) and "." not in key and not set(value) & set(spec_keys):
            for sub, v in value.items():
                out[f"{key}.{sub}"] = v
        else:
            out[key] = value
    return out


def _check_keys(table: dict, allowed, where: str) -> None:
    for key in table:
        if key not in allowed:
            raise CosimError(f"{where}: unknown key {key!r}{close_matches(key, allowed)}; "
                             f"allowed: {', '.join(allowed)}")


def _round12(x: float) -> float:
    """12 significant digits: 10 ** -5 from a log range is 1e-05, not 9.999999999999999e-06."""
    return float(f"{x:.12g}")


def _grid_values(param: Param, spec, where: str) -> tuple[list, bool]:
    """The values of one grid parameter and whether its natural axis is logarithmic."""
    if isinstance(spec, list):
        values = spec
    elif isinstance(spec, dict):
        _check_keys(spec, GRID_KEYS, where)
        if "values" in spec:
            if len(spec) > 1:
                raise CosimError(f"{where}: give either 'values' or 'from', 'to', 'num' (and 'scale')")
            values = spec["values"]
            if not isinstance(values, list):
                raise CosimError(f"{where}.values must be a list")
        else:
            missing = [k for k in ("from", "to", "num") if k not in spec]
            if missing:
                raise CosimError(f"{where}: a range needs from, to and num (missing {', '.join(missing)})")
            if param.kind not in ("start", "scale"):
                raise CosimError(f"{where}: {param.name} takes a list of values, not a range")
            lo, hi = _finite(spec["from"], f"{where}.from"), _finite(spec["to"], f"{where}.to")
            num = spec["num"]
            if isinstance(num, bool) or not isinstance(num, int) or num < 1:
                raise CosimError(f"{where}.num must be a whole number >= 1 (got {num!r})")
            scale = spec.get("scale", "linear")
            if scale not in SCALES:
                raise CosimError(f"{where}.scale must be one of {', '.join(SCALES)} (got {scale!r})")
            if num > 1 and lo == hi:
                raise CosimError(f"{where}: from = to = {lo:g} gives {num} equal runs; use num = 1 or a range")
            if scale == "log" and not (lo > 0 and hi > 0):
                raise CosimError(f"{where}: a log range needs from > 0 and to > 0 (got {lo:g}, {hi:g})")
            if num == 1:
                return [lo], scale == "log"
            if scale == "log":
                a, b = math.log10(lo), math.log10(hi)
                inner = [_round12(10 ** (a + (b - a) * k / (num - 1))) for k in range(1, num - 1)]
            else:
                inner = [_round12(lo + (hi - lo) * k / (num - 1)) for k in range(1, num - 1)]
            return [lo, *inner, hi], scale == "log"
    else:
        raise CosimError(f"{where}: expected a list of values or a range table "
                         f"{{ from = A, to = B, num = N, scale = \"linear\"|\"log\" }}")
    if not values:
        raise CosimError(f"{where}: the list of values is empty")
    for v in values:
        _check_value(param, v, where)
    return list(values), False


def _check_value(param: Param, value, where: str) -> None:
    if param.kind in ("system", "fmu"):
        if not isinstance(value, str) or not value.strip():
            raise CosimError(f"{where}: {param.name} values must be non-empty strings (got {value!r})")
    elif param.kind == "scale":
        _finite(value, f"{where}: {param.name} (a factor on the signal's values)")
    elif not _scalar(value):
        raise CosimError(f"{where}: values must be numbers, booleans or strings (got {value!r})")
    elif isinstance(value, float) and not math.isfinite(value):
        raise CosimError(f"{where}: {value!r} is not a finite value")


def _random_law(param: Param, spec, where: str) -> tuple[str, tuple]:
    if not isinstance(spec, dict):
        raise CosimError(f"{where}: expected {{ uniform = [A, B] }}, {{ log_uniform = [A, B] }} "
                         f"or {{ choice = [...] }}")
    _check_keys(spec, RANDOM_KEYS, where)
    if len(spec) != 1:
        raise CosimError(f"{where}: give exactly one of {', '.join(RANDOM_KEYS)}")
    (law, args), = spec.items()
    if law == "choice":
        if not isinstance(args, list) or not args:
            raise CosimError(f"{where}.choice must be a non-empty list")
        for v in args:
            _check_value(param, v, f"{where}.choice")
        return law, tuple(args)
    if param.kind not in ("start", "scale"):
        raise CosimError(f"{where}: {param.name} takes a choice of values, not a range")
    if not isinstance(args, list) or len(args) != 2:
        raise CosimError(f"{where}.{law} must be [low, high]")
    lo, hi = (_finite(x, f"{where}.{law}") for x in args)
    if not lo < hi:
        raise CosimError(f"{where}.{law}: low must be < high (got [{lo:g}, {hi:g}])")
    if law == "log_uniform" and lo <= 0:
        raise CosimError(f"{where}.log_uniform: low must be > 0 (got {lo:g})")
    return law, (lo, hi)


def _draw(law: str, args: tuple, rng, n: int) -> list:
    if law == "uniform":
        return [float(x) for x in rng.uniform(args[0], args[1], n)]
    if law == "log_uniform":
        return [float(math.exp(x)) for x in rng.uniform(math.log(args[0]), math.log(args[1]), n)]
    return [args[int(k)] for k in rng.integers(0, len(args), n)]


def _label(value) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, str) and ("/" in value or "\\" in value or value.endswith((".fmu", ".toml"))):
        return Path(value).stem
    return str(value)


def run_id(index: int, params: dict, width: int = 4) -> str:
    """``0003_q_TL=1e-05``: the index (unique) and the parameters (as many as fit in
    MAX_ID_LENGTH characters), short and file-name safe."""
    names = list(params)
    short = [n.split(".", 1)[1] if "." in n else n for n in names]
    if len(set(short)) < len(short):
        short = names
    text = f"{index:0{width}d}"
    for s, n in zip(short, names):  # as many whole parameters as fit
        part = re.sub(r"[^A-Za-z0-9._+=-]", "-", f"_{s}={_label(params[n])}")
        if len(text) + len(part) > MAX_ID_LENGTH:
            break
        text += part
    return text


def parse_sweep(data: dict, path: Path | None = None, base_dir: Path | None = None) -> SweepSpec:
    """A :class:`SweepSpec` from the TOML document ``data``, its runs listed."""
    import numpy as np  # noqa: PLC0415

    where = str(path) if path else "sweep"
    base_dir = base_dir or (path.resolve().parent if path else Path.cwd())
    _check_keys(data, TOP_KEYS, where)
    system = data.get("system")
    if not isinstance(system, str) or not system:
        raise CosimError(f"{where}: needs system = \"scenario1\", \"scenario2\" or the path of a system file")
    sweep = SweepSpec(name=str(data.get("name") or (path.stem if path else "sweep")), path=path,
                      base_dir=base_dir, system=system, description=str(data.get("description", "")))
    for key in ("stop_time", "output_interval"):
        if key in data:
            value = _finite(data[key], f"{where}: {key}")
            if value <= 0:
                raise CosimError(f"{where}: {key} must be > 0 (got {value:g})")
            setattr(sweep, key, value)
    metric = data.get("metric", DEFAULT_METRIC)
    metrics = [metric] if isinstance(metric, str) else metric
    if not isinstance(metrics, list) or not metrics or not all(isinstance(m, str) for m in metrics):
        raise CosimError(f"{where}: metric must be a name or a list of names")
    known = SUMMARY_METRICS + BOOKKEEPING
    for m in metrics:
        if m not in known:
            raise CosimError(f"{where}: unknown metric {m!r}{close_matches(m, known)}; "
                             f"metrics: {', '.join(known)}")
    sweep.metrics = metrics
    figures = data.get("figures", False)
    if not isinstance(figures, bool):
        raise CosimError(f"{where}: figures must be true or false")
    sweep.figures = figures

    fixed = data.get("set", {})
    if not isinstance(fixed, dict):
        raise CosimError(f"{where}: [set] must be a table of INSTANCE.VAR = value")
    for name, value in _flatten(fixed, ()).items():
        param = parse_param(name, f"{where}: set")
        if param.kind == "system":
            raise CosimError(f"{where}: set: the base system is the top-level key 'system'")
        _check_value(param, value, f"{where}: set.{name}")
        sweep.fixed[name] = value

    grid = data.get("grid", {})
    if not isinstance(grid, dict):
        raise CosimError(f"{where}: [grid] must be a table of parameter = values")
    for name, spec in _flatten(grid, GRID_KEYS).items():
        param = parse_param(name, f"{where}: grid")
        sweep.grid[name], sweep.log_scale[name] = _grid_values(param, spec, f"{where}: grid.{name}")

    rnd = data.get("random")
    if rnd is not None:
        if not isinstance(rnd, dict):
            raise CosimError(f"{where}: [random] must be a table")
        samples = rnd.get("samples")
        if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
            raise CosimError(f"{where}: random.samples must be a whole number >= 1 (got {samples!r})")
        seed = rnd.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise CosimError(f"{where}: random.seed must be a whole number >= 0 (got {seed!r})")
        sweep.samples, sweep.seed = samples, seed
        for name, spec in _flatten(rnd, RANDOM_KEYS, skip=RANDOM_SETTINGS).items():
            param = parse_param(name, f"{where}: random")
            if name in sweep.grid:
                raise CosimError(f"{where}: {name} is both in [grid] and in [random]")
            sweep.random[name] = _random_law(param, spec, f"{where}: random.{name}")
            sweep.log_scale[name] = sweep.random[name][0] == "log_uniform"
        if not sweep.random:
            raise CosimError(f"{where}: [random] has samples but no parameter "
                             f"(e.g. \"ctrl.q_TL\" = {{ log_uniform = [1e-6, 1e-1] }})")
    for name in sweep.swept:
        if name in sweep.fixed:
            raise CosimError(f"{where}: {name} is both fixed in [set] and swept")
    if not sweep.swept:
        raise CosimError(f"{where}: nothing to sweep: give a [grid] and/or [random] parameter")

    # the runs: every grid point crossed with every random sample (the same samples at
    # every grid point), grid parameters in file order, the last one varying fastest
    grid_points = list(itertools.product(*sweep.grid.values())) if sweep.grid else [()]
    draws: list[dict] = [{}]
    if sweep.random:
        rng = np.random.default_rng(sweep.seed)
        columns = {name: _draw(law, args, rng, sweep.samples) for name, (law, args) in sweep.random.items()}
        draws = [{name: columns[name][k] for name in columns} for k in range(sweep.samples)]
    n = len(grid_points) * len(draws)
    width = max(4, len(str(n - 1)))
    for point in grid_points:
        for draw in draws:
            params = dict(zip(sweep.grid, point)) | draw
            i = len(sweep.runs)
            sweep.runs.append(RunPlan(i, run_id(i, params, width), params))
    return sweep


def load_sweep(path) -> SweepSpec:
    """Read and check a sweep file (or the name of a shipped sweep)."""
    path = Path(path)
    if path.suffix == "" and not path.exists():
        if str(path) in PACKAGED_SWEEPS:
            path = packaged_sweep(str(path))
        else:
            raise CosimError(f"no sweep file {str(path)!r}{close_matches(str(path), PACKAGED_SWEEPS)}; "
                             f"shipped sweeps: {', '.join(PACKAGED_SWEEPS)}")
    data = read_toml(path, "sweep file")
    return parse_sweep(data, path)


# --- the runs, prepared on the client -------------------------------------------------

@dataclass
class PreparedRun:
    plan: RunPlan
    spec: SystemSpec
    fmus: dict[str, str]  #: instance -> sha256 of its FMU file
    signature: str  #: sha256 of everything that determines the run's results


def _resolve_system(value: str, base_dir: Path) -> str:
    """A shipped scenario name as it is; a path relative to the sweep file's directory."""
    path = Path(value).expanduser()
    if not path.is_absolute():
        path = base_dir / path
    if value in PACKAGED_SCENARIOS or (path.suffix == "" and not path.exists()):
        return value  # load_system names the shipped scenarios (with close matches)
    return str(path.resolve())


def _resolve_fmu(value: str, base_dir: Path) -> Path:
    """A shipped FMU name (FocEkf5, FocEkf4, ...), ``{fmus}/X.fmu`` or a path (relative to the sweep file)."""
    try:
        from pmsm_ev_fmus.build import FMUS  # noqa: PLC0415
    except ImportError:
        FMUS = {}
    name = value.strip()
    if name in FMUS or name.removesuffix(".fmu") in FMUS:
        return project_fmu_dir() / f"{name.removesuffix('.fmu')}.fmu"
    if not name.endswith(".fmu") and "/" not in name and "\\" not in name:
        raise CosimError(f"unknown FMU {name!r}{close_matches(name, FMUS)}; give a shipped FMU "
                         f"({', '.join(FMUS)}) or the path of an .fmu file")
    return resolve_fmu_path(name, base_dir)


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


def _apply(spec: SystemSpec, param: Param, value, base_dir: Path) -> None:
    if param.kind == "scale":  # every value of the signal's table times the factor
        sig = spec.signals.get(param.variable)
        if sig is None:
            raise CosimError(f"the system has no signal {param.variable!r}{close_matches(param.variable, spec.signals)}"
                             f"; its signals: {', '.join(spec.signals) or 'none'}")
        prof = sig.profile
        sig.profile = replace(prof, values=tuple(float(value) * v for v in prof.values))
        return
    comp = spec.component(param.instance)  # an unknown instance: close matches
    if param.kind == "fmu":
        comp.fmu, comp.fmu_text = _resolve_fmu(value, base_dir), value
    else:
        comp.start[param.variable] = value


def prepare_runs(sweep: SweepSpec, quiet: bool = True) -> list[PreparedRun]:
    """Each run's system, its FMUs built and checked: instances, variables (close matches),
    settable, values of the variable's type; FMU files readable. Nothing is launched."""
    from .cli import ensure_fmus  # noqa: PLC0415
    from .fmu import FmuInstance, convert_start, variable_unit  # noqa: PLC0415
    from .master import Master  # noqa: PLC0415

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
        system = _resolve_system(values.get("system", sweep.system), sweep.base_dir)
        if system not in bases:
            try:
                bases[system] = load_system(system)
            except CosimError as exc:
                ctx = origin("system") if "system" in values else f"{where}: system"
                raise CosimError(f"{ctx}: {exc}") from None
        spec = copy.deepcopy(bases[system])
        if sweep.stop_time is not None:
            spec.stop_time = sweep.stop_time
        if sweep.output_interval is not None:
            spec.output_interval = sweep.output_interval
        params = {name: parse_param(name, where) for name in values if name != "system"}
        for name, param in params.items():
            try:
                _apply(spec, param, values[name], sweep.base_dir)
            except CosimError as exc:
                raise CosimError(f"{origin(name)}: {exc}") from None
        key = (system, tuple((c.name, str(c.fmu)) for c in spec.components))
        if key not in checked:
            if not built or any(not c.fmu.is_file() for c in spec.components):
                try:
                    ensure_fmus(spec, quiet)  # builds (or finds up to date) all the project's FMUs
                except CosimError as exc:
                    raise CosimError(f"{where}: {exc}") from None
                built = built or any(c.fmu.parent == project_fmu_dir() for c in spec.components)
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
    try:
        from distributed import get_worker  # noqa: PLC0415
        return Path(get_worker().local_directory) / "pmsm-cosim"
    except (ImportError, ValueError, AttributeError):  # called outside a Dask worker
        global _SCRATCH
        if _SCRATCH is None:
            _SCRATCH = tempfile.TemporaryDirectory(prefix="pmsm-cosim-sweep-")  # removed at exit
        return Path(_SCRATCH.name)


_SCRATCH: tempfile.TemporaryDirectory | None = None


def _worker_address() -> str | None:
    try:
        from distributed import get_worker  # noqa: PLC0415
        return get_worker().address
    except (ImportError, ValueError, AttributeError):
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
    failed run: a refusal at load or initialization is a failed status with its reason."""
    from .cli import draw_figures  # noqa: PLC0415
    from .master import Master  # noqa: PLC0415
    from pmsm_ev.results import write_metrics  # noqa: PLC0415

    spec: SystemSpec = task["spec"]
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
            metrics = master.run(out, extra_settings={"sweep": task["sweep"]}, catch_sigint=False)
        except (CosimError, ParameterError, ProfileError) as exc:
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
            if task["figures"] and metrics.get("rows", 0) >= 2:
                draw_figures(out, spec.name, quiet=True)
        for p in sorted(out.rglob("*")):
            if p.is_file():
                result["files"][p.relative_to(out).as_posix()] = p.read_bytes()
    finally:
        shutil.rmtree(out, ignore_errors=True)
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


def _row(sweep: SweepSpec, plan: RunPlan, status: str, error: str, metrics: dict | None) -> dict:
    row = {"run": plan.id, "index": plan.index, "status": status, "error": error}
    row.update({name: plan.params[name] for name in sweep.swept})
    figures = summary_metrics(metrics or {})
    row.update(figures)
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
    columns = ["run", "index", "status", "error", *sweep.swept, *SUMMARY_METRICS, *BOOKKEEPING]
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
    try:
        import matplotlib  # noqa: PLC0415
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # noqa: PLC0415
        from matplotlib.transforms import blended_transform_factory  # noqa: PLC0415
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
                unit = SUMMARY_UNITS.get(metric) or ("s" if metric == "wall_time_s" else "")
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
    from distributed import Client  # noqa: PLC0415

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
    import logging  # noqa: PLC0415

    from distributed import LocalCluster  # noqa: PLC0415

    return LocalCluster(n_workers=workers or cpu_count(), threads_per_worker=1, processes=True,
                        dashboard_address=None, scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"},
                        silence_logs=logging.CRITICAL)


def _check_workers(client) -> None:
    """Every worker can import this package (the tasks run the orchestrator there)."""
    from importlib.metadata import version  # noqa: PLC0415

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
        task = {"id": run.plan.id, "spec": run.spec, "fmus": run.fmus, "figures": sweep.figures,
                "sweep": {"name": sweep.name, "run": run.plan.id, "index": run.plan.index,
                          "parameters": run.plan.params, "signature": run.signature}}
        needed = {sha: shipped[sha] for sha in set(run.fmus.values())}
        key = f"pmsm-cosim-run-{run.plan.id}-{run.signature[:8]}-{time.time_ns()}"
        futures[client.submit(execute_run, task, needed, pure=False, key=key)] = run
    return futures


def _collect(futures: dict, finished) -> None:
    """``finished(run, result)`` for each run as it completes; a task that raised (a worker
    that died, a task that could not be sent, ...) is a failed run."""
    from distributed import as_completed  # noqa: PLC0415

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


def run_sweep(sweep: SweepSpec, out, *, scheduler: str | None = None, workers: int | None = None,
              client=None, quiet: bool = False, stream=None) -> SweepOutcome:
    """Run the sweep's runs that are not done yet into ``out``; write summary.csv and summary.png.

    ``client``: an existing distributed Client (then ``scheduler``/``workers`` are unused).
    A failed run is recorded (status and error in summary.csv, its files kept) and the
    sweep goes on; a completed run of the same signature already in ``out`` is skipped.
    """
    from .progress import CountBar  # noqa: PLC0415

    stream = stream if stream is not None else sys.stdout
    out = Path(out)
    prepared = prepare_runs(sweep, quiet)
    out.mkdir(parents=True, exist_ok=True)
    if sweep.path is not None and sweep.path.resolve() != (out / "sweep.toml").resolve():
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
        rows[run.plan.index] = row
        done += 1
        write_summary(sweep, list(rows.values()), out)
        if res["status"] == "completed":
            tail = f", {sweep.metrics[0]} = {row[sweep.metrics[0]]:.6g}"
        else:
            tail = f": {res['error']}" if res["error"] else ""
        if bar:
            bar.close()
        say(f"[{done}/{total}] {run.plan.id}: {res['status']}{tail}")
        if bar:
            bar.update(done, force=True)

    bar = CountBar(total) if todo and CountBar.wanted(quiet) else None
    old_term = None
    if todo and threading.current_thread() is threading.main_thread():  # SIGTERM stops the sweep like Ctrl-C
        old_term = signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        if todo:
            n_workers = workers or min(len(todo), cpu_count())  # no idle processes for a short sweep
            ctx = contextlib.nullcontext(client) if client is not None else dask_client(scheduler, n_workers)
            with ctx as cl:
                futures = _submit(cl, sweep, todo)
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
