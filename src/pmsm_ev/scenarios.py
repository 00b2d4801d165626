"""Road-elevation and speed-reference profiles of section III, and user CSV profiles.

Scenario 1 (Fig. 6): 0 deg for 0-50 s, then up in 5 deg steps every 30 s to 25 deg
(170-200 s), and back down in 5 deg steps to 0 deg (320-350 s).

Scenario 2 (Fig. 7): the text is garbled (it gives 170-200 s twice and ends at 250 s);
read here as 0 deg for 0-50 s, then alternating 22 deg / 0 deg every 30 s up to 350 s,
which keeps the 350 s length of scenario 1 and the 30 s plateaus of both texts.

Speed reference (Fig. 8): 200 rad/s, reached from standstill by a ramp.

A *route* is the pair of profiles that drives a run, ``delta`` [rad] and ``omega_ref``
[rad/s] (``ROUTE_SIGNALS``); a route file is their JSON form (``route_to_json``,
``load_route``), the table the RouteProfile FMU carries in its resources.
"""

from __future__ import annotations

import bisect
import json
import math
from dataclasses import dataclass
from pathlib import Path

from .params import ScenarioParams

INTERPOLATIONS = ("previous", "linear")


class ProfileError(ValueError):
    """A malformed profile (CSV or table)."""


@dataclass(frozen=True)
class Profile:
    """A signal given at breakpoints: piecewise-constant ("previous") or linear.

    Before the first breakpoint the first value holds, after the last the last value.
    The co-simulation engine's ``pmsm_cosim.engine.signals.Table`` (system files) evaluates
    the same way; ``tests/test_scenarios.py`` holds the two equal, bit for bit.
    """

    times: tuple[float, ...]
    values: tuple[float, ...]
    interpolation: str = "previous"
    name: str = "value"
    unit: str = ""

    def __post_init__(self):
        if len(self.times) == 0 or len(self.times) != len(self.values):
            raise ProfileError(f"profile {self.name!r} needs equally many times and values (at least one)")
        if self.interpolation not in INTERPOLATIONS:
            raise ProfileError(f"interpolation must be one of {INTERPOLATIONS} (got {self.interpolation!r})")
        for i, (t, v) in enumerate(zip(self.times, self.values)):
            if not (math.isfinite(t) and math.isfinite(v)):
                raise ProfileError(f"profile {self.name!r}: breakpoint {i} is not finite ({t}, {v})")
            if i and not t > self.times[i - 1]:
                raise ProfileError(f"profile {self.name!r}: time does not increase at breakpoint {i} ({t})")

    def __call__(self, t: float) -> float:
        ts, vs = self.times, self.values
        i = bisect.bisect_right(ts, t) - 1
        if i < 0:
            return vs[0]
        if i >= len(ts) - 1 or self.interpolation == "previous":
            return vs[i]
        t0, t1 = ts[i], ts[i + 1]
        return vs[i] + (vs[i + 1] - vs[i]) * (t - t0) / (t1 - t0)

    def change_times(self) -> list[float]:
        """Times where a piecewise-constant profile jumps."""
        if self.interpolation != "previous":
            return []
        return [t for t, v0, v1 in zip(self.times[1:], self.values[:-1], self.values[1:]) if v1 != v0]

    def scaled(self, factor: float, name: str | None = None, unit: str | None = None) -> "Profile":
        return Profile(self.times, tuple(v * factor for v in self.values), self.interpolation,
                       name or self.name, self.unit if unit is None else unit)


def _steps_deg(pairs) -> Profile:
    times = tuple(float(t) for t, _ in pairs)
    values = tuple(math.radians(d) for _, d in pairs)
    return Profile(times, values, "previous", "delta", "rad")


#: scenario 1 elevation, (start time [s], angle [deg]) of each plateau
SCENARIO1_DEG = ((0, 0), (50, 5), (80, 10), (110, 15), (140, 20), (170, 25),
                 (200, 20), (230, 15), (260, 10), (290, 5), (320, 0))
#: scenario 2 elevation (reading: alternate 22/0 deg every 30 s after 50 s)
SCENARIO2_DEG = ((0, 0), (50, 22), (80, 0), (110, 22), (140, 0), (170, 22),
                 (200, 0), (230, 22), (260, 0), (290, 22), (320, 0))
SCENARIO_STOP_TIME = 350.0


def elevation_profile(scenario: int | str) -> Profile:
    """Road elevation delta [rad] of scenario 1 or 2."""
    key = str(scenario).removeprefix("scenario")
    if key == "1":
        return _steps_deg(SCENARIO1_DEG)
    if key == "2":
        return _steps_deg(SCENARIO2_DEG)
    raise ProfileError(f"unknown scenario {scenario!r}; choose 1 or 2, or give a CSV profile")


