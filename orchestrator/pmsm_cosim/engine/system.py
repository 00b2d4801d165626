"""System files: which FMUs, how they are wired, what drives them, what is recorded.

A system file is TOML (read with :mod:`tomllib`, ``tomli`` before Python 3.11); ``docs/system-file.md`` is the
reference of its schema. :func:`load_system` turns one into a :class:`SystemSpec`,
checking everything that can be checked without opening an FMU (the FMU-side checks,
variable names, causality, types and units, are done by :mod:`pmsm_cosim.engine.master`).
Every problem is a :class:`~pmsm_cosim.engine.errors.CosimError` with a one-line message
that names the file. An ``fmu`` path may start with ``{fmus}``: the FMU directory the
caller gives (``fmu_dir``; the application gives its own).
"""

from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10: the same parser, as the package tomli (a dependency there)
    import tomli as tomllib

from .errors import CosimError, close_matches, one_line
from .signals import INTERPOLATIONS, Table, TableError, load_table_csv

ALGORITHMS = ("gauss-seidel", "jacobi")
#: names that cannot be instance names (they are column sources of their own)
RESERVED_NAMES = ("time", "signals")
#: units a signal table may be written in, with the conversion to the unit it drives
SIGNAL_CONVERSIONS = {"deg": ("rad", math.radians)}
#: units a recorded column may be converted to, from the unit of its source
COLUMN_CONVERSIONS = {"deg": ("rad", math.degrees)}
#: the placeholder for the project's FMU directory in ``fmu`` paths
FMU_DIR_PLACEHOLDER = "{fmus}"


_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


# --- the parsed description ------------------------------------------------------

@dataclass
class ComponentSpec:
    """One FMU instance."""

    name: str
    fmu: Path  #: resolved FMU file
    step_multiple: int = 1  #: stepped every ``step_multiple`` base steps
    start: dict[str, Any] = field(default_factory=dict)  #: start values, by variable name
    fmu_text: str = ""  #: ``fmu`` as written (for messages and metrics)
    #: the names in ``start`` written for the FMU this instance had before another replaced it (``--controller``,
    #: ``--plant``, ``--fmu``): set where the new FMU has the variable, else left out with a warning
    #: (:func:`~pmsm_cosim.engine.checks.drop_foreign_starts`)
    optional_start: frozenset[str] = frozenset()

    def replace_fmu(self, fmu: Path, text: str) -> None:
        """Another FMU for this instance: the start values written for the one it had become optional
        (``optional_start``)."""
        if fmu != self.fmu:
            self.optional_start = frozenset(self.start)
        self.fmu, self.fmu_text = fmu, text


@dataclass(frozen=True)
class Connection:
    """``src.src_var -> dst.dst_var``."""

    src: str
    src_var: str
    dst: str
    dst_var: str

    def __str__(self) -> str:
        return f"{self.src}.{self.src_var} -> {self.dst}.{self.dst_var}"


@dataclass
class SignalSpec:
    """A scenario signal: a time profile (in the unit it drives) and the inputs it drives."""

    name: str
    profile: Table  #: values already converted (e.g. deg -> rad)
    unit: str  #: unit of the profile's values ("" when not declared)
    drives: list[tuple[str, str]]  #: (instance, variable) of each input it sets
    written_unit: str = ""  #: unit of the values as written in the table or CSV
    origin: str = "table"  #: "table" or the CSV path


@dataclass(frozen=True)
class ColumnSpec:
    """One recorded column: ``name <- source`` (time, a signal or an FMU variable)."""

    name: str
    kind: str  #: "time" | "signal" | "variable"
    instance: str = ""  #: for "variable"
    variable: str = ""  #: the variable (for "variable") or the signal name (for "signal")
    unit: str = ""  #: conversion of the recorded value ("deg"), "" for none

    @property
    def source(self) -> str:
        if self.kind == "time":
            return "time"
        base = f"signals.{self.variable}" if self.kind == "signal" else f"{self.instance}.{self.variable}"
        return f"{base} [{self.unit}]" if self.unit else base


