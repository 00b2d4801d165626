"""pmsm_ev.cycles: the standard drive cycles as package data, a user's own cycle and road profiles
by position (docs/cycles.md, "The cycles as data").

Published figures the shipped cycles are held to (the tolerance is half the last published digit):

* WLTC class 3b, UN GTR No. 15 Annex 1: 1800 s, 23.27 km, 131.3 km/h; phases Low3 0-589 s,
  Medium3-2 590-1022 s, High3-2 1023-1477 s, Extra High3 1478-1800 s (durations 589, 433, 455,
  323 s and top speeds 56.5, 76.6, 97.4, 131.3 km/h, as e.g. evdb.nz/wltp tabulates them), of
  3.095, 4.756, 7.162 and 8.254 km (the figures quoted for class 3b; no primary source for them
  was at hand, so the test also holds the trace to the regulation's table itself: its 1801 speeds
  sum to 83758.6 km/h, the checksum the wltp package keeps for its transcription of GTR No. 15).
* UDDS, 40 CFR 86 Appendix I (a): 1369 s, 7.45 mi (11.99 km), 56.7 mph (91.2 km/h); DieselNet and
  others round the distance to 7.5 mi.
* HWFET, 40 CFR 600 Appendix I: 765 s, 10.26 mi (16.51 km; DieselNet's "16.45 km" does not
  convert its own 10.26 mi), 59.9 mph (96.4 km/h).
* US06, 40 CFR 86 Appendix I (g): 600 s, 8.01 mi (12.89 km), 80.3 mph (129.2 km/h) (DieselNet).
"""

from __future__ import annotations

import hashlib
import importlib.util
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from pmsm_ev import cycles
from pmsm_ev.cycles import CycleError, RoadProfile, load, load_road
from pmsm_ev.cycles.table import data_file
from pmsm_ev.scenarios import ProfileError

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "src" / "pmsm_ev" / "cycles" / "data"
MI = 1.609344  # km per international mile
MPH = 1.609344  # km/h per mph

#: name: (duration [s], distance [km], distance tolerance [km], top speed [km/h], its tolerance)
PUBLISHED = {
    "wltc3b": (1800.0, 23.27, 0.005, 131.3, 0.05),
    "udds": (1369.0, 7.45 * MI, 0.005 * MI, 56.7 * MPH, 0.05 * MPH),
    "hwfet": (765.0, 10.26 * MI, 0.005 * MI, 59.9 * MPH, 0.05 * MPH),
    "us06": (600.0, 8.01 * MI, 0.005 * MI, 80.3 * MPH, 0.05 * MPH),
}
#: name: (stops, restarts): the issue's counts (every standstill after driving, the end's included)
#: and the published descriptions' (the stops between drives: US06 "four stops", HWFET none)
STOPS = {"wltc3b": (8, 7), "udds": (17, 16), "hwfet": (1, 0), "us06": (5, 4)}
#: WLTC class 3b phases: (duration [s], distance [km], top speed [km/h])
WLTC3B = {"low": (589.0, 3.095, 56.5), "medium": (433.0, 4.756, 76.6), "high": (455.0, 7.162, 97.4),
          "extra_high": (323.0, 8.254, 131.3)}


@pytest.mark.parametrize("name", list(PUBLISHED))
def test_a_shipped_cycle_has_its_published_duration_distance_and_top_speed(name):
    c = load(name)
    duration, km, km_tol, vmax, vmax_tol = PUBLISHED[name]
    print(f"\n{name}: {c.duration:g} s, {c.distance / 1000:.4f} km (published {km:.4f} +- {km_tol:.4f}), "
          f"top {c.top_speed * 3.6:.2f} km/h (published {vmax:.2f}), mean {c.mean_speed * 3.6:.1f} km/h, "
          f"{c.time.size} samples")
    assert c.duration == duration
    assert np.all(np.diff(c.time) == 1.0), "the shipped cycles are 1 Hz"
    assert abs(c.distance / 1000 - km) <= km_tol
    assert abs(c.top_speed * 3.6 - vmax) <= vmax_tol
    assert c.speed[0] == 0.0 and c.speed[-1] == 0.0
    assert c.grade is not None and np.all(c.grade == 0.0)  # FASTSim's cycGrade: level road
    assert cycles.SHIPPED[name].file in c.source and "FASTSim 2.1.5" in c.source


