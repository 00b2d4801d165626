"""RouteProfile.fmu: the scenario signals as an FMU.

Its outputs after a step to t_n are ``pmsm_ev.scenarios.Profile`` evaluated at exactly
t_n = n h, whatever time arithmetic the master uses (n h, an accumulated sum, differences
of integer nanoseconds as libcosim), across breakpoints and ramps; the route comes from
its resources (scenario 1 as built, the paper's scenarios by name, or a route written in
when it is packaged).
"""

from __future__ import annotations

import json
import math
import zipfile

import fmpy
import pytest
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

from orchestrator_support import project_fmus
from pmsm_ev import __version__
from pmsm_ev.scenarios import (
    ROUTE_FORMAT,
    Profile,
    ProfileError,
    load_route,
    route_from_json,
    route_to_json,
    scenario_route,
)
from pmsm_ev_fmus import write_route_fmu

H = 1e-4


@pytest.fixture(scope="module")
def route_fmu():
    return project_fmus()["RouteProfile"]


#: a compressed route: elevation steps every 0.05 s (at times that are not exact in binary),
#: a speed ramp 0.013 -> 0.1 s, then held
COMPRESSED = {
    "delta": Profile((0.0, 0.05, 0.1, 0.15, 0.3), tuple(math.radians(d) for d in (2.0, 22.0, 0.0, -7.5, 5.0)),
                     "previous", "delta", "rad"),
    "omega_ref": Profile((0.013, 0.1), (10.0, 200.0), "linear", "omega_ref", "rad/s"),
}


class Route:
    """A RouteProfile instance on fmpy's FMU2Slave."""

    def __init__(self, fmu, tmp_path, profile=None):
        self.md = fmpy.read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=fmpy.extract(str(fmu), str(tmp_path / "unzipped")),
                             modelIdentifier="RouteProfile", instanceName="route")
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        if profile is not None:
            self.fmu.setString([self.vr["profile"]], [profile])
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def values(self):
        return tuple(self.fmu.getReal([self.vr["delta"], self.vr["omega_ref"]]))

    def free(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def expected(route, t):
    return route["delta"](t), route["omega_ref"](t)


def test_model_description_is_complete(route_fmu):
    assert validate_fmu(str(route_fmu)) == []
    md = fmpy.read_model_description(str(route_fmu), validate=True)
    assert md.author and md.version == __version__ and "route" in md.description
    de = md.defaultExperiment
    assert (float(de.startTime), float(de.stopTime), float(de.stepSize)) == (0.0, 350.0, 1e-4)
    assert md.coSimulation.canHandleVariableCommunicationStepSize
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    by_name = {v.name: v for v in md.modelVariables}
    assert [v.name for v in md.modelVariables if v.causality == "input"] == ["x"]  # position mode only
    assert [v.name for v in md.modelVariables if v.causality == "output"] == ["delta", "omega_ref"]
    assert (by_name["delta"].unit, by_name["omega_ref"].unit) == ("rad", "rad/s")
    assert {u.name for u in md.unitDefinitions} == {"m", "rad", "rad/s"}
    profile = by_name["profile"]
    assert (profile.causality, profile.type, profile.start, profile.initial) == \
        ("parameter", "String", "route.json", "exact")
    # the outputs before the first step are the profile at the start time: calculated from 'profile'
    assert all(by_name[n].initial == "calculated" for n in ("delta", "omega_ref"))
    assert all(u.dependencies == [] for u in md.outputs)
    assert {u.variable.name: [d.name for d in u.dependencies] for u in md.initialUnknowns} == \
        {"delta": ["x", "profile", "road"], "omega_ref": ["profile"]}


def test_the_built_fmu_carries_scenario1_as_its_route(route_fmu):
    with zipfile.ZipFile(route_fmu) as z:
        text = z.read("resources/route.json").decode()
    assert json.loads(text)["format"] == ROUTE_FORMAT
    assert route_from_json(text) == scenario_route(1)


def test_route_json_round_trips_exactly(tmp_path):
    text = route_to_json(COMPRESSED, "compressed")
    assert route_from_json(text) == COMPRESSED  # every float bit for bit
    (tmp_path / "r.json").write_text(text)
    assert load_route(tmp_path / "r.json") == COMPRESSED
    with pytest.raises(ProfileError, match="a route has the signals delta, omega_ref"):
        route_to_json({"delta": COMPRESSED["delta"]})
    with pytest.raises(ProfileError, match="not a route file"):
        route_from_json('{"format": "other"}', "x.json")
    with pytest.raises(ProfileError, match="time does not increase"):
        route_from_json(text.replace("0.05", "0.5"))


@pytest.mark.parametrize("clock", ["n*h", "accumulated", "nanoseconds"])
def test_outputs_equal_the_profile_at_every_grid_point(route_fmu, tmp_path, clock):
    """Steps of 1e-4 s over 0.35 s, three ways of computing the communication points: the
    outputs after the step from t_{n-1} are exactly the profile at n h (the master's value
    of a signal at step n), at breakpoints that are not exact binary numbers too."""
    fmu = write_route_fmu(route_to_json(COMPRESSED), tmp_path / "R.fmu", source=route_fmu)
    r = Route(fmu, tmp_path)
    try:
        assert r.values() == expected(COMPRESSED, 0.0) == (math.radians(2.0), 10.0)  # before the first step
        t, changes = 0.0, 0
        for n in range(1, 3501):
            if clock == "n*h":
                t, h = (n - 1) * H, H
            elif clock == "nanoseconds":  # libcosim: integer ns, steps as differences of doubles
                t, h = (n - 1) * 100_000 / 1e9, n * 100_000 / 1e9 - (n - 1) * 100_000 / 1e9
            else:
                h = H
            r.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            if clock == "accumulated":  # fmpy's SSP loop: t += h
                t += h
            value = r.values()
            assert value == expected(COMPRESSED, n * H), (n, value)
            changes += value[0] != expected(COMPRESSED, (n - 1) * H)[0]
        assert changes == 4  # every elevation step seen, each at its own grid point
    finally:
        r.free()


def test_profile_parameter_selects_a_scenario(route_fmu, tmp_path):
    r = Route(route_fmu, tmp_path, profile="scenario2")
    try:
        scenario2 = scenario_route(2)
        for n in range(1, 101):
            r.fmu.doStep(currentCommunicationPoint=(n - 1) * 0.6, communicationStepSize=0.6)
            assert r.values() == expected(scenario2, n * 0.6)
        assert r.values()[0] == math.radians(22.0)  # 60 s: on the first 22 deg plateau of scenario 2
    finally:
        r.free()


def test_off_grid_steps_use_the_communication_point(route_fmu, tmp_path):
    """A variable step: off the grid of the first step, the value is at t + h as computed."""
    r = Route(route_fmu, tmp_path, profile="scenario1")
    try:
        r.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1.0)
        r.fmu.doStep(currentCommunicationPoint=1.0, communicationStepSize=0.25)
        assert r.values() == (0.0, 200.0 * 1.25 / 10.0)
    finally:
        r.free()


