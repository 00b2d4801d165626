"""Clean exits of processes that run ``pmsm_cosim.simulate`` (docs/errors.md, "Crash at exit").

    python benchmarks/clean_exit.py [-n 100] [--failing 20] [--stop-time 0.05] [--jobs 1]

Each run is a fresh ``python`` process that imports the package, runs a short ``simulate``
of scenario 1 and exits normally (no ``os._exit``): ``-n`` runs for every controller FMU
(FocEkf5, FocEkf4, FocEkf5AB, FocSensored, FocSensorless) with compiled kernels
(PMSM_EV_JIT=1) and as many with plain-Python kernels (PMSM_EV_JIT=0), then ``--failing``
runs (compiled kernels) whose plant fails during the steps (``plant.psi = 1e8``: the state is
no longer finite at the third step, fmi2Fatal, the run returns ``failed: ...``).

A run is clean when its exit code is 0 (the child checks the run's status), it was not
ended by a signal, and its stderr holds no message of glibc's allocator or of a fatal Python
error. Prints one line per group and the totals, e.g. ``FocEkf5 JIT=1: 100/100 clean``; the
exit code is 1 when any run was not clean.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

CONTROLLERS = ("FocEkf5", "FocEkf4", "FocEkf5AB", "FocSensored", "FocSensorless")
#: what glibc's allocator (malloc_printerr), the C library or CPython print when a process dies
NATIVE_TROUBLE = re.compile(r"corrupted|double free|free\(\)|malloc|munmap_chunk|realloc\(\)|"
                            r"stack smashing|Fatal Python error|Segmentation fault|Aborted")

CHILD = """
import sys
import pmsm_cosim
controller, stop_time, expected = sys.argv[1], float(sys.argv[2]), sys.argv[3]
overrides = {"plant.psi": 1e8} if expected == "failed" else None
result, metrics = pmsm_cosim.simulate("scenario1", stop_time=stop_time, controller=controller, set=overrides)
print(metrics["status"], len(result))
sys.exit(0 if metrics["status"].startswith(expected) else 3)
"""


def one_run(controller: str, jit: bool, expected: str, stop_time: float) -> tuple[bool, str]:
    """(clean, why not) of one fresh process."""
    env = dict(os.environ, PMSM_EV_JIT="1" if jit else "0")
    proc = subprocess.run([sys.executable, "-c", CHILD, controller, repr(stop_time), expected],
                          capture_output=True, text=True, env=env, timeout=600)
    if proc.returncode < 0:
        return False, f"signal {-proc.returncode}: {proc.stderr.strip()[-200:]}"
    if NATIVE_TROUBLE.search(proc.stderr):
        return False, f"stderr: {NATIVE_TROUBLE.search(proc.stderr).group(0)}: {proc.stderr.strip()[-200:]}"
    if proc.returncode != 0:
        return False, f"exit code {proc.returncode}: {(proc.stdout + proc.stderr).strip()[-200:]}"
    return True, ""


def run_group(label: str, n: int, jobs: int, *args) -> tuple[int, int]:
    t0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        outcomes = list(pool.map(lambda _: one_run(*args), range(n)))
    clean = sum(ok for ok, _ in outcomes)
    print(f"{label}: {clean}/{n} clean ({time.perf_counter() - t0:.0f} s)", flush=True)
    for why in sorted({why for ok, why in outcomes if not ok}):
        print(f"    {why}", flush=True)
    return clean, n


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=100, help="runs per controller and kernel kind (default 100)")
    parser.add_argument("--failing", type=int, default=20, help="runs whose plant fails mid-run (default 20)")
    parser.add_argument("--stop-time", type=float, default=0.05, help="simulated time of a run [s] (default 0.05)")
    parser.add_argument("--jobs", type=int, default=1, help="processes at a time (default 1)")
    parser.add_argument("--controllers", nargs="+", default=list(CONTROLLERS), choices=CONTROLLERS)
    args = parser.parse_args(argv)
    if args.n < 0 or args.failing < 0 or args.jobs < 1 or not args.stop_time > 0:
        parser.error("-n and --failing must be >= 0, --jobs >= 1, --stop-time > 0")
    # one untimed run first: builds the FMUs if they are out of date and fills numba's cache
    ok, why = one_run(CONTROLLERS[0], True, "completed", args.stop_time)
    print(f"warm-up run: {'clean' if ok else why}", flush=True)
    totals = {True: [0, 0], False: [0, 0]}
    for jit in (True, False):
        for controller in args.controllers:
            clean, n = run_group(f"{controller} JIT={int(jit)}", args.n, args.jobs, controller, jit, "completed",
                                 args.stop_time)
            totals[jit][0] += clean
            totals[jit][1] += n
    failing = run_group("failing plant (FocEkf5, JIT=1)", args.failing, args.jobs, "FocEkf5", True, "failed",
                        args.stop_time)
    for jit in (True, False):
        print(f"total JIT={int(jit)}: {totals[jit][0]}/{totals[jit][1]} clean")
    print(f"total failing mid-run: {failing[0]}/{failing[1]} clean")
    all_clean = all(c == n for c, n in (*totals.values(), failing))
    return 0 if all_clean else 1


if __name__ == "__main__":
    sys.exit(main())
