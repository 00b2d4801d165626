"""The FMUs in a host that is not Python (fmus/README.md, "Hosts that are not Python"): a small C host
(tests/c_host.c: no libpython linked, no PYTHON* variables, no preload, a cleaned environment) loads each project
FMU, unzipped; the FMU's loader (fmus/fmu_loader.c) brings up a Python itself. What must hold: the outputs of
every step equal those of the same calls made by fmpy in a Python process, and the same calls are served by the
compiled step there as in fmpy (the kernels compiled with numba, from the same cache); where no Python is found,
fmi2Instantiate returns NULL with one log line saying what was looked for and how to point at one."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import fmpy
import pytest

import pmsm_ev_fmus
from c_fmu_support import FMI2_HEADERS, c_compiler, host_steps
from pmsm_ev_fmus import build as fmu_build

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux") or c_compiler() is None or fmu_build.binding_requested() != "lean",
    reason="the FMU's loader is built on Linux (x86-64) with a C compiler")

HERE = Path(__file__).resolve().parent
STEPS, H = 300, 1e-4
#: Real inputs of each FMU kind, (a, b): a + b k before step k
INPUTS = {
    "plant": {"v_alpha": (20.0, 0.05), "v_beta": (-5.0, 0.1), "delta": (0.05, 0.0), "T_brake": (0.0, 0.0)},
    "ctrl": {"i_alpha": (1.0, 0.01), "i_beta": (0.5, -0.02), "omega_ref": (20.0, 0.1), "theta_meas": (0.3, 0.001),
             "omega_meas": (15.0, 0.05)},
    "route": {},
}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    return pmsm_ev_fmus.build_all(tmp_path_factory.mktemp("fmus"))


@pytest.fixture(scope="module")
def unzipped(fmus, tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("unzipped")
    return {name: Path(fmpy.extract(str(path), str(root / name))) for name, path in fmus.items()}


@pytest.fixture(scope="module")
def host(tmp_path_factory) -> Path:
    """tests/c_host.c compiled (no libpython, only libdl)."""
    out = tmp_path_factory.mktemp("host") / "c_host"
    done = subprocess.run([c_compiler(), "-O1", "-std=c99", "-D_GNU_SOURCE", "-Wall", "-Werror", f"-I{FMI2_HEADERS}",
                           str(HERE / "c_host.c"), "-o", str(out), "-ldl"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return out


def _kind(name: str) -> str:
    return "plant" if name == "PmsmEvPlant" else "route" if name == "RouteProfile" else "ctrl"


def spec_of(root: Path, name: str, instance: str | None = None) -> str:
    """The c_host block of the FMU unzipped in ``root``: its Real inputs ramped, every Real output printed."""
    md = fmpy.read_model_description(str(root))
    by_name = {v.name: v for v in md.modelVariables}
    lines = [f"fmu {instance or name} {root / 'binaries' / 'linux64' / (name + '.so')} "
             f"{(root / 'resources').as_uri()} {md.guid}", f"steps {STEPS} {H!r}"]
    for var, (a, b) in INPUTS[_kind(name)].items():
        assert by_name[var].causality == "input", var
        lines.append(f"input {by_name[var].valueReference} {a!r} {b!r}")
    lines += [f"output {v.valueReference}" for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    return "\n".join(lines + ["run", ""])


# the same calls through fmpy, in a Python process of its own, printed as the C host prints them
_FMPY_HOST = r"""
import ctypes
import sys
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave
blocks, current = [], None
for line in open(sys.argv[1]).read().splitlines():
    word, *rest = line.split()
    if word == "fmu":
        current = {"name": rest[0], "binary": rest[1], "in": [], "out": []}
    elif word == "steps":
        current["steps"], current["h"] = int(rest[0]), float(rest[1])
    elif word == "input":
        current["in"].append((int(rest[0]), float(rest[1]), float(rest[2])))
    elif word == "output":
        current["out"].append(int(rest[0]))
    elif word == "run":
        blocks.append(current)
