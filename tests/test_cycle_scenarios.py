"""The shipped drive-cycle scenarios (issue "Standard drive cycles"; docs/cycles.md): each lasts its cycle,
drives its trace through the sampled PCHIP reference with the speed loop's feedforward and 1 A of current
noise, and runs with any controller; a stretch of US06 with a stop and restart stays in the tolerance band
truly sensorless from rotor angles the unit was not told, and a stop and restart on the 10 % climb of the
hilly road holds the car, sensored and sensorless. The whole cycles are the report's (docs/results.md,
"Drive cycles"): here the slices a user would try first."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app.cli import main
from pmsm_cosim.app.cycles import CycleSignal
from pmsm_cosim.app.drive import PACKAGED_SCENARIOS, load_system
from pmsm_cosim.engine.recording import read_results
from pmsm_ev import cycles

CYCLES = ("wltc3b", "udds", "hwfet", "us06")
SCENARIOS = ([c for c in CYCLES] + [f"{c}-sensorless" for c in CYCLES] + [f"{c}-if" for c in CYCLES]
             + ["wltc3b-hilly", "wltc3b-battery", "wltc3b-battery-sensorless"])


@pytest.fixture(scope="module")
def fmus():
    return project_fmus()


def _run(tmp_path, name, stop, *argv):
    out = tmp_path / name
    assert main(["run", *argv, "--stop-time", str(stop), "--no-figures", "--quiet", "--out", str(out)]) == 0
    return read_results(out), json.loads((out / "metrics.json").read_text())


@pytest.mark.parametrize("name", SCENARIOS)
def test_a_shipped_cycle_scenario_lasts_its_cycle_with_the_drive_of_the_speed_range(name):
    assert name in PACKAGED_SCENARIOS
    spec = load_system(name)
    cycle = cycles.load(name.split("-")[0])
    assert spec.stop_time == cycle.duration
    sig = spec.signals["omega_ref"]
    assert isinstance(sig, CycleSignal) and sig.cycle.name == cycle.name
    assert ("ctrl", "omega_ref") in [tuple(d) for d in sig.drives]
    ctrl = next(c for c in spec.components if c.name == "ctrl")
    plant = next(c for c in spec.components if c.name == "plant")
    sensorless = name.endswith(("-sensorless", "-if"))
    assert ctrl.fmu.name == ("FocSensorless.fmu" if sensorless else "FocSensored.fmu")
    # the shipped sensorless drives use injection on the saturating plant; the -if ones the I-f strategy on
    # the plain plant (docs/sensorless.md, "Which strategy the shipped scenarios use")
    assert (ctrl.start.get("low_speed"), plant.start.get("flux_model")) == (
        ("injection", "algebraic") if name.endswith("-sensorless") else
        ("if", None) if name.endswith("-if") else (None, None))
    assert ctrl.start["reference"] == "fw" and ctrl.start["speed_feedforward"] == "inertia+road"
    assert plant.start["sensor_noise"] == 1.0
    # on the battery (docs/speed-range.md, "The battery"): from 90 %, the controller on the measured DC link
    assert (plant.start.get("battery"), plant.start.get("bat_soc0")) == (
        ("ecm", 0.9) if "-battery" in name else (None, None))
    roads = [c for c in spec.components if c.name == "road"]
    assert len(roads) == (1 if name.endswith("-hilly") else 0)
    # the reference's top speed is the cycle's at the motor: v n_g / r_w, Table II
    assert max(sig.profile.values) == pytest.approx(cycle.top_speed * 12.5 / 0.2933, rel=1e-3)


@pytest.mark.parametrize("theta0", [0.9, -2.6])
def test_us06_with_injection_through_a_stop_and_restart_from_an_angle_it_was_not_told(fmus, tmp_path, theta0):
    """The first 60 s of US06 with injection at and near zero speed, the rotor parked at theta_e0, 1 A of
    noise, the plant's algebraic flux model: inside the +-2 km/h band all the way, no turn slipped, no
    episode, the car standing at the stop, and the unit went acquire -> polarity -> injection -> EKF ->
    injection (the stop) -> EKF."""
    r, m = _run(tmp_path, "us06i", 60, "us06-sensorless", "--set", f"plant.theta_e0={theta0}")
    trace, sync = m["trace"], m["synchronism"]
    assert m["status"] == "completed"
    assert trace["inside_share"] == 1.0 and trace["rmse_kmh"] < 0.6
    assert sync["slipped_turns"] == 0 and sync["episodes"] == 0 and not sync["fault_latched"]
    modes = [int(to) for _, _, to in m["sensorless"]["mode_changes"]]
    assert modes[:5] == [4, 5, 2, 5, 2]
    stop = (r["time"] > 42.0) & (r["time"] < 47.5)
    assert np.all(np.abs(r["v_vehicle"][stop]) < 0.05)


@pytest.mark.parametrize("theta0", [2.2, -1.9])
def test_us06_sensorless_through_a_stop_and_restart_from_an_angle_it_was_not_told(fmus, tmp_path, capsys, theta0):
    """The first 60 s of US06 (a launch to 74 km/h, a stop at 41-48 s, a restart) truly sensorless, the
    rotor parked at theta_e0 (the unit aligns at an unknown angle), 1 A of current noise: inside the
    +-2 km/h band all the way, no electrical turn slipped, no loss of synchronism, and the unit went
    I-f -> EKF -> I-f (the stop) -> EKF. The run prints the band's figures and the energy."""
    r, m = _run(tmp_path, "us06", 60, "us06-if", "--set", f"plant.theta_e0={theta0}")
    trace, sync, energy = m["trace"], m["synchronism"], m["energy"]
    printed = capsys.readouterr().out
    assert f"cycle us06: inside the +-2 km/h band {100 * trace['inside_share']:.2f} % of 60 s" in printed
    assert f"energy: {energy['dc_Wh_per_km']:.1f} Wh/km at the DC link" in printed
    print(f"\ntheta_e0 {theta0}: band {100 * trace['inside_share']:.2f} %, RMSE {trace['rmse_kmh']:.2f} km/h, "
          f"largest {trace['max_deviation_kmh']:+.2f} km/h at {trace['t_max_deviation']:.2f} s; slipped "
          f"{sync['slipped_turns']}, episodes {sync['episodes']}; modes {m['sensorless']['mode_changes']}")
    assert m["status"] == "completed"
    assert trace["inside_share"] == 1.0 and trace["rmse_kmh"] < 0.6
    assert sync["slipped_turns"] == 0 and sync["episodes"] == 0 and not sync["fault_latched"]
    modes = [int(to) for _, _, to in m["sensorless"]["mode_changes"]]
    assert modes[:4] == [1, 2, 1, 2]
    stop = (r["time"] > 42.0) & (r["time"] < 47.5)
    assert np.all(np.abs(r["v_vehicle"][stop]) < 0.05)  # it stands at the stop (< 0.18 km/h)