def test_fmu_state_restores_the_time(route_fmu, tmp_path):
    r = Route(route_fmu, tmp_path, profile="scenario1")
    try:
        for n in range(10):
            r.fmu.doStep(currentCommunicationPoint=n * 0.5, communicationStepSize=0.5)
        state = r.fmu.getFMUstate()
        before = r.values()
        r.fmu.doStep(currentCommunicationPoint=5.0, communicationStepSize=0.5)
        assert r.values() != before
        r.fmu.setFMUstate(state)
        assert r.values() == before == (0.0, 100.0)
        r.fmu.doStep(currentCommunicationPoint=5.0, communicationStepSize=0.5)
        assert r.values() == (0.0, 110.0)
        r.fmu.freeFMUstate(state)
    finally:
        r.free()


@pytest.mark.parametrize("profile, message", [
    ("scenario3", "profile 'scenario3': choose scenario1, scenario2 or a route file inside resources/"),
    ("../modelDescription.xml", "inside resources/"),
    ("build_info.json", "not a route file"),
])
def test_a_bad_profile_fails_initialisation_with_the_reason(route_fmu, tmp_path, profile, message):
    messages = []

    def log(_env, _instance, status, _category, text):
        messages.append(text.decode())

    from fmpy import calloc, free
    from fmpy.fmi2 import (
        fmi2CallbackAllocateMemoryTYPE,
        fmi2CallbackFreeMemoryTYPE,
        fmi2CallbackFunctions,
        fmi2CallbackLoggerTYPE,
    )
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(log)
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    from ctypes import byref

    from fmpy.logging import addLoggerProxy
    addLoggerProxy(byref(callbacks))
    md = fmpy.read_model_description(str(route_fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=fmpy.extract(str(route_fmu), str(tmp_path / "u")),
                    modelIdentifier="RouteProfile", instanceName="route")
    fmu.instantiate(callbacks=callbacks, loggingOn=True)
    fmu.setupExperiment(startTime=0.0)
    fmu.setString([vr["profile"]], [profile])
    fmu.enterInitializationMode()
    with pytest.raises(Exception):
        fmu.exitInitializationMode()
    assert any(message in m for m in messages), messages


# -- position mode: the grade by position (docs/cycles.md, "Grade by position") -----------------------------

class RoadRoute(Route):
    """A RouteProfile instance in position mode: parameter ``road``, input ``x``."""

    def __init__(self, fmu, tmp_path, road, x0=0.0):
        self.md = fmpy.read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=fmpy.extract(str(fmu), str(tmp_path / "road")),
                             modelIdentifier="RouteProfile", instanceName="road")
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.setString([self.vr["road"]], [road])
        self.fmu.setReal([self.vr["x"]], [x0])
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def step(self, t, x, h=H):
        self.fmu.setReal([self.vr["x"]], [x])
        self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        return self.values()