@pytest.mark.parametrize("name", list(STOPS))
def test_stops_and_restarts_of_the_shipped_cycles(name):
    c = load(name)
    print(f"\n{name}: {c.stops} stops, {c.restarts} restarts; standstill periods [s]: "
          + ", ".join(f"{a:g}-{b:g}" for a, b in c.stop_periods))
    assert (c.stops, c.restarts) == STOPS[name]


def test_the_stop_definition():
    """A stop is a run of samples below 0.1 km/h after the car moved (one sample is enough); the
    standstill before the first move is none; a trace that ends moving has no final stop."""
    kmh = [0, 0, 5, 0.09, 5, 0.11, 5, 0, 0, 3]
    c = cycles.Cycle("t", np.arange(len(kmh), dtype=float), np.array(kmh) / 3.6)
    assert c.stop_periods == ((3.0, 3.0), (7.0, 8.0))
    assert (c.stops, c.restarts) == (2, 2)
    c = cycles.Cycle("t", np.arange(4.0), np.array([0, 5, 5, 0]) / 3.6)
    assert (c.stops, c.restarts) == (1, 0)


def test_the_wltc3b_phases():
    c = load("wltc3b")
    dist = c.phase_distances()
    for p in c.phases:
        duration, km, vmax = WLTC3B[p.name]
        m = (c.time >= p.start) & (c.time <= p.end)
        print(f"\nwltc3b {p.name}: {p.start:g}-{p.end:g} s, {dist[p.name] / 1000:.4f} km (published {km}), "
              f"top {c.speed[m].max() * 3.6:.1f} km/h")
        assert p.end - p.start == duration
        assert abs(dist[p.name] / 1000 - km) <= 0.0005
        assert abs(c.speed[m].max() * 3.6 - vmax) <= 0.05
        assert c.speed[m][0] == 0.0 and c.speed[m][-1] == 0.0  # every phase starts and ends at rest
    assert list(dist) == ["low", "medium", "high", "extra_high"]
    assert sum(dist.values()) == pytest.approx(c.distance, rel=1e-12)
    assert c.speed_kmh.sum() == pytest.approx(83758.6, abs=1e-6)
    with pytest.raises(CycleError, match="no phase 'city'"):
        c.phase("city")
    assert load("udds").phases == ()


def test_the_shipped_files_are_the_sources_bytes_and_ship_with_the_package():
    """The CSV files are FASTSim's, unchanged (SHA-256 of data/README.md), and what the wheel
    packs (pyproject's package-data) covers every file of the data folder."""
    readme = (DATA / "README.md").read_text(encoding="utf-8")
    sums = dict((name, digest) for digest, name in re.findall(r"^([0-9a-f]{64})  (\S+)$", readme, re.M))
    assert sorted(sums) == sorted(s.file for s in cycles.SHIPPED.values())
    for name, digest in sums.items():
        assert hashlib.sha256(data_file(name).read_bytes()).hexdigest() == digest, name
    assert data_file("wltc_3b.csv").read_bytes().startswith(b"\xef\xbb\xbf")  # as shipped: a BOM
    for extra in ("LICENSE", "NOTICE", "hilly.csv"):
        assert data_file(extra).is_file()
    assert "Apache License" in data_file("LICENSE").read_text(encoding="utf-8")
    if sys.version_info >= (3, 11):
        import tomllib
    else:
        import tomli as tomllib
    setup = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    spec = importlib.util.spec_from_file_location("project_setup", ROOT / "setup.py")
    project_setup = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(project_setup)
    assert "pmsm_ev.cycles" in project_setup.found_packages(ROOT)
    globs = setup["package-data"]["pmsm_ev.cycles"]
    folder = DATA.parent
    packed = {p for g in globs for p in folder.glob(g)}
    assert packed == set(DATA.iterdir()) - {p for p in DATA.iterdir() if p.name.startswith(".")}


def _write(tmp_path, name, text, encoding="utf-8"):
    path = tmp_path / name
    path.write_bytes(text.encode(encoding))
    return path


