"""Drive cycles: a speed trace against time, with the figures every cycle is published with.

Definitions (docs/cycles.md, "The cycles as data"):

* distance: the trapezoidal integral of the speed samples over time. At 1 Hz this equals the
  regulations' sum of the per-second speeds (GTR No. 15 and 40 CFR 86 integrate the 1 Hz trace)
  whenever the trace starts and ends at standstill, as all shipped cycles and WLTC phases do
  (sum_k v_k dt - trapezoid = (v_0 + v_N) dt / 2 = 0).
* standstill: a sample with speed below ``STANDSTILL_KMH`` = 0.1 km/h. The shipped traces are
  rounded to 0.1 km/h (WLTC) or 0.1 mph (US cycles), so their smallest speed that is not zero is
  0.16 km/h and the threshold separates exactly the zeros.
* stop: a run of one or more consecutive standstill samples after a sample that moved (the
  standstill before the first move is not a stop; the standstill at the end is). A run of one
  sample counts: the trace reaches zero there and the car must stop (UDDS has two, at 766 s and
  1100 s; ``Cycle.stop_periods``). With this, WLTC class 3b stops 8 times, UDDS 17, HWFET 1 and
  US06 5.
* restart: a stop after which the car moves again (every stop but a final one): 7, 16, 0 and 4.
  This is the count the cycles' published descriptions quote, the stops between drives without
  the end of the test: "four stops" for US06 (the SFTP's description), none for HWFET (Natural
  Resources Canada's description of the highway test).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .table import GRADE_MAX, SI_UNITS, CycleError, data_file, frozen_array, read_table, read_text

#: standstill threshold [km/h] of the stop count (module docstring)
STANDSTILL_KMH = 0.1


@dataclass(frozen=True)
class Phase:
    """A phase of a cycle: its name and time interval [s] (start, end], ends on sample times."""

    name: str
    start: float
    end: float


#: the phases of WLTC class 3b, UN GTR No. 15 Annex 1 paragraph 3.3.2 (and EU 2017/1151 Annex XXI,
#: Sub-Annex 1): Low3 0-589 s, Medium3-2 590-1022 s, High3-2 1023-1477 s, Extra High3 1478-1800 s
#: (the regulation's tables list the seconds of each phase). The car stands still from 589 to 590,
#: 1022 to 1023 and 1477 to 1478 s, so the intervals here meet at 589, 1022 and 1477 s and every
#: metre is in exactly one phase whatever the second between is given to.
WLTC3B_PHASES = (Phase("low", 0.0, 589.0), Phase("medium", 589.0, 1022.0), Phase("high", 1022.0, 1477.0),
                 Phase("extra_high", 1477.0, 1800.0))


@dataclass(frozen=True)
class Shipped:
    """A cycle shipped in ``pmsm_ev/cycles/data`` (data/README.md gives source and licence)."""

    file: str
    title: str
    regulation: str
    phases: tuple[Phase, ...] = ()


#: the cycles shipped with the package, by name (data/README.md)
SHIPPED = {
    "wltc3b": Shipped("wltc_3b.csv", "WLTC class 3b (WLTP, vehicles of > 34 W/kg and v_max >= 120 km/h)",
                      "UN GTR No. 15 Annex 1; EU 2017/1151 Annex XXI Sub-Annex 1", WLTC3B_PHASES),
    "udds": Shipped("udds.csv", "EPA Urban Dynamometer Driving Schedule (UDDS, FTP-72, LA-4)",
                    "40 CFR Part 86 Appendix I (a)"),
    "hwfet": Shipped("hwfet.csv", "EPA Highway Fuel Economy Test driving schedule (HWFET)",
                     "40 CFR Part 600 Appendix I"),
    "us06": Shipped("us06.csv", "EPA US06 driving schedule of the Supplemental FTP (SFTP)",
                    "40 CFR Part 86 Appendix I (g)"),
}
#: FASTSim 2.1.5, where the shipped CSV files come from (unchanged; data/README.md)
DATA_SOURCE = "FASTSim 2.1.5 (NREL, Apache-2.0), fastsim/resources/cycles/"


def _trapezoid(y: np.ndarray, x: np.ndarray) -> float:
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x)))


@dataclass(frozen=True, eq=False)
class Cycle:
    """A drive cycle: the speed trace [m/s] at the times [s] (strictly increasing, from 0), the
    road grade [-] (rise over run) at the same times if the file gives one, where it came from,
    and its phases (WLTC class 3b: ``WLTC3B_PHASES``). The arrays are read-only. Build one with
    ``load`` (a file, or a shipped cycle by name) or directly from arrays (checked the same way,
    the errors then name the sample index)."""

    name: str
    time: np.ndarray
    speed: np.ndarray
    grade: np.ndarray | None = None
    source: str = ""
    phases: tuple[Phase, ...] = field(default=())
    repeats: int = 1  #: the times a cycle of duration / repeats is driven back to back (``repeated``)

    def __post_init__(self):
        time, speed = frozen_array(self.time), frozen_array(self.speed)
        grade = None if self.grade is None else frozen_array(self.grade)
        if time.ndim != 1 or speed.shape != time.shape or (grade is not None and grade.shape != time.shape):
            raise CycleError(f"{self.name}: time, speed (and grade) must be 1-D and of one length "
                             f"(got {time.shape}, {speed.shape}{'' if grade is None else ', ' + str(grade.shape)})")
        if time.size < 2:
            raise CycleError(f"{self.name}: {time.size} samples; at least 2 are needed")
        arrays = {"time": time, "speed": speed, "grade": grade}
        check_trace(time, speed, grade, lambda i, problem: _fail_sample(self.name, i, problem),
                    lambda quantity, i: f"{quantity} {arrays[quantity][i]:g} {SI_UNITS[quantity]}".rstrip())
        for p in self.phases:
            if not (time[0] <= p.start < p.end <= time[-1]):
                raise CycleError(f"{self.name}: phase {p.name!r} ({p.start}-{p.end} s) is not inside the cycle")
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "speed", speed)
        object.__setattr__(self, "grade", grade)

    @property
    def speed_kmh(self) -> np.ndarray:
        """The speed trace [km/h]."""
        return self.speed * 3.6

    @property
    def duration(self) -> float:
        """Length of the cycle [s]: last time minus first (which is 0)."""
        return float(self.time[-1] - self.time[0])

    @property
    def distance(self) -> float:
        """Distance of the trace [m], trapezoidal (module docstring)."""
        return _trapezoid(self.speed, self.time)

    @property
    def cumulative_distance(self) -> np.ndarray:
        """Distance driven at each sample time [m] (trapezoidal, 0 at the start)."""
        steps = 0.5 * (self.speed[1:] + self.speed[:-1]) * np.diff(self.time)
        return np.concatenate(([0.0], np.cumsum(steps)))

    @property
    def top_speed(self) -> float:
        """Highest speed of the trace [m/s]."""
        return float(self.speed.max())

    @property
    def mean_speed(self) -> float:
        """Distance over duration [m/s] (stops included)."""
        return self.distance / self.duration

    @property
    def stop_periods(self) -> tuple[tuple[float, float], ...]:
        """The stops (module docstring): (time of the first, time of the last standstill sample) [s]
        of each; the two are equal for a stop of one sample."""
        still = self.speed * 3.6 < STANDSTILL_KMH
        out, moved, i, n = [], False, 0, still.size
        while i < n:
            if not still[i]:
                moved, i = True, i + 1
                continue
            j = i
            while j < n and still[j]:
                j += 1
            if moved:
                out.append((float(self.time[i]), float(self.time[j - 1])))
            i = j
        return tuple(out)

    @property
    def stops(self) -> int:
        """Number of stops, the final standstill included (module docstring)."""
        return len(self.stop_periods)

    @property
    def restarts(self) -> int:
        """Number of stops after which the car drives on (the stops but a final one)."""
        periods = self.stop_periods
        ends_still = bool(self.speed[-1] * 3.6 < STANDSTILL_KMH)
        return len(periods) - (1 if periods and ends_still else 0)

    def phase(self, name: str) -> Phase:
        """The phase called ``name``; a ``CycleError`` naming the cycle's phases if there is none."""
        for p in self.phases:
            if p.name == name:
                return p
        known = ", ".join(p.name for p in self.phases) or "none"
        raise CycleError(f"{self.name}: no phase {name!r} (phases: {known})")

    def phase_distance(self, name: str) -> float:
        """Distance driven in the phase [m] (trapezoidal over its samples)."""
        p = self.phase(name)
        m = (self.time >= p.start) & (self.time <= p.end)
        return _trapezoid(self.speed[m], self.time[m])

    def phase_distances(self) -> dict[str, float]:
        """{phase name: distance [m]} of all phases, in order."""
        return {p.name: self.phase_distance(p.name) for p in self.phases}


