"""SSP 1.0 packages: ``pmsm-cosim export-ssp`` and ``pmsm-cosim run FILE.ssp``.

* The package's SystemStructure.ssd and .ssv files validate against the SSP 1.0 schemas
  fmpy ships, and fmpy's own SSP reader accepts them. Every shipped scenario, with and
  without ``--set ctrl.angle_source=estimated``, exports to a package that OMSimulator
  reads too: its system annotation first in the system, no String in an .ssv (a String
  travels in a copy of the FMU), nothing at the root of the SSD but what it accepts.
* libcosim (``CosimExecution.from_ssp_file``) runs the scenario-2 package for 2 s; its
  trajectories equal the orchestrator's Jacobi run of the same system (signals, no
  RouteProfile) to 1e-9, also with the estimated angle source, which the package
  carries in a copy of the controller FMU.
* fmpy's ``simulate_ssp`` runs the package too and equals the same Jacobi run, with
  either angle source; it does not apply the package's .ssv values (nor can it set a
  String parameter), which the tests below pin down.
* OMSimulator (where an ``OMSimulator`` executable is on PATH) runs the packages
  unchanged with an empty environment (``env -i PATH=/usr/bin:/bin``: the FMUs bring up
  their own Python) and equals the Jacobi run to 1e-9 (``test_omsimulator_runs_the_package``).
* Round trip: ``run FILE.ssp`` equals the run of the system it was exported from, value
  for value (Gauss-Seidel and Jacobi, the paper's route and a user's CSV route).
* A bad package or an SSP feature the orchestrator does not implement: a one-line error.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest

import pmsm_cosim.app
from orchestrator_support import project_fmus
from pmsm_cosim.app.cli import main
from pmsm_cosim.app.drive import export_ssp, load_system
from pmsm_cosim.engine.errors import CosimError
from pmsm_cosim.engine.master import Master
from pmsm_cosim.engine.recording import read_results
from pmsm_cosim.engine.ssp import NS, load_ssp, schema_errors
from pmsm_ev.results import ALL_COLUMNS
from pmsm_ev_fmus import build as fmu_build

RTOL = ATOL = 1e-9
STEP = 1e-4


@pytest.fixture(scope="module")
def fmus():
    return project_fmus()


def scenario2(fmus, *starts, stop_time=None, algorithm=None, profile=None):
    spec = load_system("scenario2")
    spec.set_fmu("ctrl", fmus["FocEkf5"])
    spec.set_fmu("plant", fmus["PmsmEvPlant"])
    for assignment in starts:
        spec.set_start(assignment)
    if profile:
        spec.set_signal_csv(profile)
    if stop_time is not None:
        spec.stop_time = stop_time
    if algorithm is not None:
        spec.algorithm = algorithm
    return spec


def export(fmus, path, *starts, profile=None) -> Path:
    export_ssp(scenario2(fmus, *starts, profile=profile), path, route_fmu=fmus["RouteProfile"])
    return path


def run(spec, out: Path, stop_time=None, algorithm=None, output_interval=None) -> dict:
    if stop_time is not None:
        spec.stop_time = stop_time
    if algorithm is not None:
        spec.algorithm = algorithm
    if output_interval is not None:
        spec.output_interval = output_interval
    m = Master(spec).run(out, catch_sigint=False)
    assert m["status"] == "completed", m["status"]
    return read_results(out)


@pytest.fixture(scope="module")
def package(fmus, tmp_path_factory):
    return export(fmus, tmp_path_factory.mktemp("ssp") / "scenario2.ssp")


@pytest.fixture(scope="module")
def bound(fmus, tmp_path_factory):
    """Scenario 2 with a Real start value (in resources/plant.ssv) and the estimated angle
    source (in a copy of the controller FMU)."""
    return export(fmus, tmp_path_factory.mktemp("ssp") / "bound.ssp", "plant.m_v=1200",
                  "ctrl.angle_source=estimated")


# -- the package ------------------------------------------------------------------------------------
def test_package_layout_and_contents(package, bound, fmus):
    with zipfile.ZipFile(package) as z:
        names = set(z.namelist())
        ssd = z.read("SystemStructure.ssd").decode()
    # scenario 2's angle_source = "measured" is the FMU's default: left out, no .ssv
    assert names == {"SystemStructure.ssd", "resources/FocEkf5.fmu", "resources/PmsmEvPlant.fmu",
                     "resources/RouteProfile.fmu"}
    assert 'startElement="route" startConnector="delta" endElement="plant" endConnector="delta"' in ssd
    assert 'startElement="route" startConnector="omega_ref" endElement="ctrl" endConnector="omega_ref"' in ssd
    assert '<ssd:DefaultExperiment startTime="0.0" stopTime="350.0">' in ssd
    assert '<osp:FixedStepAlgorithm baseStepSize="0.0001" />' in ssd
    assert '<oms:FixedStepMaster description="oms-ma" stepSize="0.0001" />' in ssd
    assert '<ssc:Real unit="rad/s" />' in ssd and '<ssc:BaseUnit kg="1" m="2" s="-3" A="-1" />' in ssd  # V
    with zipfile.ZipFile(bound) as z:
        names = set(z.namelist())
        ssv = z.read("resources/plant.ssv").decode()
        ssd = z.read("SystemStructure.ssd").decode()
        copy = z.read("resources/FocEkf5_ctrl.fmu")
    assert names == {"SystemStructure.ssd", "resources/FocEkf5_ctrl.fmu", "resources/PmsmEvPlant.fmu",
                     "resources/RouteProfile.fmu", "resources/plant.ssv"}
    assert '<ssv:Parameter name="m_v">' in ssv and '<ssv:Real value="1200.0" />' in ssv
    assert 'source="resources/FocEkf5_ctrl.fmu"' in ssd and "angle_source" not in ssd
    with zipfile.ZipFile(io.BytesIO(copy)) as z:
        assert json.loads(z.read("resources/start_values.json")) == {"angle_source": "estimated"}
        md = ET.fromstring(z.read("modelDescription.xml"))
    with zipfile.ZipFile(fmus["FocEkf5"]) as z:
        original = ET.fromstring(z.read("modelDescription.xml"))
    # the same model description as XML but the start value of angle_source
    original.find("ModelVariables/ScalarVariable[@name='angle_source']/String").set("start", "estimated")
    assert ET.tostring(md) == ET.tostring(original)
    assert md.find("ModelVariables/ScalarVariable[@name='angle_source']/String").get("start") == "estimated"


def test_ssd_and_ssv_validate_against_the_ssp_schemas_fmpy_ships(bound):
    from fmpy.ssp.ssd import read_ssd

    with zipfile.ZipFile(bound) as z:
        assert schema_errors(z.read("SystemStructure.ssd"), "SystemStructureDescription.xsd") == []
        assert schema_errors(z.read("resources/plant.ssv"), "SystemStructureParameterValues.xsd") == []
        broken = z.read("SystemStructure.ssd").replace(b' kind="output"', b' kind="sideways"', 1)
    assert schema_errors(broken, "SystemStructureDescription.xsd")  # the validation can fail
    ssd = read_ssd(str(bound), validate=True)  # fmpy's reader, with its schema validation
    assert [e.name for e in ssd.system.elements] == ["ctrl", "plant", "route"]
    assert len(ssd.system.connections) == 12  # the drive's 10 (the friction brake, the DC link) and the route's 2
    (binding,) = ssd.system.elements[1].parameterBindings
    assert [(p.name, p.type, p.value) for p in binding.parameterValues[0].parameters] == [("m_v", "Real", "1200.0")]
    assert ssd.system.elements[0].parameterBindings == []


def system_annotations(ssd: ET.Element) -> list[str]:
    return [a.get("type") for a in ssd.findall("ssd:System/ssd:Annotations/ssc:Annotation", NS)]


SCENARIOS = sorted(p.stem for p in (Path(pmsm_cosim.app.__file__).parent / "scenarios").glob("*.toml"))


#: the scenarios whose export the default run checks (the paper's, a sensorless cycle); the others are slow
EXPORT_FAST = ("scenario1", "udds-sensorless")


@pytest.mark.parametrize("angle_source", [None, "estimated"])
@pytest.mark.parametrize("scenario", [pytest.param(s, marks=() if s in EXPORT_FAST else pytest.mark.slow)
                                      for s in SCENARIOS])
def test_every_shipped_scenario_exports_a_package_every_tool_reads(fmus, tmp_path, capsys, scenario, angle_source):
    """What OMSimulator needs (its annotation first in the system, no String in an .ssv, no
    annotations at the root), libcosim (the OSP base step) and this master (its run record,
    now in the system), and still valid SSP 1.0."""
    # the paper's 2, their 4 variants, 4 sensorless (the paper's 2 and the hill start with injection and I-f),
    # 4 acceleration (sensorless with injection and I-f), 15 drive-cycle runs (sensored, injection, I-f; hilly; the
    # battery's, sensored and with injection), 2 with the motor's thermal network (wltc3b-thermal, us06x5-thermal)
    assert len(SCENARIOS) == 31
    # a system that sets the sensorless unit's own parameters (low_speed) keeps that unit (its String travels in
    # a copy of the FMU); the rest swap in FocEkf5
    ctrl = "FocSensorless" if "low_speed" in load_system(scenario).component("ctrl").start else "FocEkf5"
    args = ["export-ssp", scenario, "-o", str(tmp_path / "p.ssp"), "--plant", str(fmus["PmsmEvPlant"]),
            "--controller", str(fmus[ctrl])]
    if angle_source:
        args += ["--set", f"ctrl.angle_source={angle_source}"]
    assert main(args) == 0
    capsys.readouterr()
    with zipfile.ZipFile(tmp_path / "p.ssp") as z:
        data = z.read("SystemStructure.ssd")
        ssvs = {n: z.read(n) for n in z.namelist() if n.endswith(".ssv")}
        fmu_names = sorted(n for n in z.namelist() if n.endswith(".fmu"))
    assert schema_errors(data, "SystemStructureDescription.xsd") == []
    for ssv in ssvs.values():
        assert schema_errors(ssv, "SystemStructureParameterValues.xsd") == []
        assert b"ssv:String" not in ssv
    root = ET.fromstring(data)
    assert [child.tag.partition("}")[2] for child in root] == ["System", "Units", "DefaultExperiment"]
    assert system_annotations(root) == ["org.openmodelica", "org.pmsm-ev-cosim"]
    master = root.find("ssd:System/ssd:Annotations/ssc:Annotation/oms:Annotations/oms:SimulationInformation/"
                       "oms:FixedStepMaster", NS)
    assert (master.get("description"), float(master.get("stepSize"))) == ("oms-ma", 1e-4)
    # a String start value that is not the FMU's default rides in a copy of the FMU: the acceleration and cycle
    # runs' set the reference generator and the plant's gear model (strings), the others only angle_source; the
    # hilly road's RouteProfile in position mode carries its road name
    # hill-start-injection's: the plant's flux model and the unit's low_speed
    cycle = scenario.split("-")[0] in ("wltc3b", "udds", "hwfet", "us06", "us06x5")  # us06x5: US06 five times
    strings = scenario.startswith("acceleration") or cycle or scenario.endswith("-injection")
    assert fmu_names == sorted(["resources/PmsmEvPlant_plant.fmu" if strings else "resources/PmsmEvPlant.fmu",
                                "resources/RouteProfile.fmu",
                                f"resources/{ctrl}_ctrl.fmu" if angle_source or strings else f"resources/{ctrl}.fmu"]
                               + (["resources/RouteProfile_road.fmu"] if scenario.endswith("-hilly") else []))
    spec = load_ssp(tmp_path / "p.ssp")
    assert spec.algorithm == "gauss-seidel"  # the run record is read
    assert spec.output_interval == (0.05 if cycle else 0.01)


def test_the_package_reads_back_as_the_same_system(package, fmus):
    spec, orig = load_ssp(package), scenario2(fmus)
    assert (spec.name, spec.algorithm, spec.step_size, spec.stop_time, spec.output_interval) == \
        ("scenario2", "gauss-seidel", 1e-4, 350.0, 0.01)
    assert [c.name for c in spec.components] == ["ctrl", "plant", "route"]  # the route is stepped last
    assert [c.start for c in spec.components] == [{}, {}, {}]
    assert [str(c) for c in spec.connections] == [str(c) for c in orig.connections] + [
        "route.delta -> plant.delta", "route.omega_ref -> ctrl.omega_ref"]
    assert [c.name for c in spec.columns] == [c.name for c in orig.columns]
    assert spec.signals == {}


# -- libcosim ------------------------------------------------------------------------------------------
def run_libcosim_ssp(package: Path, stop_time: float, every: int) -> dict:
    """The package in libcosim's fixed-step master, as read by its SSP loader (step size from
    the package); rows every ``every`` steps from t_1 on, as the last-value observer sees them."""
    pytest.importorskip("libcosimpy")
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.WARNING)
    ex = CosimExecution.from_ssp_file(str(package))
    index = {s.name.decode(): s.index for s in ex.slave_infos()}
    assert set(index) == {"ctrl", "plant", "route"}
    refs = {n: {v.name.decode(): v.reference for v in ex.slave_variables(i)} for n, i in index.items()}
    observer = CosimObserver.create_last_value()
    assert ex.add_observer(observer)
    spec = load_ssp(package)  # the recorded columns the package declares
    rows = {c.name: [] for c in spec.columns}
    n_steps = round(stop_time / STEP)
    for n in range(n_steps):
        assert ex.step(), f"libcosim step {n} failed"
        if (n + 1) % every == 0:
            rows["time"].append((n + 1) * STEP)
            for c in spec.columns[1:]:
                (value,) = observer.last_real_values(index[c.instance], [refs[c.instance][c.variable]])
                rows[c.name].append(math.degrees(value) if c.unit == "deg" else value)
    status = ex.status()
    assert status.error_code == 0 and status.current_time == n_steps * 100_000
    return {name: np.array(values) for name, values in rows.items()}


@pytest.mark.parametrize("angle_source", ["measured", "estimated"])
@pytest.mark.slow
def test_libcosim_runs_the_package_as_the_orchestrators_jacobi_run(fmus, tmp_path, angle_source):
    stop = 2.0
    package = export(fmus, tmp_path / "s2.ssp", f"ctrl.angle_source={angle_source}")
    b = run_libcosim_ssp(package, stop, every=100)
    a = run(scenario2(fmus, f"ctrl.angle_source={angle_source}"), tmp_path / "jacobi", stop, "jacobi")
    a = {k: v[1:] for k, v in a.items()}  # libcosim's observer sees t_1 onwards
    assert list(a) == list(b) == list(ALL_COLUMNS)
    for col in ALL_COLUMNS:
        np.testing.assert_allclose(a[col], b[col], rtol=RTOL, atol=ATOL, err_msg=col)
    worst = max(float(np.max(np.abs(a[c] - b[c]))) for c in ALL_COLUMNS)
    print(f"libcosim vs orchestrator Jacobi, {stop} s, angle_source={angle_source}: max |diff| = {worst:.3g}")
    assert b["omega_ref"][-1] == 40.0 and b["omega_m"][-1] > 30.0  # 2 s into the ramp: the drive follows
    # the angle source the package carries reached libcosim: the two give different runs
    other = run(scenario2(fmus, "ctrl.angle_source=" + ("estimated" if angle_source == "measured" else "measured")),
                tmp_path / "other", 0.5, "jacobi")
    assert np.max(np.abs(other["v_q"][1:51] - b["v_q"][:50])) > 1e-6


# -- fmpy ------------------------------------------------------------------------------------------------
def run_fmpy_ssp(package: Path, stop_time: float, **kwargs):
    from fmpy.ssp.simulation import simulate_ssp

    return simulate_ssp(str(package), stop_time=stop_time, step_size=STEP, **kwargs)


def compare_with_jacobi(rows, package: Path, jacobi: dict, n: int, offset: int, tol: float = RTOL) -> float:
    """Max |difference| of the recorded columns of a tool's rows (``rows[name][k]`` for
    ``k < n``, by ``INSTANCE.VARIABLE``) and the Jacobi run's rows ``k + offset``;
    asserts them equal to ``tol`` (relative and absolute)."""
    worst = 0.0
    for col in ALL_COLUMNS[1:]:
        spec_col = next(c for c in load_ssp(package).columns if c.name == col)
        values = np.asarray(rows[f"{spec_col.instance}.{spec_col.variable}"][:n])
        if spec_col.unit == "deg":
            values = np.degrees(values)
        expected = jacobi[col][offset:n + offset]
        np.testing.assert_allclose(values, expected, rtol=tol, atol=tol, err_msg=col)
        worst = max(worst, float(np.max(np.abs(values - expected))))
    return worst


@pytest.mark.parametrize("angle_source", ["measured", "estimated"])
def test_fmpy_simulate_ssp_runs_the_package(fmus, tmp_path, angle_source):
    """fmpy's loop (Jacobi: every component steps with the inputs of the last exchange, its
    time an accumulated sum) gives row k the outputs after the step from t_k, i.e. at t_{k+1}.
    The estimated angle source, a String fmpy cannot set, travels in the controller's copy."""
    stop = 0.5
    package = export(fmus, tmp_path / "s2.ssp", f"ctrl.angle_source={angle_source}")
    r = run_fmpy_ssp(package, stop)
    a = run(scenario2(fmus, f"ctrl.angle_source={angle_source}"), tmp_path / "jacobi", stop, "jacobi",
            output_interval=STEP)
    n = round(stop / STEP)
    assert len(r) >= n
    worst = compare_with_jacobi(r, package, a, n, offset=1)
    print(f"fmpy simulate_ssp vs orchestrator Jacobi, {stop} s, angle_source={angle_source}: "
          f"max |diff| = {worst:.3g}")
    assert a["omega_m"][n] > 5.0