#: start-up delay of the sensorless scenario variants [s] [chosen]: omega_ref stays 0 while the
#: sensorless unit aligns the rotor (``StartupParams().align_time`` = 2.3 s), plus 0.2 s of
#: standstill on the aligned vector; then the paper's 10 s ramp to 200 rad/s
SENSORLESS_START_DELAY = 2.5
#: the ``hill-start-if`` route [chosen]: level road to 20 s, then 22 deg (scenario 2's slope);
#: 0 -> 200 rad/s after the alignment, 200 -> 0 over 30-40 s on the slope, standstill for
#: 10 s, 0 -> 200 rad/s over 50-60 s; 20 s more at 200 rad/s
HILL_START_DEG = ((0, 0), (20, 22))
HILL_START_OMEGA_REF = ((0.0, 0.0), (SENSORLESS_START_DELAY, 0.0), (SENSORLESS_START_DELAY + 10.0, 200.0),
                        (30.0, 200.0), (40.0, 0.0), (50.0, 0.0), (60.0, 200.0))
HILL_START_STOP_TIME = 80.0


@dataclass(frozen=True)
class SyncCase:
    """A case of the synchronism test matrix (docs/sensorless.md, "Never lose the car"): a route that
    does not wait for the sensorless unit's start-up, or a load that changes while it creeps or
    stands. Tables: grade (time [s], deg; held, or ``grade_linear``), omega_ref (time [s], rad/s;
    linear); ``t_disturbance``: when the reference starts or the grade changes [s]."""

    name: str
    description: str
    grade_deg: tuple[tuple[float, float], ...]
    omega_ref: tuple[tuple[float, float], ...]
    stop_time: float
    t_disturbance: float = 0.0
    grade_linear: bool = False

    def route(self) -> dict[str, Profile]:
        g = self.grade_deg
        return {"delta": Profile(tuple(float(t) for t, _ in g), tuple(math.radians(d) for _, d in g),
                                 "linear" if self.grade_linear else "previous", "delta", "rad"),
                "omega_ref": Profile(tuple(float(t) for t, _ in self.omega_ref),
                                     tuple(float(w) for _, w in self.omega_ref), "linear", "omega_ref", "rad/s")}


#: the synchronism test matrix [chosen]: references that ramp from t = 0 at 20, 40 and 80 rad/s^2
#: (0.5, 0.9, 1.9 m/s^2 at the car) and a step to 200 rad/s, all during the 2.3 s alignment;
#: creeping at 5, 10 and 20 rad/s (0.4-1.7 km/h) into a 22 deg grade (a step, and a rise over 3 s);
#: a grade that rises in two steps under a standing car; a car parked on 8 and 16 deg that drives off
#: (the grade there during the alignment); reversing to -60 rad/s and forward again
SYNC_MATRIX = (
    SyncCase("ramp20", "0 -> 200 rad/s at 20 rad/s² from t = 0, level", ((0, 0),), ((0, 0), (10, 200)), 14.0),
    SyncCase("ramp40", "0 -> 200 rad/s at 40 rad/s² from t = 0, level", ((0, 0),), ((0, 0), (5, 200)), 10.0),
    SyncCase("ramp80", "0 -> 200 rad/s at 80 rad/s² from t = 0, level", ((0, 0),), ((0, 0), (2.5, 200)), 10.0),
    SyncCase("step200", "a step to 200 rad/s at t = 0, level", ((0, 0),), ((0, 200),), 10.0),
    SyncCase("creep5", "creep at 5 rad/s, 0 -> 22° at 6 s", ((0, 0), (6, 22)), ((0, 0), (1, 5)), 12.0, 6.0),
    SyncCase("creep10", "creep at 10 rad/s, 0 -> 22° at 6 s", ((0, 0), (6, 22)), ((0, 0), (1, 10)), 12.0, 6.0),
    SyncCase("creep20", "creep at 20 rad/s, 0 -> 22° at 6 s", ((0, 0), (6, 22)), ((0, 0), (1, 20)), 12.0, 6.0),
    SyncCase("creep10-rise", "creep at 10 rad/s, 0 -> 22° over 6-9 s", ((0, 0), (6, 0), (9, 22)),
             ((0, 0), (1, 10)), 14.0, 6.0, grade_linear=True),
    SyncCase("stand", "standing (omega_ref = 0), 0 -> 8° at 4 s, 8 -> 20° at 7 s", ((0, 0), (4, 8), (7, 20)),
             ((0, 0),), 12.0, 4.0),
    SyncCase("park8", "parked on 8°: standing 1 s, then 0 -> 100 rad/s over 1-5 s", ((0, 8),),
             ((0, 0), (1, 0), (5, 100)), 10.0),
    SyncCase("park16", "parked on 16°: standing 1 s, then 0 -> 100 rad/s over 1-5 s", ((0, 16),),
             ((0, 0), (1, 0), (5, 100)), 10.0),
    SyncCase("reverse", "0 -> -60 rad/s over 0-3 s, hold, -> 0 at 11 s, -> 60 at 14 s, level", ((0, 0),),
             ((0, 0), (3, -60), (8, -60), (11, 0), (14, 60)), 18.0),
)
#: the initial rotor angles of the matrix [rad]: 8, evenly spread, offset by 0.3 rad from the
#: angles the start-up was designed on (0, +-pi/2, pi)
SYNC_ANGLES = tuple(round(-math.pi + 0.3 + k * math.pi / 4.0, 6) for k in range(8))


