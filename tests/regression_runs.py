"""Short closed-loop runs whose results are pinned in ``tests/fixtures``.

A change that only reorganises computation (performance work) must leave them equal to
1e-12 relative; regenerate with ``python tests/regression_runs.py`` only when the
physics changes on purpose, and say so in the commit.
"""

from __future__ import annotations

import math
import shutil
import sys
import tempfile
from pathlib import Path

from pmsm_cosim.app.reference import run_reference
from pmsm_ev.params import DriveParams, ScenarioParams
from pmsm_ev.scenarios import Profile

FIXTURES = Path(__file__).parent / "fixtures"
#: (observer, angle source): the paper's EKF5, EKF4, the stationary-frame EKF5, sensored.
#: Not EKF5 with the estimated angle: at light load that loop is locally unstable (it
#: hunts), so a 1e-16 rounding difference grows to 1e-3 within 3 s: no fixture can pin it.
CASES = (("ekf5", "measured"), ("ekf4", "measured"), ("ekf5ab", "measured"), ("sensored", "measured"))
STOP_TIME = 10.0
OUTPUT_INTERVAL = 0.05
#: a quick start-up (2 s ramp) and a 0 -> 10 deg step at 6 s
PARAMS = DriveParams(scenario=ScenarioParams(startup_time=2.0))
ELEVATION = Profile((0.0, 6.0), (0.0, math.radians(10.0)), "previous", "delta")


def run_case(observer: str, angle_source: str, out_dir) -> Path:
    run_reference(out_dir, stop_time=STOP_TIME, observer=observer, angle_source=angle_source,
                  params=PARAMS, output_interval=OUTPUT_INTERVAL, elevation=ELEVATION)
    return Path(out_dir) / "results.csv"


def fixture_path(observer: str, angle_source: str) -> Path:
    return FIXTURES / f"regression_{observer}_{angle_source}.csv"


if __name__ == "__main__":
    FIXTURES.mkdir(exist_ok=True)
    for obs, src in CASES:
        with tempfile.TemporaryDirectory() as tmp:
            shutil.copy(run_case(obs, src, tmp), fixture_path(obs, src))
        print("wrote", fixture_path(obs, src), file=sys.stderr)