def test_a_users_cycle_in_kmh_mps_mph_or_fastsims_columns_is_the_same_cycle(tmp_path):
    ref = load("us06")
    t, v = ref.time.tolist(), ref.speed.tolist()
    rows = lambda f: "".join(f"{ti!r},{f(vi)!r}\n" for ti, vi in zip(t, v))  # noqa: E731
    files = {
        "kmh.csv": "time_s,speed_kmh\n" + rows(lambda x: x * 3.6),
        "mps.csv": "\ufeff# a comment line\nTime_s , Speed_mps,notes\n" + rows(lambda x: x).replace("\n", ",x\n"),
        "mph.csv": "time [s],speed [mph]\n\n" + rows(lambda x: x / 0.44704),
        "fastsim.csv": "cycSecs,cycMps,cycGrade,cycRoadType\n" + "".join(
            f"{ti!r},{vi!r},0.01,0\n" for ti, vi in zip(t, v)),
    }
    got = {name: load(_write(tmp_path, name, text)) for name, text in files.items()}
    for name, c in got.items():
        np.testing.assert_array_equal(c.time, t)
        np.testing.assert_allclose(c.speed, v, rtol=1e-14, atol=1e-15, err_msg=name)
        assert c.name == Path(name).stem and c.source.endswith(name)
        assert c.stops == ref.stops and c.distance == pytest.approx(ref.distance, rel=1e-13)
    assert got["kmh.csv"].grade is None
    np.testing.assert_array_equal(got["fastsim.csv"].grade, 0.01)
    pct = load(_write(tmp_path, "pct.csv", "time_s,speed_kmh,grade_pct\n0,0,1\n1,3.6,-2.5\n"))
    np.testing.assert_allclose(pct.grade, [0.01, -0.025])
    np.testing.assert_allclose(pct.speed, [0.0, 1.0])
    with pytest.raises(ValueError, match="read-only"):
        pct.speed[0] = 1.0


#: (file text, the row the error names (None: the file as a whole), what it says)
BAD_CYCLES = {
    "decreasing time": ("time_s,speed_kmh\n0,0\n2,10\n1,20\n", 4, "time_s 1 is before the previous time_s 2"),
    "repeated time": ("time_s,speed_kmh\n0,0\n1,10\n1,20\n", 4, "time_s 1 repeats the previous time_s 1"),
    "not from 0 s": ("time_s,speed_kmh\n5,0\n6,10\n", 2, "a cycle starts at time 0 s"),
    "negative speed": ("time_s,speed_kmh\n0,0\n1,-0.5\n", 3, "speed_kmh -0.5 is negative"),
    "NaN speed": ("time_s,speed_mps\n0,0\n1,nan\n", 3, "speed_mps is 'nan'; values must be finite"),
    "infinite speed": ("time_s,speed_mps\n0,0\n1,1\n2,inf\n", 4, "speed_mps is 'inf'; values must be finite"),
    "not a number": ("time_s,speed_kmh\n0,0\n1,fast\n", 3, "speed_kmh 'fast' is not a number"),
    "empty cell": ("time_s,speed_kmh\n0,0\n1,\n", 3, "speed_kmh is empty"),
    "short row": ("time_s,speed_kmh\n0,0\n1\n", 3, "speed_kmh is empty"),
    "missing column": ("time_s,velocity\n0,0\n1,1\n", 1, "no speed column"),
    "missing time": ("t,speed_kmh\n0,0\n1,1\n", 1, "no time column"),
    "unknown unit": ("time_s,speed_knots\n0,0\n1,1\n", 1, "unit 'knots' of column 'speed_knots' is not known"),
    "unknown time unit": ("time_min,speed_kmh\n0,0\n1,1\n", 1, "unit 'min' of column 'time_min' is not known"),
    "no unit": ("time_s,speed\n0,0\n1,1\n", 1, "column 'speed' gives no unit"),
    "two speeds": ("time_s,speed_kmh,cycMps\n0,0,0\n1,1,1\n", 1, "two speed columns"),
    "too steep": ("time_s,speed_kmh,grade_pct\n0,0,0\n1,1,60\n", 3, "grade_pct 60 is steeper than the bound"),
    "empty file": ("", None, "the file is empty"),
    "only comments": ("# nothing\n\n", None, "the file is empty"),
    "header only": ("time_s,speed_kmh\n", None, "0 data rows after the header"),
    "one row": ("time_s,speed_kmh\n0,0\n", None, "1 data row after the header"),
}


@pytest.mark.parametrize("case", list(BAD_CYCLES))
def test_a_bad_cycle_is_refused_with_one_line_naming_file_row_and_problem(tmp_path, case):
    text, row, problem = BAD_CYCLES[case]
    path = _write(tmp_path, "my cycle.csv", text)
    before = sorted(tmp_path.iterdir())
    with pytest.raises(CycleError) as err:
        load(path)
    msg = str(err.value)
    print(f"\n{case}: {msg}")
    assert "\n" not in msg
    assert msg.startswith(f"{path}: " + ("" if row is None else f"row {row}: ")), msg
    assert problem in msg
    if row is None:
        assert ": row " not in msg
    assert isinstance(err.value, ValueError) and isinstance(err.value, ProfileError)
    assert sorted(tmp_path.iterdir()) == before  # nothing written