def test_fmpy_simulate_ssp_ignores_the_packages_ssv_values(bound, fmus, tmp_path):
    """fmpy 0.3's simulate_ssp reads the ParameterBindings (read_ssd) but never applies them:
    it sets only a parameter_set its caller passes. The package's m_v = 1200 kg (.ssv) does
    not reach the plant in fmpy; its estimated angle source (the controller's copy) does."""
    stop = 0.2
    r = run_fmpy_ssp(bound, stop)
    n = round(stop / STEP)
    default_mass = run(scenario2(fmus, "ctrl.angle_source=estimated"), tmp_path / "a", stop, "jacobi",
                       output_interval=STEP)
    package_mass = run(scenario2(fmus, "ctrl.angle_source=estimated", "plant.m_v=1200"), tmp_path / "b", stop,
                       "jacobi", output_interval=STEP)
    np.testing.assert_allclose(r["plant.omega_m"][:n], default_mass["omega_m"][1:n + 1], rtol=RTOL, atol=ATOL)
    assert np.max(np.abs(r["plant.omega_m"][:n] - package_mass["omega_m"][1:n + 1])) > 1e-6


def test_fmpy_simulate_ssp_cannot_set_a_string_parameter(package):
    """Passing the values itself (system-level names, as fmpy expects) fails in fmpy's
    set_value, which knows Real, Integer, Enumeration and Boolean only."""
    from fmpy.ssp.ssd import Parameter, ParameterSet

    values = ParameterSet(parameters=[Parameter(name="ctrl.angle_source", type="String", value="estimated")])
    with pytest.raises(Exception, match="^Unsupported type: String$"):
        run_fmpy_ssp(package, 0.01, parameter_set=values)


