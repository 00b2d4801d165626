"""The whole speed range through the FMUs and the command line: the shipped acceleration scenarios with
controllers swapped in (the first seconds: the launch into field weakening), the energy balance of a
co-simulated run, and ``pmsm-cosim envelope`` (its figures of the reference generator and the loss model,
its one-line errors)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app import envelope
from pmsm_cosim.app.cli import main
from pmsm_cosim.engine.recording import read_results
from pmsm_ev import losses, references
from pmsm_ev.params import ControllerParams, MotorParams

#: the launch's first seconds: past 50 km/h (about 2.2 s after the 2.5 s launch, sensored) into field weakening
STOP = 6.0


@pytest.fixture(scope="module")
def fmus():
    return project_fmus()


def _run(tmp_path, *argv):
    out = tmp_path / "run"
    assert main(["run", *argv, "--stop-time", str(STOP), "--no-figures", "--quiet", "--out", str(out)]) == 0
    return read_results(out), json.loads((out / "metrics.json").read_text())


@pytest.mark.parametrize("scenario, controller", [("acceleration", None), ("acceleration", "sensorless"),
                                                  ("acceleration-if", "sensored"),
                                                  ("acceleration-flying", None)])
def test_the_acceleration_launches_into_field_weakening_with_any_controller(fmus, tmp_path, scenario, controller):
    argv = [scenario] + (["--controller", controller] if controller else [])
    r, m = _run(tmp_path, *argv)
    assert m["status"] == "completed"
    a = m["acceleration"]
    print(f"{scenario} {controller or ''}: 0-50 km/h {a['t_0_50']:.2f} s from {a['v_launch_kmh']:.1f} km/h, "
          f"{r['v_vehicle'][-1] * 3.6:.1f} km/h at {STOP:g} s, regions {sorted(set(r['ref_region'].tolist()))}")
    # full torque from the launch: MTPA at T_max (153 N m: 6.6 m/s^2 on 900 kg less the road) reaches 50 km/h
    # in 2.1 s at the least; the sensorless unit's I-f start and a flying start's head start change that
    assert 1.0 < a["t_0_50"] < 3.5
    assert r["v_vehicle"][-1] * 3.6 > 60.0  # 70 km/h sensored, 3.5 s after the launch
    assert {1.0, 3.0} & set(r["ref_region"].tolist())  # field weakening reached (base speed 367 rad/s)
    assert float(np.max(r["T_e"])) == pytest.approx(153.1, abs=1.5)  # T_max on MTPA at I_max
    assert np.max(np.hypot(r["i_d"], r["i_q"])) < 400.0 * 1.02  # the current limit holds
    e = m["energy"]
    assert abs(e["residual_Wh"]) < 1e-6 * e["drawn_Wh"]  # the balance closes through the FMUs
    if "synchronism" in m:
        assert m["synchronism"]["slipped_turns"] == 0


def test_envelope_of_the_paper_motor(tmp_path, capsys):
    out = tmp_path / "env"
    assert main(["envelope", "--no-efficiency", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "T_max 153.1 N m at I_max 400 A; base speed 367 rad/s, MTPV from none, max speed 5225 rad/s" in printed
    s = json.loads((out / "envelope.json").read_text())
    m = MotorParams()
    u_fw = 0.9 * 360.0 / math.sqrt(3.0)
    assert s["speeds"]["max_speed"] == pytest.approx(u_fw / (m.N * (m.psi - m.L_d * 400.0)), rel=1e-9)
    assert s["speeds"]["mtpv_speed"] is None and (out / "envelope.png").stat().st_size > 10_000


def test_envelope_of_a_motor_that_reaches_mtpv(tmp_path, capsys):
    out = tmp_path / "env"
    assert main(["envelope", "--no-efficiency", "--set", "L_d=0.3e-3", "L_q=0.45e-3", "--out", str(out)]) == 0
    s = json.loads((out / "envelope.json").read_text())
    # psi / L_d = 299 A < I_max: MTPV from some speed on, and torque left at any speed
    assert s["speeds"]["mtpv_speed"] is not None and s["speeds"]["max_speed"] is None
    assert s["speeds"]["base_speed"] < s["speeds"]["mtpv_speed"]


@pytest.mark.parametrize("argv, message", [
    (["--set", "L_x=1"], "no such parameter"),
    (["--set", "i_max=-1"], "i_max must be > 0"),
    (["--set", "T_max=500"], "T_max"),
    (["--set", "reference=fw", "v_dc=0"], "needs the DC-link voltage"),
    (["--set", "P_regen_max=-1"], "P_regen_max must be >= 0"),
    (["--run", "nowhere"], "no results.csv"),
])
def test_envelope_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "env"
    assert main(["envelope", "--no-efficiency", "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and message in err[0], err
    assert not out.exists()


def test_efficiency_map_follows_the_losses():
    p = envelope.parameters()
    lim = references.limits(p["controller"], p["motor"])
    em = envelope.efficiency_map(p, lim, 1500.0, n_speeds=6, n_torques=6)
    eff = em["efficiency"]
    finite = eff[np.isfinite(eff)]
    print(f"efficiency map 6 x 6 up to 1500 rad/s: {finite.min():.3f} .. {finite.max():.3f}")
    assert finite.size >= 16 and np.all((finite > 0.5) & (finite < 1.0))
    # at a large torque (92 N m) the copper losses, ~ i^2, weigh most at the lowest speed (the least power out)
    row = eff[4]
    assert em["T"][4] == pytest.approx(0.6 * lim.T_max)
    assert np.count_nonzero(np.isfinite(row)) >= 2 and row[0] < np.nanmax(row)
    # the inverter's losses cost efficiency: the same map without them is better everywhere
    p_ideal = envelope.parameters(["inverter_losses=false"])
    ideal = envelope.efficiency_map(p_ideal, lim, 1500.0, n_speeds=6, n_torques=6)["efficiency"]
    both = np.isfinite(eff) & np.isfinite(ideal)
    assert np.all(ideal[both] > eff[both])


def test_the_efficiency_contour_starts_where_the_losses_say():
    """level_torques: at each speed the plant's steady-state efficiency is below 90 % just under the torque it
    gives and above it just over (the losses of that operating point, not a grid's value)."""
    p = envelope.parameters()
    lim = references.limits(p["controller"], p["motor"])
    found = envelope.level_torques(p, lim, speeds=(150.0, 1500.0))
    for f in found:
        effs = []
        for t in (f["T_from"] - 0.5, f["T_from"] + 0.5):
            ops = references.operating_points(np.array([t]), np.array([f["omega"]]), lim)
            s = losses.steady_state(p["motor"], p["plant"], p["vehicle"], float(ops.i_d[0, 0]), float(ops.i_q[0, 0]),
                                    f["omega"])
            effs.append(s["efficiency"])
        assert effs[0] < 0.9 < effs[1], (f, effs)
        assert 0.9 < f["best"] < 1.0
    # the iron losses at full flux raise the contour at low speed; field weakening lowers it at high speed
    assert found[0]["T_from"] > found[1]["T_from"]


def test_the_envelope_is_the_controllers():
    """The command's envelope is the reference generator's (the same limits the controller runs)."""
    p = envelope.parameters(["i_max=300"])
    lim = references.limits(p["controller"], p["motor"])
    assert lim == references.limits(ControllerParams(reference="fw", v_dc=360.0, i_max=300.0), MotorParams())
    assert p["plant"].v_dc == 360.0 and p["controller"].i_max == 300.0


def test_a_hill_steeper_than_the_torque_is_not_an_error(fmus, tmp_path):
    """A 60 deg climb asks for more than T_max (153.1 N m holds the car on at most ~50 deg): the run completes,
    the car rolls back at full torque, and metrics.json says where and by how much it fell behind."""
    (tmp_path / "cliff.csv").write_text("time,delta\n0,60\n", encoding="utf-8")
    (tmp_path / "ref.csv").write_text("time,omega_ref\n0,0\n1,200\n", encoding="utf-8")
    out = tmp_path / "run"
    assert main(["run", "acceleration", "--profile", f"delta={tmp_path / 'cliff.csv'}", "--profile",
                 f"omega_ref={tmp_path / 'ref.csv'}", "--stop-time", "4", "--no-figures", "--quiet", "--out",
                 str(out)]) == 0
    m = json.loads((out / "metrics.json").read_text())
    r = read_results(out)
    print(f"60 deg: behind {m['behind']}, T_e max {np.max(r['T_e']):.1f} N m, x at 4 s {r['x_vehicle'][-1]:.2f} m")
    assert m["status"] == "completed"
    assert float(np.max(r["T_e"])) == pytest.approx(153.1, abs=1.0)  # full torque, to no avail
    assert r["x_vehicle"][-1] < -1.0  # it rolls back
    b = m["behind"]
    assert b["episodes"] >= 1 and b["largest_kmh"] > 200.0 * 0.2933 / 12.5 * 3.6  # more than the whole reference
    assert b["first"][1] == pytest.approx(4.0, abs=0.011)  # behind to the end