def test_a_bad_cycle_file_or_name(tmp_path):
    bad = tmp_path / "latin1.csv"
    bad.write_bytes("time_s,speed_kmh\n0,0\n1,1\xe9\n".encode("latin-1"))
    for arg, text in [(bad, f"{bad}: not UTF-8 text"), (tmp_path / "none.csv", "cycle file not found"),
                      ("wltc4", "wltc4: not a shipped cycle (wltc3b, udds, hwfet, us06) and no such file")]:
        with pytest.raises(CycleError, match=re.escape(text)):
            load(arg)
    assert load("WLTC3B").name == "wltc3b"


def test_a_cycle_from_arrays_is_checked_the_same_way():
    with pytest.raises(CycleError, match=r"^x: sample 2: time 1 s repeats the previous time 1 s"):
        cycles.Cycle("x", [0.0, 1.0, 1.0], [0.0, 1.0, 2.0])
    with pytest.raises(CycleError, match=r"^x: sample 1: speed -1 m/s is negative"):
        cycles.Cycle("x", [0.0, 1.0], [0.0, -1.0])
    with pytest.raises(CycleError, match=r"^x: sample 0: time nan s is not finite"):
        cycles.Cycle("x", [math.nan, 1.0], [0.0, 1.0])
    with pytest.raises(CycleError, match="one length"):
        cycles.Cycle("x", [0.0, 1.0], [0.0])


def test_the_hilly_road_climbs_10_percent_and_comes_back_down():
    r = load_road("hilly")
    assert r.kind == "linear" and r.length == 4000.0
    x = np.array([0.0, 499.0, 550.0, 600.0, 1000.0, 1400.0, 1450.0, 1750.0, 2500.0, 3500.0, 9000.0, -5.0])
    g = r.grade_at(x)
    assert g.shape == x.shape
    np.testing.assert_allclose(g, [0, 0, 0.05, 0.10, 0.10, 0.10, 0.05, 0, -0.10, 0, 0, 0], atol=1e-15)
    assert r.grade_at(1000.0) == 0.1 and isinstance(r.grade_at(1000.0), float)
    assert r.delta_at(1000.0) == math.atan(0.1)
    np.testing.assert_array_equal(r.delta_at(x), np.arctan(g))
    # the elevation the car climbs: the integral of sin(delta) along the road
    s = np.linspace(0.0, 4000.0, 400001)
    rise = np.concatenate(([0.0], np.cumsum(0.5 * (np.sin(r.delta_at(s[1:])) + np.sin(r.delta_at(s[:-1])))
                                              * np.diff(s))))
    top, end = rise[s == 2000.0][0], rise[-1]
    print(f"\nhilly: climbs {top:.2f} m to the summit (1500-2000 m), ends at {end:+.2e} m; "
          f"grade {r.grade_at(1000.0) * 100:g} % = {math.degrees(r.delta_at(1000.0)):.3f} deg")
    assert top == pytest.approx(89.55, abs=0.05)  # 100 m at 5 % mean, 800 m at 10 %, 100 m at 5 %
    assert abs(end) < 1e-9


def test_an_elevation_profile_has_the_slope_between_its_points(tmp_path):
    path = _write(tmp_path, "hill.csv", "distance_km,elevation_m\n0,100\n1,100\n1.5,150\n2,100\n")
    r = load_road(path)
    assert r.kind == "segments" and r.length == 2000.0
    s = 50.0 / 500.0  # sin(delta): the road is straight between the points
    np.testing.assert_allclose(r.grade, [0.0, s / math.sqrt(1 - s * s), -s / math.sqrt(1 - s * s)])
    x = np.array([-1.0, 0.0, 999.999, 1000.0, 1200.0, 1500.0, 1999.0, 2000.0, 2500.0])
    g = r.grade_at(x)
    assert list(np.sign(g)) == [0, 0, 0, 1, 1, -1, -1, -1, -1]  # a point starts its segment; ends held
    # driving the road (sin delta times the distance) gives back the elevation of every point
    z = 100.0 + np.concatenate(([0.0], np.cumsum(np.sin(np.arctan(r.grade)) * np.diff(r.distance))))
    np.testing.assert_allclose(z, r.elevation, rtol=0, atol=1e-12)
    print(f"\nelevation profile: 50 m over 500 m of road is sin(delta) = 0.1, grade {r.grade[1] * 100:.4f} %, "
          f"delta {math.degrees(r.delta_at(1200.0)):.4f} deg")