def _fail_sample(name: str, index: int, problem: str):
    raise CycleError(f"{name}: sample {index}: {problem}")


def check_trace(time: np.ndarray, speed: np.ndarray, grade: np.ndarray | None, fail, show) -> None:
    """The rules of a speed trace, in one place: finite values, time from 0 and strictly increasing,
    speed >= 0, |grade| <= ``GRADE_MAX``. ``fail(index, problem)`` raises the error for the first
    sample that breaks one, ``show(quantity, index)`` writes a value as the input gave it (the loader:
    the column's header and the cell's text; arrays: the SI value and unit)."""
    for quantity, values in (("time", time), ("speed", speed), ("grade", grade)):
        if values is None:
            continue
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            fail(int(bad[0]), f"{show(quantity, int(bad[0]))} is not finite; values must be finite")
    if time[0] != 0.0:
        fail(0, f"{show('time', 0)}: a cycle starts at time 0 s")
    back = np.flatnonzero(np.diff(time) <= 0.0)
    if back.size:
        i = int(back[0]) + 1
        what = "repeats" if time[i] == time[i - 1] else "is before"
        fail(i, f"{show('time', i)} {what} the previous {show('time', i - 1)}; time must increase")
    neg = np.flatnonzero(speed < 0.0)
    if neg.size:
        fail(int(neg[0]), f"{show('speed', int(neg[0]))} is negative; a cycle's speed is >= 0")
    if grade is not None:
        steep = np.flatnonzero(np.abs(grade) > GRADE_MAX)
        if steep.size:
            fail(int(steep[0]), f"{show('grade', int(steep[0]))} is steeper than the bound |grade| <= "
                                f"{GRADE_MAX:g} ({GRADE_MAX * 100:g} %)")


