"""The checks of a system against its time grid and its FMUs, before anything runs.

:func:`time_grid`: the stop time, the output interval and every component's step are whole
numbers of base steps. :func:`check_wiring`: every connection goes from an output to an
input of the same type (Real of the same unit, Integer, Boolean, String, or Enumeration of
the same items; no conversion between types), every signal drives Real inputs, every
recorded column is a number (convertible when a unit is asked), every start value is
settable. Each problem is a one-line :class:`~pmsm_cosim.engine.errors.CosimError` naming
the system file.
"""

from __future__ import annotations

import math

from .errors import CosimError
from .fmu import FmuInstance, convert_start, variable_unit
from .system import COLUMN_CONVERSIONS, SystemSpec

#: the variable types whose start values the run's settings keep as numbers (an Enumeration keeps the item's name)
NUMBER_TYPES = ("Real", "Integer", "Boolean")


def _a(word: str) -> str:
    """``word`` with its indefinite article."""
    return f"{'an' if word[:1].lower() in 'aeiou' else 'a'} {word}"


def time_grid(s: SystemSpec) -> tuple[int, int]:
    """(number of base steps to the stop time, base steps per recorded row); a one-line
    CosimError when the stop time, the output interval or a component's step is not a whole
    number of base steps (with the nearest values that are)."""
    h = s.step_size
    where = f"{s.path}: " if s.path else ""
    if h is None:  # an SSP package need not declare one
        raise CosimError(f"{where}no communication step size is given (give one with --step)")
    if s.stop_time is None:
        raise CosimError(f"{where}no stop time is given (give one with --stop-time)")
    if s.output_interval is None:
        s.output_interval = h
    n = round(s.stop_time / h)
    if n < 1:
        raise CosimError(f"{where}stop time {s.stop_time:g} s is shorter than one {h:g} s step")
    if abs(n * h - s.stop_time) > 1e-9 * max(1.0, s.stop_time):
        below, above = math.floor(s.stop_time / h), math.ceil(s.stop_time / h)
        hint = " or ".join(f"{k * h:.12g}" for k in sorted({below, above}) if k >= 1)
        raise CosimError(f"{where}stop time {s.stop_time:g} s is not a whole number of {h:g} s steps "
                         f"(the nearest that are: {hint} s)")
    every = round(s.output_interval / h)
    if every < 1 or abs(every * h - s.output_interval) > 1e-9 * max(1.0, s.output_interval):
        below, above = max(1, math.floor(s.output_interval / h)), max(1, math.ceil(s.output_interval / h))
        hint = " or ".join(f"{k * h:.12g}" for k in sorted({below, above}))
        raise CosimError(f"{where}output interval {s.output_interval:g} s is not a multiple of the {h:g} s "
                         f"step (the nearest that are: {hint} s)")
    for c in s.components:
        if n % c.step_multiple:
            raise CosimError(f"{where}stop time {s.stop_time} s is not a multiple of {c.name}'s step "
                             f"({c.step_multiple} x {h} s)")
    return n, every

def enumeration_items(sv) -> tuple:
    """((name, value), ...) of an Enumeration variable's declared type (() if none is declared)."""
    dt = getattr(sv, "declaredType", None)
    return tuple((item.name, int(item.value)) for item in getattr(dt, "items", None) or ())


def connection_types_problem(src, dst) -> str:
    """Why an output of ``src``'s type cannot feed an input of ``dst``'s ("" if it can)."""
    if src.type != dst.type:
        return "a connection joins variables of the same type (no conversion)"
    if src.type == "Enumeration":
        a, b = enumeration_items(src), enumeration_items(dst)
        if a and b and a != b:
            def items(sv, pairs):
                return f"{getattr(sv.declaredType, 'name', '?')}: {', '.join(f'{k}={v}' for k, v in pairs)}"
            return f"their enumeration types have different items ({items(src, a)}; {items(dst, b)})"
    return ""