def test_grade_units_give_the_same_road(tmp_path):
    rows = [(0.0, 0.0), (100.0, 0.05), (250.0, -0.08)]
    texts = {
        "grade": "distance_m,grade\n" + "".join(f"{d},{g!r}\n" for d, g in rows),
        "pct": "distance_m,grade_pct\n" + "".join(f"{d},{g * 100!r}\n" for d, g in rows),
        "deg": "distance_m,grade_deg\n" + "".join(f"{d},{math.degrees(math.atan(g))!r}\n" for d, g in rows),
        "rad": "distance [km],grade [rad]\n" + "".join(f"{d / 1000!r},{math.atan(g)!r}\n" for d, g in rows),
    }
    x = np.linspace(-10.0, 300.0, 32)
    want = np.interp(x, [d for d, _ in rows], [g for _, g in rows])
    for name, text in texts.items():
        r = load_road(_write(tmp_path, f"{name}.csv", text))
        np.testing.assert_allclose(r.grade_at(x), want, rtol=1e-12, atol=1e-15, err_msg=name)


BAD_ROADS = {
    "distance back": ("distance_m,grade_pct\n0,0\n100,1\n50,2\n", 4, "distance_m 50 is before the previous "
                      "distance_m 100"),
    "distance repeats": ("distance_m,elevation_m\n0,0\n100,1\n100,2\n", 4, "distance_m 100 repeats"),
    "too steep grade": ("distance_m,grade_pct\n0,0\n100,55\n", 3, "grade_pct 55 is a grade of 55 %, steeper"),
    "too steep angle": ("distance_m,grade_deg\n0,0\n100,-30\n", 3, "grade_deg -30 is a grade of -57.74 %"),
    "too steep hill": ("distance_m,elevation_m\n0,0\n100,0\n140,30\n", 4, "rises +30 m from the previous row "
                       "over 40 m of road (a grade of 113.4 %)"),
    "vertical": ("distance_m,elevation_m\n0,0\n10,20\n", 3, "(more than vertical)"),
    "NaN": ("distance_m,grade\n0,0\n1,nan\n", 3, "grade is 'nan'; values must be finite"),
    "grade and elevation": ("distance_m,grade,elevation_m\n0,0,0\n1,0,0\n", 1, "more than one column of grade "
                            "or elevation"),
    "neither": ("distance_m,height\n0,0\n1,0\n", 1, "no column of grade or elevation"),
    "no distance": ("x_m,grade\n0,0\n1,0\n", 1, "no distance column"),
    "unit in feet": ("distance_m,elevation_ft\n0,0\n1,0\n", 1, "unit 'ft' of column 'elevation_ft' is not known"),
    "empty": ("\n", None, "the file is empty"),
}


@pytest.mark.parametrize("case", list(BAD_ROADS))
def test_a_bad_road_profile_is_refused_with_one_line(tmp_path, case):
    text, row, problem = BAD_ROADS[case]
    path = _write(tmp_path, "road.csv", text)
    with pytest.raises(CycleError) as err:
        load_road(path)
    msg = str(err.value)
    print(f"\n{case}: {msg}")
    assert "\n" not in msg and problem in msg
    assert msg.startswith(f"{path}: " + ("" if row is None else f"row {row}: ")), msg
    assert sorted(p.name for p in tmp_path.iterdir()) == ["road.csv"]


def test_a_road_from_arrays_is_checked():
    with pytest.raises(CycleError, match="point 2: distance 1 m does not increase"):
        RoadProfile("r", [0.0, 2.0, 1.0], [0.0, 0.0, 0.0])
    with pytest.raises(CycleError, match=r"segment 0: grade 0.6 is not within \|grade\| <= 0.5"):
        RoadProfile("r", [0.0, 1.0], [0.6], "segments")
    with pytest.raises(CycleError, match="need 1 grades"):
        RoadProfile("r", [0.0, 1.0], [0.0, 0.0], "segments")
    with pytest.raises(CycleError, match="not a shipped road profile"):
        load_road("alps")