for b in blocks:
    root = b["binary"].rsplit("/binaries/", 1)[0]
    md = read_model_description(root)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=root, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=b["name"])
    print("fmu", b["name"], fmu.getVersion(), fmu.fmi2GetTypesPlatform().decode())
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    print("initialised 0")
    for k in range(b["steps"]):
        if b["in"]:
            fmu.setReal([vr for vr, _, _ in b["in"]], [a + s * k for _, a, s in b["in"]])
        fmu.doStep(k * b["h"], b["h"])
        print(k, 0, 0, " ".join("%.17g" % y for y in fmu.getReal(b["out"])))
    counters = [getattr(fmu.dll, name, None) for name in ("pmsm_fmu_fast_calls", "pmsm_fmu_compiled_calls")]
    for counter in counters:
        if counter is not None:
            counter.restype, counter.argtypes = ctypes.c_ulonglong, [ctypes.c_void_p]
    print("calls", *(counter(fmu.component) if counter is not None else 0 for counter in counters))
    fmu.terminate()
    print("terminate 0")
    fmu.freeInstance()
"""


def _clean_env(tmp_path: Path, **extra) -> dict:
    """What a tool started from a desktop has: no PYTHON* variable, no LD_PRELOAD; ``PATH`` without this
    project's interpreter; the user's ``HOME`` (so the kernels compiled by Python processes are found in the user's
    cache, ``pmsm_ev.accel``)."""
    env = {"PATH": "/usr/bin:/bin", "HOME": str(Path.home()), "LANG": "C.UTF-8"}
    env.update(extra)
    return env


def _calls(text: str) -> dict[str, tuple[int, int]]:
    """{fmu: (pmsm_fmu_fast_calls, pmsm_fmu_compiled_calls)} of what a host printed after each run."""
    calls, current = {}, None
    for line in text.splitlines():
        word, *rest = line.split()
        if word == "fmu":
            current = rest[0]
        elif word == "calls":
            calls[current] = (int(rest[0]), int(rest[1]))
    return calls




def test_every_fmu_runs_in_a_c_host_with_no_python_set_up_as_in_fmpy(unzipped, host, tmp_path):
    """All the project's FMUs, one after the other in one C process with a cleaned environment: the Python the FMU
    was built with is brought up by the FMU itself; every step's outputs equal fmpy's, bit for bit, and the calls
    are served as in fmpy: the compiled step (numba) takes every fmi2SetReal and fmi2DoStep of the plant and of the
    controllers in the C host too (``pmsm_fmu_compiled_calls``; the fmi2GetReal of every output also reads values
    that are not in the step's buffers, so Python's). Each FMU's library is unloaded after its run (dlclose, as
    fmuCheck does) and the process exits cleanly (exit code 0: pythonfmu's interpreter guard released before its
    static destructors and before numba's LLVM's, fmus/README.md)."""
    spec = tmp_path / "spec.txt"
    spec.write_text("".join(spec_of(root, name) for name, root in unzipped.items()))
    done = subprocess.run([str(host), str(spec)], capture_output=True, text=True, env=_clean_env(tmp_path),
                          timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "log " not in done.stdout, done.stdout[:3000]
    reference = subprocess.run([sys.executable, "-c", _FMPY_HOST, str(spec)], capture_output=True, text=True,
                               timeout=300)
    assert reference.returncode == 0, reference.stderr[-3000:]
    c_runs, py_runs = host_steps(done.stdout), host_steps(reference.stdout)
    assert sorted(c_runs) == sorted(unzipped)
    for name in unzipped:
        assert f"fmu {name} 2.0 default" in done.stdout
        assert len(c_runs[name]) == STEPS, name
        assert c_runs[name] == py_runs[name], name
    moved = c_runs["PmsmEvPlant"]
    assert moved[-1] != moved[0]  # the ramps reached the plant
    c_calls, py_calls = _calls(done.stdout), _calls(reference.stdout)
    assert c_calls == py_calls
    for name in unzipped:
        fast, compiled = c_calls[name]
        assert fast == (3 if INPUTS[_kind(name)] else 2) * STEPS, name  # every call on the direct path
        # compiled: a controller's every call (each of its Real outputs in its buffers); the plant's set and step,
        # its get of every output naming W_magnetic and E_kinetic, which its Python computes; RouteProfile has no
        # kernels
        assert compiled == {"ctrl": 3, "plant": 2, "route": 0}[_kind(name)] * STEPS, name


def test_the_c_host_with_plain_python_kernels_gives_the_same_numbers(unzipped, host, tmp_path):
    """``PMSM_EV_JIT=0`` in the C host: no call compiled, every call on the direct path, every step's outputs
    those of the compiled run, bit for bit."""
    names = ["PmsmEvPlant", "FocSensorless"]
    spec = tmp_path / "spec.txt"
    spec.write_text("".join(spec_of(unzipped[name], name) for name in names))
    runs = {}
    for jit in ("1", "0"):
        done = subprocess.run([str(host), str(spec)], capture_output=True, text=True,
                              env=_clean_env(tmp_path, PMSM_EV_JIT=jit), timeout=300)
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
        runs[jit] = (host_steps(done.stdout), _calls(done.stdout))
    assert runs["0"][0] == runs["1"][0]
    assert runs["1"][1] == {"PmsmEvPlant": (3 * STEPS, 2 * STEPS), "FocSensorless": (3 * STEPS, 3 * STEPS)}
    assert runs["0"][1] == {name: (3 * STEPS, 0) for name in names}


@pytest.fixture
def plant_alone(unzipped, tmp_path) -> Path:
    """A copy of the unzipped plant that names no interpreter it was built with."""
    root = Path(shutil.copytree(unzipped["PmsmEvPlant"], tmp_path / "plant"))
    (root / "resources" / fmu_build.BUILT_PYTHON_FILE).unlink()
    return root


def test_where_no_python_is_found_instantiate_fails_with_one_line(plant_alone, host, tmp_path):
    spec = tmp_path / "spec.txt"
    spec.write_text(spec_of(plant_alone, "PmsmEvPlant"))
    empty = tmp_path / "bin"
    empty.mkdir()
    done = subprocess.run([str(host), str(spec)], capture_output=True, text=True,
                          env=_clean_env(tmp_path, PATH=str(empty)), timeout=120)
    assert done.returncode == 3, done.stdout
    logs = [line for line in done.stdout.splitlines() if line.startswith("log ")]
    assert len(logs) == 1, done.stdout
    assert logs[0] == ("log 3 error no Python found for this FMU: looked for $PMSM_FMU_PYTHON (not set); "
                       "resources/python.txt (no such file); the interpreter the FMU was built with (no such file); "
                       "python3 on PATH (not found). Set PMSM_FMU_PYTHON to a Python 3 interpreter that has numpy "
                       "(built with --enable-shared), or to its libpython")
    assert "fmu PmsmEvPlant 2.0 default" in done.stdout  # fmi2GetVersion, fmi2GetTypesPlatform: no Python needed
    # an interpreter named that does not exist, or has no numpy, is said so
    done = subprocess.run([str(host), str(spec)], capture_output=True, text=True,
                          env=_clean_env(tmp_path, PATH=str(empty), PMSM_FMU_PYTHON=str(tmp_path / "nope")),
                          timeout=120)
    assert f"$PMSM_FMU_PYTHON ({tmp_path / 'nope'}: no such file)" in done.stdout


@pytest.mark.parametrize("how", ["variable", "file"])
def test_a_python_named_by_the_user_is_used(plant_alone, host, tmp_path, how):
    """$PMSM_FMU_PYTHON, or resources/python.txt, naming this interpreter: the plant runs as with the recorded one."""
    spec = tmp_path / "spec.txt"
    spec.write_text(spec_of(plant_alone, "PmsmEvPlant"))
    extra = {}
    if how == "variable":
        extra["PMSM_FMU_PYTHON"] = sys.executable
    else:
        (plant_alone / "resources" / "python.txt").write_text(sys.executable + "\n")
    empty = tmp_path / "bin"
    empty.mkdir()
    done = subprocess.run([str(host), str(spec)], capture_output=True, text=True,
                          env=_clean_env(tmp_path, PATH=str(empty), **extra), timeout=120)
    assert done.returncode == 0, done.stdout[-3000:]
    steps = host_steps(done.stdout)["PmsmEvPlant"]
    assert len(steps) == STEPS and all(v == v for row in steps for v in row)


def test_the_loader_references_no_python_symbol(unzipped):
    """What lets any host load the FMU's library: it needs nothing of Python (the binding behind it does)."""
    nm = shutil.which("nm")
    if nm is None:
        pytest.skip("needs nm")
    binary = unzipped["PmsmEvPlant"] / "binaries" / "linux64" / "PmsmEvPlant.so"
    undefined = subprocess.run([nm, "-D", "--undefined-only", str(binary)], capture_output=True, text=True,
                               check=True).stdout.split()
    assert not [s for s in undefined if s.startswith(("Py", "_Py"))]
    names = json.loads((unzipped["PmsmEvPlant"] / "resources" / "build_info.json").read_text())
    assert names["binding"] == "lean"
    assert (unzipped["PmsmEvPlant"] / "resources" / fmu_build.BUILT_PYTHON_FILE).read_text().strip() == sys.executable
    assert os.path.isfile(unzipped["PmsmEvPlant"] / "binaries" / "linux64" / fmu_build.BINDING_LIBRARY)


