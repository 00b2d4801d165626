"""Scenario signals: a time table (breakpoints, piecewise-constant or linear) and its CSV form.

A system file's ``[signals]`` give each signal as an inline ``table`` of [time, value] pairs
or as a two-column ``csv`` file; the master evaluates the :class:`Table` at the
communication points. Nothing here knows what the signals mean.
"""

from __future__ import annotations

import bisect
import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

#: how a table is read between its breakpoints
INTERPOLATIONS = ("previous", "linear")


class TableError(ValueError):
    """A malformed signal table (inline or CSV)."""


@dataclass(frozen=True)
class Table:
    """A signal given at breakpoints: piecewise-constant ("previous") or linear.

    Before the first breakpoint the first value holds, after the last the last value.
    ``pmsm_ev.scenarios.Profile`` evaluates the same way (the routes the RouteProfile FMU
    carries, which bundles ``pmsm_ev`` only); the engine imports no ``pmsm_ev``, so the two
    stay apart and ``tests/test_scenarios.py`` holds them equal, bit for bit.
    """

    times: tuple[float, ...]
    values: tuple[float, ...]
    interpolation: str = "previous"
    name: str = "value"
    unit: str = ""

    def __post_init__(self):
        if len(self.times) == 0 or len(self.times) != len(self.values):
            raise TableError(f"profile {self.name!r} needs equally many times and values (at least one)")
        if self.interpolation not in INTERPOLATIONS:
            raise TableError(f"interpolation must be one of {INTERPOLATIONS} (got {self.interpolation!r})")
        for i, (t, v) in enumerate(zip(self.times, self.values)):
            if not (math.isfinite(t) and math.isfinite(v)):
                raise TableError(f"profile {self.name!r}: breakpoint {i} is not finite ({t}, {v})")
            if i and not t > self.times[i - 1]:
                raise TableError(f"profile {self.name!r}: time does not increase at breakpoint {i} ({t})")

    def __call__(self, t: float) -> float:
        ts, vs = self.times, self.values
        i = bisect.bisect_right(ts, t) - 1
        if i < 0:
            return vs[0]
        if i >= len(ts) - 1 or self.interpolation == "previous":
            return vs[i]
        t0, t1 = ts[i], ts[i + 1]
        return vs[i] + (vs[i + 1] - vs[i]) * (t - t0) / (t1 - t0)

    def segment(self, i: int) -> tuple[float, float, float, float]:
        """The constants (v0, dv, t0, dt) of the linear segment from breakpoint i to i + 1: for a t in
        it, ``v0 + dv * (t - t0) / dt`` is ``self(t)``, bit for bit (the same operations)."""
        ts, vs = self.times, self.values
        return vs[i], vs[i + 1] - vs[i], ts[i], ts[i + 1] - ts[i]


def _show(text: str, limit: int = 40) -> str:
    """``repr`` of a piece of a file, on one line and cut to ``limit`` characters."""
    text = text.strip()
    return repr(text if len(text) <= limit else text[:limit] + "...")


def _csv_number(text: str, path, lineno: int, column: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise TableError(f"{path}:{lineno}: {column} is not a number: {_show(text)}") from None
    if not math.isfinite(value):
        raise TableError(f"{path}:{lineno}: {column} is not finite: {_show(text)}")
    return value


def load_table_csv(path, interpolation: str = "previous", name: str | None = None,
                     scale: float = 1.0, unit: str = "") -> Table:
    """Read a two-column CSV (header row, then ``time,value`` rows) into a :class:`Table`.

    The header names the two columns (e.g. ``time,delta_deg``); each following row is a
    breakpoint, times strictly increasing, values finite; blank lines are skipped, a UTF-8
    byte-order mark is accepted. ``scale`` multiplies the values (e.g. pi/180 for a file
    in degrees). Every error is a :class:`TableError` naming the file and, where there
    is one, the line (``route.csv:7: time does not increase ...``).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise TableError(f"{path}: profile file not found") from None
    except IsADirectoryError:
        raise TableError(f"{path}: is a directory, not a profile file") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise TableError(f"{path}: cannot read profile ({type(exc).__name__}: {exc})") from None
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    header = None
    times, values = [], []
    try:
        for row in reader:
            lineno = reader.line_num
            if not row or all(not c.strip() for c in row):
                continue
            if header is None:
                header = [h.strip() for h in row]
                if len(header) < 2:
                    raise TableError(f"{path}:{lineno}: the header needs two columns (time, value), "
                                       f"got {_show(','.join(row))}")
                if _is_number(header[0]) and _is_number(header[1]):
                    raise TableError(f"{path}:{lineno}: the first line must be a header naming the columns "
                                       f"(e.g. time,value), got numbers {_show(','.join(row))}")
                continue
            if len(row) < 2:
                raise TableError(f"{path}:{lineno}: missing column: need time,value, got {_show(','.join(row))}")
            t = _csv_number(row[0], path, lineno, "time")
            v = _csv_number(row[1], path, lineno, "value")
            if times and not t > times[-1]:
                raise TableError(f"{path}:{lineno}: time does not increase ({t!r} after {times[-1]!r})")
            times.append(t)
            values.append(v * scale)
    except csv.Error as exc:
        raise TableError(f"{path}:{reader.line_num}: not valid CSV ({exc})") from None
    if header is None:
        raise TableError(f"{path}:1: empty profile file (expected a header row, then time,value rows)")
    if not times:
        raise TableError(f"{path}:{reader.line_num + 1}: no data rows after the header")
    label = name or header[1] or "value"
    try:
        return Table(tuple(times), tuple(values), interpolation, label, unit)
    except TableError as exc:  # e.g. a value that overflows once scaled
        raise TableError(f"{path}: {exc}") from None


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
