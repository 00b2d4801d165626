"""Following a drive cycle (docs/cycles.md, "Following the trace" and "Grade by position"):

* the regulatory tolerance band (``pmsm_cosim.app.metrics.trace.trace_band``, ``trace_figures``) on synthetic traces
  whose answers are known: a car 1 s late stays inside; on a 1 m/s^2 ramp a delay of more than
  1 + (2 km/h) / (3.6 km/h per m/s x 1 m/s^2) = 1.556 s leaves it (1.5 s stays inside by 0.2 km/h);
  a constant +2.5 km/h leaves it wherever the trace is flat over +-1 s, and stays inside on the ramp;
* the speed reference (``pmsm_ev.cycles.speed_reference``, PCHIP through the trace) of every shipped
  cycle: inside the band, never negative, exactly 0 during every stop, acceleration bounded by
  ``ACCEL_MARGIN`` times the trace's own;
* a run driven by ``[cycle]`` and ``[road]`` sections and by ``--cycle``: omega_ref = v n_g / r_w of the
  reference, delta = the road's angle at the plant's recorded x_vehicle; bad input one line, exit 2,
  nothing written; the system exported as an SSP package runs to the same numbers.
"""

from __future__ import annotations

import json
import math
from importlib import resources

import numpy as np
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app.cli import main
from pmsm_cosim.app.metrics.rows import KMH
from pmsm_cosim.app.metrics.trace import EPA_BAND_KMH, trace_band, trace_figures
from pmsm_cosim.app.overrides import apply_overrides
from pmsm_cosim.engine.errors import CosimError
from pmsm_cosim.engine.recording import read_results
from pmsm_ev import cycles
from pmsm_ev.cycles import ACCEL_MARGIN, Cycle, CycleError, load, load_road, pchip, speed_reference
from pmsm_ev.params import VehicleParams

ROW = 0.01  #: the rows' interval of results.csv [s]
BAND = 2.0 / KMH  #: the band [m/s]


def ramp_cycle(a: float = 1.0) -> Cycle:
    """0 for 5 s, up at ``a`` m/s^2 for 10 s, 10 s held, down at -a for 10 s, 5 s standing (1 Hz)."""
    t = np.arange(41.0)
    v = np.interp(t, [0, 5, 15, 25, 35, 40], [0, 0, 10 * a, 10 * a, 0, 0])
    return Cycle("ramp", t, v)


def rows(cycle: Cycle) -> np.ndarray:
    return np.round(np.arange(0.0, cycle.duration + ROW / 2, ROW), 9)


def late(cycle: Cycle, t: np.ndarray, delay: float) -> np.ndarray:
    """The car driving the trace ``delay`` seconds late."""
    return np.interp(t - delay, cycle.time, cycle.speed)


# -- the band -------------------------------------------------------------------------------------------

def test_the_band_is_the_traces_extremes_within_one_second_plus_minus_2_kmh():
    c = Cycle("triangle", np.array([0.0, 1.0, 2.0, 3.0, 4.0]), np.array([0.0, 0.0, 10.0, 0.0, 0.0]))
    t = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 10.0])
    lower, upper = trace_band(c.time, c.speed, time=t)
    # highest within +-1 s: the apex (10 at 2 s) for 1 <= t <= 3; at 0.5 s the trace at 1.5 s (5); else 0
    np.testing.assert_allclose(upper - BAND, [0, 5, 10, 10, 10, 10, 10, 5, 0, 0], atol=1e-12)
    # lowest within +-1 s: 0 everywhere but at 2 s (the trace at 1 s and 3 s is 0 too)
    np.testing.assert_allclose(lower + BAND, 0.0, atol=1e-12)
    lower, upper = trace_band(c.time, c.speed, band_kmh=0.0, window_s=0.0, time=t)  # no band: the trace
    np.testing.assert_allclose(upper, np.interp(t, c.time, c.speed), atol=1e-12)
    np.testing.assert_allclose(lower, upper, atol=1e-12)
    assert EPA_BAND_KMH == pytest.approx(3.218688)  # 2 mph, 40 CFR 86.115-78(b)(1)
    with pytest.raises(ValueError, match="t_trace increasing"):
        trace_band([0.0, 0.0], [1.0, 2.0])