def test_position_mode_gives_the_road_angle_at_the_input_x(route_fmu, tmp_path):
    """delta after a step is the hilly road's angle at x as set for the step (no direct feedthrough:
    setting x alone changes nothing until the next step); before the first step, at x's start value;
    omega_ref keeps the route's time table; the state round trip keeps delta."""
    from pmsm_ev.cycles import load_road

    road = load_road("hilly")
    r = RoadRoute(route_fmu, tmp_path, "hilly", x0=1000.0)
    try:
        assert r.values()[0] == road.delta_at(1000.0) == math.atan(0.1)
        xs = (0.0, 540.0, 550.0, 1000.0, 1450.0, 2000.0, 2500.0, 3900.0, 5000.0, -10.0)
        for n, x in enumerate(xs):
            delta, omega_ref = r.step(n * H, x)
            assert delta == road.delta_at(x), x
            assert omega_ref == scenario_route("scenario1")["omega_ref"]((n + 1) * H)
        print("\nhilly road by position: delta [deg] at x [m]: "
              + ", ".join(f"{x:g}: {math.degrees(road.delta_at(x)):.3f}" for x in xs))
        r.fmu.setReal([r.vr["x"]], [1000.0])  # an input set, no step: the output stays
        assert r.values()[0] == road.delta_at(-10.0) == 0.0
        state = r.fmu.getFMUstate()
        r.step(len(xs) * H, 1000.0)
        assert r.values()[0] == math.atan(0.1)
        r.fmu.setFMUstate(state)
        assert r.values()[0] == 0.0  # the angle of the last step's x, not of the input set after it
        r.fmu.freeFMUstate(state)
    finally:
        r.free()


def test_position_mode_reads_a_road_file_in_resources(route_fmu, tmp_path):
    from pmsm_ev.cycles import load_road
    from pmsm_ev_fmus import write_road_fmu

    csv = tmp_path / "ramp.csv"
    csv.write_text("distance_m,elevation_m\n0,0\n100,5\n200,5\n300,-10\n", encoding="utf-8")
    fmu = write_road_fmu(csv, tmp_path / "RouteProfile_ramp.fmu", source=route_fmu)
    assert validate_fmu(str(fmu)) == []
    road = load_road(csv)
    r = RoadRoute(fmu, tmp_path, "ramp.csv")
    try:
        for n, x in enumerate((0.0, 50.0, 100.0, 150.0, 250.0, 299.0, 400.0)):
            assert r.step(n * H, x)[0] == road.delta_at(x)
        assert r.values()[0] == -math.asin(15.0 / 100.0)  # the last segment's slope holds after the end
    finally:
        r.free()
    bad = tmp_path / "bad.csv"
    bad.write_text("distance_m,grade_pct\n0,0\n10,80\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"bad.csv: row 3: grade_pct 80 is a grade of 80 %"):
        write_road_fmu(bad, tmp_path / "x.fmu", source=route_fmu)
    assert not (tmp_path / "x.fmu").exists()


@pytest.mark.parametrize("road, message", [
    ("hilly2", "road 'hilly2': choose a shipped road (hilly) or a road file inside resources/"),
    ("../modelDescription.xml", "inside resources/"),
    ("route.json", "no distance column"),
])
def test_a_bad_road_fails_initialisation(route_fmu, tmp_path, road, message):
    messages = []

    def log(_env, _instance, status, _category, text):
        messages.append(text.decode())

    from ctypes import byref

    from fmpy import calloc, free
    from fmpy.fmi2 import (
        fmi2CallbackAllocateMemoryTYPE,
        fmi2CallbackFreeMemoryTYPE,
        fmi2CallbackFunctions,
        fmi2CallbackLoggerTYPE,
    )
    from fmpy.logging import addLoggerProxy
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(log)
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    addLoggerProxy(byref(callbacks))
    md = fmpy.read_model_description(str(route_fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=fmpy.extract(str(route_fmu), str(tmp_path / "u")),
                    modelIdentifier="RouteProfile", instanceName="road")
    fmu.instantiate(callbacks=callbacks, loggingOn=True)
    fmu.setupExperiment(startTime=0.0)
    fmu.setString([vr["road"]], [road])
    fmu.enterInitializationMode()
    with pytest.raises(Exception):
        fmu.exitInitializationMode()
    assert any(message in m for m in messages), messages