def repeated(cycle: Cycle, times: int) -> Cycle:
    """``cycle`` driven ``times`` times back to back (a heat run: US06 repeated, docs/speed-range.md, "A motor that
    warms"): each repetition's samples shifted by the duration, the first sample of each after the first dropped
    (it is the previous one's last time); its phases repeated with the repetition's number. A cycle must end at the
    speed (and grade) it starts with, else ``CycleError`` names both. ``times`` = 1: the cycle itself."""
    if isinstance(times, bool) or not isinstance(times, int) or times < 1:
        raise CycleError(f"{cycle.name}: repeat must be a whole number >= 1 (got {times!r})")
    if times == 1:
        return cycle
    if cycle.speed[-1] != cycle.speed[0] or (cycle.grade is not None and cycle.grade[-1] != cycle.grade[0]):
        raise CycleError(f"{cycle.name}: cannot repeat it: it ends at {cycle.speed[-1]:g} m/s and starts at "
                         f"{cycle.speed[0]:g} m/s (a repeated cycle must join)")
    d = cycle.duration
    time = np.concatenate([cycle.time] + [cycle.time[1:] + k * d for k in range(1, times)])
    speed = np.concatenate([cycle.speed] + [cycle.speed[1:]] * (times - 1))
    grade = None if cycle.grade is None else np.concatenate([cycle.grade] + [cycle.grade[1:]] * (times - 1))
    phases = tuple(Phase(f"{p.name}_{k + 1}", p.start + k * d, p.end + k * d) for k in range(times)
                   for p in cycle.phases)
    return Cycle(f"{cycle.name}x{times}", time, speed, grade, f"{cycle.source}; {times} times back to back", phases,
                 cycle.repeats * times)


def names() -> tuple[str, ...]:
    """The names of the shipped cycles."""
    return tuple(SHIPPED)


def load(name_or_path) -> Cycle:
    """A drive cycle: a shipped one by name (``names()``: wltc3b, udds, hwfet, us06; case does not
    matter) or a CSV file (module ``table``: a time column, ``time_s`` or ``cycSecs``, and a speed
    column with its unit, ``speed_kmh``, ``speed_mps``, ``speed_mph`` or ``cycMps``; a grade column,
    ``grade``, ``grade_pct``, ``grade_deg``, ``grade_rad`` or ``cycGrade``, if given). Bad input
    raises one ``CycleError`` line naming the file, the row and the problem; nothing is written."""
    key = str(name_or_path).strip().lower()
    if key in SHIPPED and not Path(str(name_or_path)).is_file():
        info = SHIPPED[key]
        text = data_file(info.file).read_bytes().decode("utf-8-sig")
        return _from_text(text, key, f"shipped cycle {info.file}", f"{DATA_SOURCE}{info.file}; "
                          f"{info.title}; {info.regulation}", info.phases)
    path = Path(name_or_path)
    if not path.is_file() and path.suffix == "" and not path.exists():
        raise CycleError(f"{name_or_path}: not a shipped cycle ({', '.join(SHIPPED)}) and no such file")
    text = read_text(path, "cycle")
    return _from_text(text, path.stem, str(path), str(path), ())


def _from_text(text: str, name: str, where: str, source: str, phases: tuple[Phase, ...]) -> Cycle:
    table = read_table(text, where, required=("time", "speed"), optional=("grade",))
    time = np.array(table.columns["time"].to_si(table.numbers("time")))
    speed = np.array(table.columns["speed"].to_si(table.numbers("speed")))
    grade = None
    if "grade" in table.columns:
        grade = np.array(table.columns["grade"].to_si(table.numbers("grade")))
    check_trace(time, speed, grade, table.fail, table.show)
    return Cycle(name, time, speed, grade, source, phases)
