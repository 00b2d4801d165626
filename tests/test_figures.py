"""Figures 6-17 from a small synthetic results.csv."""

import math

import numpy as np
import pytest

from pmsm_cosim.app import figures
from pmsm_cosim.app.figures import FiguresError, figure_plan, make_figures, unwrap_with_speed
from pmsm_ev.results import ALL_COLUMNS

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

SCENARIO1_NAMES = ["fig06_elevation.png", "fig08_speed_reference.png", "fig09_speed.png",
                   "fig10_speed_zoom.png", "fig13_angle.png", "fig14_currents.png",
                   "fig16_load_torque.png"]
SCENARIO2_NAMES = ["fig07_elevation.png", "fig08_speed_reference.png", "fig11_speed.png",
                   "fig12_speed_zoom.png", "fig13_angle.png", "fig15_currents.png",
                   "fig17_load_torque.png"]
GENERIC_NAMES = ["elevation.png", "speed_reference.png", "speed.png", "speed_zoom.png",
                 "angle.png", "currents.png", "load_torque.png"]


def synthetic_columns(stop=6.0, dt=0.01, t_step=3.0, n_pole=4):
    """A run-like record: speed ramp to 200 rad/s, a 0 -> 10 deg step at t_step with a
    speed dip, an estimate slightly off, angles integrated from the speeds."""
    t = np.round(np.arange(0.0, stop + dt / 2, dt), 10)
    delta = np.where(t >= t_step, 10.0, 0.0)
    omega_ref = np.minimum(200.0, 200.0 * t / 1.0)
    dip = np.where(t >= t_step, -12.0 * (t - t_step) * np.exp(-(t - t_step) / 0.5) / 0.5, 0.0)
    omega_m = omega_ref + dip
    omega_hat = omega_m + 0.2 * np.sin(3 * t)
    theta_c = np.concatenate([[0.0], np.cumsum(0.5 * (omega_m[1:] + omega_m[:-1]) * np.diff(t))]) * n_pole
    theta_hat_c = theta_c + 0.05 * np.sin(t)
    wrap = lambda a: (a + math.pi) % (2 * math.pi) - math.pi  # noqa: E731
    T_L = 3.0 + np.where(t >= t_step, 40.0, 0.0)
    cols = {
        "time": t, "delta_deg": delta, "omega_ref": omega_ref, "omega_m": omega_m,
        "omega_hat": omega_hat, "theta_e": wrap(theta_c), "theta_hat": wrap(theta_hat_c),
        "i_d": 0.01 * np.sin(7 * t), "i_q": T_L / 0.36, "i_d_hat": 0.01 * np.sin(7 * t),
        "i_q_hat": T_L / 0.36, "T_e": T_L, "T_L_mech": T_L, "T_L_hat": T_L + 0.5 * np.cos(t),
        "v_d": -50 + 0 * t, "v_q": 70 + 0 * t,
    }
    for name in ALL_COLUMNS:
        cols.setdefault(name, 0.1 * np.cos(t))
    return cols


def write_csv(path, cols, columns=ALL_COLUMNS):
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = np.column_stack([cols[c] for c in columns])
    with open(path, "w", encoding="ascii") as fh:
        fh.write(",".join(columns) + "\n")
        for row in rows:
            fh.write(",".join(repr(float(v)) for v in row) + "\n")
    return path


@pytest.fixture
def run_dir(tmp_path):
    d = tmp_path / "run"
    write_csv(d / "results.csv", synthetic_columns())
    return d


def check_pngs(paths):
    for p in paths:
        data = p.read_bytes()
        assert data[:8] == PNG_MAGIC, p
        assert len(data) > 8000, (p, len(data))


@pytest.mark.parametrize("label, names", [
    ("scenario1", SCENARIO1_NAMES), ("scenario2", SCENARIO2_NAMES),
    (None, GENERIC_NAMES), ("custom", GENERIC_NAMES),
])
def test_make_figures_writes_one_png_per_figure(run_dir, label, names):
    paths = make_figures(run_dir, scenario_label=label)
    assert [p.name for p in paths] == names
    assert all(p.parent == run_dir / "figures" for p in paths)
    assert sorted(p.name for p in (run_dir / "figures").iterdir()) == sorted(names)
    check_pngs(paths)


def test_out_dir_and_csv_path(run_dir, tmp_path):
    out = tmp_path / "elsewhere"
    paths = make_figures(run_dir / "results.csv", out_dir=out, scenario_label="scenario1")
    assert [p.parent for p in paths] == [out] * len(SCENARIO1_NAMES)
    assert not (run_dir / "figures").exists()
    check_pngs(paths)


