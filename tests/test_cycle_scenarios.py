"""The shipped drive-cycle scenarios (issue "Standard drive cycles"; docs/cycles.md): each lasts its cycle,
drives its trace through the sampled PCHIP reference with the speed loop's feedforward and 1 A of current
noise, and runs with any controller; a stretch of US06 with a stop and restart stays in the tolerance band
truly sensorless from rotor angles the unit was not told, and a stop and restart on the 10 % climb of the
hilly road holds the car, sensored and sensorless. The whole cycles are the report's (docs/results.md,
"Drive cycles"): here the slices a user would try first."""

from __future__ import annotations

import json

import numpy as np
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app.cli import main
from pmsm_cosim.app.cycles import CycleSignal
from pmsm_cosim.app.drive import PACKAGED_SCENARIOS, load_system
from pmsm_cosim.engine.recording import read_results
from pmsm_ev import cycles

CYCLES = ("wltc3b", "udds", "hwfet", "us06")
SCENARIOS = [c for c in CYCLES] + [f"{c}-sensorless" for c in CYCLES] + ["wltc3b-hilly"]


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
    assert ctrl.fmu.name == ("FocSensorless.fmu" if name.endswith("-sensorless") else "FocSensored.fmu")
    assert ctrl.start["reference"] == "fw" and ctrl.start["speed_feedforward"] == "inertia+road"
    assert plant.start["sensor_noise"] == 1.0
    roads = [c for c in spec.components if c.name == "road"]
    assert len(roads) == (1 if name.endswith("-hilly") else 0)
    # the reference's top speed is the cycle's at the motor: v n_g / r_w, Table II
    assert max(sig.profile.values) == pytest.approx(cycle.top_speed * 12.5 / 0.2933, rel=1e-3)


@pytest.mark.parametrize("theta0", [2.2, -1.9])
def test_us06_sensorless_through_a_stop_and_restart_from_an_angle_it_was_not_told(fmus, tmp_path, capsys, theta0):
    """The first 60 s of US06 (a launch to 74 km/h, a stop at 41-48 s, a restart) truly sensorless, the
    rotor parked at theta_e0 (the unit aligns at an unknown angle), 1 A of current noise: inside the
    +-2 km/h band all the way, no electrical turn slipped, no loss of synchronism, and the unit went
    I-f -> EKF -> I-f (the stop) -> EKF. The run prints the band's figures and the energy."""
    r, m = _run(tmp_path, "us06", 60, "us06-sensorless", "--set", f"plant.theta_e0={theta0}")
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