@dataclass
class SystemSpec:
    name: str
    components: list[ComponentSpec]
    connections: list[Connection]
    signals: dict[str, SignalSpec]
    columns: list[ColumnSpec]
    step_size: float | None  #: None only from an SSP package that declares none (the CLI's --step)
    stop_time: float | None  #: None only from an SSP package that declares none (--stop-time)
    output_interval: float | None  #: None: the step size
    algorithm: str = "gauss-seidel"
    description: str = ""
    path: Path | None = None  #: the system file (None when built in code)

    # -- look-ups ---------------------------------------------------------------
    def component(self, name: str, context: str = "") -> ComponentSpec:
        for c in self.components:
            if c.name == name:
                return c
        names = [c.name for c in self.components]
        where = f"{context}: " if context else (f"{self.path}: " if self.path else "")
        raise CosimError(f"{where}unknown instance {name!r}{close_matches(name, names)}; "
                         f"instances: {', '.join(names)}")

    # -- overrides (command line) -------------------------------------------------
    def set_start(self, assignment: str) -> None:
        """Apply ``INSTANCE.VAR=VALUE`` (the value stays a string until the FMU's type is known)."""
        target, sep, value = assignment.partition("=")
        if not sep:
            raise CosimError(f"--set {assignment!r}: expected INSTANCE.VAR=VALUE")
        inst, var = split_reference(target.strip(), f"--set {assignment!r}")
        self.component(inst, f"--set {assignment!r}").start[var] = value.strip()

    def set_fmu(self, instance: str, path, context: str = "") -> None:
        """Replace the FMU of an instance (``--fmu INSTANCE=FMU``, ``--plant``, ``--controller``)."""
        comp = self.component(instance, context or f"--fmu {instance}={path}")
        comp.replace_fmu(user_path(str(path), where=f"--fmu {instance}"), str(path))

    def set_signal_csv(self, assignment: str) -> None:
        """Apply ``SIGNAL=CSV``: the signal's values come from a (time, value) CSV file."""
        name, sep, path = assignment.partition("=")
        name = name.strip()
        if not sep or not path.strip():
            raise CosimError(f"--profile {assignment!r}: expected SIGNAL=CSV")
        if name not in self.signals:
            raise CosimError(f"--profile: unknown signal {name!r}{close_matches(name, self.signals)}; "
                             f"signals: {', '.join(self.signals) or '(none)'}")
        sig = self.signals[name]
        sig.profile = _csv_profile(user_path(path.strip(), where=f"--profile {name}"), name, sig.written_unit,
                                   sig.profile.interpolation)
        sig.origin = str(path.strip())

    def settings(self) -> dict:
        """The run's settings, for metrics.json."""
        return {
            "system": self.name,
            "system_file": str(self.path) if self.path else None,
            "algorithm": self.algorithm,
            "step_size": self.step_size,
            "stop_time": self.stop_time,
            "output_interval": self.output_interval,
            "components": [{"name": c.name, "fmu": str(c.fmu), "step_multiple": c.step_multiple,
                            "start": {k: v for k, v in c.start.items()}} for c in self.components],
            "connections": [str(c) for c in self.connections],
            "signals": {s.name: {"drives": [f"{i}.{v}" for i, v in s.drives], "unit": s.unit,
                                 "interpolation": s.profile.interpolation, "origin": s.origin}
                        for s in self.signals.values()},
        }


# --- parsing ---------------------------------------------------------------------

def split_reference(text: str, where: str) -> tuple[str, str]:
    """``"inst.var"`` -> ("inst", "var"); the variable may itself contain dots."""
    inst, dot, var = text.strip().partition(".")
    if not dot or not inst or not var:
        raise CosimError(f"{where}: expected INSTANCE.VARIABLE, got {text!r}")
    return inst.strip(), var.strip()


def _check_keys(table: dict, allowed, where: str) -> None:
    for key in table:
        if key not in allowed:
            raise CosimError(f"{where}: unknown key {key!r}{close_matches(key, allowed)}; "
                             f"allowed: {', '.join(allowed)}")


