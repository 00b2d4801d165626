"""The FMUs (fmus/, issue 3): build, modelDescription, physics alone, bit-identity with
the monolithic reference, isolation of instances, FMU state, errors, self-containment
and co-simulation in libcosim.

The FMUs are built once per session into a temporary directory.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET
import zipfile
from ctypes import byref
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy.validation import validate_fmu

import pmsm_ev_fmus
from fmpy_process import simulate_fmu, simulate_fmus
from pmsm_cosim.app.reference import run_reference
from pmsm_cosim.engine.recording import read_results
from pmsm_ev import __version__, accel
from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.params import (
    BatteryParams,
    ControllerParams,
    DriveParams,
    EkfParams,
    InjectionParams,
    MotorParams,
    ParameterError,
    PlantParams,
    ScenarioParams,
    StartupParams,
    VehicleParams,
)
from pmsm_ev.plant import BATTERY_SLOTS, THERMAL_SLOTS, Plant
from pmsm_ev_fmus import build as fmu_build
from pmsm_ev_fmus.metadata import PARAMETERS, UNITS

CONTROLLERS = ("FocEkf5", "FocEkf4", "FocEkf5AB", "FocSensored", "FocSensorless")
OBSERVER = {fmu: observer for observer, fmu in pmsm_ev_fmus.OBSERVER_FMUS.items()}
PLANT_INPUTS = ("v_alpha", "v_beta", "delta", "T_brake")
PLANT_OUTPUTS = ("i_alpha", "i_beta", "i_d", "i_q", "omega_m", "theta_e", "T_e", "T_L_mech", "v_vehicle",
                 "x_vehicle", "E_dc", "E_dc_abs", "E_regen", "E_copper", "E_friction", "E_shaft", "E_gear", "E_aero",
                 "E_rolling", "E_grade", "E_brake", "E_inverter", "E_iron", "W_magnetic", "E_kinetic", "P_dc",
                 *BATTERY_SLOTS, *THERMAL_SLOTS, "R_s_now", "psi_now")
CTRL_INPUTS = ("i_alpha", "i_beta", "omega_ref", "theta_meas", "omega_meas", "v_dc_meas", "P_charge_max",
               "P_discharge_max")
CTRL_OUTPUTS = ("v_alpha", "v_beta", "v_d", "v_q", "i_d_hat", "i_q_hat", "omega_hat", "theta_hat", "T_L_hat",
                "i_d", "i_q", "i_qref", "mode", "fault", "theta_ctrl", "omega_ctrl", "i_dref", "T_ref", "T_brake",
                "ref_region", "psi_est", "R_s_est", "psi_observable", "R_s_observable", "L_d_id", "L_q_id",
                "saliency_id", "R_s_id", "noise_id", "offset_a_id", "offset_b_id", "angle_accuracy", "blind",
                "axis_cos", "gain_ratio_id")
#: the controllers' outputs that are codes, flags or ratios: no unit
UNITLESS = ("mode", "fault", "ref_region", "soc", "over_temperature", "psi_observable", "R_s_observable",
            "saliency_id", "blind", "axis_cos", "gain_ratio_id")
DT = 1e-4
DELTA_22 = math.radians(22.0)


# -- fixtures and helpers --------------------------------------------------------------
@pytest.fixture(scope="session")
def fmus(tmp_path_factory) -> dict[str, Path]:
    return pmsm_ev_fmus.build_all(tmp_path_factory.mktemp("fmus"))


@pytest.fixture(scope="session")
def unzipped(fmus, tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("unzipped")
    return {name: Path(fmpy.extract(str(path), str(root / name))) for name, path in fmus.items()}


class Instance:
    """An FMU instance driven by variable names (fmpy's FMU2Slave underneath)."""

    def __init__(self, unzipped, name, instance_name=None, start=None, initialize=True, messages=None):
        self.md = fmpy.read_model_description(str(unzipped[name]))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.type = {v.name: v.type for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=str(unzipped[name]),
                             modelIdentifier=self.md.coSimulation.modelIdentifier,
                             instanceName=instance_name or name)
        callbacks = None
        if messages is not None:  # collect the FMU's log messages
            def log(_env, _instance, status, _category, message):
                messages.append((status, message.decode()))
            callbacks = fmi2CallbackFunctions()
            callbacks.logger = fmi2CallbackLoggerTYPE(log)
            callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
            callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)
            from fmpy.logging import addLoggerProxy
            addLoggerProxy(byref(callbacks))
        self.fmu.instantiate(callbacks=callbacks, loggingOn=messages is not None)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.set(**(start or {}))
        if initialize:
            self.fmu.exitInitializationMode()
        self.t = 0.0

    def set(self, **values):
        for name, value in values.items():
            setter = {"Real": self.fmu.setReal, "Integer": self.fmu.setInteger,
                      "Boolean": self.fmu.setBoolean, "String": self.fmu.setString}[self.type[name]]
            setter([self.vr[name]], [value])

    def refs(self, names):
        return [self.vr[n] for n in names]

    def get(self, names):
        return self.fmu.getReal(self.refs(names))

    def step(self, h=DT):
        self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=h)
        self.t += h

    def free(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def plant_outputs(p: Plant):
    e = p.energies()
    return [p.i_alpha, p.i_beta, p.i_d, p.i_q, p.omega_m, p.theta_e, p.T_e, p.T_L_mech, p.v_vehicle, p.x_vehicle,
            *(e[name] for name in PLANT_OUTPUTS[10:23]), e["W_magnetic"], e["E_kinetic"], p.P_dc,
            *(float(p.energy[slot]) for slot in BATTERY_SLOTS.values()),
            *(float(p.energy[slot]) for slot in THERMAL_SLOTS.values()), p.thermal()["R_s"], p.thermal()["psi"]]


def unit_outputs(u: ControlUnit, theta_meas: float = 0.0):
    """The controller FMU's outputs (CTRL_OUTPUTS) of the unit after a step given ``theta_meas``."""
    theta_ctrl = u.theta_ctrl if u.sensorless or u.angle_source == "estimated" else theta_meas
    return [u.v_alpha, u.v_beta, u.v_d, u.v_q, *u.estimates, u.i_d, u.i_q, u.i_qref, u.mode, u.fault, theta_ctrl,
            u.omega_ctrl, u.i_dref, u.T_ref, u.T_brake, u.ref_region, *(getattr(u, n) for n in CTRL_OUTPUTS[20:])]


def omega_ramp(t):
    return 200.0 * min(t / 10.0, 1.0)


# -- build -----------------------------------------------------------------------------
def test_build_writes_every_fmu_with_its_hash(fmus):
    assert set(fmus) == set(pmsm_ev_fmus.FMUS) == {"PmsmEvPlant", *CONTROLLERS, "RouteProfile"}
    for name, path in fmus.items():
        assert path.name == f"{name}.fmu" and path.is_file()
        info = fmu_build.read_build_info(path)
        assert info["hash"] == fmu_build.source_hash(name)
        tag = info["tag"]
        with zipfile.ZipFile(path) as zf:
            files = set(zf.namelist())
            assert zf.read("resources/slavemodule.txt").decode().strip() == info["slave_module"]
        assert f"resources/pmsm_ev_{tag}/__init__.py" in files
        assert f"resources/pmsm_ev_fmus_slave_support_{tag}.py" in files
        assert f"binaries/linux64/{name}.so" in files
        assert "documentation/index.html" in files


def test_build_is_incremental_and_follows_the_sources(fmus, tmp_path, monkeypatch):
    out = fmus["PmsmEvPlant"].parent
    mtime = fmus["PmsmEvPlant"].stat().st_mtime_ns
    assert pmsm_ev_fmus.build_all(out, names=["PmsmEvPlant"]) == {"PmsmEvPlant": fmus["PmsmEvPlant"]}
    assert fmus["PmsmEvPlant"].stat().st_mtime_ns == mtime  # up to date: not rebuilt
    assert fmu_build.build_fmu("PmsmEvPlant", tmp_path)[1] is True
    assert fmu_build.build_fmu("PmsmEvPlant", tmp_path)[1] is False
    assert fmu_build.build_fmu("PmsmEvPlant", tmp_path, force=True)[1] is True
    # a changed physics source changes the hash and triggers a rebuild
    physics = tmp_path / "pmsm_ev"
    (physics / "kernels").mkdir(parents=True)
    for src in [*fmu_build.physics_dir().glob("*.py"), *fmu_build.physics_dir().glob("kernels/*.py")]:
        (physics / src.relative_to(fmu_build.physics_dir())).write_bytes(src.read_bytes())
    (physics / "plant.py").write_text((physics / "plant.py").read_text() + "\n# changed\n")
    before = {name: fmu_build.source_hash(name) for name in ("PmsmEvPlant", "FocEkf5")}
    monkeypatch.setattr(fmu_build, "physics_dir", lambda: physics)
    assert fmu_build.source_hash("PmsmEvPlant") != before["PmsmEvPlant"]
    assert not fmu_build.is_up_to_date("PmsmEvPlant", tmp_path)
    assert fmu_build.build_fmu("PmsmEvPlant", tmp_path)[1] is True
    # a controller does not bundle plant.py: its hash does not depend on it
    assert fmu_build.source_hash("FocEkf5") == before["FocEkf5"]
    # both bundle the whole kernels package: a change in any of its files changes both
    with zipfile.ZipFile(tmp_path / "PmsmEvPlant.fmu") as zf:
        bundled = {n.split("/", 2)[2] for n in zf.namelist() if n.startswith("resources/pmsm_ev_") and "/" in n[10:]}
    assert {f"kernels/{p.name}" for p in (physics / "kernels").glob("*.py")} <= bundled
    now = {name: fmu_build.source_hash(name) for name in ("PmsmEvPlant", "FocEkf5")}
    (physics / "kernels" / "startup.py").write_text((physics / "kernels" / "startup.py").read_text() + "\n# changed\n")
    assert all(fmu_build.source_hash(name) != now[name] for name in now)
    assert not (tmp_path / ".build").exists()


def test_build_rejects_unknown_names(tmp_path):
    with pytest.raises(pmsm_ev_fmus.BuildError, match="unknown FMU"):
        pmsm_ev_fmus.build_all(tmp_path, names=["NoSuchFmu"])
    with pytest.raises(SystemExit):
        pmsm_ev_fmus.main(["--out", str(tmp_path), "NoSuchFmu"])


def test_fmus_go_to_the_user_cache_keyed_by_their_content(monkeypatch, tmp_path):
    """Not into the package (site-packages for an installation): the user's cache, a folder
    per content of all the FMUs' sources; $PMSM_COSIM_FMU_DIR instead when set."""
    monkeypatch.delenv("PMSM_COSIM_FMU_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    key = fmu_build.content_key()
    assert len(key) == 16 and int(key, 16) >= 0
    assert fmu_build.default_out_dir() == tmp_path / "cache" / "pmsm-ev-cosim" / "fmus" / key
    assert fmu_build.HERE not in fmu_build.default_out_dir().parents
    # one changed physics source: another key
    physics = tmp_path / "pmsm_ev"
    shutil.copytree(fmu_build.physics_dir(), physics, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(fmu_build, "physics_dir", lambda: physics)
    assert fmu_build.content_key() == key  # the same content elsewhere: the same key
    (physics / "results.py").write_text((physics / "results.py").read_text() + "\n# changed\n")
    assert fmu_build.content_key() == key  # in no FMU
    (physics / "plant.py").write_text((physics / "plant.py").read_text() + "\n# changed\n")
    assert fmu_build.content_key() != key
    monkeypatch.setenv("PMSM_COSIM_FMU_DIR", str(tmp_path / "mine"))
    assert fmu_build.default_out_dir() == tmp_path / "mine"


@pytest.mark.parametrize("platform, expected", [("linux", ".cache/pmsm-ev-cosim"),
                                                ("darwin", "Library/Caches/pmsm-ev-cosim"),
                                                ("win32", "AppData/Local/pmsm-ev-cosim")])
def test_the_user_cache_of_each_platform(monkeypatch, tmp_path, platform, expected):
    for name in ("XDG_CACHE_HOME", "LOCALAPPDATA"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setattr(fmu_build.sys, "platform", platform)
    assert fmu_build.user_cache_dir() == tmp_path / expected
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert fmu_build.user_cache_dir() == tmp_path / "xdg" / "pmsm-ev-cosim"


def test_a_physics_package_folder_is_bundled_whole(fmus, tmp_path, monkeypatch):
    """A module of pmsm_ev may be a package folder (its __init__.py, the modules it imports,
    ``from ..x import`` out of it): bundled with its layout, in the hash, and the FMU runs
    with the same numbers."""
    physics = tmp_path / "pmsm_ev"
    shutil.copytree(fmu_build.physics_dir(), physics, ignore=shutil.ignore_patterns("__pycache__"))
    (physics / "transforms").mkdir()
    text = (physics / "transforms.py").read_text().replace("from .kernels import", "from ..kernels import")
    (physics / "transforms" / "__init__.py").write_text(text + "\nfrom ._origin import ORIGIN  # noqa: E402,F401\n")
    (physics / "transforms" / "_origin.py").write_text("from .. import __version__\n\nORIGIN = __version__\n")
    (physics / "transforms.py").unlink()
    monkeypatch.setattr(fmu_build, "physics_dir", lambda: physics)
    files = fmu_build._physics_files("pmsm_ev_plant.py")
    assert {Path("transforms/__init__.py"), Path("transforms/_origin.py"), Path("kernels/__init__.py"),
            Path("__init__.py")} <= set(files) and Path("transforms.py") not in files
    digest = fmu_build.source_hash("PmsmEvPlant")
    (physics / "transforms" / "_origin.py").write_text("from .. import __version__\n\nORIGIN = 'x' + __version__\n")
    assert fmu_build.source_hash("PmsmEvPlant") != digest
    path, built = fmu_build.build_fmu("PmsmEvPlant", tmp_path / "out")
    tag = fmu_build.read_build_info(path)["tag"]
    with zipfile.ZipFile(path) as zf:
        names = set(zf.namelist())
    assert {f"resources/pmsm_ev_{tag}/transforms/__init__.py", f"resources/pmsm_ev_{tag}/transforms/_origin.py"} \
        <= names and f"resources/pmsm_ev_{tag}/transforms.py" not in names
    signals = np.array([(0.0, 1.0, 0.5, 0.0), (0.01, 1.0, 0.5, 0.0)],
                       dtype=[("time", float), ("v_alpha", float), ("v_beta", float), ("delta", float)])
    runs = [simulate_fmu(str(fmu), stop_time=0.01, step_size=DT, output_interval=DT, input=signals,
                              start_values={"theta_e0": 0.3}, output=["i_d", "i_q", "theta_e"])
            for fmu in (fmus["PmsmEvPlant"], path)]
    for name in ("i_d", "i_q", "theta_e"):
        assert np.array_equal(runs[0][name], runs[1][name]) and np.max(np.abs(runs[0][name])) > 0


def _xml_tree(data: bytes) -> list:
    root = ET.fromstring(data)
    return [(e.tag, dict(e.attrib), (e.text or "").strip()) for e in root.iter()]


def test_changed_start_values_are_edited_as_xml(fmus, tmp_path):
    """write_fmu_with_starts changes the start attributes it is given and nothing else of
    the model description (every element, attribute and text as before)."""
    values = {"angle_source": "estimated", "q_omega": 0.25, "R_s": 2, "dt": 1e-4}
    copy = pmsm_ev_fmus.write_fmu_with_starts(fmus["FocEkf5"], tmp_path / "c.fmu", values)
    with zipfile.ZipFile(fmus["FocEkf5"]) as z:
        before = z.read("modelDescription.xml")
    with zipfile.ZipFile(copy) as z:
        after = z.read("modelDescription.xml")
        assert json.loads(z.read("resources/start_values.json")) == values
    old, new = _xml_tree(before), _xml_tree(after)
    assert len(old) == len(new) and new[0] == old[0]
    changed = {}
    for (tag, attrs, text), (tag2, attrs2, text2) in zip(old, new):
        assert (tag, text, list(attrs)) == (tag2, text2, list(attrs2))  # same attributes, in order
        if attrs != attrs2:
            assert {k for k in attrs if attrs[k] != attrs2[k]} == {"start"}
            changed[attrs2["start"]] = attrs["start"]
    assert sorted(changed) == ["0.0001", "0.25", "2", "estimated"]
    md = fmpy.read_model_description(str(copy))
    starts = {v.name: v.start for v in md.modelVariables if v.name in values}
    assert starts == {"angle_source": "estimated", "q_omega": "0.25", "R_s": "2", "dt": "0.0001"}
    assert validate_fmu(str(copy)) == []
    with pytest.raises(pmsm_ev_fmus.BuildError, match="no parameter 'omega_m' with a start value"):
        pmsm_ev_fmus.write_fmu_with_starts(fmus["FocEkf5"], tmp_path / "d.fmu", {"omega_m": 1.0})
    assert not (tmp_path / "d.fmu").exists() and [p.name for p in tmp_path.iterdir()] == ["c.fmu"]


def test_concurrent_builds_into_one_folder_do_not_clash(tmp_path):
    """Two processes building the same FMU into the same folder at once (pytest or Dask
    workers): both succeed, the FMU is whole, no staging file is left."""
    out = tmp_path / "fmus"
    cmd = [sys.executable, "-m", "pmsm_cosim.app.cli", "build", "--out", str(out), "--force", "RouteProfile"]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) for _ in range(2)]
    outputs = [p.communicate(timeout=300)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outputs
    assert all(f"RouteProfile: {out / 'RouteProfile.fmu'}" in text for text in outputs), outputs
    assert sorted(p.name for p in out.iterdir()) == ["RouteProfile.fmu"]
    assert validate_fmu(str(out / "RouteProfile.fmu")) == []
    assert fmu_build.read_build_info(out / "RouteProfile.fmu")["hash"] == fmu_build.source_hash("RouteProfile")


def test_the_command_line_takes_the_fmu_folder(fmus, tmp_path, capsys, monkeypatch):
    """--fmu-dir DIR (build: --out DIR): the project's FMUs are those in DIR ({fmus} and the
    names of --controller, info); $PMSM_COSIM_FMU_DIR is as it was afterwards."""
    from pmsm_cosim.app.cli import main

    monkeypatch.delenv("PMSM_COSIM_FMU_DIR", raising=False)
    folder = fmus["FocEkf4"].parent
    assert main(["build", "--out", str(folder), "FocEkf4"]) == 0
    assert capsys.readouterr().out.strip() == f"FocEkf4: {folder / 'FocEkf4.fmu'}"
    assert main(["info", "ekf4", "--fmu-dir", str(folder), "--causality", "input"]) == 0
    assert capsys.readouterr().out.startswith("FocEkf4 (FMI 2.0, co-simulation")
    out = tmp_path / "run"
    assert main(["run", "scenario1", "--controller", "ekf4", "--fmu-dir", str(folder), "--stop-time", "0.01",
                 "-q", "--no-figures", "--out", str(out)]) == 0
    components = json.loads((out / "metrics.json").read_text())["settings"]["components"]
    assert [c["fmu"] for c in components] == [str(folder / "FocEkf4.fmu"), str(folder / "PmsmEvPlant.fmu")]
    assert "PMSM_COSIM_FMU_DIR" not in os.environ and sorted(p.name for p in folder.iterdir()) == sorted(
        f"{n}.fmu" for n in pmsm_ev_fmus.FMUS)


def test_build_cli_reports_up_to_date(fmus, capsys):
    out = fmus["FocEkf5"].parent
    assert pmsm_ev_fmus.main(["--out", str(out), "FocEkf5", "FocSensored"]) == 0
    text = capsys.readouterr().out
    assert "FocEkf5: up to date" in text and "FocSensored: up to date" in text


def test_bundled_imports_are_renamed():
    src = textwrap.dedent("""\
        from pmsm_ev import __version__
        from pmsm_ev.plant import Plant
        from pmsm_ev_fmus.slave_support import (DriveSlave,
                                                FmuUsageError)
        import math
        """)
    out = fmu_build.rewrite_imports(src, "0badc0de")
    assert "from pmsm_ev_0badc0de import __version__" in out
    assert "from pmsm_ev_0badc0de.plant import Plant" in out
    assert "from pmsm_ev_fmus_slave_support_0badc0de import (DriveSlave," in out
    assert out.count("\n") == src.count("\n")  # line numbers kept for tracebacks
    with pytest.raises(pmsm_ev_fmus.BuildError):
        fmu_build._project_imports("import pmsm_ev.plant\n", "x.py")
    with pytest.raises(pmsm_ev_fmus.BuildError):
        fmu_build._project_imports("from .slave_support import DriveSlave\n", "x.py")


# -- modelDescription ------------------------------------------------------------------
@pytest.mark.parametrize("name", ["PmsmEvPlant", *CONTROLLERS])
def test_fmpy_validation_finds_no_problem(fmus, name):
    assert validate_fmu(str(fmus[name])) == []


def test_metadata_covers_every_parameter_field():
    for cls in (MotorParams, VehicleParams, PlantParams, ControllerParams, EkfParams, StartupParams):
        for f in dataclasses.fields(cls):
            assert f.name in PARAMETERS, f"{cls.__name__}.{f.name} has no unit/description in fmus/metadata.py"
            unit, text = PARAMETERS[f.name]
            assert unit is None or unit in UNITS
            assert text


@pytest.mark.parametrize("name", ["PmsmEvPlant", *CONTROLLERS])
def test_model_description_is_complete(fmus, name):
    md = fmpy.read_model_description(str(fmus[name]), validate=True)
    assert md.author and md.version == __version__ and md.description
    experiment = md.defaultExperiment
    assert (float(experiment.startTime), float(experiment.stopTime), float(experiment.stepSize)) == (0.0, 350.0, 1e-4)
    cs = md.coSimulation
    assert cs.canGetAndSetFMUstate and cs.canSerializeFMUstate
    assert cs.canHandleVariableCommunicationStepSize  # the controllers keep their own sample clock
    units = {u.name for u in md.unitDefinitions}
    by_name = {v.name: v for v in md.modelVariables}
    for v in md.modelVariables:
        assert v.description, v.name
        if v.causality == "parameter":
            assert v.variability == "fixed" and v.initial == "exact" and v.start is not None
            assert PARAMETERS[v.name][0] == v.unit
        if v.unit is not None:
            assert v.unit in units
    groups = (MotorParams, VehicleParams, PlantParams, BatteryParams) if name == "PmsmEvPlant" else \
        (ControllerParams, EkfParams, MotorParams, StartupParams, InjectionParams) if name == "FocSensorless" else \
        (ControllerParams, EkfParams, MotorParams)
    expected = {f.name for cls in groups for f in dataclasses.fields(cls)}
    if name != "PmsmEvPlant":
        expected |= {"angle_source", "dt"}
        assert by_name["dt"].start == "0.0" and by_name["dt"].unit == "s"  # 0: the first step size
    assert {v.name for v in md.modelVariables if v.causality == "parameter"} == expected
    inputs = PLANT_INPUTS if name == "PmsmEvPlant" else CTRL_INPUTS
    outputs = PLANT_OUTPUTS if name == "PmsmEvPlant" else CTRL_OUTPUTS
    assert [v.name for v in md.modelVariables if v.causality == "input"] == list(inputs)
    assert [v.name for v in md.modelVariables if v.causality == "output"] == list(outputs)
    for n in inputs + outputs:  # all with units, but the mode, the fault, the region (codes 0 / 1 / 2 ...), soc
        unitless = n in UNITLESS
        assert by_name[n].type == "Real" and (by_name[n].unit is None if unitless else by_name[n].unit in units)
    assert by_name["omega_m" if name == "PmsmEvPlant" else "omega_hat"].unit == "rad/s"
    # no direct feedthrough: every output's dependency list is empty
    assert len(md.outputs) == len(outputs)
    assert all(u.dependencies == [] for u in md.outputs)
    if name == "PmsmEvPlant":  # initial outputs are calculated from the parameters
        assert all(by_name[n].initial == "calculated" for n in outputs)
        deps = {u.variable.name: {d.name for d in u.dependencies} for u in md.initialUnknowns}
        assert deps["i_alpha"] == {"i_d0", "i_q0", "theta_e0"}
        assert deps["omega_m"] == {"omega_m0"}
        assert set(deps) == set(outputs)
    else:  # zero until the first step, whatever the parameters
        # zero, but the mode: 0 (alignment) for the sensorless unit, 2 (closed loop) for the others
        mode = "0.0" if name == "FocSensorless" else "2.0"
        assert all(by_name[n].initial == "exact" and by_name[n].start == (mode if n == "mode" else "0.0")
                   for n in outputs)
        assert all(by_name[n].variability == "discrete" for n in outputs)
        assert md.initialUnknowns == []


def test_parameter_start_values_round_trip_exactly(fmus):
    for name, groups in (("PmsmEvPlant", (MotorParams(), VehicleParams(), PlantParams())),
                         ("FocEkf5", (ControllerParams(), EkfParams(), MotorParams()))):
        md = fmpy.read_model_description(str(fmus[name]))
        by_name = {v.name: v for v in md.modelVariables}
        for group in groups:
            for f in dataclasses.fields(group):
                default, v = getattr(group, f.name), by_name[f.name]
                if v.type == "Real":
                    assert float(v.start) == default and isinstance(default, float), f.name
                elif v.type == "Boolean":
                    assert v.start == str(default).lower()
                else:
                    assert type(default)(v.start) == default


def test_fmpy_dump_lists_the_interface(fmus, capsys):
    for name in ("PmsmEvPlant", "FocEkf5"):
        fmpy.dump(str(fmus[name]))
        text = capsys.readouterr().out
        inputs, outputs = (PLANT_INPUTS, PLANT_OUTPUTS) if name == "PmsmEvPlant" else (CTRL_INPUTS, CTRL_OUTPUTS)
        for variable in inputs + outputs:
            assert f" {variable} " in text, (name, variable)
        assert "Co-Simulation" in text or "CoSimulation" in text


# -- each FMU alone ----------------------------------------------------------------------
def test_plant_with_rotor_held_settles_to_ohmic_currents(fmus):
    """Constant stationary-frame voltage, rotor held (huge vehicle mass): each dq current
    follows the first-order response v/R_s (1 - exp(-t R_s/L)), v by Park at theta_e0."""
    m = MotorParams()
    theta0, v_alpha, v_beta = 0.3, 1.0, 0.5
    stop = 0.15  # 6.4 L_d/R_s (23 ms), 4.5 L_q/R_s (33 ms)
    signals = np.array([(0.0, v_alpha, v_beta, 0.0), (stop, v_alpha, v_beta, 0.0)],
                       dtype=[("time", float), ("v_alpha", float), ("v_beta", float), ("delta", float)])
    r = simulate_fmu(str(fmus["PmsmEvPlant"]), stop_time=stop, step_size=DT, output_interval=DT,
                          input=signals, start_values={"m_v": 1e12, "theta_e0": theta0},
                          output=["i_d", "i_q", "i_alpha", "i_beta", "omega_m", "theta_e", "T_e"])
    t = r["time"]
    v_d = math.cos(theta0) * v_alpha + math.sin(theta0) * v_beta
    v_q = -math.sin(theta0) * v_alpha + math.cos(theta0) * v_beta
    i_d = v_d / m.R_s * (1.0 - np.exp(-t * m.R_s / m.L_d))
    i_q = v_q / m.R_s * (1.0 - np.exp(-t * m.R_s / m.L_q))
    assert np.allclose(r["i_d"], i_d, rtol=1e-6, atol=1e-6)
    assert np.allclose(r["i_q"], i_q, rtol=1e-6, atol=1e-6)
    assert abs(r["i_d"][-1] / (v_d / m.R_s) - 1.0) < 0.002  # settled: exp(-6.4)
    assert abs(r["i_q"][-1] / (v_q / m.R_s) - 1.0) < 0.012  # exp(-4.5)
    assert np.max(np.abs(r["omega_m"])) < 1e-6 and np.allclose(r["theta_e"], theta0, atol=1e-6)
    c, s = np.cos(r["theta_e"]), np.sin(r["theta_e"])
    assert np.allclose(r["i_alpha"], c * r["i_d"] - s * r["i_q"], rtol=1e-12, atol=1e-9)
    assert np.allclose(r["i_beta"], s * r["i_d"] + c * r["i_q"], rtol=1e-12, atol=1e-9)
    assert np.allclose(r["T_e"], m.N * (m.psi * r["i_q"] + (m.L_d - m.L_q) * r["i_d"] * r["i_q"]))


@pytest.mark.parametrize("step", [DT, DT / 3])
def test_plant_fmu_dead_time_and_delay_follow_the_switching_period(fmus, step):
    """The plant FMU's switching_period (1e-4 s by default), not its communication step, sets the dead
    time's error and the inverter delay: 12 V on alpha into the held rotor from t = 0, delayed by one
    switching period, settles at (12 V - 4/3 v_dc t_d / T_s) / R_s stepped at 1e-4 s or at a third of it."""
    md = fmpy.read_model_description(str(fmus["PmsmEvPlant"]))
    var = {v.name: v for v in md.modelVariables}["switching_period"]
    assert (var.causality, var.unit, float(var.start)) == ("parameter", "s", 1e-4)
    signals = np.array([(0.0, 12.0, 0.0, 0.0), (1.0, 12.0, 0.0, 0.0)],
                       dtype=[("time", float), ("v_alpha", float), ("v_beta", float), ("delta", float)])
    r = simulate_fmu(str(fmus["PmsmEvPlant"]), stop_time=0.3, step_size=step, output_interval=step,
                          input=signals, output=["i_d"],
                          start_values={"m_v": 1e12, "v_dc": 360.0, "dead_time": 2e-6, "inverter_delay": 1})
    assert r["i_d"][-1] == pytest.approx((12.0 - 4.0 / 3.0 * 7.2) / MotorParams().R_s, rel=1e-4)
    first = np.argmax(np.abs(r["i_d"]) > 1e-6)  # the first output after a step with a voltage applied
    assert r["time"][first] == pytest.approx(DT + step, rel=1e-9)  # applied from t = 1e-4 s on


ANGLE_SOURCES = ("measured", "estimated")


@pytest.fixture(scope="module")
def constant_input_runs(fmus) -> dict[tuple[str, str], np.ndarray]:
    """{(controller, angle source): fmpy.simulate_fmu's rows} of every controller FMU with constant inputs over
    0.2 s, run one after the other by one fmpy process of their own."""
    signals = np.array([(0.0, 20.0, -5.0, 100.0, 0.4, 10.0, 0.0, 0.0, 0.0),
                        (1.0, 20.0, -5.0, 100.0, 0.4, 10.0, 0.0, 0.0, 0.0)],
                       dtype=[("time", float)] + [(n, float) for n in CTRL_INPUTS])
    keys = [(name, angle_source) for name in CONTROLLERS for angle_source in ANGLE_SOURCES]
    rows = simulate_fmus([(fmus[name], dict(stop_time=0.2, step_size=DT, output_interval=DT, input=signals,
                                            start_values={"angle_source": angle_source}))
                          for name, angle_source in keys])
    return dict(zip(keys, rows))


@pytest.mark.parametrize("name", CONTROLLERS)
@pytest.mark.parametrize("angle_source", ANGLE_SOURCES)
def test_controller_with_constant_inputs_gives_bounded_voltages(constant_input_runs, name, angle_source):
    u_max = ControllerParams().u_max
    r = constant_input_runs[(name, angle_source)]
    for n in CTRL_OUTPUTS:
        assert np.all(np.isfinite(r[n])), n
    assert np.max(np.hypot(r["v_alpha"], r["v_beta"])) <= u_max * (1 + 1e-12)
    assert np.max(np.hypot(r["v_d"], r["v_q"])) <= u_max * (1 + 1e-12)
    assert np.max(np.hypot(r["v_d"], r["v_q"])) > 1.0  # it does act
    assert np.max(np.abs(r["i_qref"])) <= ControllerParams().i_q_max
    if name == "FocSensored":
        assert np.all(r["omega_hat"][1:] == 10.0) and np.all(r["T_L_hat"] == 0.0)
    if name == "FocEkf4":
        assert np.all(r["T_L_hat"] == 0.0)


def test_outputs_before_the_first_step(unzipped):
    start = {"i_d0": 12.0, "i_q0": -3.0, "theta_e0": 1.1, "omega_m0": 50.0}
    p = Instance(unzipped, "PmsmEvPlant", start=start, initialize=False)
    ref = Plant(plant=PlantParams(**start))
    assert p.get(PLANT_OUTPUTS) == plant_outputs(ref)  # in initialization mode already
    p.set(omega_m0=60.0)
    assert p.get(["omega_m"]) == [60.0]
    p.fmu.exitInitializationMode()
    assert p.get(["omega_m", "i_alpha"]) == [60.0, Plant(plant=PlantParams(**{**start, "omega_m0": 60.0})).i_alpha]
    c = Instance(unzipped, "FocEkf5", start={"u_max": 100.0})
    assert c.get(CTRL_OUTPUTS) == [0.0] * 12 + [2.0, 0.0, 0.0, 0.0] + [0.0] * 19  # mode 2: closed loop; no fault


# -- the FMUs in co-simulation -------------------------------------------------------------
#: the reference generator on (docs/speed-range.md): MTPA, field weakening, a regen limit
FW_START = {"reference": "fw", "v_dc": 360.0, "P_regen_max": 20e3}


@pytest.mark.parametrize("name,angle_source,extra", [(n, "measured", {}) for n in CONTROLLERS]
                         + [("FocEkf5", "estimated", {}), ("FocEkf5AB", "estimated", {})]
                         + [(n, "measured", FW_START) for n in ("FocSensored", "FocEkf5AB")])
def test_cosimulation_is_bit_identical_to_the_classes(unzipped, name, angle_source, extra):
    """Gauss-Seidel, controller first: the FMUs give exactly the numbers of Plant and
    ControlUnit called in the same order (the monolithic reference's loop)."""
    p = Instance(unzipped, "PmsmEvPlant", instance_name="plant")
    c = Instance(unzipped, name, instance_name="ctrl", start={"angle_source": angle_source, **extra})
    plant, unit = Plant(), ControlUnit(OBSERVER[name], angle_source, dt=DT, controller=ControllerParams(**extra))
    p_out, c_out = p.refs(PLANT_OUTPUTS), c.refs(CTRL_OUTPUTS)
    c_in, p_in = c.refs(CTRL_INPUTS[:5]), p.refs(PLANT_INPUTS)
    for k in range(1500):
        t = k * DT
        po = p.fmu.getReal(p_out)
        assert po == plant_outputs(plant), k
        c.fmu.setReal(c_in, [po[0], po[1], omega_ramp(t), po[5], po[4]])
        c.fmu.doStep(t, DT)
        co = c.fmu.getReal(c_out)
        unit.step(plant.i_alpha, plant.i_beta, omega_ramp(t), plant.theta_e, plant.omega_m)
        assert co == unit_outputs(unit, po[5]), k
        p.fmu.setReal(p_in, [co[0], co[1], DELTA_22])
        p.fmu.doStep(t, DT)
        plant.step(unit.v_alpha, unit.v_beta, DELTA_22, DT)
    # 22 deg from standstill: it rolls back first (the sensored drives while their speed PI's integral
    # builds up; the sensorless unit until its alignment ends on the run-away rotor: -2.1 rad/s)
    assert p.get(["omega_m"])[0] < -1.0
    p.free()
    c.free()


@pytest.mark.parametrize("observer,angle_source", [("ekf5", "measured"), ("ekf5ab", "estimated")])
def test_cosimulation_reproduces_run_reference(unzipped, tmp_path, observer, angle_source):
    stop, dt = 0.15, DT
    params = DriveParams(scenario=ScenarioParams(startup_time=0.1))
    run_reference(tmp_path, scenario=2, stop_time=stop, observer=observer, angle_source=angle_source,
                  params=params, output_interval=dt)
    ref = read_results(tmp_path)
    p = Instance(unzipped, "PmsmEvPlant", instance_name="plant")
    c = Instance(unzipped, pmsm_ev_fmus.OBSERVER_FMUS[observer], instance_name="ctrl",
                 start={"angle_source": angle_source})
    n = round(stop / dt)
    for k in range(n + 1):
        po = dict(zip(PLANT_OUTPUTS, p.get(PLANT_OUTPUTS)))
        co = dict(zip(CTRL_OUTPUTS, c.get(CTRL_OUTPUTS)))
        for col in ("omega_m", "theta_e", "i_d", "i_q", "T_e", "T_L_mech", "i_alpha", "i_beta", "v_vehicle"):
            assert po[col] == ref[col][k], (k, col)
        for col in ("omega_hat", "theta_hat", "i_d_hat", "i_q_hat", "T_L_hat", "v_d", "v_q", "v_alpha",
                    "v_beta", "i_qref"):
            assert co[col] == ref[col][k], (k, col)
        if k == n:
            break
        omega_ref = ref["omega_ref"][k]
        c.set(i_alpha=po["i_alpha"], i_beta=po["i_beta"], omega_ref=omega_ref, theta_meas=po["theta_e"],
              omega_meas=po["omega_m"])
        c.step(dt)
        co = dict(zip(CTRL_OUTPUTS, c.get(CTRL_OUTPUTS)))
        p.set(v_alpha=co["v_alpha"], v_beta=co["v_beta"], delta=0.0)  # scenario 2 is level before 50 s
        p.step(dt)


def test_foc_ekf5ab_recovers_an_unknown_initial_angle_like_the_reference(unzipped, tmp_path):
    """FocEkf5AB sensorless from a 200 rad/s flying start, its angle guess 0.5 rad wrong,
    sigma = 0.1 A current noise: step for step equal to run_reference with the same
    settings (tests/test_realism.py checks the physics over 1.2 s), and recovered."""
    stop, dt, theta0, w0 = 0.2, DT, 1.0, 200.0
    plant_start = {"omega_m0": w0, "theta_e0": theta0, "sensor_noise": 0.1, "sensor_seed": 5}
    ctrl_start = {"angle_source": "estimated", "x0_omega": w0, "x0_theta": theta0 + 0.5}
    params = DriveParams(plant=PlantParams(**plant_start), ekf=EkfParams(x0_omega=w0, x0_theta=theta0 + 0.5),
                         scenario=ScenarioParams(startup_time=0.0))
    run_reference(tmp_path, scenario=1, stop_time=stop, observer="ekf5ab", angle_source="estimated",
                  params=params, output_interval=dt)
    ref = read_results(tmp_path)
    p = Instance(unzipped, "PmsmEvPlant", instance_name="plant", start=plant_start)
    c = Instance(unzipped, "FocEkf5AB", instance_name="ctrl", start=ctrl_start)
    n = round(stop / dt)
    for k in range(n + 1):
        po = dict(zip(PLANT_OUTPUTS, p.get(PLANT_OUTPUTS)))
        co = dict(zip(CTRL_OUTPUTS, c.get(CTRL_OUTPUTS)))
        for col in ("omega_m", "theta_e", "i_alpha", "i_beta"):
            assert po[col] == ref[col][k], (k, col)
        for col in ("omega_hat", "theta_hat", "T_L_hat", "v_alpha", "v_beta"):
            assert co[col] == ref[col][k], (k, col)
        if k == n:
            break
        c.set(i_alpha=po["i_alpha"], i_beta=po["i_beta"], omega_ref=w0, theta_meas=po["theta_e"],
              omega_meas=po["omega_m"])
        c.step(dt)
        co = dict(zip(CTRL_OUTPUTS, c.get(CTRL_OUTPUTS)))
        p.set(v_alpha=co["v_alpha"], v_beta=co["v_beta"], delta=0.0)
        p.step(dt)
    # theta_hat was computed one period before the plant's theta_e: propagate it
    err = co["theta_hat"] + MotorParams().N * co["omega_hat"] * dt - po["theta_e"]
    assert abs((err + math.pi) % (2 * math.pi) - math.pi) < 2e-3
    p.free()
    c.free()


def test_two_plant_instances_do_not_share_state(unzipped):
    a = Instance(unzipped, "PmsmEvPlant", instance_name="a", start={"m_v": 1e12})
    b = Instance(unzipped, "PmsmEvPlant", instance_name="b", start={"theta_e0": 1.0})
    ra, rb = Plant(vehicle=VehicleParams(m_v=1e12)), Plant(plant=PlantParams(theta_e0=1.0))
    for k in range(300):
        a.set(v_alpha=2.0, v_beta=0.0, delta=0.0)
        b.set(v_alpha=-1.0, v_beta=3.0 * math.sin(100 * k * DT), delta=0.1)
        a.step()
        b.step()
        ra.step(2.0, 0.0, 0.0, DT)
        rb.step(-1.0, 3.0 * math.sin(100 * k * DT), 0.1, DT)
        assert a.get(PLANT_OUTPUTS) == plant_outputs(ra)
        assert b.get(PLANT_OUTPUTS) == plant_outputs(rb)
    assert a.get(["i_d"]) != b.get(["i_d"])
    a.free()
    b.free()


def _closed_loop(p, c, steps, delta=DELTA_22, record=True, omega_ref=None):
    rows = []
    for _ in range(steps):
        po = p.get(PLANT_OUTPUTS)
        c.set(i_alpha=po[0], i_beta=po[1], omega_ref=omega_ramp(c.t) if omega_ref is None else omega_ref,
              theta_meas=po[5], omega_meas=po[4])
        c.step()
        co = c.get(CTRL_OUTPUTS)
        p.set(v_alpha=co[0], v_beta=co[1], delta=delta)
        p.step()
        if record:
            rows.append(tuple(p.get(PLANT_OUTPUTS)) + tuple(c.get(CTRL_OUTPUTS)))
    return rows


@pytest.mark.parametrize("angle_source", ["measured", "estimated"])
def test_fmu_state_restores_the_trajectory_exactly(unzipped, angle_source):
    """Save plant and FocEkf5, go on, wander off with other inputs, restore, re-run: the
    same numbers; likewise through serialisation and into fresh instances."""
    p = Instance(unzipped, "PmsmEvPlant", instance_name="plant")
    c = Instance(unzipped, "FocEkf5", instance_name="ctrl", start={"angle_source": angle_source})
    _closed_loop(p, c, 400, record=False)
    saved_p, saved_c, t_saved = p.fmu.getFMUstate(), c.fmu.getFMUstate(), p.t
    reference = _closed_loop(p, c, 300)
    # wander off: other elevation and speed reference change every state of both units
    p.fmu.setFMUstate(saved_p)
    c.fmu.setFMUstate(saved_c)
    p.t = c.t = t_saved
    wandered = _closed_loop(p, c, 200, delta=-0.2, omega_ref=50.0)
    assert wandered[-1] != reference[199]
    # restore and re-run
    p.fmu.setFMUstate(saved_p)
    c.fmu.setFMUstate(saved_c)
    p.t = c.t = t_saved
    assert _closed_loop(p, c, 300) == reference
    # serialised, into fresh instances (no initialisation of their own)
    blob_p, blob_c = p.fmu.serializeFMUstate(saved_p), c.fmu.serializeFMUstate(saved_c)
    assert json.loads(blob_c)["physics"]["dt"] == DT
    p2 = Instance(unzipped, "PmsmEvPlant", instance_name="plant2", initialize=False)
    c2 = Instance(unzipped, "FocEkf5", instance_name="ctrl2", initialize=False)
    p2.fmu.setFMUstate(p2.fmu.deSerializeFMUstate(blob_p))
    c2.fmu.setFMUstate(c2.fmu.deSerializeFMUstate(blob_c))
    p2.t = c2.t = t_saved
    assert _closed_loop(p2, c2, 300) == reference
    for fmu, state in ((p, saved_p), (c, saved_c)):
        fmu.fmu.freeFMUstate(state)
    for fmu in (p, c, p2, c2):
        fmu.free()


def test_a_restored_state_keeps_the_sample_clock(unzipped):
    """A state saved at a 2e-4 s sample period, restored into a fresh instance, goes on at
    2e-4 s, exactly as the original, also when the master then steps at 1e-4 s: a period
    at every other step, on the inputs of that step."""
    inputs = dict(i_alpha=15.0, i_beta=-4.0, omega_ref=30.0, theta_meas=0.2, omega_meas=1.0)
    c = Instance(unzipped, "FocEkf5", start={"angle_source": "estimated"})
    c.set(**inputs)
    for _ in range(10):
        c.step(2e-4)
    blob = c.fmu.serializeFMUstate(c.fmu.getFMUstate())
    assert json.loads(blob)["physics"]["k_next"] == 10
    expected = []
    for _ in range(10):
        c.step(2e-4)
        expected.append(c.get(CTRL_OUTPUTS))
    fresh = Instance(unzipped, "FocEkf5", instance_name="fresh")
    fresh.fmu.setFMUstate(fresh.fmu.deSerializeFMUstate(blob))
    fresh.t = 10 * 2e-4
    got = []
    for _ in range(10):
        fresh.step(2e-4)
        got.append(fresh.get(CTRL_OUTPUTS))
    assert got == expected
    fresh.fmu.setFMUstate(fresh.fmu.deSerializeFMUstate(blob))
    fresh.t = 10 * 2e-4
    halves = []
    for _ in range(20):
        fresh.step(1e-4)
        halves.append(fresh.get(CTRL_OUTPUTS))
    assert halves[0::2] == expected and halves[1::2] == expected
    c.free()
    fresh.free()


def test_the_state_holds_the_whole_control_unit(unzipped):
    c = Instance(unzipped, "FocEkf5", start={"angle_source": "estimated"})
    for k in range(50):
        c.set(i_alpha=10.0 * math.cos(0.01 * k), i_beta=10.0 * math.sin(0.01 * k), omega_ref=20.0)
        c.step()
    state = json.loads(c.fmu.serializeFMUstate(c.fmu.getFMUstate()))
    unit = ControlUnit("ekf5", "estimated", dt=DT)
    saved = state["physics"]["unit"]  # EKF x and P, integrators, filters, by name
    assert {k: len(v) for k, v in saved.items()} == {k: len(v) for k, v in unit.get_state().items()}
    assert len(saved["x"]) == 5 and len(saved["p"]) == 25 and "pht" not in saved  # no scratch
    assert saved["theta_prior"] != [0.0] and saved["w_int"] != [0.0]
    assert state["variables"]["angle_source"] == "estimated"
    c.free()


def test_a_state_of_another_fmu_or_version_is_refused_naming_the_field(unzipped):
    """fmi2SetFMUstate checks the state's named fields, and the lengths of the unit's, before
    using it: a controller's state into the plant, a unit field too short, one left out."""
    messages = []
    p = Instance(unzipped, "PmsmEvPlant", instance_name="plant", messages=messages)
    c = Instance(unzipped, "FocEkf5", instance_name="ctrl", messages=messages)
    c.step()
    good = json.loads(c.fmu.serializeFMUstate(c.fmu.getFMUstate()))
    short = json.loads(json.dumps(good))
    short["physics"]["unit"]["p"] = short["physics"]["unit"]["p"][:16]
    missing = json.loads(json.dumps(good))
    del missing["physics"]["unit"]["w_int"]
    cases = [(p, good, "PmsmEvPlant FMU state, variables: the fields differ from this FMU's"),
             (c, short, "field 'p' of the saved state has 16 values, expected 25"),
             (c, missing, "the saved state has no field 'w_int'")]
    for fmu, state, expected in cases:
        del messages[:]
        blob = json.dumps(state).encode()
        with pytest.raises(Exception, match="fmi2SetFMUstate"):
            fmu.fmu.setFMUstate(fmu.fmu.deSerializeFMUstate(blob))
        assert any(expected in m for _, m in messages), messages
    p.free()
    c.free()


# -- errors ------------------------------------------------------------------------------------
def _fails_to_initialise(fmus, name, start, expected):
    messages = []
    with pytest.raises(Exception, match="fmi2ExitInitializationMode failed"):
        fmpy.simulate_fmu(str(fmus[name]), stop_time=0.001, step_size=DT, start_values=start,
                          debug_logging=True, logger=lambda *a: messages.append(a[4].decode()))
    assert any(expected in m for m in messages), messages


def test_invalid_parameters_fail_initialisation_with_the_reason_logged(fmus):
    _fails_to_initialise(fmus, "PmsmEvPlant", {"m_v": -1.0}, "ParameterError('m_v must be > 0 kg (got -1.0)')")
    _fails_to_initialise(fmus, "PmsmEvPlant", {"load_model": "magic"}, "load_model must be one of")
    _fails_to_initialise(fmus, "PmsmEvPlant", {"rk4_substeps": 0}, "rk4_substeps must be")
    _fails_to_initialise(fmus, "FocEkf5", {"u_max": -1.0}, "u_max must be > 0 V")
    _fails_to_initialise(fmus, "FocEkf5", {"r_i": 0.0}, "r_i must be > 0")
    _fails_to_initialise(fmus, "FocEkf4", {"angle_source": "sideways"}, "angle_source must be one of")
    _fails_to_initialise(fmus, "FocSensored", {"L_d": 0.0}, "L_d must be > 0 H")
    _fails_to_initialise(fmus, "FocEkf5", {"dt": -1e-4}, "dt must be > 0 s, or 0 for the size of the first")


def _clocked(unzipped, steps, start=None, inputs=None):
    """FocEkf5 stepped by ``steps`` [(t, h)] (fmpy's FMU2Slave), inputs ``inputs(t)``; the
    outputs after each step."""
    c = Instance(unzipped, "FocEkf5", instance_name="clocked", start=start)
    rows = []
    for t, h in steps:
        c.set(**inputs(t))
        c.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        rows.append(c.get(CTRL_OUTPUTS))
    state = json.loads(c.fmu.serializeFMUstate(c.fmu.getFMUstate()))["physics"]
    c.free()
    return rows, state


def _ctrl_inputs(t):
    return dict(i_alpha=20.0 * math.cos(300.0 * t), i_beta=20.0 * math.sin(300.0 * t), omega_ref=omega_ramp(t),
                theta_meas=(300.0 * t) % (2 * math.pi) - math.pi, omega_meas=75.0)


def _unit_at(instants, h_inputs=None):
    """The ControlUnit run at the sample instants k dt, each on the inputs at ``h_inputs(k)``
    (default: at k dt); its outputs after each period."""
    unit, out = ControlUnit("ekf5", "measured", dt=DT), []
    for k in instants:
        i = _ctrl_inputs(h_inputs(k) if h_inputs else k * DT)
        unit.step(i["i_alpha"], i["i_beta"], i["omega_ref"], i["theta_meas"], i["omega_meas"])
        out.append(unit_outputs(unit, i["theta_meas"]))
    return out


def test_the_controller_keeps_its_sample_clock_at_shorter_steps(unzipped):
    """h = dt/3 with dt = 1e-4 s set: a control period at the steps from k dt (on the inputs
    there), none at the two others, so the outputs change only at the sample instants and
    equal the unit's run at dt, number for number. Time as fmpy's SSP loop makes it (t += h)."""
    h, steps, t = DT / 3, [], 0.0
    for _ in range(300):
        steps.append((t, h))
        t += h
    rows, state = _clocked(unzipped, steps, start={"dt": DT}, inputs=_ctrl_inputs)
    assert state["dt"] == DT and state["k_next"] == 100
    expected = _unit_at(range(100), h_inputs=lambda k: steps[3 * k][0])  # the inputs at the step's t
    assert rows[0::3] == expected and rows[1::3] == expected and rows[2::3] == expected
    # without dt set, the first step size is the sample period: a period at every step
    rows, state = _clocked(unzipped, steps[:30], inputs=_ctrl_inputs)
    assert state["dt"] == h and state["k_next"] == 30 and len({r[3] for r in rows}) == 30


def test_the_controller_runs_several_periods_in_a_longer_step(unzipped):
    """h = 2.5 dt: the instants k dt in [t, t + h) are 3, then 2 per step, all on the inputs
    held from t; the outputs are those of the last period."""
    steps = [(n * 2.5 * DT, 2.5 * DT) for n in range(8)]
    rows, state = _clocked(unzipped, steps, start={"dt": DT}, inputs=_ctrl_inputs)
    assert state["k_next"] == 20
    step_of = {k: math.floor(k / 2.5 + 1e-9) for k in range(20)}  # the step whose [t, t+h) holds k dt
    expected = _unit_at(range(20), h_inputs=lambda k: step_of[k] * 2.5 * DT)
    last_period = [max(k for k in range(20) if step_of[k] == n) for n in range(8)]
    assert rows == [expected[k] for k in last_period] and last_period[:3] == [2, 4, 7]


def test_a_sliver_step_runs_no_period_and_the_run_goes_on(unzipped):
    """A master that ends its run with a sliver (OMSimulator: 2e-13 s) or goes on after one:
    the sliver runs no period; the instant k dt just after it (within 1e-2 dt of the next
    step's start) runs at the next step, so the trajectory is the one at h = dt."""
    steps = [(n * DT, DT) for n in range(10)] + [(10 * DT, 1e-13), (10 * DT + 1e-13, DT - 1e-13),
                                                   (11 * DT, DT)]
    rows, state = _clocked(unzipped, steps, inputs=_ctrl_inputs)
    expected = _unit_at(range(12), h_inputs=lambda k: 10 * DT + 1e-13 if k == 10 else k * DT)
    assert rows[:10] == expected[:10]
    assert rows[10] == rows[9]  # the sliver: no period
    assert rows[11:] == expected[10:12] and state["k_next"] == 12


def test_a_step_size_of_zero_is_an_error_for_a_controller(unzipped):
    messages = []
    c = Instance(unzipped, "FocEkf5", messages=messages)
    c.step(DT)
    with pytest.raises(Exception, match="fmi2DoStep failed"):
        c.step(0.0)
    assert any("communication step size must be > 0 s (got 0.0)" in m for _, m in messages), messages


def test_a_fixed_parameter_cannot_change_after_initialisation(unzipped):
    messages = []
    p = Instance(unzipped, "PmsmEvPlant", messages=messages)
    p.set(m_v=VehicleParams().m_v)  # the same value: accepted
    p.step()
    with pytest.raises(Exception, match="fmi2SetReal failed"):
        p.set(m_v=1000.0)
    assert any("parameter 'm_v' is fixed" in m for _, m in messages), messages


def test_slave_classes_validate_in_plain_python():
    from pmsm_ev_fmus.foc_ekf5 import FocEkf5
    from pmsm_ev_fmus.pmsm_ev_plant import PmsmEvPlant

    slave = PmsmEvPlant(instance_name="direct")
    slave.set_real([next(vr for vr, v in slave.vars.items() if v.name == "m_v")], [0.0])
    slave.enter_initialization_mode()
    with pytest.raises(ParameterError, match="m_v must be > 0"):
        slave.exit_initialization_mode()
    assert slave.log_queue == []  # nothing queued: the wrapper would pass it on with the exception set
    ctrl = FocEkf5(instance_name="direct")
    ctrl.enter_initialization_mode()
    ctrl.exit_initialization_mode()
    ctrl.do_step(0.0, 2e-4)
    assert ctrl._unit.dt == 2e-4  # the first step size is the sample period


def test_get_real_reads_the_present_values_of_the_same_references_every_time():
    """get_real keeps a reader per set of value references asked for: the values it gives are those of
    the moment (outputs after a step, a property of the unit), and a reference that is not a Real
    variable is still refused after a set was kept."""
    from pmsm_ev_fmus.foc_sensorless import FocSensorless
    from pmsm_ev_fmus.slave_support import FmuUsageError

    slave = FocSensorless(instance_name="direct")
    vr = {v.name: ref for ref, v in slave.vars.items()}
    slave.enter_initialization_mode()
    slave.exit_initialization_mode()
    refs = [vr["v_alpha"], vr["mode"], vr["T_brake"]]
    seen = []
    for k in range(30000):  # into the alignment's ramp: the voltage moves
        slave.i_alpha, slave.i_beta = 0.01 * math.sin(k), 0.0
        slave.do_step(k * DT, DT)
        if k % 10000 == 0:
            seen.append(slave.get_real(refs))
            assert seen[-1] == [slave.v_alpha, slave.mode, slave._unit.T_brake]
            assert slave.get_real([vr["v_alpha"]]) == [slave.v_alpha]
    assert len({tuple(v) for v in seen}) == len(seen)  # the values of the moment, not the first ones
    assert (tuple(refs), ) == tuple(key for key in slave._real_reads if len(key) == 3)
    with pytest.raises(FmuUsageError, match="is not a Real"):
        slave.get_real([vr["v_alpha"], vr["reference"]])
    with pytest.raises(FmuUsageError, match="no variable has the value reference 100000"):
        slave.get_real([vr["v_alpha"], 100000])


FAILURE_SCRIPT = """
import sys, fmpy
from fmpy.fmi2 import FMU2Slave
path = sys.argv[1]
md = fmpy.read_model_description(path)
d = fmpy.extract(path)
vr = {v.name: v.valueReference for v in md.modelVariables}
for i in range(40):
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=f"i{i}")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.setReal([vr["m_v"]], [-1.0 if i % 2 else 900.0])
    try:
        fmu.exitInitializationMode()
        fmu.doStep(0.0, 1e-4)
        fmu.terminate()
    except Exception:
        assert i % 2
    fmu.freeInstance()
print("survived", flush=True)
"""


def test_freeing_failed_instances_does_not_crash_the_host(fmus, tmp_path):
    """pythonfmu 0.7.0 releases a failed instance twice; the slave compensates (subprocess:
    a crash would otherwise take pytest down)."""
    script = tmp_path / "failures.py"
    script.write_text(FAILURE_SCRIPT)
    r = subprocess.run([sys.executable, str(script), str(fmus["PmsmEvPlant"])], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and "survived" in r.stdout, r.stderr[-2000:]


# -- self-contained ------------------------------------------------------------------------------
ISOLATED_SCRIPT = """
import importlib.util, json, sys
if sys.argv[3] == "no-numba":
    sys.modules["numba"] = None  # import numba fails: a host without numba
assert importlib.util.find_spec("pmsm_ev") is None, "the project is importable"
assert importlib.util.find_spec("pmsm_ev_fmus") is None, "the project is importable"
import fmpy, numpy as np
plant, ctrl = sys.argv[1], sys.argv[2]
signals = np.array([(0.0, 1.0, 0.5, 0.0), (1.0, 1.0, 0.5, 0.0)],
                   dtype=[("time", float), ("v_alpha", float), ("v_beta", float), ("delta", float)])
r = fmpy.simulate_fmu(plant, stop_time=0.01, step_size=1e-4, output_interval=1e-4, input=signals,
                      start_values={"m_v": 1e12, "theta_e0": 0.3})
signals = np.array([(0.0, 20.0, -5.0, 100.0, 0.4, 10.0)],
                   dtype=[("time", float)] + [(n, float) for n in ("i_alpha", "i_beta", "omega_ref", "theta_meas",
                                                                    "omega_meas")])
q = fmpy.simulate_fmu(ctrl, stop_time=0.01, step_size=1e-4, output_interval=1e-4, input=signals)
physics = sorted(m for m in sys.modules if m.startswith("pmsm_ev"))
files = sorted({sys.modules[m].__file__ for m in physics})
print(json.dumps({"i_d": float(r["i_d"][-1]), "v_q": float(q["v_q"][-1]), "modules": physics, "files": files}),
      flush=True)
"""


@pytest.mark.parametrize("host", ["numba", "no-numba"])
def test_fmus_run_where_the_project_is_not_installed(fmus, tmp_path, host):
    """``python -S``: no site processing, so the project's editable install is invisible; the
    PYTHONPATH holds only the site-packages directory (numpy, fmpy, numba). Without numba
    the FMUs run their kernels as plain Python, with the same numbers. With numba they use the kernels' cache
    ``PMSM_EV_CACHE_DIR`` names, this process's (warm: its compilation from cold is
    ``tests/test_kernels.py``'s), under a HOME of their own."""
    site_packages = str(Path(np.__file__).resolve().parents[1])
    assert not (Path(site_packages) / "pmsm_ev").exists()
    script = tmp_path / "isolated.py"
    script.write_text(ISOLATED_SCRIPT)
    cache = accel.cache_dir()
    env = {"PATH": os.environ.get("PATH", ""), "PYTHONPATH": site_packages, "HOME": str(tmp_path),
           accel.ENV_CACHE_DIR: str(cache)}
    r = subprocess.run([sys.executable, "-S", str(script), str(fmus["PmsmEvPlant"]), str(fmus["FocEkf5"]), host],
                       capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    tags = {fmu_build.read_build_info(fmus[n])["tag"] for n in ("PmsmEvPlant", "FocEkf5")}
    assert {f"pmsm_ev_{tag}" for tag in tags} <= set(out["modules"])
    # the bundled code, or (compiled with numba) the copy of the bundled kernels package that
    # pmsm_ev.accel keeps in the kernels' cache
    compiled = [f for f in out["files"] if Path(f).parent.parent == cache]
    assert all("/resources/" in f and "/work/" not in f.replace(str(tmp_path), "")
               for f in out["files"] if f not in compiled)
    assert len({Path(f).parent for f in compiled}) == (1 if host == "numba" else 0), out["files"]
    kernel_files = len(list((fmu_build.physics_dir() / "kernels").glob("*.py")))
    assert len(compiled) == (kernel_files if host == "numba" else 0), out["files"]
    # the numbers of this process (fmpy's steps are t_next - t: round-off in h)
    plant = Plant(vehicle=VehicleParams(m_v=1e12), plant=PlantParams(theta_e0=0.3))
    for _ in range(100):
        plant.step(1.0, 0.5, 0.0, DT)
    assert out["i_d"] == pytest.approx(plant.i_d, rel=1e-12)
    unit = ControlUnit("ekf5", "measured", dt=DT)
    for _ in range(100):
        unit.step(20.0, -5.0, 100.0, 0.4, 10.0)
    assert out["v_q"] == pytest.approx(unit.v_q, rel=1e-12)


# -- libcosim ----------------------------------------------------------------------------------------
def test_plant_and_controller_cosimulate_in_libcosim(fmus):
    """libcosim (libcosimpy) loads the pythonfmu FMUs in this Python process (the FMU binary
    finds libpython's symbols in the host). Fixed-step Jacobi master, 1e-4 s, 1 s: 22 deg
    from t = 0 and a speed ramp set through an override manipulator every step."""
    libcosimpy = pytest.importorskip("libcosimpy")
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    assert libcosimpy
    log_output_level(CosimLogLevel.WARNING)
    ex = CosimExecution.from_step_size(step_size=100_000)  # ns
    plant = ex.add_local_slave(CosimLocalSlave(fmu_path=str(fmus["PmsmEvPlant"]), instance_name="plant"))
    ctrl = ex.add_local_slave(CosimLocalSlave(fmu_path=str(fmus["FocEkf5"]), instance_name="ctrl"))
    assert (plant, ctrl) == (0, 1)
    pv = {v.name.decode(): v.reference for v in ex.slave_variables(plant)}
    cv = {v.name.decode(): v.reference for v in ex.slave_variables(ctrl)}
    for out, inp in (("i_alpha", "i_alpha"), ("i_beta", "i_beta"), ("theta_e", "theta_meas"),
                     ("omega_m", "omega_meas")):
        assert ex.connect_real_variables(plant, pv[out], ctrl, cv[inp]) == 0
    for name in ("v_alpha", "v_beta"):
        assert ex.connect_real_variables(ctrl, cv[name], plant, pv[name]) == 0
    assert ex.real_initial_value(plant, pv["delta"], 0.38397)
    manipulator = CosimManipulator.create_override()
    assert ex.add_manipulator(manipulator)
    observer = CosimObserver.create_last_value()
    assert ex.add_observer(observer)

    p_names = ("omega_m", "i_d", "i_q", "theta_e")
    c_names = ("omega_hat", "v_alpha", "v_beta", "v_d", "v_q", "i_qref")
    rows = []
    for k in range(10_000):
        assert manipulator.slave_real_values(ctrl, [cv["omega_ref"]], [200.0 * k * DT / 10.0])
        assert ex.step(), f"libcosim step {k} failed"
        if k % 100 == 99:
            rows.append(list(observer.last_real_values(plant, [pv[n] for n in p_names]))
                        + list(observer.last_real_values(ctrl, [cv[n] for n in c_names])))
    status = ex.status()
    assert status.current_time == 1_000_000_000 and status.error_code == 0
    r = {n: np.array(col) for n, col in zip(p_names + c_names, np.array(rows).T)}
    for n, values in r.items():
        assert np.all(np.isfinite(values)), n
    omega = r["omega_m"]
    # rolls back on the 22 deg slope, then the speed loop drives it up again
    assert omega.min() < -15.0 and omega[-1] > omega.min() + 15.0
    assert np.all(np.diff(omega[-50:]) > 0)  # rising over the last 0.5 s
    assert np.max(np.abs(r["i_q"])) < ControllerParams().i_q_max * 1.1
    assert np.max(np.hypot(r["v_alpha"], r["v_beta"])) <= ControllerParams().u_max * (1 + 1e-12)
    assert np.allclose(r["omega_hat"], omega, atol=0.5)  # the EKF follows
    # libcosim's fixed-step master is Jacobi: both step at once, each with the other's
    # outputs at t_k, so the voltage reaches the plant one step later than in the
    # Gauss-Seidel reference; the classes called that way give the same trajectory
    p, u = Plant(), ControlUnit("ekf5", "measured", dt=DT)
    emulated = []
    for k in range(10_000):
        v_alpha, v_beta = u.v_alpha, u.v_beta
        u.step(p.i_alpha, p.i_beta, 200.0 * k * DT / 10.0, p.theta_e, p.omega_m)
        p.step(v_alpha, v_beta, 0.38397, DT)
        if k % 100 == 99:
            emulated.append([p.omega_m, p.i_d, p.i_q, p.theta_e, u.estimates[2], u.v_alpha, u.v_beta, u.v_d,
                             u.v_q, u.i_qref])
    assert np.allclose(np.array(rows), np.array(emulated), rtol=1e-9, atol=1e-9)


# -- a host that is not Python -------------------------------------------------------------------
C_HOST = r"""
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include "fmi2Functions.h"
static void logger(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c, fmi2String m, ...)
{ printf("log %d %s\n", s, m); }
int main(int argc, char **argv) {
    void *h = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!h) { printf("dlopen failed: %s\n", dlerror()); return 2; }
    fmi2InstantiateTYPE *instantiate = dlsym(h, "fmi2Instantiate");
    fmi2SetupExperimentTYPE *setup = dlsym(h, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE *enter = dlsym(h, "fmi2EnterInitializationMode");
    fmi2ExitInitializationModeTYPE *leave = dlsym(h, "fmi2ExitInitializationMode");
    fmi2SetRealTYPE *set_real = dlsym(h, "fmi2SetReal");
    fmi2GetRealTYPE *get_real = dlsym(h, "fmi2GetReal");
    fmi2DoStepTYPE *do_step = dlsym(h, "fmi2DoStep");
    fmi2TerminateTYPE *terminate = dlsym(h, "fmi2Terminate");
    fmi2FreeInstanceTYPE *free_instance = dlsym(h, "fmi2FreeInstance");
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = instantiate("plant", fmi2CoSimulation, argv[3], argv[2], &cb, fmi2False, fmi2True);
    if (!c) { printf("instantiate failed\n"); return 3; }
    fmi2ValueReference v_ref[2] = {atoi(argv[4]), atoi(argv[5])}, m_ref[1] = {atoi(argv[6])},
                       i_ref[1] = {atoi(argv[7])};
    fmi2Real v[2] = {1.0, 0.5}, m_v[1] = {1e12}, i_d;
    if (setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) || enter(c) || set_real(c, m_ref, 1, m_v) || leave(c)
        || set_real(c, v_ref, 2, v)) return 4;
    for (int k = 0; k < 1000; k++) if (do_step(c, k * 1e-4, 1e-4, fmi2True)) return 5;
    if (get_real(c, i_ref, 1, &i_d) || terminate(c)) return 6;
    free_instance(c);
    printf("i_d %.17g\n", i_d);
    return 0;
}
"""


@pytest.mark.slow
def test_a_c_host_runs_the_plant_with_or_without_libpython_preloaded(fmus, unzipped, tmp_path):
    """A host that is not Python: the FMU brings up its own Python (fmus/README.md, "Hosts that are not Python";
    tests/test_c_host.py); the set-up README.md once asked for (libpython preloaded, PYTHONHOME) works as well."""
    import shutil
    import sysconfig

    gcc = shutil.which("gcc")
    libpython = Path(sysconfig.get_config_var("LIBDIR") or "", sysconfig.get_config_var("LDLIBRARY") or "")
    if gcc is None or not sysconfig.get_config_var("Py_ENABLE_SHARED") or not libpython.is_file():
        pytest.skip("needs gcc and a Python built with --enable-shared")
    (tmp_path / "host.c").write_text(C_HOST)
    headers = Path(fmpy.__file__).parent / "c-code"
    subprocess.run([gcc, "-I", str(headers), str(tmp_path / "host.c"), "-o", str(tmp_path / "host"), "-ldl"],
                   check=True, capture_output=True)
    root = unzipped["PmsmEvPlant"]
    md = fmpy.read_model_description(str(root))
    vr = {v.name: str(v.valueReference) for v in md.modelVariables}
    args = [str(tmp_path / "host"), str(root / "binaries" / "linux64" / "PmsmEvPlant.so"),
            (root / "resources").as_uri(), md.guid, vr["v_alpha"], vr["v_beta"], vr["m_v"], vr["i_d"]]
    # the user's HOME: the kernels are compiled in this host too, from the user's cache (pmsm_ev.accel)
    env = {"PATH": "/usr/bin:/bin", "HOME": str(Path.home())}
    plant = Plant(vehicle=VehicleParams(m_v=1e12))
    for _ in range(1000):
        plant.step(1.0, 0.5, 0.0, DT)
    r = subprocess.run(args, capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]  # no libpython: the FMU loads one
    assert float(r.stdout.split("i_d ")[-1]) == plant.i_d
    env.update(LD_PRELOAD=str(libpython), PYTHONHOME=sys.base_prefix)
    site_packages = str(Path(np.__file__).resolve().parents[1])
    if not site_packages.startswith(sys.base_prefix):
        env["PYTHONPATH"] = site_packages
    r = subprocess.run(args, capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert float(r.stdout.split("i_d ")[-1]) == plant.i_d