# -- OMSimulator -----------------------------------------------------------------------------------------
def omsimulator_env() -> dict:
    """The environment of a user who runs OMSimulator with no set-up for these Python FMUs (README: the FMUs
    bring up their own Python): ``env -i PATH=/usr/bin:/bin``, nothing else (no ``PYTHON*`` variable, no
    preload, not this project's interpreter on ``PATH``, no ``HOME``). An FMU built without the loader (no C
    compiler) still needs the set-up of fmus/README.md: this interpreter's libpython preloaded, its home, and its
    site-packages (numpy) on the path."""
    env = {"PATH": "/usr/bin:/bin"}
    if fmu_build.binding_requested() != "lean":
        libpython = Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("LDLIBRARY")
        env.update(LD_PRELOAD=str(libpython), PYTHONHOME=sys.base_prefix,
                   PYTHONPATH=os.pathsep.join(p for p in sys.path if p.endswith("site-packages")))
    return env


def run_omsimulator(package: Path, stop_time: float, work: Path) -> tuple[dict, str]:
    """``OMSimulator FILE.ssp --stopTime=T`` as a user runs it (the executable found on this process's
    ``PATH``, run with ``omsimulator_env()``), results as CSV; the last row of each communication point
    (OMSimulator writes some twice) by ``INSTANCE.VARIABLE``."""
    work.mkdir()
    command = [shutil.which("OMSimulator"), str(package), f"--stopTime={stop_time!r}", "--resultFile=res.csv",
               f"--tempDir={work}"]
    proc = subprocess.run(command, cwd=work, env=omsimulator_env(), capture_output=True, text=True, timeout=600)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    # no line of an error (its closing count, "info:    0 errors", is printed after any warning: e.g. with no
    # HOME, "settings.json couldn't be saved"; where its install leaves the SSD schema out, no validation)
    assert not re.search(r"^\s*(error|fatal)|\b[1-9][0-9]* errors?\b", out, re.IGNORECASE | re.MULTILINE), out
    data = np.genfromtxt(work / "res.csv", delimiter=",", names=True, deletechars="", dtype=float)
    steps = np.round(data["time"] / STEP).astype(int)
    last = np.unique(steps[::-1], return_index=True)[1]
    last = len(steps) - 1 - last  # the last row of each step
    # columns MODEL.SYSTEM.INSTANCE.VARIABLE (model and system named by the SSD) and time
    rows = {(name.split(".", 2)[2] if name.count(".") >= 3 else name): data[name][last]
            for name in data.dtype.names}
    return rows, out