def _number(value, where: str, positive: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CosimError(f"{where} must be a number (got {value!r})")
    value = float(value)
    if not math.isfinite(value) or (positive and value <= 0):
        raise CosimError(f"{where} must be a finite number > 0 (got {value!r})")
    return value


def user_path(text: str, base_dir: Path | None = None, where: str = "path") -> Path:
    """A path as written by the user: ``~`` expanded, relative to ``base_dir`` (if given),
    resolved; a one-line CosimError for what no file system accepts (NUL, unknown ``~user``)."""
    if "\x00" in text:
        raise CosimError(f"{where}: {text!r} is not a valid path (it contains a NUL character)")
    try:
        path = Path(text).expanduser()
        if base_dir is not None and not path.is_absolute():
            path = base_dir / path
        return path.resolve()
    except (OSError, RuntimeError, ValueError) as exc:
        raise CosimError(f"{where}: {text!r} is not a usable path ({exc})") from None


def resolve_fmu_path(text: str, base_dir: Path, where: str = "fmu", fmu_dir: Path | None = None) -> Path:
    """``{fmus}/X.fmu`` -> ``fmu_dir``/X.fmu; relative paths -> relative to ``base_dir``."""
    if text.startswith(FMU_DIR_PLACEHOLDER):
        if fmu_dir is None:
            raise CosimError(f"{where}: {text!r} starts with {FMU_DIR_PLACEHOLDER} but no FMU directory was given "
                             f"for it")
        rest = text[len(FMU_DIR_PLACEHOLDER):].lstrip("/\\")
        return user_path(str(Path(fmu_dir) / rest), where=where)
    return user_path(text, base_dir, where)


def _csv_profile(path: Path, name: str, written_unit: str, interpolation: str) -> Table:
    try:
        prof = load_table_csv(path, interpolation=interpolation, name=name, unit=written_unit)
    except TableError as exc:
        raise CosimError(f"signal {name!r}: {exc}") from None
    return _convert_profile(prof, written_unit)


def _convert_profile(prof: Table, written_unit: str) -> Table:
    """Values in the unit the signal drives: deg -> rad with math.radians, value by value."""
    if written_unit in SIGNAL_CONVERSIONS:
        si_unit, conv = SIGNAL_CONVERSIONS[written_unit]
        return Table(prof.times, tuple(conv(v) for v in prof.values), prof.interpolation, prof.name, si_unit)
    return prof


def _parse_signal(name: str, table, where: str, base_dir: Path) -> SignalSpec:
    if not isinstance(table, dict):
        raise CosimError(f"{where}: must be a table")
    _check_keys(table, ("unit", "interpolation", "table", "csv", "drives", "description"), where)
    written_unit = table.get("unit", "")
    if not isinstance(written_unit, str):
        raise CosimError(f"{where}.unit must be a string")
    interpolation = table.get("interpolation", "previous")
    if interpolation not in INTERPOLATIONS:
        raise CosimError(f"{where}.interpolation must be one of {', '.join(INTERPOLATIONS)} "
                         f"(got {interpolation!r})")
    drives = table.get("drives", [])
    if isinstance(drives, str):
        drives = [drives]
    if not isinstance(drives, list) or not all(isinstance(d, str) for d in drives):
        raise CosimError(f"{where}.drives must be \"INSTANCE.VAR\" or a list of them")
    drives = [split_reference(d, f"{where}.drives") for d in drives]
    has_table, has_csv = "table" in table, "csv" in table
    if has_table == has_csv:
        raise CosimError(f"{where}: give exactly one of 'table' (inline [[time, value], ...]) or 'csv' (a file)")
    if has_csv:
        if not isinstance(table["csv"], str):
            raise CosimError(f"{where}.csv must be a path string")
        csv_path = user_path(table["csv"], base_dir, f"{where}.csv")
        profile = _csv_profile(csv_path, name, written_unit, interpolation)
        origin = str(csv_path)
    else:
        rows = table["table"]
        if not isinstance(rows, list) or not rows:
            raise CosimError(f"{where}.table must be a non-empty list of [time, value] pairs")
        times, values = [], []
        for i, row in enumerate(rows):
            if (not isinstance(row, list) or len(row) != 2
                    or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in row)):
                raise CosimError(f"{where}.table[{i}] must be a [time, value] pair of numbers (got {row!r})")
            times.append(float(row[0]))
            values.append(float(row[1]))
        try:
            profile = Table(tuple(times), tuple(values), interpolation, name, written_unit)
        except TableError as exc:
            raise CosimError(f"{where}: {exc}") from None
        profile = _convert_profile(profile, written_unit)
        origin = "table"
    return SignalSpec(name, profile, profile.unit, drives, written_unit, origin)