def check_wiring(s: SystemSpec, instances: dict[str, FmuInstance]) -> None:
    """Connections, signals, recorded columns and start values against the FMUs' variables:
    names (with close matches), causality, type, units. A start value of a number type is converted to
    that type in ``s`` (``convert_start``: the value the FMU gets, also in the run's settings)."""
    where = f"{s.path}: " if s.path else ""
    for conn in s.connections:
        ctx = f"{where}connection {conn}"
        src = instances[conn.src].variable(conn.src_var, ctx)
        dst = instances[conn.dst].variable(conn.dst_var, ctx)
        if src.causality != "output":
            raise CosimError(f"{ctx}: {conn.src}.{conn.src_var} is {_a(src.causality)}, not an output "
                             f"(a connection goes from an output to an input)")
        if dst.causality != "input":
            raise CosimError(f"{ctx}: {conn.dst}.{conn.dst_var} is {_a(dst.causality)}, not an input "
                             f"(a connection goes from an output to an input)")
        problem = connection_types_problem(src, dst)
        if not problem and src.type not in (*NUMBER_TYPES, "Enumeration", "String"):
            problem = "the master connects Real (FMI 3.0: Float64), Integer (Int32), Enumeration, Boolean and String"
        if not problem and src.type == "Boolean" and instances[conn.src].fmi != instances[conn.dst].fmi:
            problem = "a Boolean connection joins units of the same FMI version (FMI 3.0's is a C bool, 2.0's an int)"
        if problem:
            raise CosimError(f"{ctx}: {conn.src}.{conn.src_var} is {_a(src.type)}, {conn.dst}.{conn.dst_var} is "
                             f"{_a(dst.type)}: {problem}")
        u_src, u_dst = variable_unit(src), variable_unit(dst)
        if u_src and u_dst and u_src != u_dst:
            raise CosimError(f"{ctx}: units differ ({u_src!r} -> {u_dst!r})")
    for sig in s.signals.values():
        for inst, var in sig.drives:
            ctx = f"{where}signal {sig.name}"
            sv = instances[inst].variable(var, ctx)
            if sv.causality != "input" or sv.type != "Real":
                raise CosimError(f"{ctx}: {inst}.{var} is {_a(sv.type)} {sv.causality}; "
                                 f"a signal drives Real inputs")
            u = variable_unit(sv)
            if u and sig.unit and u != sig.unit:
                raise CosimError(f"{ctx}: the signal is in {sig.unit!r} but {inst}.{var} is in {u!r}")
    for col in s.columns:
        if col.kind != "variable":
            continue
        ctx = f"{where}record.{col.name}"
        sv = instances[col.instance].variable(col.variable, ctx)
        if sv.type not in ("Real", "Integer", "Enumeration", "Boolean"):
            raise CosimError(f"{ctx}: {col.instance}.{col.variable} is {_a(sv.type)}; only numbers can be "
                             f"recorded (Real, Integer, Enumeration, Boolean as 0/1): results.csv holds numbers")
        if col.unit:
            need = COLUMN_CONVERSIONS[col.unit][0]
            u = variable_unit(sv)
            if sv.type != "Real" or (u and u != need):
                raise CosimError(f"{ctx}: cannot convert {col.instance}.{col.variable} "
                                 f"({u or sv.type}) to {col.unit!r}")
    for comp in s.components:
        inst = instances[comp.name]
        for var, value in comp.start.items():
            ctx = f"start value {comp.name}.{var}"
            sv = inst.check_settable(var, ctx)
            if sv.type in NUMBER_TYPES:  # the value the FMU gets, in its type: a --set's text becomes a number
                comp.start[var] = convert_start(sv, value, ctx)  # here, in the run's settings (metrics.json) too


def drop_foreign_starts(spec: SystemSpec, instances: dict[str, FmuInstance]) -> list[str]:
    """Take out of each component's start values those written for the FMU it replaced
    (``ComponentSpec.optional_start``) that its FMU has no variable for; a warning for each."""
    out = []
    for comp in spec.components:
        inst = instances[comp.name]
        foreign = [var for var in comp.start if var in comp.optional_start and var not in inst.variables]
        for var in foreign:
            out.append(f"start value {comp.name}.{var} = {comp.start.pop(var)!r} (written for the FMU that "
                       f"{inst.path.name} replaced) not set: {inst.path.name} has no such variable")
    return out


def unconnected_inputs(spec: SystemSpec, instances: dict[str, FmuInstance]) -> list[str]:
    """A warning per input that nothing drives (it keeps its start value). An input clock (FMI 3.0) is no value:
    the master ticks it in event mode, or the unit keeps its own time without (``Master``'s module doc, "Clocks")."""
    driven = {(c.dst, c.dst_var) for c in spec.connections}
    driven |= {d for sig in spec.signals.values() for d in sig.drives}
    out = []
    for name, inst in instances.items():
        for sv in inst.md.modelVariables:
            if sv.causality == "input" and sv.type != "Clock" and (name, sv.name) not in driven \
                    and sv.name not in spec.component(name).start:
                out.append(f"input {name}.{sv.name} is not connected; it keeps its start value "
                           f"({sv.start if sv.start is not None else 'none declared'})")
    return out
