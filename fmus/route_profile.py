"""Slave of RouteProfile.fmu: the scenario signals of a run, road elevation ``delta`` [rad]
and speed reference ``omega_ref`` [rad/s], as an FMI 2.0 co-simulation unit, so that a
whole scenario runs in any master. The profiles are ``pmsm_ev.scenarios.Profile`` objects
(the orchestrator's own signal evaluation), read from a route file in ``resources/``.

**Position mode** (parameter ``road`` not empty: a shipped road profile by name, ``hilly``, or a
road file in ``resources/``, ``pmsm_ev.cycles.load_road``): ``delta`` is the road's angle at the
input ``x`` [m], the distance along the road (connected from the plant's ``x_vehicle``), instead
of the route's time table (docs/cycles.md, "Grade by position"). An output after
``fmi2DoStep(t, h)`` is defined at t + h, and x(t + h) is not known then (no direct
feedthrough), so ``delta`` after the step is ``delta_at(x)`` of the input as it was set for the
step, x(t): the value the plant holds over its next step from t + h anyway (with the road stepped
after the plant in a Gauss-Seidel order, the input set for the step is already the plant's x at
t + h; with Jacobi it lags one step, 3.6 mm at 36 m/s and 10 kHz). Before the first step:
``delta_at(x)`` of the input's value at initialisation (its start value, 0 m).
"""

from __future__ import annotations

from pathlib import Path

from pythonfmu import String

from pmsm_ev import __version__
from pmsm_ev.cycles import SHIPPED_ROADS, load_road
from pmsm_ev.scenarios import PACKAGED_ROUTES, load_route, scenario_route
from pmsm_ev_fmus.slave_support import DriveSlave, FmuUsageError

#: the route file in resources/ used by default: scenario 1 as built, the system's route
#: in an SSP package written by ``pmsm-cosim export-ssp``
DEFAULT_ROUTE = "route.json"
#: a communication point within this fraction of the first step h0 of the grid t0 + k h0 is on it
GRID_TOLERANCE = 1e-6

DESCRIPTION = (
    "Scenario signals of a sensorless EV drive (Wicaksono, Harini, Yusivar, 'Sensorless PMSM "
    "Control using Fifth Order EKF in Electric Vehicle Application'): road elevation delta and "
    "speed reference omega_ref from a route table (piecewise-constant or linear between "
    "breakpoints, first value before the first breakpoint, last value after the last). "
    "The outputs after fmi2DoStep(t, h) are the profiles at t + h; before the first step, at "
    "the start time. A communication point t + h within 1e-6 h0 of the grid start + k h0 "
    "(h0: the first step size) is taken as exactly start + k h0, so that a master's time "
    "arithmetic (an accumulated sum, differences of integer nanoseconds) changes no value "
    "and moves no breakpoint by a step. No inputs. Parameter 'profile': "
    "'scenario1', 'scenario2' (the paper's scenarios) or the name of a route file in "
    "resources/ (default route.json: scenario 1, or the route an SSP package was written "
    "with). Position mode: parameter 'road' (default '': off) names a shipped road profile "
    "('hilly') or a road file (CSV, distance against grade or elevation) in resources/; delta "
    "is then the road angle at the input x [m], the distance along the road: after "
    "fmi2DoStep(t, h), the angle at x as set for that step (no direct feedthrough); before "
    "the first step, at x's value at initialisation. "
    "A Python FMU (pythonfmu): it needs a Python 3 interpreter with numpy."
)