def _parse_column(name: str, value, where: str) -> ColumnSpec:
    unit = ""
    if isinstance(value, dict):
        _check_keys(value, ("from", "unit"), where)
        if "from" not in value:
            raise CosimError(f"{where}: needs 'from'")
        unit = value.get("unit", "")
        value = value["from"]
        if not isinstance(unit, str):
            raise CosimError(f"{where}.unit must be a string (got {unit!r})")
        if unit and unit not in COLUMN_CONVERSIONS:
            raise CosimError(f"{where}.unit: only {', '.join(COLUMN_CONVERSIONS)} can be converted to "
                             f"(got {unit!r})")
    if not isinstance(value, str):
        raise CosimError(f"{where}: source must be \"time\", \"signals.NAME\" or \"INSTANCE.VAR\"")
    if not name.strip() or not (name.isascii() and name.isprintable()) or any(c in name for c in ',"'):
        raise CosimError(f"{where}: a column name must be non-empty printable ASCII without commas or quotes "
                         f"(got {name!r})")
    if value == "time":
        if unit:
            raise CosimError(f"{where}: time cannot be converted")
        return ColumnSpec(name, "time")
    inst, var = split_reference(value, where)
    if inst == "signals":
        return ColumnSpec(name, "signal", variable=var, unit=unit)
    return ColumnSpec(name, "variable", inst, var, unit)


def load_system_file(path, fmu_dir: Path | None = None) -> SystemSpec:
    """Read and check a system file (TOML); ``fmu_dir`` is what ``{fmus}`` stands for."""
    path = Path(path)
    return parse_system(read_toml(path, "system file"), path, fmu_dir=fmu_dir)