def test_plan_numbers_and_titles():
    p1, p2 = figure_plan("scenario1"), figure_plan("scenario2")
    assert [p1[k][0][:5] for k in p1] == ["fig06", "fig08", "fig09", "fig10", "fig13", "fig14", "fig16"]
    assert [p2[k][0][:5] for k in p2] == ["fig07", "fig08", "fig11", "fig12", "fig13", "fig15", "fig17"]
    assert p1["speed"][1].startswith("Fig. 9, scenario 1:")
    assert p2["speed"][1].startswith("Fig. 11, scenario 2:")
    assert p2["angle"][1].startswith("Fig. 13, scenario 2:")
    assert p1["load_torque"][1].startswith("Fig. 16, scenario 1:")
    assert p2["currents"][1].startswith("Fig. 15, scenario 2:")
    # the same label in other spellings; anything else is generic
    assert figure_plan("Scenario 2") == p2 and figure_plan("2") == p2
    generic = figure_plan("hill")
    assert all(not name.startswith("fig") for name, _ in generic.values())
    assert all("Fig." not in title and "(hill)" in title for _, title in generic.values())


def test_no_elevation_change_skips_zoom(tmp_path):
    cols = synthetic_columns()
    cols["delta_deg"] = np.zeros_like(cols["time"])
    write_csv(tmp_path / "flat" / "results.csv", cols)
    paths = make_figures(tmp_path / "flat", scenario_label="scenario1")
    assert "fig10_speed_zoom.png" not in [p.name for p in paths]
    assert len(paths) == len(SCENARIO1_NAMES) - 1


def test_finely_sampled_angle_is_drawn_from_the_rows(tmp_path):
    cols = synthetic_columns(stop=2.0, dt=0.001, t_step=1.5)
    write_csv(tmp_path / "fine" / "results.csv", cols)
    paths = make_figures(tmp_path / "fine")
    check_pngs(paths)


def test_unwrap_with_speed_recovers_fast_angle():
    # 800 rad/s electrical sampled every 10 ms: 8 rad per row, beyond np.unwrap
    t = np.arange(0.0, 1.0, 0.01)
    omega_e = 800.0 + 10.0 * t
    theta = 800.0 * t + 5.0 * t ** 2
    wrapped = (theta + math.pi) % (2 * math.pi) - math.pi
    got = unwrap_with_speed(t, wrapped, omega_e)
    assert np.allclose(got - got[0], theta - theta[0], atol=1e-9)


def test_envelope_keeps_extremes():
    t = np.linspace(0.0, 350.0, 35001)
    y = np.sin(t)
    y[12345] = 50.0
    y[23456] = -50.0
    tt, yy = figures.envelope(t, y, buckets=500)
    assert len(yy) <= 1001
    assert yy.max() == 50.0 and yy.min() == -50.0
    assert np.all(np.diff(tt) > 0) and tt[-1] == t[-1]


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(FiguresError, match="results.csv: results file not found"):
        make_figures(tmp_path / "nothing")


@pytest.mark.parametrize("content, reason", [
    ("", "empty"),
    ("time,delta_deg\n0,0\n1,0\n", "missing columns: omega_ref"),
    (",".join(ALL_COLUMNS) + "\n" + ",".join(["0"] * len(ALL_COLUMNS)) + "\n", "at least 2 data rows"),
    (",".join(ALL_COLUMNS) + "\n" + ",".join(["x"] * len(ALL_COLUMNS)) + "\n", "malformed"),
])
def test_malformed_file_is_a_clear_error(tmp_path, content, reason):
    path = tmp_path / "bad" / "results.csv"
    path.parent.mkdir()
    path.write_text(content, encoding="ascii")
    with pytest.raises(FiguresError) as info:
        make_figures(path.parent)
    assert str(path) in str(info.value) and reason in str(info.value)


def test_cli_prints_paths(run_dir, capsys):
    assert figures.main([str(run_dir), "--scenario", "scenario2"]) == 0
    out = capsys.readouterr().out.split()
    assert [p.rsplit("/", 1)[-1] for p in out] == SCENARIO2_NAMES


def test_cli_missing_file_exits_2_with_one_line(tmp_path, capsys):
    assert figures.main([str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ") and "results.csv" in err


def test_cli_help(capsys):
    with pytest.raises(SystemExit) as info:
        figures.main(["--help"])
    assert info.value.code == 0
    assert "RUN_DIR" in capsys.readouterr().out
