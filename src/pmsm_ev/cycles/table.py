"""The CSV format of drive cycles and road profiles, defined once: headers, units, rows.

A file is UTF-8 text (a byte-order mark is accepted, as spreadsheets write it), comma-separated,
with one header row and one row per point. Blank lines and lines starting with ``#`` are skipped
(comments). A header names a quantity and its unit: ``speed_kmh``, ``speed [km/h]`` or
``speed (km/h)`` are the same column; case and spaces do not matter. FASTSim's column names
(``cycSecs``, ``cycMps``, ``cycGrade``) are accepted as they are. Columns of other quantities
(FASTSim's ``cycRoadType``, a note) are ignored; a known quantity with a unit not listed in
``UNITS`` is refused.

Rows are numbered as a spreadsheet shows them: the file's first line is row 1 (the header,
if no comment precedes it), the first data row is row 2. Every error is one line,
``<file>: row <n>: <problem>`` (or ``<file>: <problem>`` for the file as a whole), raised as
``CycleError``. Reading writes nothing.
"""

from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from ..scenarios import ProfileError


class CycleError(ProfileError):
    """A drive cycle or road profile that cannot be used: one line naming the file, the row
    (1-based, the header is row 1) and the problem. A ``ValueError`` (via ``ProfileError``, so the
    CLI's handling of bad profiles, exit 2, applies to it as it is)."""


#: the unit of each quantity: {unit as written in a header: factor to SI, or a function for the
#: grade's angles}. The grade is rise over run (tan of the road angle delta); "" means a fraction.
UNITS: dict[str, dict[str, float | str]] = {
    "time": {"s": 1.0},
    "speed": {"m/s": 1.0, "mps": 1.0, "km/h": 1.0 / 3.6, "kmh": 1.0 / 3.6, "kph": 1.0 / 3.6,
              "mph": 0.44704},  # 1 mile = 1609.344 m exactly (international mile)
    "grade": {"": 1.0, "-": 1.0, "%": 0.01, "pct": 0.01, "percent": 0.01, "rad": "angle_rad",
              "deg": "angle_deg"},
    "distance": {"m": 1.0, "km": 1000.0},
    "elevation": {"m": 1.0},
}
#: FASTSim's cycle columns (fastsim/resources/cycles/*.csv): name -> (quantity, unit)
#: the SI unit each quantity is held in after reading (the grade: a fraction, rise over run)
SI_UNITS = {"time": "s", "speed": "m/s", "grade": "", "distance": "m", "elevation": "m"}
#: the steepest grade accepted [-] (rise over run, tan delta) [chosen]: 0.5 (50 %, 26.6 deg). The
#: steepest public streets are about 35-37 %; the paper's steepest elevation, 25 deg (46.6 %),
#: fits; anything steeper is taken for a unit mistake (degrees written as percent, a grade in %
#: written as a fraction).
GRADE_MAX = 0.5
ALIASES = {"cycsecs": ("time", "s"), "cycmps": ("speed", "m/s"), "cycgrade": ("grade", "")}
_HEADER = re.compile(r"^([a-z]+)(?:\s*_\s*|\s*[\[(]\s*|\s+)?([^\])]*?)\s*[\])]?$")


@dataclass(frozen=True)
class Column:
    """A recognised column: its quantity, the unit as written, where it is and its header text."""

    quantity: str
    unit: str
    index: int
    header: str

    def to_si(self, values: list[float]) -> list[float]:
        """The values in SI (grade: the fraction rise over run)."""
        factor = UNITS[self.quantity][self.unit]
        if factor == "angle_rad":
            return [math.tan(v) for v in values]
        if factor == "angle_deg":
            return [math.tan(math.radians(v)) for v in values]
        return [v * factor for v in values]


@dataclass(frozen=True)
class Table:
    """A read file: its name (for errors), the recognised columns by quantity, the data rows (as
    text) and each data row's row number."""

    where: str
    columns: dict[str, Column]
    rows: list[list[str]]
    row_numbers: list[int]

    def fail(self, index: int | None, problem: str):
        """Raise the one-line error for data row ``index`` (None: the file as a whole)."""
        if index is None:
            raise CycleError(f"{self.where}: {problem}")
        raise CycleError(f"{self.where}: row {self.row_numbers[index]}: {problem}")

    def show(self, quantity: str, index: int) -> str:
        """The cell of ``quantity`` in data row ``index`` as the file wrote it, with its header."""
        col = self.columns[quantity]
        return f"{col.header} {self.rows[index][col.index].strip()}"

    def numbers(self, quantity: str) -> list[float]:
        """The column of ``quantity`` as numbers in its own unit; refuses empty cells, text that
        is not a number, NaN and infinities, naming the row."""
        col = self.columns[quantity]
        out = []
        for i, row in enumerate(self.rows):
            if col.index >= len(row) or not row[col.index].strip():
                self.fail(i, f"{col.header} is empty")
            text = row[col.index].strip()
            try:
                value = float(text)
            except ValueError:
                self.fail(i, f"{col.header} {text!r} is not a number")
            if not math.isfinite(value):
                self.fail(i, f"{col.header} is {text!r}; values must be finite")
            out.append(value)
        return out


