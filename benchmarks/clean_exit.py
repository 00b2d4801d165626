"""Clean exits of processes that run ``pmsm_cosim.simulate`` (docs/errors.md, "Crash at exit"), or of a host that
is not Python.

    python benchmarks/clean_exit.py [-n 100] [--failing 20] [--stop-time 0.05] [--jobs 1]
    python benchmarks/clean_exit.py --c-host [-n 20] [--jobs 1]
    python benchmarks/clean_exit.py --foreign [-n 30] [--jobs 1]

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

``--c-host``: each run is a fresh process of the C host of the tests (``tests/c_host.c``, compiled here; no
libpython linked) that runs all seven FMUs (built as ``pmsm-cosim build`` builds them, unzipped) for 300 steps
each, with an environment of ``PATH=/usr/bin:/bin``, ``HOME`` and nothing else (the FMU brings up its Python,
fmus/README.md, "Hosts that are not Python"), or with libpython preloaded and ``PYTHONHOME`` set (pythonfmu
then starts and finalizes the interpreter); each FMU's library unloaded after its run (as fmuCheck does) or
none (``keep``); kernels compiled (PMSM_EV_JIT=1) or plain. A run is clean as above and when it printed the
binding's counters of all seven FMUs; the line of a group ends with the compiled calls of each FMU (0 for plain
kernels).

``--foreign``: each run is a fresh ``python`` process whose master runs FMUs of another origin, built with
pythonfmu alone (the tests' toy FMUs, ``tests/toy_fmus``, built by the process as a test session builds them):
``pmsm-cosim run`` of a system of the two, then ``pmsm-cosim info`` of one. Such an FMU does not reset
pythonfmu's interpreter guard itself; the master does (``pmsm_cosim.engine.fmu.reset_guard_at_exit``). A run is
clean as above.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

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


def exit_verdict(proc: subprocess.CompletedProcess) -> tuple[bool, str]:
    """(clean, why not) of a finished fresh process: not ended by a signal, no native trouble on stderr, exit 0."""
    if proc.returncode < 0:
        return False, f"signal {-proc.returncode}: {proc.stderr.strip()[-200:]}"
    if NATIVE_TROUBLE.search(proc.stderr):
        return False, f"stderr: {NATIVE_TROUBLE.search(proc.stderr).group(0)}: {proc.stderr.strip()[-200:]}"
    if proc.returncode != 0:
        return False, f"exit code {proc.returncode}: {(proc.stdout + proc.stderr).strip()[-200:]}"
    return True, ""


def one_run(controller: str, jit: bool, expected: str, stop_time: float) -> tuple[bool, str]:
    """(clean, why not) of one fresh process."""
    env = dict(os.environ, PMSM_EV_JIT="1" if jit else "0")
    proc = subprocess.run([sys.executable, "-c", CHILD, controller, repr(stop_time), expected],
                          capture_output=True, text=True, env=env, timeout=600)
    return exit_verdict(proc)


def run_group(label: str, n: int, jobs: int, *args, run=None) -> tuple[int, int]:
    t0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        outcomes = list(pool.map(lambda _: (run or one_run)(*args), range(n)))
    clean = sum(ok for ok, *_ in outcomes)
    extra = f"; {outcomes[-1][2]}" if outcomes and len(outcomes[-1]) > 2 else ""
    print(f"{label}: {clean}/{n} clean ({time.perf_counter() - t0:.0f} s){extra}", flush=True)
    for why in sorted({why for ok, why, *_ in outcomes if not ok}):
        print(f"    {why}", flush=True)
    return clean, n


# -- a host that is not Python -------------------------------------------------------------------------------------
C_HOST = Path(__file__).resolve().parents[1] / "tests" / "c_host.c"
C_STEPS, C_H = 300, 1e-4


def c_host_setup(work: Path) -> tuple[Path, Path]:
    """(the compiled C host, the spec of all seven FMUs unzipped in ``work``)."""
    import fmpy  # noqa: PLC0415 - only this mode needs fmpy and the FMUs

    import pmsm_ev_fmus  # noqa: PLC0415

    compiler = next((shutil.which(c) for c in (os.environ.get("CC"), "cc", "gcc") if c and shutil.which(c)), None)
    if compiler is None:
        raise SystemExit("error: --c-host needs a C compiler (cc, gcc or $CC)")
    host = work / "c_host"
    subprocess.run([compiler, "-O1", "-std=c99", "-D_GNU_SOURCE", f"-I{Path(fmpy.__file__).parent / 'c-code'}",
                    str(C_HOST), "-o", str(host), "-ldl"], check=True)
    lines = []
    for name, fmu in pmsm_ev_fmus.build_all().items():
        root = Path(fmpy.extract(str(fmu), str(work / name)))
        md = fmpy.read_model_description(str(root))
        lines += [f"fmu {name} {root / 'binaries' / 'linux64' / (name + '.so')} {(root / 'resources').as_uri()} "
                  f"{md.guid}", f"steps {C_STEPS} {C_H!r}"]
        outputs = [v for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
        lines += [f"output {v.valueReference}" for v in outputs]
        lines.append("run")
    spec = work / "spec.txt"
    spec.write_text("\n".join(lines) + "\n")
    (work / "spec_keep.txt").write_text("keep\n" + spec.read_text())
    return host, spec


def one_c_run(host: Path, spec: Path, jit: bool, preload: bool) -> tuple[bool, str, str]:
    """(clean, why not, the compiled calls of each FMU) of one fresh C host process."""
    env = {"PATH": "/usr/bin:/bin", "HOME": os.path.expanduser("~"), "PMSM_EV_JIT": "1" if jit else "0"}
    if preload:
        env["LD_PRELOAD"] = os.path.join(sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("LDLIBRARY"))
        env["PYTHONHOME"] = sys.base_prefix
        import numpy  # noqa: PLC0415 - where numpy is, for the preloaded interpreter's sys.path

        site = str(Path(numpy.__file__).resolve().parents[1])
        if not site.startswith(sys.base_prefix):
            env["PYTHONPATH"] = site
    proc = subprocess.run([str(host), str(spec)], capture_output=True, text=True, env=env, timeout=600)
    calls = [line.split() for line in proc.stdout.splitlines() if line.startswith("calls ")]
    compiled = "compiled calls " + " ".join(c[2] for c in calls)
    if proc.returncode < 0:
        return False, f"signal {-proc.returncode}: {proc.stderr.strip()[-200:]}", compiled
    if NATIVE_TROUBLE.search(proc.stderr):
        return False, f"stderr: {NATIVE_TROUBLE.search(proc.stderr).group(0)}: {proc.stderr.strip()[-200:]}", compiled
    if proc.returncode != 0 or len(calls) != 7:
        return False, f"exit code {proc.returncode}: {(proc.stdout + proc.stderr).strip()[-200:]}", compiled
    return True, "", compiled


def main_c_host(n: int, jobs: int) -> int:
    work = Path(tempfile.mkdtemp(prefix="clean-exit-"))
    try:
        host, spec = c_host_setup(work)
        ok, why, compiled = one_c_run(host, spec, True, False)  # fills numba's cache if it must
        print(f"warm-up run: {'clean' if ok else why}; {compiled}", flush=True)
        totals = [0, 0]
        for unload in (True, False):
            for preload in (False, True):
                for jit in (True, False):
                    label = (f"C host, {'each FMU unloaded' if unload else 'none unloaded'}, "
                             f"{'libpython preloaded' if preload else 'no Python set up'}, JIT={int(jit)}")
                    clean, runs = run_group(label, n, jobs, host, spec if unload else work / "spec_keep.txt", jit,
                                            preload, run=one_c_run)
                    totals[0] += clean
                    totals[1] += runs
        print(f"total: {totals[0]}/{totals[1]} clean")
        return 0 if totals[0] == totals[1] else 1
    finally:
        shutil.rmtree(work, ignore_errors=True)


# -- FMUs of another origin, through the master ---------------------------------------------------------------------
FOREIGN_CHILD = """
import sys
from pathlib import Path
sys.path.insert(0, sys.argv[1])
from orchestrator_support import toy_fmus, toy_system
from pmsm_cosim.app.cli import main
work = Path(sys.argv[2])
code = main(["run", str(toy_system(work)), "--out", str(work / "out"), "--quiet", "--set", "snk.gain=2"])
sys.exit(code or main(["info", str(toy_fmus()["ToySink"])]))
"""


def one_foreign_run(work: Path) -> tuple[bool, str]:
    child = Path(tempfile.mkdtemp(prefix="run-", dir=work))
    proc = subprocess.run([sys.executable, "-c", FOREIGN_CHILD, str(C_HOST.parent), str(child)],
                          capture_output=True, text=True, timeout=600)
    return exit_verdict(proc)


def main_foreign(n: int, jobs: int) -> int:
    work = Path(tempfile.mkdtemp(prefix="clean-exit-"))
    try:
        clean, runs = run_group("pythonfmu FMUs of another origin (the tests' ToySource, ToySink) through the master",
                                n, jobs, work, run=one_foreign_run)
        return 0 if clean == runs else 1
    finally:
        shutil.rmtree(work, ignore_errors=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=100, help="runs per controller and kernel kind (default 100)")
    parser.add_argument("--failing", type=int, default=20, help="runs whose plant fails mid-run (default 20)")
    parser.add_argument("--stop-time", type=float, default=0.05, help="simulated time of a run [s] (default 0.05)")
    parser.add_argument("--jobs", type=int, default=1, help="processes at a time (default 1)")
    parser.add_argument("--controllers", nargs="+", default=list(CONTROLLERS), choices=CONTROLLERS)
    parser.add_argument("--c-host", action="store_true", help="runs of the seven FMUs in a C host (Linux)")
    parser.add_argument("--foreign", action="store_true", help="runs of FMUs of another origin through the master")
    args = parser.parse_args(argv)
    if args.n < 0 or args.failing < 0 or args.jobs < 1 or not args.stop_time > 0:
        parser.error("-n and --failing must be >= 0, --jobs >= 1, --stop-time > 0")
    if args.c_host:
        return main_c_host(args.n, args.jobs)
    if args.foreign:
        return main_foreign(args.n, args.jobs)
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