class RouteProfile(DriveSlave):
    """FMU slave evaluating a route's profiles at the communication points."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = DESCRIPTION
        self.version = __version__
        at_start = "; before the first step: the profile at the start time"
        self.add_input("x", "m", "position mode: distance along the road (connect the plant's x_vehicle); "
                       "unused when 'road' is empty")
        self.add_output("delta", "rad", "road elevation angle, uphill positive, at the end of the last step"
                        + at_start + "; position mode: at the input x as set for the last step",
                        start=None, start_dependencies=("profile", "road", "x"), display_unit="deg")
        self.add_output("omega_ref", "rad/s", "speed reference at the end of the last step" + at_start,
                        start=None, start_dependencies=("profile",), display_unit="rpm")
        self.add_parameter("profile", DEFAULT_ROUTE, String,
                           description="route: 'scenario1', 'scenario2' or a route file (JSON, "
                                       "pmsm_ev.scenarios.route_to_json) in resources/")
        self.add_parameter("road", "", String,
                           description="position mode: '' (off: delta from the route's time table), a shipped "
                                       f"road profile ({', '.join(SHIPPED_ROADS)}) or a road file (CSV, "
                                       "pmsm_ev.cycles.load_road) in resources/; delta = the road angle at x")
        self._delta = self._omega_ref = None
        self._road = None  # position mode: the RoadProfile
        self._t0 = 0.0  # start time (fmi2SetupExperiment)
        self._t = 0.0  # time of the outputs
        self._h0 = None  # size of the first step: the grid t0 + k h0 of the communication points

    # -- physics hooks ---------------------------------------------------------------
    def build(self) -> None:
        name = self.profile
        if name in PACKAGED_ROUTES:
            route = scenario_route(name)
        else:
            resources = Path(self.resources or ".").resolve()
            path = (resources / name).resolve()
            if not name or resources not in path.parents or not path.is_file():
                raise FmuUsageError(f"profile {name!r}: choose {', '.join(PACKAGED_ROUTES)} or a route file "
                                    f"inside resources/ (no such file there)")
            route = load_route(path)
        self._delta, self._omega_ref = route["delta"], route["omega_ref"]
        self._road = self._load_road(self.road) if self.road else None
        self.mark_built()
        self._t, self._h0 = self._t0, None
        self._evaluate()

    def _load_road(self, name: str):
        key = name.strip().lower()
        if key in SHIPPED_ROADS:
            # from this instance's resources/: the project code bundled there is imported once per process
            # under its content-keyed name, so the package's own data folder may be another (since removed)
            # extraction of an FMU with the same code
            bundled = load_road.__module__.split(".")[0]
            path = Path(self.resources or ".").resolve() / bundled / "cycles" / "data" / SHIPPED_ROADS[key]
            return load_road(path) if path.is_file() else load_road(name)
        resources = Path(self.resources or ".").resolve()
        path = (resources / name).resolve()
        if resources not in path.parents or not path.is_file():
            raise FmuUsageError(f"road {name!r}: choose a shipped road ({', '.join(SHIPPED_ROADS)}) or a road file "
                                f"inside resources/ (no such file there)")
        return load_road(path)

    def physics_state(self):
        return [self._t, self._h0, self.delta]  # delta: position mode's comes from x as set for the last step

    def restore_physics(self, snapshot) -> None:
        if self._delta is None or self.needs_rebuild():
            self.build()
        self._t, self._h0 = float(snapshot[0]), snapshot[1]
        self._evaluate()
        if self._road is not None and len(snapshot) > 2:
            self.delta = float(snapshot[2])

    def forget_physics(self) -> None:
        self._delta = self._omega_ref = self._road = None

    def _evaluate(self) -> None:
        t = self._t
        self.delta = self._delta(t) if self._road is None else self._road.delta_at(self.x)
        self.omega_ref = self._omega_ref(t)

    # -- FMI -------------------------------------------------------------------------
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        super().setup_experiment(start_time, stop_time, tolerance)
        self._t0 = float(start_time)

    def do_step(self, current_time, step_size):
        try:
            if not self._initialized:
                raise FmuUsageError("fmi2DoStep before fmi2ExitInitializationMode")
            h0 = self._h0
            if h0 is None:
                h0 = self._h0 = step_size
            t = current_time + step_size
            k = round((t - self._t0) / h0)
            if abs(t - self._t0 - k * h0) <= GRID_TOLERANCE * h0:
                t = self._t0 + k * h0  # on the grid: exactly t_n = n h, as the master's own signals
            self._t = t
            self.delta = self._delta(t) if self._road is None else self._road.delta_at(self.x)
            self.omega_ref = self._omega_ref(t)
        except Exception as exc:
            self._fail("fmi2DoStep", exc)
            raise
        return True