def parse_header(text: str) -> tuple[str, str] | None:
    """(quantity, unit) of a header cell, None if it names no quantity of ``UNITS``; the unit is
    returned as written (lower case), checked by ``read_table``."""
    key = text.strip().lower()
    if key in ALIASES:
        return ALIASES[key]
    m = _HEADER.match(key)
    if m is None or m.group(1) not in UNITS:
        return None
    return m.group(1), m.group(2).strip()


def frozen_array(values) -> np.ndarray:
    """A read-only float copy of ``values``."""
    a = np.array(values, dtype=float)
    a.setflags(write=False)
    return a


def data_file(filename: str):
    """A file of the package's data folder (an ``importlib.resources`` traversable: found in a
    wheel, an editable install or a source tree alike)."""
    return resources.files(__package__).joinpath("data", filename)


def read_text(path: Path, kind: str) -> str:
    """The file's text (UTF-8, a byte-order mark dropped); ``kind`` names it in errors."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise CycleError(f"{path}: {kind} file not found") from None
    except OSError as exc:
        raise CycleError(f"{path}: cannot read the {kind} file ({exc.strerror or exc})") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise CycleError(f"{path}: not UTF-8 text (byte {exc.start})") from None


def read_table(text: str, where: str, required: tuple[str, ...], one_of: tuple[str, ...] = (),
               optional: tuple[str, ...] = ()) -> Table:
    """Parse a CSV text: the header row, then the data rows. ``required`` quantities must each have
    a column; exactly one of ``one_of`` must have one (if given); ``optional`` ones may. A quantity
    given twice, a unit not in ``UNITS`` and a quantity with no unit where it needs one (all but the
    grade) are refused. At least two data rows."""
    reader = csv.reader(io.StringIO(text))
    header, header_row, rows, numbers = None, 0, [], []
    for row in reader:
        if not any(cell.strip() for cell in row) or row[0].lstrip().startswith("#"):
            continue
        if header is None:
            header, header_row = row, reader.line_num
        else:
            rows.append(row)
            numbers.append(reader.line_num)
    if header is None:
        raise CycleError(f"{where}: the file is empty (expected a header row such as "
                         f"'{','.join(_example(required, one_of))}')")
    wanted = set(required) | set(one_of) | set(optional)
    columns: dict[str, Column] = {}
    for i, cell in enumerate(header):
        parsed = parse_header(cell)
        if parsed is None or parsed[0] not in wanted:
            continue
        quantity, unit = parsed
        if quantity in columns:
            raise CycleError(f"{where}: row {header_row}: two {quantity} columns "
                             f"({columns[quantity].header!r} and {cell.strip()!r})")
        known = UNITS[quantity]
        if unit not in known:
            if unit == "":
                tokens = list(dict.fromkeys(_unit_token(u) for u in known if u))
                raise CycleError(f"{where}: row {header_row}: column {cell.strip()!r} gives no unit "
                                 f"(write e.g. {' or '.join(f'{quantity}_{t}' for t in tokens[:2])})")
            raise CycleError(f"{where}: row {header_row}: unit {unit!r} of column {cell.strip()!r} is not known "
                             f"for {quantity} (known: {', '.join(u for u in known if u)})")
        columns[quantity] = Column(quantity, unit, i, cell.strip())
    names = ", ".join(repr(c.strip()) for c in header)
    for quantity in required:
        if quantity not in columns:
            raise CycleError(f"{where}: row {header_row}: no {quantity} column (header: {names}; "
                             f"expected e.g. '{','.join(_example(required, one_of))}')")
    if one_of:
        given = [q for q in one_of if q in columns]
        if len(given) != 1:
            what = "no" if not given else "more than one"
            raise CycleError(f"{where}: row {header_row}: {what} column of {' or '.join(one_of)} "
                             f"(header: {names}; give exactly one)")
    if len(rows) < 2:
        raise CycleError(f"{where}: {len(rows)} data row{'s' if len(rows) != 1 else ''} after the header; "
                         f"at least 2 are needed")
    return Table(where, columns, rows, numbers)


def _unit_token(unit: str) -> str:
    return {"m/s": "mps", "km/h": "kmh"}.get(unit, unit)


def _example(required: tuple[str, ...], one_of: tuple[str, ...]) -> list[str]:
    first = {"time": "time_s", "speed": "speed_kmh", "distance": "distance_m", "grade": "grade_pct",
             "elevation": "elevation_m"}
    return [first[q] for q in required + one_of[:1]]
