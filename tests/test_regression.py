"""Pinned short runs: performance work must not move results (1e-12 relative)."""

import numpy as np
import pytest

from pmsm_cosim.engine.recording import read_results
from pmsm_ev.results import CONTRACT_COLUMNS
from regression_runs import CASES, fixture_path, run_case


@pytest.mark.parametrize("observer,angle_source", CASES)
def test_results_match_pinned_run(tmp_path, observer, angle_source):
    expected = read_results(fixture_path(observer, angle_source))
    got = read_results(run_case(observer, angle_source, tmp_path))
    for col in CONTRACT_COLUMNS:
        a, b = got[col], expected[col]
        if col in ("theta_e", "theta_hat"):  # compare angles on the circle
            a, b = np.unwrap(a), np.unwrap(b)
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-9, err_msg=col)