@pytest.mark.parametrize("name", ["ramp", "wltc3b", "us06"])
def test_a_car_one_second_late_stays_inside(name):
    c = ramp_cycle() if name == "ramp" else load(name)
    t = rows(c)
    for delay in (-1.0, 1.0):
        f = trace_figures(t, late(c, t, delay), c)
        assert f["inside_share"] == 1.0 and f["excursions"] == 0 and f["longest_excursion_s"] is None, (name, f)
    f = trace_figures(t, late(c, t, 1.0), c)
    print(f"\n{name}: 1 s late: inside {f['inside_share']:.4f}, RMSE {f['rmse_kmh']:.3f} km/h, largest "
          f"deviation {f['max_deviation_kmh']:+.2f} km/h at {f['t_max_deviation']:.2f} s")
    if name == "ramp":  # on the 1 m/s^2 ramps: 3.6 km/h behind, then ahead: RMS over 20 of 40 s
        assert f["max_deviation_kmh"] == pytest.approx(-3.6, abs=1e-9)
        assert f["rmse_kmh"] == pytest.approx(3.6 * math.sqrt((2 * 9 + 2 * 2 / 3) / 40), rel=2e-3)


def test_on_a_ramp_the_band_holds_a_delay_up_to_1_556_s():
    """On a 1 m/s^2 ramp the lower limit is the trace 1 s before minus 2 km/h: a car late by d is
    3.6 d km/h below the trace, inside while 3.6 d <= 3.6 + 2, d <= 1.556 s."""
    c = ramp_cycle(1.0)
    t = rows(c)
    d_max = 1.0 + BAND / 1.0
    for delay, inside in ((1.5, True), (1.55, True), (1.56, False), (1.6, False), (2.0, False)):
        f = trace_figures(t, late(c, t, delay), c)
        assert (f["inside_share"] == 1.0) is inside, (delay, f)
        if not inside:
            # out from 1 + band/a after the ramp's start to delay - band/a after its end, up and down
            length = 10.0 + delay - 1.0 - 2.0 * BAND
            assert f["excursions"] == 2, f
            assert f["excursion_lengths_s"] == pytest.approx([length, length], abs=2.5 * ROW), (delay, f)
            assert f["t_longest_excursion"] == pytest.approx(5.0 + d_max, abs=2 * ROW)
    f = trace_figures(t, late(c, t, 1.6), c)
    print(f"\nramp 1 m/s^2: the band holds a delay up to {d_max:.4f} s; 1.6 s late: inside {f['inside_share']:.4f}, "
          f"{f['excursions']} excursions of {', '.join(f'{x:.2f}' for x in f['excursion_lengths_s'])} s "
          f"(expected {10.0 + 0.6 - 2.0 * BAND:.3f} s each), the first at {f['t_longest_excursion']:.2f} s")


def test_a_constant_offset_of_2_5_kmh_leaves_a_flat_trace_everywhere_but_not_a_ramp():
    flat = Cycle("flat", np.arange(21.0), np.full(21, 50.0 / KMH))
    t = rows(flat)
    for sign in (1.0, -1.0):
        f = trace_figures(t, flat.speed[0] + sign * 2.5 / KMH + 0 * t, flat)
        assert f["inside_share"] == 0.0 and f["excursions"] == 1, f
        assert f["excursion_lengths_s"] == [pytest.approx(flat.duration + ROW)]
        assert f["rmse_kmh"] == pytest.approx(2.5) and f["max_deviation_kmh"] == pytest.approx(sign * 2.5)
    f = trace_figures(t, flat.speed[0] + 1.9 / KMH + 0 * t, flat)
    assert f["inside_share"] == 1.0 and f["rmse_kmh"] == pytest.approx(1.9)
    # on a 1 m/s^2 ramp the upper limit is the trace 1 s ahead + 2 km/h, 5.6 km/h above: +2.5 km/h is inside
    # where the trace within +-1 s rises 0.5 km/h above its value: from 1 - x s before a ramp's start to x s
    # before its end (x = 0.5 / 3.6 s), 10 + 1 - 2 x s for each ramp
    c = ramp_cycle()
    t = rows(c)
    f = trace_figures(t, late(c, t, 0.0) + 2.5 / KMH, c)
    x = 0.5 / KMH
    share_expected = 2 * (10.0 + 1.0 - 2 * x) / c.duration
    assert f["inside_share"] == pytest.approx(share_expected, abs=3 * ROW / c.duration), f
    assert f["excursion_lengths_s"] == pytest.approx([4.0 + x, 10.0 + 2 * x, 4.0 + x], abs=2 * ROW), f
    print(f"\n+2.5 km/h: flat trace inside 0 %; ramp cycle inside {100 * f['inside_share']:.2f} % "
          f"(expected {100 * share_expected:.2f} %), excursions of "
          f"{', '.join(f'{v:.2f}' for v in f['excursion_lengths_s'])} s")


