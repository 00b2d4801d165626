"""Drive cycles and roads by position in a system (docs/system-file.md, "[cycle]" and "[road]";
docs/cycles.md): the application expands them into what the engine knows, an ordinary signal table
and an ordinary component with its connections. The engine knows FMI and time, never cycles.

* ``[cycle]`` (``name = "wltc3b"`` or ``file = "my.csv"``; ``repeat``, default 1: the cycle that many times back to
  back, ``pmsm_ev.cycles.repeated``; ``drives``, default ``ctrl.omega_ref``;
  ``r_w`` [m] and ``n_g`` [-], default the plant's start values, else ``pmsm_ev.params.VehicleParams``'
  Table II values; ``dt`` [s], default ``pmsm_ev.cycles.REFERENCE_DT``) and ``--cycle NAME|CSV``: the
  signal ``omega_ref`` becomes a linear table of ``pmsm_ev.cycles.speed_reference`` (PCHIP through the
  trace, omega = v n_g / r_w) sampled every ``dt``; the stop time, when the system file gives none
  (``[cycle]``) or the command line gives none (``--cycle``), is the cycle's duration.
* ``[road]`` (``name = "hilly"`` or ``file = "road.csv"``; ``drives``, default ``plant.delta``;
  ``position``, default ``plant.x_vehicle``; ``instance``, default ``road``): a RouteProfile component in
  position mode (``road`` parameter; a file travels in a copy of the FMU, in its resources/) stepped
  after the others, connected ``position -> road.x`` and ``road.delta -> drives``; the time-based
  signal that drove ``drives`` is dropped and a recorded ``signals.delta`` becomes ``road.delta``.

A run from a cycle adds ``trace`` to its metrics.json (:func:`with_trace_figures`: the tolerance band's
figures, ``pmsm_cosim.app.metrics.trace.trace_figures``).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

from pmsm_ev import cycles as pcycles
from pmsm_ev.params import VehicleParams
from pmsm_ev_fmus import build as fmu_build

from ..engine.errors import CosimError, close_matches
from ..engine.recording import read_results
from ..engine.signals import Table
from ..engine.system import ColumnSpec, SignalSpec, SystemSpec, split_reference, user_path
from .metrics.trace import trace_figures

#: the signal a cycle drives, and the input by default
CYCLE_SIGNAL = "omega_ref"
CYCLE_DRIVES = "ctrl.omega_ref"
CYCLE_KEYS = ("name", "file", "repeat", "drives", "r_w", "n_g", "dt", "description")
#: the road component's defaults
ROAD_INSTANCE = "road"
ROAD_DRIVES = "plant.delta"
ROAD_POSITION = "plant.x_vehicle"
ROAD_KEYS = ("name", "file", "drives", "position", "instance", "description")
#: the plant instance whose start values give r_w and n_g
PLANT = "plant"


@dataclass
class CycleSignal(SignalSpec):
    """The signal ``omega_ref`` of a cycle: an ordinary :class:`SignalSpec` for the engine, plus what it
    was made from, so that a later ``--set plant.r_w=...`` resamples it (``resample``)."""

    cycle: pcycles.Cycle | None = None
    r_w: float | None = None  #: stated in [cycle]; None: the plant's
    n_g: float | None = None
    dt: float = pcycles.REFERENCE_DT


def _fail(where: str, message: str):
    raise CosimError(f"{where}: {message}")


def load_cycle(text: str, where: str, base_dir: Path | None = None) -> pcycles.Cycle:
    """A shipped cycle by name or a CSV file (relative to ``base_dir``, else the working directory); an
    unknown name gives the close matches; a bad file is ``CycleError``'s one line."""
    key = str(text).strip()
    path = user_path(key, base_dir, where)
    if key.lower() in pcycles.names() and not path.is_file():
        return pcycles.load(key)
    if not path.exists() and path.suffix == "":
        _fail(where, f"unknown cycle {key!r}{close_matches(key.lower(), pcycles.names())}; shipped cycles: "
                     f"{', '.join(pcycles.names())}, or give a CSV file")
    return pcycles.load(path)


