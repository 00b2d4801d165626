"""Road profiles by position: the grade of the road against the distance driven, so that the car
meets a hill at the same place whatever its speed (docs/cycles.md, "Road profiles").

The distance is along the road, what the car drives (the integral of its speed); a map's
horizontal distance is shorter by cos(delta), 0.5 % at 10 %. The grade is rise over run,
tan(delta) of the road angle delta of eq 2 (``delta_at``).

A profile file gives the distance and one of:

* the grade at points (``grade``, ``grade_pct``, ``grade_deg``, ``grade_rad``): linear between
  the points (a ramp from one grade to the next; a step is two points close together);
* the elevation at points (``elevation_m``): the road is straight between the points, so the grade
  is constant on each segment, with sin(delta) = (rise) / (distance between the points) and a
  step at each point (piecewise-linear elevation, piecewise-constant grade; not smoothed).

Before the first point and after the last, the grade at that end holds (a grade table's end
value, an elevation table's first or last segment).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .table import GRADE_MAX, CycleError, data_file, frozen_array, read_table, read_text

#: the road profiles shipped with the package, by name: file (data/README.md)
SHIPPED_ROADS = {"hilly": "hilly.csv"}
#: how the grade runs between the points: "linear" (a grade table), "segments" (an elevation table)
ROAD_KINDS = ("linear", "segments")


@dataclass(frozen=True, eq=False)
class RoadProfile:
    """A road by position: the points' distances [m] (strictly increasing), the grade [-] there
    ("linear": at each point, linear between) or on each segment ("segments": one per segment,
    from an elevation table, whose elevations [m] are kept), where it came from. Read-only arrays."""

    name: str
    distance: np.ndarray
    grade: np.ndarray
    kind: str = "linear"
    elevation: np.ndarray | None = None
    source: str = ""

    def __post_init__(self):
        if self.kind not in ROAD_KINDS:
            raise CycleError(f"{self.name}: kind must be one of {ROAD_KINDS} (got {self.kind!r})")
        distance, grade = frozen_array(self.distance), frozen_array(self.grade)
        n = distance.size
        want = n if self.kind == "linear" else n - 1
        if distance.ndim != 1 or n < 2 or grade.shape != (want,):
            raise CycleError(f"{self.name}: {n} distances need {want} grades for kind {self.kind!r} "
                             f"(got {grade.shape})")
        bad = np.flatnonzero(~np.isfinite(distance))
        if bad.size:
            raise CycleError(f"{self.name}: point {bad[0]}: distance {distance[bad[0]]} is not finite")
        back = np.flatnonzero(np.diff(distance) <= 0.0)
        if back.size:
            raise CycleError(f"{self.name}: point {back[0] + 1}: distance {distance[back[0] + 1]:g} m does not "
                             f"increase (point {back[0]}: {distance[back[0]]:g} m)")
        steep = np.flatnonzero(~(np.abs(grade) <= GRADE_MAX))
        if steep.size:
            raise CycleError(f"{self.name}: {'point' if self.kind == 'linear' else 'segment'} {steep[0]}: grade "
                             f"{grade[steep[0]]:g} is not within |grade| <= {GRADE_MAX:g}")
        object.__setattr__(self, "distance", distance)
        object.__setattr__(self, "grade", grade)
        if self.elevation is not None:
            object.__setattr__(self, "elevation", frozen_array(self.elevation))

    @property
    def length(self) -> float:
        """From the first point to the last [m]."""
        return float(self.distance[-1] - self.distance[0])

    def grade_at(self, x):
        """The grade [-] (tan delta) at distance ``x`` [m] along the road; ``x`` a number or an
        array (the result has its shape). "segments": a point belongs to the segment it starts."""
        xa = np.asarray(x, dtype=float)
        if self.kind == "linear":
            g = np.interp(xa, self.distance, self.grade)
        else:
            i = np.clip(np.searchsorted(self.distance, xa, side="right") - 1, 0, self.grade.size - 1)
            g = self.grade[i]
        return float(g) if np.ndim(g) == 0 else g

    def delta_at(self, x):
        """The road angle delta [rad] of eq 2 at distance ``x`` [m]: atan(grade_at(x))."""
        d = np.arctan(self.grade_at(x))
        return float(d) if np.ndim(d) == 0 else d


def load_road(name_or_path) -> RoadProfile:
    """A road profile: a shipped one by name (``SHIPPED_ROADS``: hilly) or a CSV file with a
    distance column (``distance_m``, ``distance_km``) and one of a grade column (``grade``,
    ``grade_pct``, ``grade_deg``, ``grade_rad``) or an elevation column (``elevation_m``), in the
    format of module ``table``. Bad input raises one ``CycleError`` line naming the file, the row
    and the problem; nothing is written."""
    key = str(name_or_path).strip().lower()
    if key in SHIPPED_ROADS and not Path(str(name_or_path)).is_file():
        text = data_file(SHIPPED_ROADS[key]).read_bytes().decode("utf-8-sig")
        where = f"shipped road {SHIPPED_ROADS[key]}"
        return _from_text(text, key, where, f"pmsm_ev/cycles/data/{SHIPPED_ROADS[key]}")
    path = Path(name_or_path)
    if not path.exists() and path.suffix == "":
        raise CycleError(f"{name_or_path}: not a shipped road profile ({', '.join(SHIPPED_ROADS)}) and no such file")
    return _from_text(read_text(path, "road profile"), path.stem, str(path), str(path))


def _from_text(text: str, name: str, where: str, source: str) -> RoadProfile:
    table = read_table(text, where, required=("distance",), one_of=("grade", "elevation"))
    distance = table.columns["distance"].to_si(table.numbers("distance"))
    for i in range(1, len(distance)):
        if not distance[i] > distance[i - 1]:
            what = "repeats" if distance[i] == distance[i - 1] else "is before"
            table.fail(i, f"{table.show('distance', i)} {what} the previous {table.show('distance', i - 1)}; "
                          f"distance must increase")
    if "grade" in table.columns:
        grade = table.columns["grade"].to_si(table.numbers("grade"))
        for i, g in enumerate(grade):
            if not abs(g) <= GRADE_MAX:
                table.fail(i, f"{table.show('grade', i)} is a grade of {g * 100:.4g} %, steeper than the bound "
                              f"|grade| <= {GRADE_MAX * 100:g} %")
        return RoadProfile(name, np.array(distance), np.array(grade), "linear", None, source)
    elevation = table.columns["elevation"].to_si(table.numbers("elevation"))
    sin_max = GRADE_MAX / math.sqrt(1.0 + GRADE_MAX**2)
    grade = []
    for i in range(1, len(distance)):
        rise, run = elevation[i] - elevation[i - 1], distance[i] - distance[i - 1]
        s = rise / run
        if not abs(s) <= sin_max:
            slope = f"a grade of {s / math.sqrt(1.0 - s * s) * 100:.4g} %" if abs(s) < 1.0 else "more than vertical"
            table.fail(i, f"{table.show('elevation', i)} rises {rise:+.4g} m from the previous row over {run:.4g} m "
                          f"of road ({slope}), steeper than the bound |grade| <= {GRADE_MAX * 100:g} %")
        grade.append(s / math.sqrt(1.0 - s * s))
    return RoadProfile(name, np.array(distance), np.array(grade), "segments", np.array(elevation), source)