@pytest.mark.parametrize("controller", [None, "sensorless"])
@pytest.mark.slow
def test_a_stop_and_restart_on_the_ten_percent_climb(fmus, tmp_path, controller):
    """WLTC 3b on the hilly road by position: its first stop (99-137 s) falls at 614 m, on the 10 % climb;
    the car stands on it and drives on uphill, sensored and truly sensorless, inside the band."""
    argv = ["wltc3b-hilly"] + (["--controller", controller] if controller else [])
    r, m = _run(tmp_path, "hilly", 160, *argv)
    trace = m["trace"]
    stand = (r["time"] > 101.0) & (r["time"] < 136.0)
    x_stand = r["x_vehicle"][stand]
    print(f"\n{controller or 'sensored'}: band {100 * trace['inside_share']:.2f} %, RMSE {trace['rmse_kmh']:.2f} "
          f"km/h; stands at {x_stand[0]:.1f} m on {np.tan(np.radians(r['delta_deg'][stand][0])) * 100:.1f} %, "
          f"moves {1000 * (x_stand.max() - x_stand.min()):.1f} mm; x at 160 s {r['x_vehicle'][-1]:.1f} m")
    assert m["status"] == "completed"
    assert np.tan(np.radians(r["delta_deg"][stand])).min() > 0.095  # on the climb
    assert x_stand.max() - x_stand.min() < 0.05  # held within 5 cm
    assert trace["inside_share"] >= 0.99
    if controller:
        assert m["synchronism"]["slipped_turns"] == 0