def _positive(value, what: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        _fail(where, f"{what} must be a number (got {value!r})")
    try:
        x = float(value)
    except ValueError:
        _fail(where, f"{what} = {value!r} is not a number")
    if not (math.isfinite(x) and x > 0):
        _fail(where, f"{what} must be a finite number > 0 (got {value!r})")
    return x


def _wheel(spec: SystemSpec, sig: CycleSignal, where: str) -> tuple[float, float]:
    """(r_w, n_g): stated in [cycle], else the plant's start values, else Table II's."""
    plant = next((c for c in spec.components if c.name == PLANT), None)
    starts = plant.start if plant is not None else {}
    defaults = VehicleParams()
    out = []
    for name, stated in (("r_w", sig.r_w), ("n_g", sig.n_g)):
        if stated is not None:
            out.append(stated)
        elif name in starts:
            what = "wheel radius r_w [m]" if name == "r_w" else "gear ratio n_g"
            try:
                out.append(_positive(starts[name], f"{PLANT}.{name}", where))
            except CosimError:
                raise CosimError(f"{where}: {PLANT}.{name} = {starts[name]!r} is not a number > 0 (the {what} the "
                                 f"speed reference of cycle {sig.cycle.name!r} is made with)") from None
        else:
            out.append(getattr(defaults, name))
    return out[0], out[1]


def resample(spec: SystemSpec, where: str = "cycle") -> None:
    """(Re)sample every cycle signal of ``spec`` with the wheel radius and gear ratio it uses now."""
    for sig in spec.signals.values():
        if isinstance(sig, CycleSignal) and sig.cycle is not None:
            r_w, n_g = _wheel(spec, sig, where)
            ref = pcycles.speed_reference(sig.cycle, r_w, n_g, sig.dt)
            sig.profile = Table(tuple(ref.time.tolist()), tuple(ref.omega.tolist()), "linear", sig.name, "rad/s")
            sig.origin = (f"cycle {sig.cycle.name} ({sig.cycle.source}), PCHIP every {sig.dt:g} s, "
                          f"r_w = {r_w:g} m, n_g = {n_g:g}")


def drive_with_cycle(spec: SystemSpec, cycle: pcycles.Cycle, drives: list[tuple[str, str]], where: str,
                     r_w: float | None = None, n_g: float | None = None, dt: float = pcycles.REFERENCE_DT) -> None:
    """``spec`` (changed) with the signal ``omega_ref`` the cycle's speed reference, driving ``drives``: a
    signal of that name is replaced, any other signal or connection driving one of those inputs stops
    driving it."""
    for name, sig in list(spec.signals.items()):
        sig.drives = [d for d in sig.drives if d not in drives]
    # a connection into one of them (an SSP package's route component) gives way too, and a column that
    # recorded its source records the cycle's signal instead
    gone = {(c.src, c.src_var) for c in spec.connections if (c.dst, c.dst_var) in drives}
    spec.connections = [c for c in spec.connections if (c.dst, c.dst_var) not in drives]
    spec.columns = [ColumnSpec(col.name, "signal", variable=CYCLE_SIGNAL, unit=col.unit)
                    if col.kind == "variable" and (col.instance, col.variable) in gone else col
                    for col in spec.columns]
    sig = CycleSignal(CYCLE_SIGNAL, Table((0.0,), (0.0,), "linear", CYCLE_SIGNAL, "rad/s"), "rad/s", list(drives),
                      "rad/s", "cycle", cycle=cycle, r_w=r_w, n_g=n_g, dt=dt)
    spec.signals[CYCLE_SIGNAL] = sig
    resample(spec, where)


# -- the system-file sections -----------------------------------------------------------------------

def _drives(value, default: str, where: str) -> list[tuple[str, str]]:
    value = default if value is None else value
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not value or not all(isinstance(d, str) for d in value):
        _fail(where, "drives must be \"INSTANCE.VAR\" or a list of them")
    return [split_reference(d, f"{where}.drives") for d in value]


def _one_source(table: dict, where: str, what: str) -> tuple[str, str]:
    has_name, has_file = "name" in table, "file" in table
    if has_name == has_file:
        _fail(where, f"give exactly one of 'name' (a shipped {what}) or 'file' (a CSV file)")
    key = "name" if has_name else "file"
    if not isinstance(table[key], str) or not table[key].strip():
        _fail(where, f"{key} must be a non-empty string (got {table[key]!r})")
    return key, table[key]


def _check_keys(table, allowed, where: str) -> None:
    if not isinstance(table, dict):
        _fail(where, "must be a table")
    for key in table:
        if key not in allowed:
            _fail(where, f"unknown key {key!r}{close_matches(key, allowed)}; allowed: {', '.join(allowed)}")


def pop_sections(data: dict, where: str, base_dir: Path, fmu_dir: Path):
    """Take ``[cycle]`` and ``[road]`` out of a system file's TOML table ``data`` (changed): the road is
    added to it as a component with its connections (the time-based signal it replaces dropped); the
    cycle is returned as ``(cycle, drives, r_w, n_g, dt, where)`` for :func:`apply_cycle_section` after
    parsing (None without one), with ``experiment.stop_time`` the cycle's duration if the file gives none."""
    cycle_part = None
    if "cycle" in data:
        cw = f"{where}: [cycle]"
        table = data.pop("cycle")
        _check_keys(table, CYCLE_KEYS, cw)
        key, text = _one_source(table, cw, "cycle")
        cycle = load_cycle(text, f"{cw}.{key}", base_dir if key == "file" else None)
        if "repeat" in table:
            repeat = table["repeat"]
            if isinstance(repeat, bool) or not isinstance(repeat, int) or repeat < 1:
                _fail(cw, f"repeat must be a whole number >= 1 (got {repeat!r})")
            try:
                cycle = pcycles.repeated(cycle, repeat)
            except pcycles.CycleError as exc:
                _fail(cw, str(exc))
        drives = _drives(table.get("drives"), CYCLE_DRIVES, cw)
        r_w = _positive(table["r_w"], "r_w [m]", cw) if "r_w" in table else None
        n_g = _positive(table["n_g"], "n_g", cw) if "n_g" in table else None
        dt = _positive(table["dt"], "dt [s]", cw) if "dt" in table else pcycles.REFERENCE_DT
        exp = data.get("experiment")
        if isinstance(exp, dict) and "stop_time" not in exp:
            exp["stop_time"] = cycle.duration
        signals = data.setdefault("signals", {})
        if isinstance(signals, dict):  # a placeholder, so that the file's checks see the signal
            for name, sig in signals.items():
                if isinstance(sig, dict) and name != CYCLE_SIGNAL:
                    sig["drives"] = [d for d in _listed(sig.get("drives", [])) if _ref(d) not in drives]
            signals[CYCLE_SIGNAL] = {"unit": "rad/s", "interpolation": "linear", "table": [[0.0, 0.0]],
                                     "drives": [f"{i}.{v}" for i, v in drives]}
        cycle_part = (cycle, drives, r_w, n_g, dt, cw)
    if "road" in data:
        _road_section(data, data.pop("road"), f"{where}: [road]", base_dir, fmu_dir)
    return cycle_part


def _listed(drives):
    return [drives] if isinstance(drives, str) else list(drives) if isinstance(drives, list) else drives


def _ref(text) -> tuple[str, str] | None:
    inst, dot, var = str(text).strip().partition(".")
    return (inst.strip(), var.strip()) if dot else None


def apply_cycle_section(spec: SystemSpec, part) -> None:
    if part is not None:
        cycle, drives, r_w, n_g, dt, where = part
        drive_with_cycle(spec, cycle, drives, where, r_w, n_g, dt)


def _road_section(data: dict, table, rw: str, base_dir: Path, fmu_dir: Path) -> None:
    _check_keys(table, ROAD_KEYS, rw)
    key, text = _one_source(table, rw, "road profile")
    instance = table.get("instance", ROAD_INSTANCE)
    if not isinstance(instance, str) or not instance.isidentifier():
        _fail(rw, f"instance must be an identifier (got {instance!r})")
    drives = _drives(table.get("drives"), ROAD_DRIVES, rw)
    position = table.get("position", ROAD_POSITION)
    if not isinstance(position, str):
        _fail(rw, f"position must be \"INSTANCE.OUTPUT\" (got {position!r})")
    src = split_reference(position, f"{rw}.position")
    if key == "name":
        if text.strip().lower() not in pcycles.SHIPPED_ROADS:
            _fail(f"{rw}.name", f"unknown road profile {text!r}{close_matches(text.lower(), pcycles.SHIPPED_ROADS)}; "
                                f"shipped roads: {', '.join(pcycles.SHIPPED_ROADS)}, or give file = a CSV file")
        pcycles.load_road(text)
        fmu, road = f"{{fmus}}/{fmu_build.ROUTE_FMU}.fmu", text.strip().lower()
    else:
        path = user_path(text, base_dir, f"{rw}.file")
        if not path.is_file():
            _fail(f"{rw}.file", f"{path}: road profile file not found")
        pcycles.load_road(path)  # a bad file: CycleError's line, before anything is built
        fmu, road = str(road_fmu(path, fmu_dir)), path.name
    components = data.get("components")
    if isinstance(components, list):
        if any(isinstance(c, dict) and c.get("name") == instance for c in components):
            _fail(rw, f"instance name {instance!r} is used by a component already; choose another with instance = ...")
        components.append({"name": instance, "fmu": fmu, "start": {"road": road}})
    # the time-based signal(s) that drove the input: dropped there; a recorded signals.delta -> the road's
    signals = data.get("signals", {})
    replaced = []
    if isinstance(signals, dict):
        for name, sig in list(signals.items()):
            if not isinstance(sig, dict):
                continue
            kept = [d for d in _listed(sig.get("drives", [])) if _ref(d) not in drives]
            if len(kept) != len(_listed(sig.get("drives", []))):
                replaced.append(name)
                if kept:
                    sig["drives"] = kept
                else:
                    del signals[name]
    record = data.get("record")
    if isinstance(record, dict):
        for column, source in list(record.items()):
            base = source.get("from") if isinstance(source, dict) else source
            if isinstance(base, str) and base.startswith("signals.") and base[len("signals."):] in replaced \
                    and base[len("signals."):] not in signals:
                new = f"{instance}.delta"
                record[column] = {**source, "from": new} if isinstance(source, dict) else new
    connections = data.setdefault("connections", [])
    if isinstance(connections, list):
        connections.append(f"{src[0]}.{src[1]} -> {instance}.x")
        connections += [f"{instance}.delta -> {i}.{v}" for i, v in drives]


def road_fmu(path: Path, fmu_dir: Path) -> Path:
    """The RouteProfile FMU carrying the road file ``path`` in its resources/: a copy in
    ``fmu_dir/roads/``, named by the content of the RouteProfile build and the file (made once)."""
    try:
        source = fmu_build.build_all(out_dir=fmu_dir, names=[fmu_build.ROUTE_FMU])[fmu_build.ROUTE_FMU]
    except Exception as exc:
        raise CosimError(f"building {fmu_build.ROUTE_FMU}.fmu failed: {type(exc).__name__}: {exc}") from None
    digest = hashlib.sha256(fmu_build.source_hash(fmu_build.ROUTE_FMU).encode() + b"\0" + path.name.encode()
                            + b"\0" + path.read_bytes()).hexdigest()[:16]
    dest = fmu_dir / "roads" / f"{fmu_build.ROUTE_FMU}_{digest}.fmu"
    if not dest.is_file():
        dest.parent.mkdir(parents=True, exist_ok=True)
        fmu_build.write_road_fmu(path, dest, source=source)
    return dest


# -- the figures of merit of a run from a cycle ------------------------------------------------------------

def cycle_of(spec: SystemSpec) -> pcycles.Cycle | None:
    """The cycle that drives ``spec`` (its ``omega_ref`` from ``[cycle]`` or ``--cycle``), None if none."""
    sig = spec.signals.get(CYCLE_SIGNAL)
    return sig.cycle if isinstance(sig, CycleSignal) else None


def with_trace_figures(metrics_of, spec: SystemSpec):
    """``metrics_of`` (the master's, ``drive.drive_metrics``) for a run of ``spec``: as it is without a cycle
    (every other run's metrics.json unchanged); with one, plus ``trace``: ``metrics.trace.trace_figures`` of
    the recorded ``v_vehicle`` against the cycle (the tolerance band's figures; docs/cycles.md)."""
    cycle = cycle_of(spec)
    if cycle is None:
        return metrics_of

    def measured(out_dir, columns, rows: int) -> dict:
        m = metrics_of(out_dir, columns, rows)
        if rows >= 2 and "time" in columns and "v_vehicle" in columns:
            r = read_results(out_dir, columns=("time", "v_vehicle"))
            m["trace"] = {"cycle": cycle.name, **trace_figures(r["time"], r["v_vehicle"], cycle)}
        return m

    return measured
