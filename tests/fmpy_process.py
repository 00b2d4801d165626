"""``fmpy.simulate_fmu`` in a Python process of its own, as another tool would run an FMU.

Each ``fmpy.simulate_fmu`` call unpacks the FMU, loads a fresh copy of its binary, runs it and unloads it.
In a long pytest worker (hundreds of FMU loads and unloads, Dask clusters started and stopped) one such
call crashed the worker with a segmentation fault inside fmi2DoStep (CI, 2026-12-02), which pytest-xdist
then could not recover from. In a process of its own the comparison is the same, the FMU meets a clean
interpreter as it would in another tool, and a crash is one failed test that says so. ``simulate_fmus`` runs
a few such calls one after the other in one new interpreter (a module's handful of FMU loads, not a worker's
hundreds): a crash there fails the tests that asked for them.
"""

from __future__ import annotations

import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

_SCRIPT = """
import pickle, sys
import numpy as np
import fmpy
for k, (filename, kwargs) in enumerate(pickle.load(open(sys.argv[1], "rb"))):
    np.save(f"{sys.argv[2]}{k}.npy", fmpy.simulate_fmu(filename, **kwargs), allow_pickle=False)
"""


def simulate_fmu(filename, timeout: float = 600.0, **kwargs) -> np.ndarray:
    """``fmpy.simulate_fmu(filename, **kwargs)`` run by a new interpreter; its result array. The keyword
    arguments must pickle (no ``logger`` callback). An exception or a crash in that process raises
    RuntimeError with its exit code and the end of what it wrote to stderr."""
    (result,) = simulate_fmus([(filename, kwargs)], timeout)
    return result


def simulate_fmus(calls, timeout: float = 600.0) -> list[np.ndarray]:
    """``fmpy.simulate_fmu(filename, **kwargs)`` for each ``(filename, kwargs)`` of ``calls``, one after the other,
    by one new interpreter (a few FMU loads, not a worker's hundreds); their result arrays. As ``simulate_fmu``
    otherwise."""
    calls = [(str(filename), kwargs) for filename, kwargs in calls]
    with tempfile.TemporaryDirectory() as tmp:
        args, out = Path(tmp) / "args.pkl", Path(tmp) / "result"
        args.write_bytes(pickle.dumps(calls))
        done = subprocess.run([sys.executable, "-c", _SCRIPT, str(args), str(out)], capture_output=True, text=True,
                              timeout=timeout)
        if done.returncode != 0:
            names = ", ".join(sorted({Path(filename).name for filename, _ in calls}))
            raise RuntimeError(f"fmpy.simulate_fmu({names}) in its own process exited with "
                               f"{done.returncode}:\n{done.stderr[-4000:]}")
        return [np.load(f"{out}{k}.npy", allow_pickle=False) for k in range(len(calls))]