@pytest.mark.skipif(shutil.which("OMSimulator") is None,
                    reason="no OMSimulator executable on PATH (README: building it from its sources)")
@pytest.mark.parametrize("angle_source", ["measured", "estimated"])
def test_omsimulator_runs_the_package(fmus, tmp_path, angle_source):
    """OMSimulator (its fixed-step master, oms-ma, Jacobi) runs the exported package as it
    is, 2 s as in its README's command; row t_k holds the outputs at t_k, as this master's.
    Its time is an accumulated sum: it ends the run with a sliver step (2e-13 s), which the
    controller runs without an extra period."""
    stop = 2.0
    package = export(fmus, tmp_path / "s2.ssp", f"ctrl.angle_source={angle_source}")
    rows, out = run_omsimulator(package, stop, tmp_path / "oms")
    n = round(stop / STEP)
    assert len(rows["time"]) == n + 1 and rows["time"][-1] == stop
    a = run(scenario2(fmus, f"ctrl.angle_source={angle_source}"), tmp_path / "jacobi", stop, "jacobi",
            output_interval=STEP)
    worst = compare_with_jacobi({k: v[1:] for k, v in rows.items()}, package, a, n, offset=1)
    print(f"OMSimulator vs orchestrator Jacobi, {stop} s, angle_source={angle_source}: max |diff| = {worst:.3g}")
    assert a["omega_ref"][-1] == 40.0 and a["omega_m"][-1] > 30.0