def test_a_run_shorter_than_the_cycle_is_measured_up_to_its_end():
    c = ramp_cycle()
    t = rows(c)[:1001]  # 10 s of 40
    f = trace_figures(t, late(c, t, 0.0), c)
    assert f["t_end"] == 10.0 and f["inside_share"] == 1.0 and f["rmse_kmh"] == 0.0


# -- the speed reference ---------------------------------------------------------------------------------

@pytest.mark.parametrize("name", cycles.names())
def test_the_speed_reference_is_inside_the_band_never_negative_and_zero_at_stops(name):
    c = load(name)
    veh = VehicleParams()
    ref = speed_reference(c, veh.r_w, veh.n_g)
    assert ref.time[0] == 0.0 and ref.time[-1] == c.duration and np.all(np.diff(ref.time) > 0)
    assert ref.time.size == round(c.duration / ref.dt) + 1
    np.testing.assert_array_equal(ref.omega, ref.v * (veh.n_g / veh.r_w))
    np.testing.assert_array_equal(ref.domega, ref.a * (veh.n_g / veh.r_w))
    # inside the band on the grid and between its points (midpoints, the exact cubic)
    mid = 0.5 * (ref.time[1:] + ref.time[:-1])
    v_mid, _ = pchip(c.time, c.speed, mid)
    for at, v in ((ref.time, ref.v), (mid, v_mid)):
        lower, upper = trace_band(c.time, c.speed, time=at)
        assert np.all(v >= lower) and np.all(v <= upper)
    margin = min(float(np.min(ref.v - trace_band(c.time, c.speed, time=ref.time)[0])),
                 float(np.min(trace_band(c.time, c.speed, time=ref.time)[1] - ref.v))) * KMH
    assert margin >= 2.0 - 1e-9  # PCHIP stays between the trace's points: the whole band to spare
    assert np.all(ref.v >= 0.0) and np.all(v_mid >= -1e-12)
    # exactly 0 during every stop (its first to last standstill sample), one-sample stops included
    for t0, t1 in c.stop_periods:
        still = (ref.time >= t0 - 1e-9) & (ref.time <= t1 + 1e-9)
        assert np.any(still) and np.all(ref.v[still] == 0.0) and np.all(ref.a[still] == 0.0), (t0, t1)
    # the acceleration: finite, continuous, bounded by ACCEL_MARGIN x the trace's own (its interval and neighbours)
    secant = np.abs(np.diff(c.speed) / np.diff(c.time))
    i = np.clip(np.searchsorted(c.time, ref.time, side="right") - 1, 0, secant.size - 1)
    local = np.maximum.reduce([secant[np.clip(i + k, 0, secant.size - 1)] for k in (-1, 0, 1)])
    assert np.all(np.isfinite(ref.a)) and np.all(np.abs(ref.a) <= ACCEL_MARGIN * local + 1e-12)
    ratio = float(np.max(np.abs(ref.a)[local > 0] / local[local > 0]))
    assert float(np.max(np.abs(np.diff(ref.a)))) <= ACCEL_MARGIN * 6.0 * float(secant.max()) * ref.dt  # C1: no jump
    # the derivative is the reference's: central differences of the cubic over +-1e-4 s agree (to eps/2 x the
    # jump of its second derivative at a point, a few m/s^3: C1, not C2)
    eps = 1e-4
    dv = (pchip(c.time, c.speed, ref.time + eps)[0] - pchip(c.time, c.speed, ref.time - eps)[0]) / (2 * eps)
    inner = (ref.time > eps) & (ref.time < c.duration - eps)
    assert float(np.max(np.abs(dv - ref.a)[inner])) < 1e-3
    # the chord between grid points (linear interpolation) stays within 0.1 km/h of the cubic
    chord = float(np.max(np.abs(np.interp(mid, ref.time, ref.v) - v_mid))) * KMH
    assert chord < 0.1
    print(f"\n{name}: {ref.time.size} points every {ref.dt} s; band margin {margin:.3f} km/h; stops "
          f"{len(c.stop_periods)} all 0; |a| max {np.abs(ref.a).max():.3f} m/s^2 (trace {secant.max():.3f}), "
          f"at most {ratio:.3f} x the local trace's (bound {ACCEL_MARGIN}); chord error {chord:.4f} km/h")