def test_the_exported_package_runs_in_a_c_jacobi_master_as_in_the_orchestrator(fmus, unzipped, host, tmp_path):
    """What OMSimulator does with ``export-ssp scenario2`` (all FMUs loaded at once in one process that is not
    Python, stepped Jacobi, the package's start values set), done by tests/c_host.c with no Python set up: every
    recorded column equals the orchestrator's Jacobi run of the system, bit for bit (the kernels compiled in both
    processes; the route comes from the packaged RouteProfile)."""
    from pmsm_cosim.app.drive import export_ssp, load_system
    from pmsm_cosim.engine.master import Master
    from pmsm_cosim.engine.recording import read_results
    from pmsm_cosim.engine.ssp import load_ssp
    from pmsm_ev.results import ALL_COLUMNS

    steps, stop = 500, 0.05
    spec = load_system("scenario2")
    spec.set_fmu("ctrl", fmus["FocEkf5"])
    spec.set_fmu("plant", fmus["PmsmEvPlant"])
    spec.set_start("plant.m_v=1700.0")  # an .ssv value, applied by the host
    package = tmp_path / "s2.ssp"
    export_ssp(spec, package, route_fmu=fmus["RouteProfile"], quiet=True)
    system = load_ssp(package)
    index, lines, md_of = {}, [], {}
    for i, comp in enumerate(system.components):
        root = Path(fmpy.extract(str(comp.fmu), str(tmp_path / "members" / comp.name)))
        md = fmpy.read_model_description(str(root))
        md_of[comp.name] = {v.name: v for v in md.modelVariables}
        index[comp.name] = i
        lines.append(f"member {comp.name} {root / 'binaries' / 'linux64' / (md.coSimulation.modelIdentifier + '.so')} "
                     f"{(root / 'resources').as_uri()} {md.guid}")
        for name, value in comp.start.items():
            var = md_of[comp.name][name]
            kind = {"Real": "R", "Integer": "I", "Boolean": "B"}[var.type]
            lines.append(f"start {i} {var.valueReference} {kind} {float(value)!r}")
    assert any(line.startswith("start ") for line in lines)
    for c in system.connections:
        src, dst = md_of[c.src][c.src_var], md_of[c.dst][c.dst_var]
        assert src.type == dst.type == "Real"
        lines.append(f"connect {index[c.src]} {src.valueReference} {index[c.dst]} {dst.valueReference}")
    columns = [next(col for col in system.columns if col.name == name) for name in ALL_COLUMNS[1:]]
    lines += [f"record {index[col.instance]} {md_of[col.instance][col.variable].valueReference}" for col in columns]
    lines += [f"steps {steps} {H!r}", "run_system", ""]
    spec_file = tmp_path / "system.txt"
    spec_file.write_text("\n".join(lines))
    done = subprocess.run([str(host), str(spec_file)], capture_output=True, text=True, env=_clean_env(tmp_path),
                          timeout=300)
    assert done.returncode == 0 and "system initialised 0" in done.stdout, done.stdout[-3000:] + done.stderr[-2000:]
    rows = [line.split() for line in done.stdout.splitlines() if line.split(" ", 1)[0].isdigit()]
    assert len(rows) == steps and all(row[1] == "0" for row in rows)
    values = [[float(v) for v in row[2:]] for row in rows]
    spec.algorithm, spec.stop_time, spec.output_interval = "jacobi", stop, H
    Master(spec).run(tmp_path / "jacobi", catch_sigint=False)
    jacobi = read_results(tmp_path / "jacobi")
    for j, col in enumerate(columns):  # row k of the C host: after the step from t_k, the orchestrator's row k + 1
        got = [math.degrees(row[j]) if col.unit == "deg" else row[j] for row in values]
        expected = list(jacobi[col.name][1:steps + 1])
        assert got == expected, col.name
    assert jacobi["omega_m"][-1] != 0.0