def test_a_cycle_that_moves_before_the_alignment_ends(fmus, tmp_path, monkeypatch):
    """A user's cycle that asks to move at 1 s, before the sensorless unit has aligned (2.35 s): the unit
    aligns first, then catches up through I-f into FOC, no turn slipped; the band's figures name the one
    excursion, at the start and about as long as the alignment still had to run, and nothing after it."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "early.csv").write_text("time_s,speed_kmh\n0,0\n1,5\n4,25\n10,50\n15,50\n20,0\n25,0\n")
    r, m = _run(tmp_path, "early", 25, "us06-if", "--cycle", "early.csv")
    trace, sync = m["trace"], m["synchronism"]
    print(f"\nexcursions {trace['excursion_lengths_s']} from {trace['t_longest_excursion']:.2f} s; modes "
          f"{m['sensorless']['mode_changes']}; slipped {sync['slipped_turns']}")
    assert trace["excursions"] == 1 and trace["t_longest_excursion"] < 2.0
    assert 1.5 < trace["longest_excursion_s"] < 3.0
    assert trace["t_longest_excursion"] + trace["longest_excursion_s"] < 4.5
    assert sync["slipped_turns"] == 0 and sync["episodes"] == 0
    assert m["sensorless"]["mode_changes"][0][0] == pytest.approx(2.35, abs=0.05)
    late = r["time"] > 6.0
    assert np.max(np.abs(r["omega_ref"][late] - r["omega_m"][late])) < 15.0  # caught up: < 1.3 km/h


@pytest.mark.parametrize("name", [f"{c}-sensorless" for c in CYCLES] + ["acceleration-sensorless",
                                                                        "hill-start-injection"])
def test_the_sensored_drive_swaps_into_a_sensorless_scenario(fmus, tmp_path, capsys, name):
    """``--controller sensored`` on a scenario written for the sensorless unit: its ``low_speed`` (a variable
    FocSensored does not have) is left out with a note, the run completes; the user's own ``--set`` of it is
    refused as before."""
    out = tmp_path / "swap"
    assert main(["run", name, "--controller", "sensored", "--stop-time", "0.01", "--no-figures", "--out",
                 str(out)]) == 0
    err = capsys.readouterr().err
    assert "start value ctrl.low_speed = 'injection'" in err and "FocSensored.fmu has no such variable" in err
    m = json.loads((out / "metrics.json").read_text())
    assert m["status"] == "completed"
    assert main(["run", name, "--controller", "sensored", "--set", "ctrl.low_speed=if", "--stop-time", "0.01",
                 "--no-figures", "--out", str(tmp_path / "refused")]) == 2
    assert "has no variable 'low_speed'" in capsys.readouterr().err
    assert not (tmp_path / "refused").exists()
    # so does its SSP package: the sensored drive's, without the sensorless unit's parameter
    assert main(["export-ssp", name, "--controller", "sensored", "-o", str(tmp_path / "p.ssp")]) == 0
    with zipfile.ZipFile(tmp_path / "p.ssp") as z:
        assert not any(b"low_speed" in z.read(n) for n in z.namelist() if n.endswith((".ssd", ".ssv")))