def test_bad_speed_reference_arguments_are_one_line():
    c = ramp_cycle()
    for kwargs, text in (({"r_w": 0.0}, "r_w must be"), ({"n_g": math.nan}, "n_g must be"),
                         ({"dt": -1.0}, "dt must be")):
        args = {"r_w": 0.3, "n_g": 12.5, **kwargs}
        with pytest.raises(CycleError, match=text):
            speed_reference(c, **args)


# -- a run from a cycle on a road by position ------------------------------------------------------------

CYCLE_CSV = "time_s,speed_kmh\n0,0\n1,0\n2,3.6\n3,7.2\n4,7.2\n"
#: a road that climbs from level to 10 % over the first metres the car drives (0.5 - 2.5 m)
ROAD_CSV = "distance_m,grade_pct\n0,0\n0.5,0\n2.5,10\n"


def system_file(tmp_path, cycle='file = "cyc.csv"', road='file = "road.csv"', extra="", stop_time=None):
    """Scenario 1's system with a [cycle] and a [road] section (its time tables left in, replaced), no stop
    time (or ``stop_time``), x_vehicle recorded."""
    (tmp_path / "cyc.csv").write_text(CYCLE_CSV, encoding="utf-8")
    (tmp_path / "road.csv").write_text(ROAD_CSV, encoding="utf-8")
    text = (resources.files("pmsm_cosim.app") / "scenarios" / "scenario1.toml").read_text(encoding="utf-8")
    text = text.replace('name = "scenario1"', 'name = "cycle-road"')
    text = text.replace("stop_time = 350.0", "" if stop_time is None else f"stop_time = {stop_time!r}")
    sections = (f"[cycle]\n{cycle}\n\n" if cycle else "") + (f"[road]\n{road}\n\n" if road else "") + extra
    i = text.index("[record]")
    path = tmp_path / "sys.toml"
    path.write_text(text[:i] + sections + text[i:] + 'x_vehicle = "plant.x_vehicle"\n', encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def fmus():
    return project_fmus()


def test_a_run_follows_the_cycle_and_meets_the_grade_by_position(fmus, tmp_path, capsys):
    path = system_file(tmp_path)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--quiet", "--no-figures"]) == 0
    r = read_results(out)
    veh = VehicleParams()
    c, road = load(tmp_path / "cyc.csv"), load_road(tmp_path / "road.csv")
    assert r["time"][-1] == c.duration  # the stop time is the cycle's
    ref = speed_reference(c, veh.r_w, veh.n_g)
    np.testing.assert_allclose(r["omega_ref"], np.interp(r["time"], ref.time, ref.omega), rtol=0, atol=1e-12)
    assert r["omega_ref"].max() == pytest.approx(7.2 / KMH * veh.n_g / veh.r_w)
    # delta is the road's at the plant's recorded position, row by row (the road steps after the plant)
    np.testing.assert_array_equal(r["delta_deg"], np.degrees(road.delta_at(r["x_vehicle"])))
    assert r["x_vehicle"][-1] > 2.5 and r["delta_deg"][-1] == pytest.approx(math.degrees(math.atan(0.1)))
    f = trace_figures(r["time"], r["v_vehicle"], c)
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert metrics["trace"] == {"cycle": "cyc", **f}  # the run's own figures of the band
    assert "cycle cyc: inside the +-2 km/h band" in capsys.readouterr().out
    with capsys.disabled():
        print(f"\n[cycle] + [road], 4 s: x = {r['x_vehicle'][-1]:.3f} m, delta up to {r['delta_deg'].max():.3f} "
              f"deg; inside the band {100 * f['inside_share']:.1f} %, RMSE {f['rmse_kmh']:.3f} km/h, largest "
              f"deviation {f['max_deviation_kmh']:+.3f} km/h at {f['t_max_deviation']:.2f} s")
    # the same system exported as an SSP package runs to the same numbers
    ssp = tmp_path / "cycle-road.ssp"
    assert main(["export-ssp", str(path), "-o", str(ssp), "--quiet", "--stop-time", "1"]) == 0
    assert "components ctrl, plant, road, route" in capsys.readouterr().out
    assert main(["run", str(ssp), "--out", str(tmp_path / "ssp"), "--quiet", "--no-figures"]) == 0
    s = read_results(tmp_path / "ssp")
    n = len(s["time"])
    assert s["time"][-1] == 1.0
    for col in ("omega_ref", "delta_deg", "omega_m", "x_vehicle", "i_q"):
        np.testing.assert_array_equal(s[col], r[col][:n], err_msg=col)
    # --cycle on the package: its route component's omega_ref connection gives way, the column follows
    assert main(["run", str(ssp), "--cycle", str(tmp_path / "cyc.csv"), "--stop-time", "1", "--out",
                 str(tmp_path / "ssp2"), "--quiet", "--no-figures"]) == 0
    np.testing.assert_array_equal(read_results(tmp_path / "ssp2")["omega_ref"], r["omega_ref"][:n])


def test_set_plant_wheel_and_gear_resamples_the_cycle(tmp_path):
    path = system_file(tmp_path, road="")
    spec = apply_overrides(str(path), set=["plant.r_w=0.3", "plant.n_g=10"])
    sig = spec.signals["omega_ref"]
    ref = speed_reference(load(tmp_path / "cyc.csv"), 0.3, 10.0)
    assert sig.profile.times == tuple(ref.time) and sig.profile.values == tuple(ref.omega)
    assert "r_w = 0.3 m, n_g = 10" in sig.origin and spec.stop_time == 4.0
    stated = apply_overrides(str(system_file(tmp_path, cycle='file = "cyc.csv"\nr_w = 0.25\nn_g = 8', road="")),
                             set=["plant.r_w=0.3"])
    assert stated.signals["omega_ref"].profile.values == tuple(speed_reference(load(tmp_path / "cyc.csv"),
                                                                               0.25, 8.0).omega)
    # the shipped cycle by name; --cycle on a shipped scenario; the stop time given wins
    spec = apply_overrides("scenario1", cycle="wltc3b", cli=True)
    assert spec.stop_time == 1800.0 and len(spec.signals["omega_ref"].profile.times) == 18001
    assert spec.signals["omega_ref"].drives == [("ctrl", "omega_ref")]
    assert apply_overrides("scenario1", cycle="us06", stop_time=30.0).stop_time == 30.0
    assert apply_overrides("scenario1").signals["omega_ref"].origin == "table"  # paper mode untouched


def test_cli_cycle_drives_omega_ref_of_a_shipped_scenario(fmus, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "cyc.csv").write_text(CYCLE_CSV, encoding="utf-8")
    out = tmp_path / "o"
    assert main(["run", "scenario1", "--cycle", "cyc.csv", "--stop-time", "3", "--out", str(out), "--quiet",
                 "--no-figures", "--record", "omega_ref", "v_vehicle", "delta_deg"]) == 0
    r = read_results(out)
    veh = VehicleParams()
    ref = speed_reference(load(tmp_path / "cyc.csv"), veh.r_w, veh.n_g)
    assert r["time"][-1] == 3.0
    np.testing.assert_allclose(r["omega_ref"], np.interp(r["time"], ref.time, ref.omega), rtol=0, atol=1e-12)
    assert np.all(r["delta_deg"] == 0.0)  # scenario 1's elevation table: 0 until 50 s, kept


@pytest.mark.parametrize("argv_tail, section, message", [
    (["--cycle", "wltc"], None, "--cycle wltc: unknown cycle 'wltc' (did you mean: wltc3b?)"),
    (["--cycle", "bad.csv"], None, "bad.csv: row 4: time_s 1 is before the previous time_s 2; time must increase"),
    (["--cycle", "neg.csv"], None, "neg.csv: row 3: speed_kmh -1 is negative"),
    ([], ('name = "udds"\nfile = "cyc.csv"', ""), "[cycle]: give exactly one of 'name'"),
    ([], ('name = "hwfet"\nspeed = 1', ""), "[cycle]: unknown key 'speed'"),
    ([], ('name = "us6"', ""), "[cycle].name: unknown cycle 'us6' (did you mean: us06"),
    ([], ('file = "cyc.csv"\nr_w = -0.3', ""), "[cycle]: r_w [m] must be a finite number > 0"),
    ([], ("", 'name = "hily"'), "[road].name: unknown road profile 'hily' (did you mean: hilly?)"),
    ([], ("", 'file = "steep.csv"'), "steep.csv: row 3: grade_pct 60 is a grade of 60 %"),
    ([], ("", 'file = "none.csv"'), "none.csv: road profile file not found"),
    ([], ("", 'name = "hilly"\ninstance = "plant"'), "instance name 'plant' is used by a component"),
    (["--set", "plant.r_w=abc"], ('file = "cyc.csv"', ""), "plant.r_w = 'abc' is not a number"),
])
def test_bad_input_is_one_line_exit_2_nothing_written(tmp_path, capsys, monkeypatch, argv_tail, section, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.csv").write_text("time_s,speed_kmh\n0,0\n2,1\n1,2\n", encoding="utf-8")
    (tmp_path / "neg.csv").write_text("time_s,speed_kmh\n0,0\n1,-1\n", encoding="utf-8")
    (tmp_path / "steep.csv").write_text("distance_m,grade_pct\n0,0\n10,60\n", encoding="utf-8")
    system = "scenario1" if section is None else str(system_file(tmp_path, cycle=section[0], road=section[1]))
    out = tmp_path / "out"
    assert main(["run", system, "--out", str(out), "--quiet", *argv_tail]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ") and message in err, err
    assert not out.exists()


def test_a_cycle_error_is_a_cosim_or_profile_error_of_one_line():
    with pytest.raises(CosimError, match="unknown cycle 'udd'"):
        apply_overrides("scenario1", cycle="udd")


def test_a_shipped_road_by_name_becomes_a_component_and_its_connections(tmp_path):
    """[road] name = "hilly": a RouteProfile component 'road' last in the order, the paper's delta table
    dropped, the recorded delta_deg taken from road.delta (in deg); the system keeps everything else."""
    spec = apply_overrides(str(system_file(tmp_path, cycle="", road='name = "hilly"', stop_time=60.0)))
    assert [c.name for c in spec.components] == ["ctrl", "plant", "road"]
    road = spec.components[-1]
    assert road.fmu.name == "RouteProfile.fmu" and road.start == {"road": "hilly"}
    assert "delta" not in spec.signals and spec.signals["omega_ref"].origin == "table"
    conns = [str(c) for c in spec.connections]
    assert conns[-2:] == ["plant.x_vehicle -> road.x", "road.delta -> plant.delta"]
    column = next(c for c in spec.columns if c.name == "delta_deg")
    assert (column.kind, column.instance, column.variable, column.unit) == ("variable", "road", "delta", "deg")
    assert spec.stop_time == 60.0  # the file's: no cycle to take it from
    with pytest.raises(CosimError, match=r"\[experiment\] needs stop_time"):  # and without one, none
        apply_overrides(str(system_file(tmp_path, cycle="", road='name = "hilly"')))


def test_simulate_takes_a_cycle(fmus):
    import pmsm_cosim

    result, metrics = pmsm_cosim.simulate("scenario1", cycle="us06", stop_time=0.5, controller="sensored")
    assert metrics["status"] == "completed" and metrics["trace"]["cycle"] == "us06"
    assert metrics["trace"]["t_end"] == 0.5 and metrics["settings"]["signals"]["omega_ref"]["origin"].startswith(
        "cycle us06")
