"""Scenario profiles of section III and CSV profiles."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pmsm_cosim.engine.signals import Table, TableError, load_table_csv
from pmsm_ev.params import ScenarioParams
from pmsm_ev.scenarios import Profile, ProfileError, elevation_profile, speed_reference


def deg(p, t):
    return math.degrees(p(t))


def test_scenario1_steps_up_and_down():
    p = elevation_profile(1)
    assert [round(deg(p, t)) for t in (10, 60, 90, 120, 150, 180, 210, 240, 270, 300, 330)] == \
        [0, 5, 10, 15, 20, 25, 20, 15, 10, 5, 0]
    assert p.change_times() == [50, 80, 110, 140, 170, 200, 230, 260, 290, 320]


def test_scenario2_alternates_every_30_s():
    p = elevation_profile("scenario2")
    assert [round(deg(p, t)) for t in range(5, 350, 30)][:12] == [0, 0, 22, 0, 22, 0, 22, 0, 22, 0, 22, 0]
    assert deg(p, 49.999) == 0 and deg(p, 50.0) == pytest.approx(22)


def test_speed_reference_ramp():
    w = speed_reference(ScenarioParams(omega_ref=200.0, startup_time=10.0))
    assert (w(0.0), w(5.0), w(10.0), w(300.0)) == (0.0, 100.0, 200.0, 200.0)


def test_unknown_scenario():
    with pytest.raises(ProfileError):
        elevation_profile(3)


def test_csv_profile(tmp_path):
    f = tmp_path / "route.csv"
    f.write_text("time,delta_deg\n0,0\n10,4\n20,0\n")
    p = load_table_csv(f, "linear", scale=math.pi / 180)
    assert deg(p, 5.0) == pytest.approx(2.0)
    assert deg(p, 25.0) == pytest.approx(0.0)


@pytest.mark.parametrize("text,where", [
    ("", "empty"),
    ("time\n0\n", ":1:"),
    ("time,v\n0,1\n1\n", ":3:"),
    ("time,v\n0,abc\n", ":2:"),
    ("time,v\n0,1\n0,2\n", ":3:"),
    ("time,v\n0,nan\n", ":2:"),
    ("time,v\n", "no data"),
])
def test_csv_profile_errors_name_file_and_line(tmp_path, text, where):
    f = tmp_path / "bad.csv"
    f.write_text(text)
    with pytest.raises(TableError) as e:
        load_table_csv(f)
    assert "bad.csv" in str(e.value) and where in str(e.value)


# The engine's signal tables (system files) and the physics' profiles (the paper's routes, carried
# inside the RouteProfile FMU, which bundles pmsm_ev only) are two classes on purpose: the engine
# imports no pmsm_ev. They must give the same number at every time, bit for bit, or a route
# played by the master and by the RouteProfile FMU would differ.
@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.floats(-1e3, 1e3), st.floats(-1e6, 1e6)), min_size=1, max_size=8,
                unique_by=lambda p: p[0]),
       st.sampled_from(("previous", "linear")),
       st.lists(st.floats(-2e3, 2e3), min_size=1, max_size=20))
def test_engine_tables_and_physics_profiles_agree_bit_for_bit(points, interpolation, times):
    points = sorted(points)
    ts, vs = tuple(p[0] for p in points), tuple(p[1] for p in points)
    table, profile = Table(ts, vs, interpolation), Profile(ts, vs, interpolation)
    for t in list(times) + list(ts):
        assert table(t) == profile(t) or (math.isnan(table(t)) and math.isnan(profile(t)))
