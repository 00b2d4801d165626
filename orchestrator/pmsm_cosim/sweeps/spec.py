"""Sweep files: parsing, checking and listing the runs (grid and random samples).

A *sweep file* (TOML, ``docs/sweeps.md``) names a base system or scenario, the values
fixed for every run and the swept parameters: a grid (a list of values or a linear/log
range per parameter, crossed) and/or random samples (uniform, log-uniform or a choice,
drawn with a seed; whole numbers drawn uniformly). A parameter is a start value
``INSTANCE.VAR`` (as ``--set``), the FMU of an instance ``fmu.INSTANCE`` (as ``--fmu``), a
factor on a signal table ``scale.SIGNAL``, a constant added to a signal table
``offset.SIGNAL``, or the ``system`` itself. What a sweep's application adds (its scenarios
by name, its FMUs, its figures of merit) comes in :class:`SweepHooks`.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..engine.errors import CosimError, close_matches
from ..engine.loading import load_system
from ..engine.system import SystemSpec, read_toml, split_reference

TOP_KEYS = ("name", "description", "system", "stop_time", "output_interval", "metric", "figures", "set",
            "grid", "random")
GRID_KEYS = ("values", "from", "to", "num", "scale")
SCALES = ("linear", "log")
RANDOM_KEYS = ("uniform", "log_uniform", "choice", "integers")
RANDOM_SETTINGS = ("samples", "seed")
#: numbers in summary.csv besides the figures of merit: the stepping loop's wall time and cost a step (the
#: master's), and the sample's whole cost on its worker (``sample_s``: loading, initialising, stepping, metrics,
#: figures; what a study's throughput is made of)
BOOKKEEPING = ("wall_time_s", "us_per_step", "sample_s")
#: run directories live in OUT/runs/
RUNS_DIR = "runs"
MAX_ID_LENGTH = 80


@dataclass(frozen=True)
class SweepHooks:
    """What an application adds to the sweep engine; every field has a neutral default, with
    which a sweep of any system runs and records bookkeeping only.

    The functions are called on the client (``load_system``, ``prepare``) and on the Dask
    workers (``metrics_of``, ``figures``): give module-level functions, which the workers
    import by name."""

    #: a system by name or path -> its spec (default: a system file or SSP package)
    load_system: Callable[[str], SystemSpec] = load_system
    #: names ``load_system`` resolves itself (not paths relative to the sweep file)
    system_names: tuple[str, ...] = ()
    #: what ``{fmus}`` stands for, and where an FMU given by name (``FocEkf4``) is
    fmu_dir: Path | None = None
    #: FMUs that may be given by name: ``fmu_dir / <name>.fmu``
    fmu_names: tuple[str, ...] = ()
    #: ``prepare(spec, quiet)`` before a system's FMUs are opened (e.g. build them)
    prepare: Callable[[SystemSpec, bool], None] | None = None
    #: the master's ``metrics_of(out_dir, columns, rows)``: a run's figures of merit
    metrics_of: Callable | None = None
    #: ``metrics_for(metrics_of, spec)``: the ``metrics_of`` of a run of ``spec`` (e.g. with figures that
    #: depend on the run's system, as a drive cycle's tolerance band); default ``metrics_of`` itself
    metrics_for: Callable | None = None
    #: ``adjust(spec)`` after a run's swept and fixed values are applied to its system (e.g. a signal
    #: derived from start values made again with the run's values)
    adjust: Callable[[SystemSpec], None] | None = None
    #: ``figures(run_dir, name, quiet)``: draw a run's figures (``figures = true`` in a sweep)
    figures: Callable | None = None
    #: the figures of merit of summary.csv: names, units and ``summary_of(metrics) -> {name: value}``
    summary_metrics: tuple[str, ...] = ()
    summary_units: dict = field(default_factory=dict)
    summary_of: Callable[[dict], dict] | None = None
    #: exception types a run fails with that need no type name in its one-line error
    run_errors: tuple[type, ...] = ()
    #: the metric named first in a sweep without ``metric``
    default_metric: str = "wall_time_s"

# --- the sweep file -------------------------------------------------------------

@dataclass(frozen=True)
class Param:
    """A swept or fixed parameter: ``kind`` "start" (INSTANCE.VAR), "fmu" (fmu.INSTANCE), "scale"
    (scale.SIGNAL: a factor on the values of one of the system's signal tables), "offset"
    (offset.SIGNAL: a constant added to them, in the signal's unit) or "system"."""

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
    metrics: list[str] = field(default_factory=list)
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
    hooks: SweepHooks = field(default_factory=SweepHooks)  #: what the application adds
    redrawn: bool = False  #: drawn again (``load_sweep``'s samples, seed): its file's name, samples, seed replaced

    @property
    def swept(self) -> list[str]:
        return list(self.grid) + list(self.random)

    @property
    def where(self) -> str:
        return str(self.path) if self.path else "sweep"



def parse_param(name: str, where: str) -> Param:
    """``system``, ``fmu.INSTANCE``, ``scale.SIGNAL``, ``offset.SIGNAL`` or ``INSTANCE.VAR``."""
    if name == "system":
        return Param(name, "system")
    inst, var = split_reference(name, f"{where}: {name!r}")
    if inst == "fmu":
        return Param(name, "fmu", instance=var)
    if inst in ("scale", "offset"):
        return Param(name, inst, variable=var)
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
            if param.kind not in ("start", "scale", "offset"):
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
    elif param.kind == "offset":
        _finite(value, f"{where}: {param.name} (a constant added to the signal's values)")
    elif not _scalar(value):
        raise CosimError(f"{where}: values must be numbers, booleans or strings (got {value!r})")
    elif isinstance(value, float) and not math.isfinite(value):
        raise CosimError(f"{where}: {value!r} is not a finite value")


def _random_law(param: Param, spec, where: str) -> tuple[str, tuple]:
    if not isinstance(spec, dict):
        raise CosimError(f"{where}: expected {{ uniform = [A, B] }}, {{ log_uniform = [A, B] }}, "
                         f"{{ integers = [A, B] }} or {{ choice = [...] }}")
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
    if param.kind not in ("start", "scale", "offset"):
        raise CosimError(f"{where}: {param.name} takes a choice of values, not a range")
    if not isinstance(args, list) or len(args) != 2:
        raise CosimError(f"{where}.{law} must be [low, high]")
    if law == "integers":
        if not all(isinstance(x, int) and not isinstance(x, bool) for x in args):
            raise CosimError(f"{where}.integers must be two whole numbers [low, high] (got {args!r})")
        if not args[0] <= args[1]:
            raise CosimError(f"{where}.integers: low must be <= high (got {args!r})")
        return law, (args[0], args[1])
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
    if law == "integers":  # low .. high, both included, each equally likely
        return [int(x) for x in rng.integers(args[0], args[1], n, endpoint=True)]
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


def parse_sweep(data: dict, path: Path | None = None, base_dir: Path | None = None,
                hooks: SweepHooks | None = None) -> SweepSpec:
    """A :class:`SweepSpec` from the TOML document ``data``, its runs listed."""
    hooks = hooks or SweepHooks()
    where = str(path) if path else "sweep"
    base_dir = base_dir or (path.resolve().parent if path else Path.cwd())
    _check_keys(data, TOP_KEYS, where)
    system = data.get("system")
    if not isinstance(system, str) or not system:
        raise CosimError(f"{where}: needs system = \"scenario1\", \"scenario2\" or the path of a system file")
    sweep = SweepSpec(name=sweep_name(data, path), path=path,
                      base_dir=base_dir, system=system, description=str(data.get("description", "")), hooks=hooks)
    for key in ("stop_time", "output_interval"):
        if key in data:
            value = _finite(data[key], f"{where}: {key}")
            if value <= 0:
                raise CosimError(f"{where}: {key} must be > 0 (got {value:g})")
            setattr(sweep, key, value)
    metric = data.get("metric", hooks.default_metric)
    metrics = [metric] if isinstance(metric, str) else metric
    if not isinstance(metrics, list) or not metrics or not all(isinstance(m, str) for m in metrics):
        raise CosimError(f"{where}: metric must be a name or a list of names")
    known = hooks.summary_metrics + BOOKKEEPING
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


def redrawn_text(text: str, sweep: SweepSpec) -> str:
    """A sweep file's text with the name, samples and seed of ``sweep`` (drawn again) in place of its own, so that
    the copy beside the results is the sweep that was run (and runs again as it): the top-level ``name`` line
    and the [random] table's ``samples`` and ``seed`` lines rewritten, or added where the file had none."""
    lines = text.splitlines()
    table = None
    found = {"name": False, "samples": False, "seed": False}
    values = {"name": f'"{sweep.name}"', "samples": str(sweep.samples), "seed": str(sweep.seed)}
    random_at = None
    for k, line in enumerate(lines):
        header = re.match(r"\s*\[+\s*([^\]]+?)\s*\]+", line)
        if header:
            table = header.group(1)
            if table == "random":
                random_at = k
            continue
        key = re.match(r"\s*(name|samples|seed)\s*=", line)
        if key and ((table is None and key.group(1) == "name") or (table == "random" and key.group(1) != "name")):
            lines[k] = f"{key.group(1)} = {values[key.group(1)]}  # drawn again (pmsm-cosim sweep --samples/--seed)"
            found[key.group(1)] = True
    extra = [f"{key} = {values[key]}  # drawn again (pmsm-cosim sweep --samples/--seed)"
             for key in ("samples", "seed") if not found[key]]
    if random_at is not None:
        lines[random_at + 1:random_at + 1] = extra
    if not found["name"]:
        lines.insert(0, f"name = {values['name']}  # drawn again (pmsm-cosim sweep --samples/--seed)")
    return "\n".join(lines) + "\n"


def sweep_name(data: dict, path: Path | None) -> str:
    """A sweep's name: its ``name``, else its file's stem."""
    return str(data.get("name") or (path.stem if path else "sweep"))


def load_sweep(path, hooks: SweepHooks | None = None, *, samples: int | None = None,
               seed: int | None = None) -> SweepSpec:
    """Read and check a sweep file; ``samples``, ``seed``: a Monte-Carlo sweep drawn again (``redraw``)."""
    path = Path(path)
    data = read_toml(path, "sweep file")
    if samples is None and seed is None:
        return parse_sweep(data, path, hooks=hooks)
    sweep = parse_sweep(redraw(data, samples, seed, path), path, hooks=hooks)
    sweep.redrawn = True
    return sweep


def redraw(data: dict, samples: int | None, seed: int | None, path: Path | None = None) -> dict:
    """A Monte-Carlo sweep's document with its draw replaced: ``samples`` samples and/or the seed ``seed`` in
    its [random] table, and a name of its own (``<name>_seed<seed>``, ``_n<samples>``), so that its runs and
    summary go to a folder of their own by default. CosimError (one line) for a sweep without [random]."""
    rnd = data.get("random")
    if not isinstance(rnd, dict):
        raise CosimError(f"{path or 'sweep'}: --samples and --seed draw a Monte-Carlo sweep again, and this sweep "
                         f"has no [random] table")
    rnd = dict(rnd)
    name = sweep_name(data, path)
    if seed is not None:
        rnd["seed"] = seed
        name += f"_seed{seed}"
    if samples is not None:
        rnd["samples"] = samples
        name += f"_n{samples}"
    return {**data, "name": name, "random": rnd}