def read_toml(path: Path, what: str) -> dict:
    """The table of a TOML file; a one-line CosimError naming ``path`` and ``what`` it is
    (e.g. "system file") if it is missing, unreadable or not valid TOML."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CosimError(f"{path}: {what} not found") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise CosimError(f"{path}: cannot read {what} ({one_line(exc)})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CosimError(f"{path}: not valid TOML ({exc})") from None


def parse_system(data: dict, path: Path | None = None, base_dir: Path | None = None,
                 fmu_dir: Path | None = None) -> SystemSpec:
    """A :class:`SystemSpec` from the TOML document ``data``."""
    where = str(path) if path else "system"
    base_dir = base_dir or (path.resolve().parent if path else Path.cwd())
    _check_keys(data, ("name", "description", "experiment", "components", "connections", "signals",
                       "record"), where)

    exp = data.get("experiment")
    if not isinstance(exp, dict):
        raise CosimError(f"{where}: missing [experiment] table (step_size, stop_time, ...)")
    _check_keys(exp, ("step_size", "stop_time", "output_interval", "algorithm"), f"{where}: [experiment]")
    for key in ("step_size", "stop_time"):
        if key not in exp:
            raise CosimError(f"{where}: [experiment] needs {key}")
    step = _number(exp["step_size"], f"{where}: experiment.step_size")
    stop = _number(exp["stop_time"], f"{where}: experiment.stop_time")
    interval = _number(exp.get("output_interval", step), f"{where}: experiment.output_interval")
    algorithm = exp.get("algorithm", "gauss-seidel")
    if algorithm not in ALGORITHMS:
        raise CosimError(f"{where}: experiment.algorithm must be one of {', '.join(ALGORITHMS)} "
                         f"(got {algorithm!r})")

    comps_raw = data.get("components")
    if not isinstance(comps_raw, list) or not comps_raw:
        raise CosimError(f"{where}: needs at least one [[components]] entry")
    components: list[ComponentSpec] = []
    for i, c in enumerate(comps_raw):
        cw = f"{where}: components[{i}]"
        if not isinstance(c, dict):
            raise CosimError(f"{cw} must be a table")
        _check_keys(c, ("name", "fmu", "step_multiple", "start", "description"), cw)
        name = c.get("name")
        if not isinstance(name, str) or not _NAME.match(name):
            raise CosimError(f"{cw}.name must be an identifier (letters, digits, _), got {name!r}")
        if name in RESERVED_NAMES:
            raise CosimError(f"{cw}.name {name!r} is reserved")
        if any(x.name == name for x in components):
            raise CosimError(f"{cw}: instance name {name!r} used twice")
        fmu = c.get("fmu")
        if not isinstance(fmu, str) or not fmu:
            raise CosimError(f"{cw} ({name}) needs fmu = \"path/to/Model.fmu\"")
        mult = c.get("step_multiple", 1)
        if isinstance(mult, bool) or not isinstance(mult, int) or mult < 1:
            raise CosimError(f"{cw}.step_multiple must be a whole number >= 1 (got {mult!r})")
        start = c.get("start", {})
        if not isinstance(start, dict):
            raise CosimError(f"{cw}.start must be a table of variable = value")
        for var, val in start.items():
            if not isinstance(val, (bool, int, float, str)):
                raise CosimError(f"{cw}.start.{var} must be a number, boolean or string (got {val!r})")
        path_ = resolve_fmu_path(fmu, base_dir, f"{cw}.fmu", fmu_dir)
        components.append(ComponentSpec(name, path_, mult, dict(start), fmu))

    connections: list[Connection] = []
    conns_raw = data.get("connections", [])
    if not isinstance(conns_raw, list):
        raise CosimError(f"{where}: connections must be a list of \"a.x -> b.y\" strings")
    for i, text in enumerate(conns_raw):
        cw = f"{where}: connections[{i}]"
        if not isinstance(text, str) or text.count("->") != 1:
            raise CosimError(f"{cw}: expected \"INSTANCE.OUTPUT -> INSTANCE.INPUT\", got {text!r}")
        left, right = text.split("->")
        src, src_var = split_reference(left, cw)
        dst, dst_var = split_reference(right, cw)
        connections.append(Connection(src, src_var, dst, dst_var))

    signals: dict[str, SignalSpec] = {}
    sigs_raw = data.get("signals", {})
    if not isinstance(sigs_raw, dict):
        raise CosimError(f"{where}: [signals] must be a table of signal tables")
    for name, table in sigs_raw.items():
        if not _NAME.match(name):
            raise CosimError(f"{where}: signal name must be an identifier, got {name!r}")
        signals[name] = _parse_signal(name, table, f"{where}: signals.{name}", base_dir)

    rec_raw = data.get("record")
    if not isinstance(rec_raw, dict) or not rec_raw:
        raise CosimError(f"{where}: needs a [record] table (column = \"source\")")
    # a name that is not printable is quoted where it is named, so that the error stays on one line
    columns = [_parse_column(name, value, f"{where}: record.{name if name.isprintable() else repr(name)}")
               for name, value in rec_raw.items()]

    name = data.get("name") or (path.stem if path else "system")
    if not isinstance(name, str) or not name.isprintable() or any(c in name for c in "/\\") \
            or name.strip() in (".", ".."):
        raise CosimError(f"{where}: name must be a string without slashes, it names the output directory "
                         f"runs/<name> (got {name!r})")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise CosimError(f"{where}: description must be a string")
    spec = SystemSpec(
        name=name, description=description,
        components=components, connections=connections, signals=signals, columns=columns,
        step_size=step, stop_time=stop, output_interval=interval, algorithm=algorithm, path=path,
    )
    check_references(spec)
    return spec


def check_references(spec: SystemSpec) -> None:
    """Instance and signal names used by connections, signals and columns exist; no input
    is driven twice. (Variables are checked against the FMUs by the master.)"""
    names = [c.name for c in spec.components]
    where = f"{spec.path}: " if spec.path else ""

    def known(inst: str, context: str) -> None:
        if inst not in names:
            raise CosimError(f"{where}{context}: unknown instance {inst!r}{close_matches(inst, names)}; "
                             f"instances: {', '.join(names)}")

    drivers: dict[tuple[str, str], str] = {}
    for conn in spec.connections:
        known(conn.src, f"connection {conn}")
        known(conn.dst, f"connection {conn}")
        key = (conn.dst, conn.dst_var)
        if key in drivers:
            raise CosimError(f"{where}input {conn.dst}.{conn.dst_var} is driven twice "
                             f"({drivers[key]} and {conn})")
        drivers[key] = f"connection {conn}"
    for sig in spec.signals.values():
        for inst, var in sig.drives:
            known(inst, f"signal {sig.name}")
            key = (inst, var)
            if key in drivers:
                raise CosimError(f"{where}input {inst}.{var} is driven twice "
                                 f"({drivers[key]} and signal {sig.name})")
            drivers[key] = f"signal {sig.name}"
    seen = set()
    for col in spec.columns:
        if col.name in seen:
            raise CosimError(f"{where}column {col.name!r} recorded twice")
        seen.add(col.name)
        if col.kind == "variable":
            known(col.instance, f"record.{col.name}")
        elif col.kind == "signal" and col.variable not in spec.signals:
            raise CosimError(f"{where}record.{col.name}: unknown signal {col.variable!r}"
                             f"{close_matches(col.variable, spec.signals)}; "
                             f"signals: {', '.join(spec.signals) or '(none)'}")
        if col.unit and col.kind == "signal":
            sig_unit = spec.signals[col.variable].unit
            need = COLUMN_CONVERSIONS[col.unit][0]
            if sig_unit and sig_unit != need:
                raise CosimError(f"{where}record.{col.name}: cannot convert signal {col.variable} "
                                 f"from {sig_unit!r} to {col.unit!r}")