@pytest.mark.skipif(shutil.which("OMSimulator") is None,
                    reason="no OMSimulator executable on PATH (README: building it from its sources)")
def test_omsimulator_runs_the_sensorless_hill_start(fmus, tmp_path):
    """A scenario whose name is no identifier (hill-start-if: OMSimulator needs identifiers for
    its model and system) and the sensorless unit: alignment, I-f and handover in 5 s."""
    stop = 5.0
    spec = load_system("hill-start-if")
    spec.set_fmu("ctrl", fmus["FocSensorless"])
    spec.set_fmu("plant", fmus["PmsmEvPlant"])
    package = tmp_path / "hill.ssp"
    export_ssp(spec, package, route_fmu=fmus["RouteProfile"])
    rows, _ = run_omsimulator(package, stop, tmp_path / "oms")
    n = round(stop / STEP)
    assert set(np.unique(rows["ctrl.mode"])) == {0.0, 1.0, 2.0}
    a = run(spec, tmp_path / "jacobi", stop, "jacobi", output_interval=STEP)
    # measured: up to 1.3e-8 from the Jacobi run over the start-up (round-off differences grow
    # through the alignment and I-f, ~1e-11 in the paper's scenarios), so 1e-8 relative here
    worst = compare_with_jacobi({k: v[1:] for k, v in rows.items()}, package, a, n, offset=1, tol=1e-8)
    print(f"OMSimulator vs orchestrator Jacobi, hill-start-if, {stop} s: max |diff| = {worst:.3g}")


