"""The controller FMUs' own sample clock in a co-simulation (fmus/README.md, "Co-simulation
semantics"): plant and controller both stepped at h = dt/3 with the controller's ``dt`` set
to 1e-4 s, scenario 2, Gauss-Seidel (controller first), 0.5 s.

* The controller runs one period at each multiple of dt (at the step from k dt, on the
  plant's currents there) and none at the two steps between, so its outputs change only
  at multiples of dt.
* The plant integrates the same held voltage in three RK4 steps of dt/3 instead of one of
  dt: the trajectory stays within 1e-9 (relative and absolute) of the h = dt run, the
  plant's finer integration (measured: 6e-11 A, 5e-12 rad/s), and within 1e-11 of the
  h = dt run whose plant takes three RK4 sub-steps (``rk4_substeps = 3``: the same
  integration, up to round-off).
* The same controller stepped once per dt beside the plant at dt/3 (``step_multiple = 3``)
  gives the same run, number for number.
* h = dt is bit-identical to the monolithic reference: ``tests/test_equality.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from orchestrator_support import project_fmus
from pmsm_cosim.app.drive import load_system
from pmsm_cosim.engine.master import Master
from pmsm_cosim.engine.recording import read_results
from pmsm_ev.results import ALL_COLUMNS

DT = 1e-4
STOP = 0.5
CTRL_COLUMNS = ("omega_hat", "theta_hat", "i_d_hat", "i_q_hat", "T_L_hat", "v_d", "v_q", "v_alpha", "v_beta",
                "i_qref")


@pytest.fixture(scope="module")
def fmus():
    return project_fmus()


def scenario2(fmus, out, step, *starts, ctrl_multiple=1) -> dict:
    spec = load_system("scenario2")
    spec.set_fmu("ctrl", fmus["FocEkf5"])
    spec.set_fmu("plant", fmus["PmsmEvPlant"])
    for assignment in starts:
        spec.set_start(assignment)
    spec.components[[c.name for c in spec.components].index("ctrl")].step_multiple = ctrl_multiple
    spec.step_size, spec.stop_time, spec.output_interval, spec.algorithm = step, STOP, step, "gauss-seidel"
    assert Master(spec).run(out, catch_sigint=False)["status"] == "completed"
    return read_results(out)


@pytest.fixture(scope="module")
def runs(fmus, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("clock")
    return {
        "dt": scenario2(fmus, tmp / "dt", DT),
        "dt/3": scenario2(fmus, tmp / "dt3", DT / 3, f"ctrl.dt={DT!r}"),
        "dt, 3 substeps": scenario2(fmus, tmp / "sub", DT, "plant.rk4_substeps=3"),
        "dt/3, ctrl every 3": scenario2(fmus, tmp / "multiple", DT / 3, ctrl_multiple=3),
    }


def test_the_controllers_outputs_change_only_at_multiples_of_dt(runs):
    r = runs["dt/3"]
    assert len(r["time"]) == 3 * round(STOP / DT) + 1
    for col in CTRL_COLUMNS:
        changed = np.nonzero(np.diff(r[col]))[0]  # row n + 1 differs from row n: a period in the step from t_n
        assert set(changed % 3) == {0}, col
    # ... and a period at every multiple of dt: v_q moves at nearly all of them
    assert len(np.nonzero(np.diff(r["v_q"]))[0]) > 0.95 * STOP / DT


def test_the_trajectory_at_dt_over_3_stays_within_the_plants_finer_integration(runs):
    fine, coarse, substeps = runs["dt/3"], runs["dt"], runs["dt, 3 substeps"]
    for col in ALL_COLUMNS:
        np.testing.assert_allclose(fine[col][::3], coarse[col], rtol=1e-9, atol=1e-9, err_msg=col)
        np.testing.assert_allclose(fine[col][::3], substeps[col], rtol=1e-11, atol=1e-11, err_msg=col)
    worst = max(float(np.max(np.abs(fine[c][::3] - coarse[c]))) for c in ALL_COLUMNS)
    assert 0.0 < worst  # the finer integration is not the same numbers
    assert coarse["omega_m"][-1] > 5.0  # the drive follows the ramp


def test_a_clocked_controller_equals_one_stepped_at_its_period(runs):
    a, b = runs["dt/3"], runs["dt/3, ctrl every 3"]
    for col in ALL_COLUMNS:
        np.testing.assert_array_equal(a[col], b[col], err_msg=col)