def speed_reference(p: ScenarioParams | None = None, delay: float = 0.0) -> Profile:
    """omega_ref [rad/s]: ramp from 0 to ``omega_ref`` in ``startup_time``, then constant;
    with ``delay`` [s] the ramp starts that late (0 until then)."""
    p = p or ScenarioParams()
    if delay > 0:
        return Profile((0.0, delay, delay + p.startup_time), (0.0, 0.0, p.omega_ref), "linear", "omega_ref",
                       "rad/s")
    if p.startup_time > 0:
        return Profile((0.0, p.startup_time), (0.0, p.omega_ref), "linear", "omega_ref", "rad/s")
    return Profile((0.0,), (p.omega_ref,), "previous", "omega_ref", "rad/s")


# -- routes: the profiles of a run, as one JSON file ----------------------------------
#: the signals of a route and their units
ROUTE_SIGNALS: dict[str, str] = {"delta": "rad", "omega_ref": "rad/s"}
ROUTE_FORMAT = "pmsm-ev-cosim route 1"
#: the routes known by name (``scenario_route``)
PACKAGED_ROUTES = ("scenario1", "scenario2")


def hill_start_route() -> dict[str, Profile]:
    """The ``hill-start-if`` route: stop, stand and restart on a 22 deg slope."""
    w = HILL_START_OMEGA_REF
    return {"delta": _steps_deg(HILL_START_DEG),
            "omega_ref": Profile(tuple(t for t, _ in w), tuple(v for _, v in w), "linear", "omega_ref", "rad/s")}


def scenario_route(scenario: int | str, p: ScenarioParams | None = None) -> dict[str, Profile]:
    """The route of scenario 1 or 2: its elevation and the speed reference."""
    return {"delta": elevation_profile(scenario), "omega_ref": speed_reference(p)}


def route_to_json(route: dict[str, Profile], name: str = "route") -> str:
    """A route as JSON; floats are written exactly (``repr``), so ``route_from_json``
    gives back the same profiles bit for bit."""
    check_route(route, name)
    signals = {key: {"unit": ROUTE_SIGNALS[key], "interpolation": route[key].interpolation,
                     "times": list(route[key].times), "values": list(route[key].values)}
               for key in ROUTE_SIGNALS}
    return json.dumps({"format": ROUTE_FORMAT, "name": name, "signals": signals}, indent=1) + "\n"


def check_route(route: dict[str, Profile], where: str = "route") -> None:
    """A route has exactly the signals of ``ROUTE_SIGNALS``, in their units (or unitless)."""
    if set(route) != set(ROUTE_SIGNALS):
        raise ProfileError(f"{where}: a route has the signals {', '.join(ROUTE_SIGNALS)} "
                           f"(got {', '.join(route) or 'none'})")
    for key, unit in ROUTE_SIGNALS.items():
        if route[key].unit not in ("", unit):
            raise ProfileError(f"{where}: signal {key!r} must be in {unit!r} (got {route[key].unit!r})")


def route_from_json(text: str, where: str = "route") -> dict[str, Profile]:
    """The profiles of a route file's text (see ``route_to_json``); errors name ``where``."""
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise ProfileError(f"{where}: not a route file (invalid JSON: {exc})") from None
    if not isinstance(data, dict) or data.get("format") != ROUTE_FORMAT or not isinstance(data.get("signals"), dict):
        raise ProfileError(f"{where}: not a route file (expected \"format\": \"{ROUTE_FORMAT}\" and \"signals\")")
    route = {}
    for key, sig in data["signals"].items():
        if not isinstance(sig, dict):
            raise ProfileError(f"{where}: signal {key!r} must be an object")
        times, values = sig.get("times"), sig.get("values")
        if not isinstance(times, list) or not isinstance(values, list) or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in times + values):
            raise ProfileError(f"{where}: signal {key!r} needs lists of numbers 'times' and 'values'")
        route[key] = Profile(tuple(float(t) for t in times), tuple(float(v) for v in values),
                             sig.get("interpolation", "previous"), key, sig.get("unit", ""))
    check_route(route, where)
    return route


def load_route(path) -> dict[str, Profile]:
    """Read a route file (JSON, see ``route_to_json``)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ProfileError(f"{path}: route file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ProfileError(f"{path}: cannot read route file ({exc})") from None
    return route_from_json(text, str(path))