# -- round trip ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_round_trip_equals_the_original_run_value_for_value(package, fmus, tmp_path, algorithm):
    stop = 1.0
    a = run(load_ssp(package), tmp_path / "ssp", stop, algorithm)
    b = run(scenario2(fmus), tmp_path / "toml", stop, algorithm)
    assert list(a) == list(b) == list(ALL_COLUMNS)
    for col in ALL_COLUMNS:
        np.testing.assert_array_equal(a[col], b[col], err_msg=col)
    assert len(a["time"]) == 101 and a["omega_ref"][-1] == 20.0


def test_round_trip_of_a_user_route_from_csv(fmus, tmp_path):
    """export-ssp --profile delta=CSV: the route written into the packaged RouteProfile FMU;
    elevation steps every 0.1 s (not binary fractions) cross the boundary on the same step."""
    csv = tmp_path / "route.csv"
    csv.write_text("time,delta_deg\n" + "".join(f"{0.1 * k!r},{(0, 8.5, -3, 22)[k % 4]}\n" for k in range(6)))
    package = export(fmus, tmp_path / "user.ssp", profile=f"delta={csv}")
    a = run(load_ssp(package), tmp_path / "ssp", 0.5, output_interval=STEP)
    b = run(scenario2(fmus, profile=f"delta={csv}"), tmp_path / "toml", 0.5, output_interval=STEP)
    for col in ALL_COLUMNS:
        np.testing.assert_array_equal(a[col], b[col], err_msg=col)
    assert set(np.round(a["delta_deg"], 9)) == {0.0, 8.5, -3.0, 22.0}


