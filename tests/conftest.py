import sys
from pathlib import Path

# let tests import helper modules that live beside them (regression_runs)
sys.path.insert(0, str(Path(__file__).parent))


# -- leaving the test process ---------------------------------------------------------------
# The tests load many FMUs in this process (pythonfmu binaries embedding this interpreter)
# and, with numba, compiled kernels. The native teardown after the interpreter's
# finalization can abort in free() (see pmsm_cosim.app.cli.entry_point, which the command
# uses for the same reason) after every test has passed and been reported; leave with the
# session's exit status before that teardown.
import os  # noqa: E402

import pytest  # noqa: E402

_SESSION_STATUS: list[int] = []


def pytest_sessionfinish(session, exitstatus):
    _SESSION_STATUS.append(int(exitstatus))


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    if _SESSION_STATUS:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_SESSION_STATUS[-1])