def test_cli_export_and_run(fmus, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = ["--plant", str(fmus["PmsmEvPlant"]), "--controller", str(fmus["FocEkf5"])]
    assert main(["export-ssp", "scenario2", "-o", "s2.ssp", "--stop-time", "0.3", "--set", "plant.m_v=1200",
                 *args]) == 0
    out = capsys.readouterr().out
    assert "wrote s2.ssp: components ctrl, plant, route; 12 connections; 1 parameter value;" in out
    with zipfile.ZipFile("s2.ssp") as z:
        assert b'<ssv:Real value="1200.0" />' in z.read("resources/plant.ssv")
    assert main(["run", "s2.ssp", "--out", "a", "--no-figures", "-q"]) == 0
    assert main(["run", "scenario2", "--stop-time", "0.3", "--set", "plant.m_v=1200", "--out", "b",
                 "--no-figures", "-q", *args]) == 0
    assert (tmp_path / "a/results.csv").read_bytes() == (tmp_path / "b/results.csv").read_bytes()


# -- errors ----------------------------------------------------------------------------------------------
def one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("error: ")
    return err[0]


def rewrite(package: Path, dest: Path, old: str = "", new: str = "", member: str = "SystemStructure.ssd",
            drop: str | None = None) -> Path:
    """A copy of ``package`` with ``old`` replaced by ``new`` in ``member`` and ``drop`` left out."""
    with zipfile.ZipFile(package) as zin, zipfile.ZipFile(dest, "w") as zout:
        for item in zin.infolist():
            if item.filename == drop:
                continue
            data = zin.read(item)
            if item.filename == member and old:
                text = data.decode()
                assert old in text, old
                data = text.replace(old, new, 1).encode()
            zout.writestr(item, data)
    return dest


SUB_SYSTEM = '<ssd:System name="inner" />\n    </ssd:Elements>'


@pytest.mark.parametrize("old, new, message", [
    ('</ssd:Elements>', SUB_SYSTEM, "unsupported SSP feature: sub-system (nested ssd:System)"),
    ('endConnector="i_alpha" />', 'endConnector="i_alpha"><ssc:LinearTransformation factor="2.0" /></ssd:Connection>',
     "connection plant.i_alpha -> ctrl.i_alpha: unsupported SSP feature: LinearTransformation"),
    ('startElement="plant" startConnector="i_beta" ', 'startConnector="i_beta" ',
     "unsupported SSP feature: connection to a connector of the system itself"),
    ('implementation="CoSimulation"', 'implementation="ModelExchange"',
     "ctrl: unsupported SSP feature: implementation=\"ModelExchange\""),
    ('<ssd:ParameterBinding type=', '<ssd:ParameterBinding prefix="plant." type=',
     "plant: unsupported SSP feature: parameter binding prefix 'plant.'"),
    ('startTime="0.0"', 'startTime="1.5"', "unsupported SSP feature: DefaultExperiment startTime 1.5"),
    ('source="resources/PmsmEvPlant.fmu"', 'source="resources/Nope.fmu"',
     "plant: resources/Nope.fmu is not in the package"),
    ('source="resources/PmsmEvPlant.fmu"', 'source="http://example.org/P.fmu"', "outside the package"),
    ('version="1.0"', 'version="2.0"', "SSP version '2.0' is not supported (SSP 1.0)"),
    (' kind="output"', ' kind="sideways"', "not valid SSP 1.0 (SystemStructureDescription.xsd): line"),
    ('<ssd:Elements>', '<ssd:Elements', "SystemStructure.ssd: not well-formed XML"),
])
def test_unsupported_or_broken_ssd_is_a_one_line_error(bound, tmp_path, capsys, old, new, message):
    bad = rewrite(bound, tmp_path / "bad.ssp", old, new)
    assert main(["run", str(bad), "--out", str(tmp_path / "out"), "-q"]) == 2
    assert message in one_line_error(capsys)
    assert not (tmp_path / "out").exists()


def test_bad_parameter_values_and_packages(package, bound, tmp_path, capsys):
    bad = rewrite(bound, tmp_path / "enum.ssp", '<ssv:Real value="1200.0" />',
                  '<ssv:Enumeration value="1200.0" />', member="resources/plant.ssv")
    assert main(["run", str(bad), "-q"]) == 2
    assert "parameter 'm_v' of type Enumeration" in one_line_error(capsys)
    # a String value (from another tool's package) is read, and a bad one refused
    bad = rewrite(bound, tmp_path / "value1.ssp", 'name="m_v"', 'name="load_model"', member="resources/plant.ssv")
    bad = rewrite(bad, tmp_path / "value.ssp", '<ssv:Real value="1200.0" />', '<ssv:String value="sideways" />',
                  member="resources/plant.ssv")
    assert load_ssp(bad).components[1].start == {"load_model": "sideways"}
    assert main(["run", str(bad), "-q", "--out", str(tmp_path / "o")]) == 2
    assert "load_model must be one of" in one_line_error(capsys)
    bad = rewrite(bound, tmp_path / "nossv.ssp", drop="resources/plant.ssv")
    assert main(["run", str(bad), "-q"]) == 2
    assert "resources/plant.ssv is not in the package" in one_line_error(capsys)
    not_zip = tmp_path / "text.ssp"
    not_zip.write_text("hello")
    assert main(["run", str(not_zip), "-q"]) == 2
    assert "not an SSP package (not a zip archive)" in one_line_error(capsys)
    no_ssd = rewrite(package, tmp_path / "nossd.ssp", drop="SystemStructure.ssd")
    assert main(["run", str(no_ssd), "-q"]) == 2
    assert "not an SSP package (no SystemStructure.ssd at its root)" in one_line_error(capsys)
    assert main(["run", str(tmp_path / "missing.ssp"), "-q"]) == 2
    assert "SSP package not found" in one_line_error(capsys)


def test_a_package_without_step_or_annotation_needs_step_and_runs_jacobi(package, fmus, tmp_path, capsys):
    """A package from another tool: no base step, no pmsm-ev-cosim annotation: --step is
    needed, the coupling is Jacobi and every output connector is recorded."""
    with zipfile.ZipFile(package) as z:
        ssd = z.read("SystemStructure.ssd").decode()
    start = ssd.index("    <ssd:Annotations>\n      <ssc:Annotation type=\"org.openmodelica\">")
    end = ssd.index("</ssd:Annotations>", start) + len("</ssd:Annotations>\n")
    bare = rewrite(package, tmp_path / "bare.ssp", ssd[start:end], "")
    bare = rewrite(bare, tmp_path / "bare2.ssp", '<osp:FixedStepAlgorithm baseStepSize="0.0001" />', "")
    assert main(["run", str(bare), "--stop-time", "0.01", "-q", "--out", str(tmp_path / "o")]) == 2
    assert "no communication step size is given (give one with --step)" in one_line_error(capsys)
    spec = load_ssp(bare)
    assert spec.algorithm == "jacobi" and spec.step_size is None
    assert [c.name for c in spec.columns][:3] == ["time", "ctrl.v_alpha", "ctrl.v_beta"]
    assert main(["run", str(bare), "--stop-time", "0.05", "--step", "1e-4", "--no-figures", "-q",
                 "--out", str(tmp_path / "bare_run")]) == 0
    a = read_results(tmp_path / "bare_run")
    b = run(scenario2(fmus), tmp_path / "jacobi", 0.05, "jacobi", output_interval=STEP)
    np.testing.assert_array_equal(a["plant.omega_m"], b["omega_m"])
    np.testing.assert_array_equal(a["route.omega_ref"], b["omega_ref"])


def test_a_package_with_the_run_record_at_the_root_still_reads(package, tmp_path):
    """Packages written before the run record moved into the system (OMSimulator refuses
    annotations at the root) keep their coupling, output interval and columns."""
    with zipfile.ZipFile(package) as z:
        ssd = z.read("SystemStructure.ssd").decode()
    start = ssd.index('      <ssc:Annotation type="org.pmsm-ev-cosim">')
    end = ssd.index("</ssc:Annotation>", start) + len("</ssc:Annotation>\n")
    record = ssd[start:end]
    old = rewrite(package, tmp_path / "old1.ssp", record, "")
    old = rewrite(old, tmp_path / "old.ssp", "</ssd:SystemStructureDescription>",
                  f"<ssd:Annotations>{record}</ssd:Annotations></ssd:SystemStructureDescription>")
    with zipfile.ZipFile(old) as z:
        assert schema_errors(z.read("SystemStructure.ssd"), "SystemStructureDescription.xsd") == []
        assert system_annotations(ET.fromstring(z.read("SystemStructure.ssd"))) == ["org.openmodelica"]
    a, b = load_ssp(old), load_ssp(package)
    assert (a.algorithm, a.output_interval, [c.name for c in a.columns]) == \
        (b.algorithm, b.output_interval, [c.name for c in b.columns]) == ("gauss-seidel", 0.01, list(ALL_COLUMNS))


def test_export_refuses_signals_the_route_cannot_carry(fmus, tmp_path):
    spec = scenario2(fmus)
    spec.signals["load"] = spec.signals.pop("omega_ref")
    spec.signals["load"].name = "load"
    with pytest.raises(CosimError, match="the signals must be delta and omega_ref"):
        export_ssp(spec, tmp_path / "x.ssp", route_fmu=fmus["RouteProfile"])
    assert not (tmp_path / "x.ssp").exists()
