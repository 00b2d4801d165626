"""The FMI 3.0 co-simulation units (fmus/README.md, "FMI 3.0"): each FMU of the project as an FMI 3.0 unit, the FMI
3.0 layer (fmus/fmi3_layer.c) in front of the same FMI 2.0 stack as its FMI 2.0 unit (``pmsm-cosim build --fmi 3``).

* every unit validates (fmpy), and declares the variables of its FMI 2.0 unit: names, value references, types,
  causality, variability, initial, start values, units, and the model structure;
* fmpy's ``simulate_fmu`` runs each unit alone, with inputs read from a CSV file, and gives the outputs of its FMI
  2.0 unit run the same way, exactly; the plant and the controllers serve every set, step and get on the compiled
  path through the FMI 3.0 layer as through FMI 2.0 (the lean binding's counters);
* misuse on the plant and a controller (a step before initialisation, a step after terminate, a time that goes back,
  a non-finite input, a NULL or freed instance, functions that do not apply) answers fmi3Error with one log line
  each (none for an instance that is not one), and no crash (each sequence in a process of its own: fmpy's
  FMU3Slave with its default logger);
* an FMU state got, restored, serialized and deserialized gives the same step again;
* several instances at once and two threads each stepping its own give the numbers of one instance alone;
* the misuse sequences, the instances and threads, and the FMU state under AddressSanitizer and UBSan: the layer, the
  FMI 2.0 loader and the lean binding compiled with ``-fsanitize=address,undefined`` (``PMSM_EV_BINDING_CFLAGS``),
  ASan's runtime preloaded into the Python host: no report, the same answers as the plain build.
"""

from __future__ import annotations

import functools
import json
import math
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest

from pmsm_cosim.app.drive import PACKAGED_SCENARIOS
from pmsm_ev_fmus import build as fmu_build
from sanitizer_support import build_sanitized, is_sanitized, needs_asan, no_report, sanitized_env

pytestmark = pytest.mark.skipif(fmu_build.binding_requested() != "lean",
                                reason="the FMI 3.0 units need the lean build (Linux x86-64, a C compiler)")

ERROR = 3
STEPS = 300
H = 1e-4


@functools.lru_cache(maxsize=None)
def _units() -> tuple[dict[str, Path], dict[str, Path]]:
    fmi3 = fmu_build.build_all(fmi=3)  # the FMI 2.0 units first, in the user's cache; the 3.0 ones in its fmi3/
    return fmu_build.build_all(), fmi3


@pytest.fixture(scope="module")
def units() -> tuple[dict[str, Path], dict[str, Path]]:
    return _units()


def _description(fmu: Path) -> ET.Element:
    with zipfile.ZipFile(fmu) as z:
        return ET.fromstring(z.read("modelDescription.xml"))


def _shape(element: ET.Element) -> tuple:
    """An element's tag, attributes and children's shapes (its white space aside)."""
    return element.tag, sorted(element.attrib.items()), [_shape(child) for child in element]


def test_the_units_are_in_their_own_folder_with_the_fmi2_stack_behind_the_layer(units):
    fmi2, fmi3 = units
    assert set(fmi3) == set(fmu_build.FMUS)
    for name, path in fmi3.items():
        assert path.parent == fmu_build.fmi3_out_dir(fmi2[name].parent)
        with zipfile.ZipFile(path) as z:
            binaries = sorted(n for n in z.namelist() if n.startswith("binaries/"))
            info = json.loads(z.read("resources/build_info.json"))
        folder = f"binaries/{fmu_build.FMI3_PLATFORM}/"
        assert binaries == sorted(folder + f for f in (f"{name}.so", fmu_build.FMI3_INNER_LOADER,
                                                       fmu_build.BINDING_LIBRARY, fmu_build.INNER_LIBRARY))
        assert info["fmiVersion"] == "3.0" and info["fmi3_hash"] == fmu_build.fmi3_hash(name)
        assert info["hash"] == fmu_build.source_hash(name)  # the FMI 2.0 unit's sources, the same stack
    again = fmu_build.build_all(fmi=3, names=["FocEkf5"])  # up to date: not rebuilt
    assert again["FocEkf5"].stat().st_mtime_ns == fmi3["FocEkf5"].stat().st_mtime_ns


def test_the_units_validate_and_declare_the_fmi2_units_variables(units):
    """... and the controllers their sample clock (hasEventMode="true")."""
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    fmi2, fmi3 = units
    types = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}
    for name in fmu_build.FMUS:
        assert validate_fmu(str(fmi3[name])) == [], name
        md3 = read_model_description(str(fmi3[name]), validate=True)
        md2 = read_model_description(str(fmi2[name]))
        assert md3.fmiVersion == "3.0" and md3.guid == md2.guid  # the instantiation token: the 2.0 GUID
        cs2, cs3 = md2.coSimulation, md3.coSimulation
        assert cs3.modelIdentifier == name and cs3.canHandleVariableCommunicationStepSize
        assert (cs3.canGetAndSetFMUstate, cs3.canSerializeFMUstate) == (cs2.canGetAndSetFMUstate,
                                                                          cs2.canSerializeFMUstate)
        assert cs3.hasEventMode == fmu_build.clocked(name) == (name in fmu_build.OBSERVER_FMUS.values())
        clocks = [v for v in md3.modelVariables if v.type == "Clock"]
        if fmu_build.clocked(name):  # the sample clock: a periodic input clock at the sample period
            (clock,) = clocks
            element = next(e for e in _description(fmi3[name]).iter("Clock"))
            assert (clock.name, clock.valueReference, clock.causality, clock.variability, clock.intervalVariability,
                    float(element.get("intervalDecimal"))) == (fmu_build.FMI3_CLOCK_NAME,
                                                               fmu_build.FMI3_CLOCK_REFERENCE, "input", "discrete",
                                                               "constant", 1e-4)
        else:
            assert clocks == []
        time, *variables = [v for v in md3.modelVariables if v.type != "Clock"]
        assert (time.name, time.causality, time.valueReference) == ("time", "independent",
                                                                     fmu_build.FMI3_TIME_REFERENCE)
        assert len(variables) == len(md2.modelVariables)
        for v2, v3 in zip(md2.modelVariables, variables):
            assert (v3.name, v3.valueReference, v3.type, v3.causality, v3.variability, v3.initial, v3.start,
                    v3.unit, v3.displayUnit, v3.description) == (
                v2.name, v2.valueReference, types[v2.type], v2.causality, v2.variability, v2.initial, v2.start,
                v2.unit, v2.displayUnit, v2.description), (name, v2.name)
        units2 = {u.get("name"): _shape(u) for u in _description(fmi2[name]).iter("Unit")}
        units3 = {u.get("name"): _shape(u) for u in _description(fmi3[name]).iter("Unit")}
        assert {k: v for k, v in units3.items() if k in units2} == units2  # the same definitions (and "s")
        assert set(units3) - set(units2) <= {"s"}
        assert [(u.variable.valueReference, [d.valueReference for d in u.dependencies or []])
                for u in md3.outputs] == [(u.variable.valueReference, [d.valueReference for d in u.dependencies or []])
                                          for u in md2.outputs]
        assert [(u.variable.valueReference, sorted(d.valueReference for d in u.dependencies or []))
                for u in md3.initialUnknowns] == [
            (u.variable.valueReference, sorted(d.valueReference for d in u.dependencies or []))
            for u in md2.initialUnknowns]
        ex2, ex3 = md2.defaultExperiment, md3.defaultExperiment
        assert (ex3.startTime, ex3.stopTime, ex3.stepSize) == (ex2.startTime, ex2.stopTime, ex2.stepSize)


def test_the_model_description_is_converted_from_the_fmi2_one():
    """A String start value becomes a <Start> element; a model structure's indices become value references."""
    md2 = b"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="M" guid="g-1" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="M" canGetAndSetFMUstate="true" canNotUseMemoryManagementFunctions="true"/>
  <ModelVariables>
    <ScalarVariable name="u" valueReference="4" causality="input" variability="continuous"><Real start="1.5"/>
    </ScalarVariable>
    <ScalarVariable name="s" valueReference="7" causality="parameter" variability="fixed" initial="exact">
      <String start="a &amp; b"/></ScalarVariable>
    <ScalarVariable name="y" valueReference="9" causality="output" variability="continuous" initial="calculated">
      <Real unit="V"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="3" dependencies="1"/></Outputs>
    <InitialUnknowns><Unknown index="3" dependencies="1 2"/></InitialUnknowns></ModelStructure>
</fmiModelDescription>"""
    root = ET.fromstring(fmu_build.model_description_fmi3(md2))
    assert root.get("fmiVersion") == "3.0" and root.get("instantiationToken") == "g-1" and root.get("guid") is None
    assert root.find("CoSimulation").attrib == {"modelIdentifier": "M", "canGetAndSetFMUState": "true",
                                                "hasEventMode": "false"}
    names = [(v.tag, v.get("name"), v.get("valueReference")) for v in root.find("ModelVariables")]
    assert names == [("Float64", "time", str(fmu_build.FMI3_TIME_REFERENCE)), ("Float64", "u", "4"),
                     ("String", "s", "7"), ("Float64", "y", "9")]
    assert root.find("ModelVariables/String/Start").get("value") == "a & b"
    assert [u.attrib for u in root.find("ModelStructure")] == [
        {"valueReference": "9", "dependencies": "4"}, {"valueReference": "9", "dependencies": "4 7"}]
    assert root.find("UnitDefinitions/Unit[@name='s']/BaseUnit").attrib == {"s": "1"}
    with pytest.raises(fmu_build.BuildError, match="not an FMI 2.0 co-simulation"):
        fmu_build.model_description_fmi3(fmu_build.model_description_fmi3(md2))


# -- fmpy's simulate_fmu: the 3.0 unit against the 2.0 unit --------------------------------------------------------
_SIMULATE = r"""
import json, sys, ctypes
import numpy as np
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from fmpy.util import read_csv
plan = json.loads(sys.argv[1])
out = {}
for name, (fmu2, fmu3, csv, stop) in plan.items():
    signals = read_csv(csv)
    runs, counts = [], []
    for path, kind in ((fmu2, FMU2Slave), (fmu3, FMU3Slave)):
        md = read_model_description(path)
        fmu = kind(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                   instanceName=name)
        fmu.instantiate()
        runs.append(simulate_fmu(path, fmu_instance=fmu, model_description=md, input=signals, stop_time=stop,
                                 output_interval=1e-4))
        calls = [getattr(fmu.dll, f)(ctypes.c_void_p(fmu.component)) for f in ("pmsm_fmu_fast_calls",
                                                                               "pmsm_fmu_compiled_calls")]
        counts.append(calls)
        fmu.freeInstance()
    r2, r3 = runs
    names = list(r2.dtype.names)
    out[name] = {"names": names == list(r3.dtype.names), "rows": [len(r2), len(r3)],
                 "max_difference": max(float(np.max(np.abs(r3[n] - r2[n]))) for n in names),
                 "equal": all(bool(np.array_equal(r3[n], r2[n])) for n in names), "columns": len(names) - 1,
                 "counts": counts, "finite": bool(all(np.isfinite(r3[n]).all() for n in names))}
print(json.dumps(out))
"""


def _inputs(name: str, fmu2: Path, folder: Path, stop: float) -> Path:
    """A CSV file of inputs for every Real input of the unit (fmpy's input format: a time column first)."""
    import numpy as np
    from fmpy import read_model_description

    md = read_model_description(str(fmu2))
    names = [v.name for v in md.modelVariables if v.causality == "input" and v.type == "Real"]
    t = np.round(np.arange(0.0, stop + H / 2, H), 12)
    wave = {"v_alpha": 20 * np.cos(300 * t), "v_beta": 20 * np.sin(300 * t), "delta": 0.02 + 0 * t,
            "T_brake": 5.0 * (t > stop / 2), "i_alpha": 3 * np.cos(250 * t), "i_beta": 3 * np.sin(250 * t),
            "omega_ref": 2000 * t, "theta_meas": (250 * t) % (2 * np.pi), "omega_meas": 60 * t,
            "x": 2 * t}  # the controllers' v_dc_meas, P_charge_max, P_discharge_max 0: the constant DC link
    columns = [wave.get(n, 0 * t) for n in names]
    path = folder / f"{name}-inputs.csv"
    rows = ["time," + ",".join(names)] + [",".join(repr(float(c[k])) for c in [t, *columns]) for k in range(len(t))]
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def test_simulate_fmu_runs_each_unit_as_its_fmi2_unit(units, tmp_path):
    """Each unit alone under fmpy's simulate_fmu, inputs from a CSV file, 300 steps of 1e-4 s: every output of the
    FMI 3.0 unit equals its FMI 2.0 unit's, bit for bit (the same stack: 1e-12 would be the tolerance), and the
    lean binding's counters are the same through the FMI 3.0 layer (the plant and the controllers: every set, step
    and get served on the compiled path)."""
    fmi2, fmi3 = units
    stop = STEPS * H
    plan = {name: (str(fmi2[name]), str(fmi3[name]), str(_inputs(name, fmi2[name], tmp_path, stop)), stop)
            for name in fmu_build.FMUS}
    done = subprocess.run([sys.executable, "-c", _SIMULATE, json.dumps(plan)], capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    found = json.loads(done.stdout.strip().splitlines()[-1])
    for name, result in found.items():
        assert result["names"] and result["rows"] == [STEPS + 1] * 2 and result["finite"], (name, result)
        assert result["max_difference"] <= 1e-12 and result["equal"], (name, result)
        two, three = result["counts"]
        assert three == two, (name, result)
        if name != fmu_build.ROUTE_FMU:  # the plant and the controllers: the compiled step served the loop
            assert three[1] > 0, (name, result)
    print({name: (r["columns"], r["max_difference"], r["counts"][1]) for name, r in found.items()})


# -- misuse --------------------------------------------------------------------------------------------------------
# call sequences on one unit, each on an instance of its own, in one process; per sequence: the calls with their
# statuses (0 for fmi3OK), the log lines (fmpy's default logger prints "[ERROR] message"), the values read
_MISUSE = r"""
import ctypes, json, math, sys
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave
path, END = sys.argv[1], sys.argv[2]
md = read_model_description(path)
vr = {v.name: v.valueReference for v in md.modelVariables}
inputs = [v.name for v in md.modelVariables if v.causality == "input" and v.type == "Float64"]
outputs = [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Float64"]
unzipped = extract(path)
def make(**options):
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="m")
    fmu.instantiate(**options)
    return fmu
def sequence(case):
    out = {"calls": [], "values": {}}
    if case == "event-mode-used":
        try:
            make(eventModeUsed=True)
            out["calls"].append(["instantiate", 0])
        except Exception:
            out["calls"].append(["instantiate", "NULL"])
        print(END + json.dumps(out), flush=True)
        return
    if case == "ticks":  # in event mode: the clock set outside event mode, steps past a tick
        clock = [v.valueReference for v in md.modelVariables if v.type == "Clock"]
        try:
            fmu = make(eventModeUsed=True)
        except Exception:
            out["calls"].append(["instantiate", "NULL"])
            print(END + json.dumps(out), flush=True)
            return
    else:
        fmu = make()
    def call(name, *args):
        try:
            result = getattr(fmu, name)(*args)
            out["calls"].append([name, 0])
            return result
        except FMICallException as exc:
            out["calls"].append([name, exc.status])
    def init():
        call("enterInitializationMode", None, 0.0)
        call("exitInitializationMode")
    def read(label, names):
        out["values"][label] = [v if math.isfinite(v) else repr(v) for v in fmu.getFloat64([vr[n] for n in names])]
    if case == "step-before-init":
        call("doStep", 0.0, 1e-4)
        call("enterInitializationMode", None, 0.0)
        call("doStep", 0.0, 1e-4)
        call("exitInitializationMode")
        call("doStep", 0.0, 1e-4)
    elif case == "step-after-terminate":
        init()
        call("doStep", 0.0, 1e-4)
        call("terminate")
        call("doStep", 1e-4, 1e-4)
    elif case == "time":
        init()
        read("start", ["time"])
        call("doStep", 0.0, 1e-4)
        call("doStep", 1e-4, 1e-4)
        read("stepped", ["time"])
        call("doStep", 0.0, 1e-4)       # back in time
        call("doStep", 5e-4, 1e-4)      # a gap
        call("setFloat64", [vr["time"]], [1.0])
        call("doStep", 2e-4, 1e-4)
    elif case == "non-finite":
        init()
        call("setFloat64", [vr[inputs[0]]], [float("inf")])
        call("setFloat64", [vr[n] for n in inputs], [1.0] * (len(inputs) - 1) + [float("nan")])
        call("doStep", 0.0, 1e-4)
        read("after", outputs)
    elif case == "not-applicable":
        init()
        call("getFloat32", [vr[outputs[0]]])
        call("getInt64", [vr[outputs[0]]])
        call("enterEventMode")
        call("enterStepMode")
        call("setClock", [0], [True])
        call("fmi3GetIntervalDecimal", fmu.component, (ctypes.c_uint32 * 1)(0), 1, (ctypes.c_double * 1)(),
             (ctypes.c_int * 1)())
        call("updateDiscreteStates")
        call("enterConfigurationMode")
        call("fmi3SetTime", fmu.component, 0.0)
        call("fmi3GetNumberOfContinuousStates", fmu.component, ctypes.byref(ctypes.c_size_t()))
        call("doStep", 0.0, 1e-4)
    elif case == "ticks":
        init()
        call("setClock", clock, [True])  # in step mode: refused
        call("doStep", 0.0, 1e-4)        # past the first tick (at 0) without it
        call("enterEventMode")
        call("setClock", clock, [True])
        call("updateDiscreteStates")     # the tick: the sample at 0
        call("enterStepMode")
        call("doStep", 0.0, 5e-5)        # within the sample period: the outputs held
        read("half", outputs)
        call("doStep", 5e-5, 5e-5)
        read("period", outputs + ["time"])
        call("doStep", 1e-4, 1e-4)       # past the next tick (at 1e-4) without it
        call("enterEventMode")
        call("setClock", clock, [True])
        call("updateDiscreteStates")
        call("enterStepMode")
        call("doStep", 1e-4, 1e-4)
    elif case == "wrong-reference":  # the clock taken for a value (an FMI 3.0 host did), a reference of nothing
        init()
        clock = [v.valueReference for v in md.modelVariables if v.type == "Clock"]
        nowhere = max(v.valueReference for v in md.modelVariables) + 1000
        for refs in ([clock] if clock else []) + [[nowhere]]:
            call("getFloat64", refs)
            call("setFloat64", refs, [1.0])
            call("getBoolean", refs)
        call("doStep", 0.0, 1e-4)
        read("after", outputs)
        out["values"]["nowhere"] = nowhere
    elif case == "threads":  # instances side by side, stepped in turn, then two threads each stepping its own
        import threading
        refs_in, refs_out = [vr[n] for n in inputs], [vr[n] for n in outputs]
        def ready(f):
            f.enterInitializationMode(startTime=0.0)
            f.exitInitializationMode()
            return f
        def step(f, k):
            f.setFloat64(refs_in, [0.5 + 0.01 * j + 1e-3 * k for j in range(len(refs_in))])
            f.doStep(k * 1e-4, 1e-4)
            return f.getFloat64(refs_out)
        def drive(f, n, into):
            into.extend(step(f, k) for k in range(n))
        serial = []
        drive(ready(fmu), 300, serial)
        side = [ready(make()) for _ in range(3)]
        turns = [[step(f, k) for f in side] for k in range(300)]
        pair, found = [ready(make()), ready(make())], [[], []]
        workers = [threading.Thread(target=drive, args=(f, 300, into)) for f, into in zip(pair, found)]
        for t in workers:
            t.start()
        for t in workers:
            t.join()
        out["values"]["side"] = [[row[i] for row in turns] == serial for i in range(3)]
        out["values"]["threads"] = [into == serial for into in found]
        out["values"]["moved"] = serial[-1] != serial[0]
        for f in side + pair:
            f.terminate()
            f.freeInstance()
    elif case == "foreign-instance":  # a freed instance, then NULL: fmi3Error each, nothing touched, no line
        init()
        call("doStep", 0.0, 1e-4)
        dll, freed = fmu.dll, ctypes.c_void_p(fmu.component)
        fmu.terminate()
        fmu.freeInstance()
        refs, values = (ctypes.c_uint32 * 1)(vr[outputs[0]]), (ctypes.c_double * 1)(0.0)
        flag, when = ctypes.c_bool(False), ctypes.c_double(0.0)
        for label, c in (("freed", freed), ("null", None)):
            out["values"][label] = [
                dll.fmi3DoStep(c, ctypes.c_double(1e-4), ctypes.c_double(1e-4), ctypes.c_bool(True),
                               ctypes.byref(flag), ctypes.byref(flag), ctypes.byref(flag), ctypes.byref(when)),
                dll.fmi3GetFloat64(c, refs, ctypes.c_size_t(1), values, ctypes.c_size_t(1)),
                dll.fmi3SetFloat64(c, refs, ctypes.c_size_t(1), values, ctypes.c_size_t(1)),
                dll.fmi3EnterInitializationMode(c, ctypes.c_bool(False), ctypes.c_double(0.0), ctypes.c_double(0.0),
                                                ctypes.c_bool(False), ctypes.c_double(0.0)),
                dll.fmi3ExitInitializationMode(c), dll.fmi3Terminate(c), dll.fmi3Reset(c), dll.fmi3EnterEventMode(c),
                dll.fmi3GetFloat32(c, refs, ctypes.c_size_t(1), (ctypes.c_float * 1)(), ctypes.c_size_t(1))]
        dll.fmi3FreeInstance(freed)  # again: nothing
        dll.fmi3FreeInstance(None)
        print(END + json.dumps(out), flush=True)
        return
    fmu.terminate()
    fmu.freeInstance()
    print(END + json.dumps(out), flush=True)
for case in sys.argv[3:]:
    sequence(case)
"""
_END = "@@sequence@@ "
CASES = ("step-before-init", "step-after-terminate", "time", "non-finite", "not-applicable", "foreign-instance",
         "event-mode-used", "ticks", "threads", "wrong-reference")


@functools.lru_cache(maxsize=None)
def _misuse(fmu: Path, sanitized: bool = False) -> dict[str, tuple[list, list[str], dict]]:
    """{case: (the calls with their statuses, the log lines, the values read)} of the sequences ``CASES`` on the unit
    ``fmu`` in a process of their own (``sanitized``: with the sanitizers' runtime preloaded, no report)."""
    done = subprocess.run([sys.executable, "-c", _MISUSE, str(fmu), _END, *CASES], capture_output=True, text=True,
                          timeout=600, env=sanitized_env() if sanitized else None)
    if sanitized:
        no_report(done)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    results, log = {}, []
    for line in done.stdout.strip().splitlines():
        if line.startswith(_END):
            out = json.loads(line[len(_END):])
            results[CASES[len(results)]] = (out["calls"], log, out["values"])
            log = []
        elif line.startswith("[") or not log:
            log.append(line)
        else:
            log[-1] += "\n" + line
    assert list(results) == list(CASES) and not log
    return results


@pytest.fixture(scope="module", params=["PmsmEvPlant", "FocSensorless"])
def misuse(request, units):
    return {**_misuse(units[1][request.param]), "unit": request.param}


def test_a_step_before_initialisation_is_an_error(misuse):
    calls, log, _ = misuse["step-before-init"]
    assert calls == [["doStep", ERROR], ["enterInitializationMode", 0], ["doStep", ERROR],
                     ["exitInitializationMode", 0], ["doStep", 0]]
    assert log == ["[ERROR] fmi2DoStep before fmi2ExitInitializationMode (the FMU is in instantiated)",
                   "[ERROR] fmi2DoStep before fmi2ExitInitializationMode (the FMU is in initialization mode)"]


def test_a_step_after_terminate_is_an_error(misuse):
    calls, log, _ = misuse["step-after-terminate"]
    assert calls == [["enterInitializationMode", 0], ["exitInitializationMode", 0], ["doStep", 0], ["terminate", 0],
                     ["doStep", ERROR]]
    assert log == ["[ERROR] fmi2DoStep after fmi2Terminate (the FMU is in terminated)"]


def test_a_time_that_goes_back_or_jumps_is_an_error_and_time_cannot_be_set(misuse):
    calls, log, values = misuse["time"]
    assert calls[2:] == [["doStep", 0], ["doStep", 0], ["doStep", ERROR], ["doStep", ERROR], ["setFloat64", ERROR],
                         ["doStep", 0]]
    assert values == {"start": [0.0], "stepped": [2e-4]}
    assert len(log) == 3
    assert log[0] == ("[ERROR] fmi2DoStep at t = 0.0 s does not continue the last step, which ended at 0.0002 s "
                      "(restore an FMU state to step from another time)")
    assert log[1].startswith("[ERROR] fmi2DoStep at t = 0.0005 s does not continue the last step")
    assert log[2] == "[ERROR] fmi3SetFloat64: the independent variable time cannot be set; nothing set"


def test_non_finite_inputs_are_refused(misuse):
    calls, log, values = misuse["non-finite"]
    assert calls[-3:] == [["setFloat64", ERROR], ["setFloat64", ERROR], ["doStep", 0]]
    assert len(log) == 2 and all(line.startswith("[ERROR] fmi2SetReal: input '") for line in log)
    assert log[0].endswith("' = inf is not finite; not set") and log[1].endswith("' = nan is not finite; not set")
    assert all(isinstance(v, float) for v in values["after"])  # every output finite


def test_functions_that_do_not_apply_are_errors_with_a_line_each(misuse):
    calls, log, _ = misuse["not-applicable"]
    assert [status for _, status in calls[2:-1]] == [ERROR] * 10 and calls[-1] == ["doStep", 0]
    if misuse["unit"] == "PmsmEvPlant":
        events = ["[ERROR] fmi3EnterEventMode: this FMU has no event mode",
                  "[ERROR] fmi3EnterStepMode: this FMU has no event mode (it is in step mode)",
                  "[ERROR] fmi3SetClock: this FMU has no clock",
                  "[ERROR] fmi3GetIntervalDecimal: this FMU has no clock",
                  "[ERROR] fmi3UpdateDiscreteStates: this FMU has no event mode"]
    else:  # a controller instantiated without event mode: it samples in fmi3DoStep, its clock is not set
        events = ["[ERROR] fmi3EnterEventMode: event mode was not asked for at instantiation (eventModeUsed false): "
                  "the unit samples at its own period in fmi3DoStep",
                  "[ERROR] fmi3EnterStepMode: not in event mode",
                  "[ERROR] fmi3SetClock: outside event mode: a clock ticks in event mode (fmi3EnterEventMode "
                  "first); nothing set",
                  "[ERROR] fmi3GetIntervalDecimal: not a clock of this FMU",
                  "[ERROR] fmi3UpdateDiscreteStates: outside event mode (fmi3EnterEventMode first)"]
    assert log == ["[ERROR] fmi3GetFloat32: this FMU has no variable of type fmi3Float32",
                   "[ERROR] fmi3GetInt64: this FMU has no variable of type fmi3Int64",
                   *events,
                   "[ERROR] fmi3EnterConfigurationMode: this FMU has no structural parameter",
                   "[ERROR] fmi3SetTime: a function of model exchange; this FMU is for co-simulation",
                   "[ERROR] fmi3GetNumberOfContinuousStates: a function of model exchange; this FMU is for "
                   "co-simulation"]


def test_a_null_or_freed_instance_is_an_error_and_touched_nowhere(misuse):
    calls, log, values = misuse["foreign-instance"]
    assert values == {"freed": [ERROR] * 9, "null": [ERROR] * 9} and log == []


def test_event_mode_is_refused_at_instantiation_without_a_clock(misuse):
    calls, log, _ = misuse["event-mode-used"]
    if misuse["unit"] != "PmsmEvPlant":  # a controller: event mode with its sample clock
        assert calls == [["instantiate", 0]] and log == []
        return
    assert calls == [["instantiate", "NULL"]]
    assert log == ['[ERROR] fmi3InstantiateCoSimulation: eventModeUsed, but this FMU has no event mode '
                   '(hasEventMode="false")']


def test_a_clock_set_outside_event_mode_or_a_tick_passed_is_an_error(misuse):
    """A controller in event mode: fmi3SetClock in step mode and an fmi3DoStep past a tick of the sample clock not
    set are fmi3Error with a line each, and change nothing (the ticks after them run as they should); within a
    sample period the outputs are held."""
    calls, log, values = misuse["ticks"]
    if misuse["unit"] == "PmsmEvPlant":
        assert calls == [["instantiate", "NULL"]]
        return
    assert calls[2:] == [["setClock", ERROR], ["doStep", ERROR], ["enterEventMode", 0], ["setClock", 0],
                         ["updateDiscreteStates", 0], ["enterStepMode", 0], ["doStep", 0], ["doStep", 0],
                         ["doStep", ERROR], ["enterEventMode", 0], ["setClock", 0], ["updateDiscreteStates", 0],
                         ["enterStepMode", 0], ["doStep", 0]]
    passing = ("which was not set (in event mode, set the clock at each tick: fmi3EnterEventMode, "
               "fmi3SetClock, fmi3UpdateDiscreteStates)")
    assert log == ["[ERROR] fmi3SetClock: outside event mode: a clock ticks in event mode (fmi3EnterEventMode "
                   "first); nothing set",
                   f"[ERROR] fmi3DoStep to t = 0.0001 s passes the sample clock's tick at 0 s, {passing}",
                   f"[ERROR] fmi3DoStep to t = 0.0002 s passes the sample clock's tick at 0.0001 s, {passing}"]
    assert values["period"][:-1] == values["half"] and values["period"][-1] == 1e-4


def test_the_clock_or_a_reference_of_nothing_taken_for_a_value_is_an_error(misuse):
    """fmi3GetFloat64, fmi3SetFloat64, fmi3GetBoolean on a controller's sample clock (OMSimulator's FMI 3.0 prototype
    reads it as a value, docs: fmus/README.md) or on a reference of no variable: fmi3Error with a line each (the
    clock's from the layer; the other from the FMI 2.0 stack, which pythonfmu alone answered with fmi2Fatal), nothing
    read or set, and the unit steps on."""
    calls, log, values = misuse["wrong-reference"]
    clocked = misuse["unit"] != "PmsmEvPlant"
    assert calls[2:] == [["getFloat64", ERROR], ["setFloat64", ERROR], ["getBoolean", ERROR]] * (1 + clocked) + [
        ["doStep", 0]]
    nowhere = values["nowhere"]
    lines = [f"[ERROR] fmi2GetReal: no variable has the value reference {nowhere}; nothing read",
             f"[ERROR] fmi2SetReal: no variable has the value reference {nowhere}; nothing set",
             f"[ERROR] fmi2GetBoolean: no variable has the value reference {nowhere}; nothing read"]
    if clocked:
        lines = [f"[ERROR] {f}: value reference {fmu_build.FMI3_CLOCK_REFERENCE} is the sample clock, not a value of "
                 "this type (fmi3SetClock sets it); nothing done"
                 for f in ("fmi3GetFloat64", "fmi3SetFloat64", "fmi3GetBoolean")] + lines
    assert log == lines
    assert all(isinstance(v, float) and math.isfinite(v) for v in values["after"])


def test_instances_side_by_side_and_in_two_threads_give_the_serial_numbers(misuse):
    """Three instances at once, stepped in turn, and two more each stepped by a thread of its own: every output at
    every step equal to one instance stepped alone."""
    _, log, values = misuse["threads"]
    assert values == {"side": [True] * 3, "threads": [True] * 2, "moved": True} and log == []


# -- the FMU state -------------------------------------------------------------------------------------------------
_STATE = r"""
import json, sys
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave
out = {}
for path in sys.argv[1:]:
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    inputs = [vr[v.name] for v in md.modelVariables if v.causality == "input" and v.type == "Float64"]
    outputs = [vr[v.name] for v in md.modelVariables if v.causality == "output" and v.type == "Float64"]
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="s")
    fmu.instantiate()
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    def step(k):
        fmu.setFloat64(inputs, [1.0 + 0.1 * j + 0.01 * k for j in range(len(inputs))])
        fmu.doStep(k * 1e-4, 1e-4)
        return fmu.getFloat64(outputs) + fmu.getFloat64([vr["time"]])
    for k in range(20):
        step(k)
    state = fmu.getFMUState()
    serialized = fmu.serializeFMUState(state)
    first = [step(20), step(21)]
    fmu.setFMUState(state)
    again = [step(20), step(21)]
    restored = fmu.deserializeFMUState(serialized)
    fmu.setFMUState(restored)
    thawed = [step(20), step(21)]
    fmu.freeFMUState(state)
    fmu.freeFMUState(restored)
    fmu.terminate()
    fmu.freeInstance()
    out[md.modelName] = {"again": again == first, "thawed": thawed == first, "bytes": len(serialized),
                         "time": first[-1][-1]}
print(json.dumps(out))
"""


def test_an_fmu_state_restored_gives_the_same_steps_again(units):
    fmi3 = units[1]
    done = subprocess.run([sys.executable, "-c", _STATE, str(fmi3["PmsmEvPlant"]), str(fmi3["FocEkf5"])],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    found = json.loads(done.stdout.strip().splitlines()[-1])
    for name in ("PmsmEvPlant", "FocEkf5"):
        assert found[name]["again"] and found[name]["thawed"] and found[name]["bytes"] > 0, found
        assert found[name]["time"] == pytest.approx(22e-4, abs=1e-15)


# -- under the sanitizers ----------------------------------------------------------------------------------------
SANITIZED = ("PmsmEvPlant", "FocSensorless")


@pytest.fixture(scope="module")
def sanitized(tmp_path_factory) -> dict[str, Path]:
    """The FMI 3.0 units of the plant and a controller with the FMI 3.0 layer, the FMI 2.0 loader and the lean
    binding compiled with ``-fsanitize=address,undefined`` (``PMSM_EV_BINDING_CFLAGS``, which the layer takes too)."""
    return build_sanitized(tmp_path_factory.mktemp("fmi3-sanitized"), SANITIZED, fmi=3)


@needs_asan
@pytest.mark.slow
def test_the_sanitized_fmi3_build_is_sanitized(sanitized):
    """The layer, the loader and the binding behind it link the sanitizers' runtimes (so that the tests below check
    what they say)."""
    folder = f"binaries/{fmu_build.FMI3_PLATFORM}/"
    for name, fmu in sanitized.items():
        for library in (f"{name}.so", fmu_build.FMI3_INNER_LOADER, fmu_build.BINDING_LIBRARY):
            assert is_sanitized(fmu, folder + library), (name, library)


@needs_asan
@pytest.mark.parametrize("name", SANITIZED)
@pytest.mark.slow
def test_the_fmi3_misuse_suite_under_the_sanitizers_reports_nothing_and_answers_as_the_plain_build(units, sanitized,
                                                                                                   name):
    """Every sequence above (wrong order, a step after terminate, a time that goes back, non-finite inputs, a clock
    set outside event mode and a tick passed, functions that do not apply, a freed and a NULL instance, several
    instances, two threads) on the sanitized unit, in a process with ASan's runtime preloaded: no report, no crash,
    and the same statuses, log lines and numbers as the plain build."""
    assert _misuse(sanitized[name], sanitized=True) == _misuse(units[1][name])


@needs_asan
@pytest.mark.slow
def test_an_fmu_state_under_the_sanitizers_reports_nothing(sanitized):
    """Got, restored, serialized and deserialized (the layer hands the FMI 2.0 stack's buffers through)."""
    done = subprocess.run([sys.executable, "-c", _STATE, *(str(sanitized[name]) for name in SANITIZED)],
                          capture_output=True, text=True, timeout=600, env=sanitized_env())
    no_report(done)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    found = json.loads(done.stdout.strip().splitlines()[-1])
    assert all(found[name]["again"] and found[name]["thawed"] for name in SANITIZED), found


# -- the master ----------------------------------------------------------------------------------------------------
COUNTERS = ("pmsm_fmu_fast_calls", "pmsm_fmu_compiled_calls")


def _run_master(system, fmi, out: Path, stop_time: float, mixed: dict | None = None, loop=None, event_mode=True,
                step=None, start=None) -> tuple[dict, dict]:
    """A run of the master on the project's FMUs as FMI ``fmi`` units (``mixed``: instance -> FMI version of those
    that differ); (metrics.json's content, {instance: (fast calls, compiled calls)} read before each is freed)."""
    import ctypes

    from pmsm_cosim.app.drive import ensure_fmus, with_fmi
    from pmsm_cosim.app.overrides import apply_overrides
    from pmsm_cosim.engine.fmu import FmuInstance
    from pmsm_cosim.engine.master import Master

    spec = with_fmi(apply_overrides(system, stop_time=stop_time, step_size=step, set=start), fmi)
    for comp in spec.components:
        if comp.name in (mixed or {}):
            folder = comp.fmu.parent if fmi == 2 else comp.fmu.parent.parent
            comp.fmu = (fmu_build.fmi3_out_dir(folder) if mixed[comp.name] == 3 else folder) / comp.fmu.name
    ensure_fmus(spec, quiet=True)
    counts, close = {}, FmuInstance.close

    def counted_close(inst):
        if inst.fmu is not None and inst.handle:
            functions = [inst.fmu.dll[name] for name in COUNTERS]
            for f in functions:
                f.restype = ctypes.c_ulonglong
            counts[inst.name] = (inst.fmi, *(f(ctypes.c_void_p(inst.handle)) for f in functions))
        close(inst)

    FmuInstance.close = counted_close
    try:
        master = Master(spec, loop=loop, note=lambda line: None, event_mode=event_mode)
        assert set(master.ticks) == ({c.name for c in spec.components if c.fmu.parent.name == fmu_build.FMI3_FOLDER
                                      and fmu_build.clocked(c.fmu.stem)} if event_mode else set())
        metrics = master.run(out, catch_sigint=False)
    finally:
        FmuInstance.close = close
    return metrics, counts


@pytest.mark.parametrize("scenario, stop", [("scenario1", 0.3), ("udds-sensorless", 1.0)])
def test_the_master_runs_the_fmi3_units_as_the_fmi2_units(units, tmp_path, scenario, stop):
    """A shipped scenario, cut short, on the FMI 3.0 units, on the FMI 2.0 ones and on both mixed (the controller
    3.0, the plant 2.0; a sensorless drive cycle: the route's signals and the plant's battery): results.csv byte for
    byte the same (cmp), the compiled loop, and the lean binding's compiled step serving the plant and the
    controller through the FMI 3.0 layer as often as through FMI 2.0."""
    import filecmp

    runs = {}
    for label, fmi, mixed in (("fmi2", 2, None), ("fmi3", 3, None), ("mixed", 3, {"plant": 2})):
        runs[label] = _run_master(scenario, fmi, tmp_path / label, stop, mixed)
    steps = round(stop / 1e-4)
    for label, (metrics, counts) in runs.items():
        assert metrics["status"] == "completed" and metrics["macro_steps"] == steps, (label, metrics["status"])
        assert metrics["loop"] == "compiled", label
        assert filecmp.cmp(tmp_path / "fmi2" / "results.csv", tmp_path / label / "results.csv", shallow=False), label
    two, three, mixed = (runs[k][1] for k in ("fmi2", "fmi3", "mixed"))
    assert {k: v[0] for k, v in three.items()} == {"ctrl": 3, "plant": 3}
    assert {k: v[0] for k, v in mixed.items()} == {"ctrl": 3, "plant": 2}
    for name in ("ctrl", "plant"):
        assert three[name][1:] == two[name][1:] == mixed[name][1:], (name, two, three, mixed)
        assert three[name][2] >= steps, (name, three)  # at least every step compiled
    print(scenario, {name: three[name][1:] for name in three})



@pytest.mark.slow
@pytest.mark.parametrize("scenario", sorted(PACKAGED_SCENARIOS))
def test_every_shipped_scenario_whole_on_the_fmi3_units(units, tmp_path, scenario):
    """Every shipped scenario, whole, on the FMI 3.0 units (the controllers ticked at their clock in event mode)
    and on the FMI 2.0 units: the same status, results.csv byte for byte (cmp), the compiled loop, and the lean
    binding's compiled step counted as often through the FMI 3.0 layer as through FMI 2.0 (slow tier: some
    40 minutes on one core for all of them)."""
    import filecmp

    runs = {fmi: _run_master(scenario, fmi, tmp_path / f"fmi{fmi}", None) for fmi in (2, 3)}
    (two, counts2), (three, counts3) = runs[2], runs[3]
    assert three["status"] == two["status"] and three["macro_steps"] == two["macro_steps"], (two, three)
    assert two["loop"] == three["loop"] == "compiled", (two["loop"], three["loop"])
    assert filecmp.cmp(tmp_path / "fmi2" / "results.csv", tmp_path / "fmi3" / "results.csv", shallow=False)
    assert {k: v[0] for k, v in counts3.items()} == {k: 3 for k in counts2}
    assert {k: v[1:] for k, v in counts3.items()} == {k: v[1:] for k, v in counts2.items()}, (counts2, counts3)
    print(scenario, two["status"], two["macro_steps"], {k: v[1:] for k, v in counts3.items()})

def test_the_plain_loop_and_the_command_line_run_the_fmi3_units(units, tmp_path):
    """``pmsm-cosim run SCENARIO --fmi 3`` (and ``--plain-loop``) gives the results.csv of ``--fmi 2``, byte for
    byte; ``export-ssp --fmi 3`` packs the FMI 3.0 units, and the package runs to the same results.csv."""
    import filecmp

    from pmsm_cosim.app.cli import main

    base = ["--stop-time", "0.1", "--no-figures", "-q"]
    for label, extra in (("fmi2", ["--fmi", "2"]), ("fmi3", ["--fmi", "3"]), ("plain", ["--fmi", "3", "--plain-loop"])):
        assert main(["run", "scenario2", *base, *extra, "--out", str(tmp_path / label)]) == 0, label
        assert filecmp.cmp(tmp_path / "fmi2" / "results.csv", tmp_path / label / "results.csv", shallow=False), label
    for fmi in ("2", "3"):
        package = tmp_path / f"scenario2-{fmi}.ssp"
        assert main(["export-ssp", "scenario2", "--fmi", fmi, "-o", str(package), "-q"]) == 0
        with zipfile.ZipFile(package) as z:
            versions = {}
            for member in z.namelist():
                if member.endswith(".fmu"):
                    with zipfile.ZipFile(z.open(member)) as inner:
                        versions[Path(member).stem] = _description_bytes(inner).get("fmiVersion")
        assert sorted(versions.values()) == (["2.0", f"{fmi}.0", f"{fmi}.0"] if fmi == "3" else ["2.0"] * 3), versions
        out = tmp_path / f"ssp{fmi}"
        assert main(["run", str(package), *base, "--out", str(out)]) == 0
    assert filecmp.cmp(tmp_path / "ssp2" / "results.csv", tmp_path / "ssp3" / "results.csv", shallow=False)


def test_a_clock_is_not_an_unconnected_input(units):
    """The controller's sample clock is ticked by the master (or by the unit itself without event mode): no "input
    ctrl.sample is not connected" among the run's warnings, with or without event mode; a real input left
    unconnected still is one."""
    from pmsm_cosim.app.drive import ensure_fmus, with_fmi
    from pmsm_cosim.app.overrides import apply_overrides
    from pmsm_cosim.engine.master import Master

    spec = with_fmi(apply_overrides("scenario1", stop_time=0.01), 3)
    ensure_fmus(spec, quiet=True)
    for event_mode in (True, False):
        master = Master(spec, note=lambda line: None, event_mode=event_mode)
        try:
            assert not [w for w in master.warnings if "is not connected" in w], (event_mode, master.warnings)
        finally:
            master.close()
    spec.connections = [c for c in spec.connections if (c.dst, c.dst_var) != ("ctrl", "i_alpha")]
    master = Master(spec, note=lambda line: None)
    try:
        unconnected = [w for w in master.warnings if "is not connected" in w]
        assert len(unconnected) == 1 and unconnected[0].startswith("input ctrl.i_alpha is not connected"), unconnected
    finally:
        master.close()


def _description_bytes(z: zipfile.ZipFile) -> ET.Element:
    return ET.fromstring(z.read("modelDescription.xml"))


@pytest.mark.parametrize("loop", ["compiled", "plain"])
def test_the_master_ticks_the_controller_at_its_clock_as_it_samples_alone(units, tmp_path, loop):
    """scenario1 with a base step of half the sample period (the controller's dt = 1e-4 s): the master ticks the
    controller's clock in event mode at every other step (the FMI 2.0 stack stepped once a tick: half the compiled
    steps of the run without event mode, which samples inside fmi3DoStep), and results.csv is the same, byte for
    byte, as without event mode and as the FMI 2.0 units'."""
    import filecmp

    runs = {}
    for label, fmi, event_mode in (("fmi2", 2, False), ("free", 3, False), ("ticked", 3, True)):
        runs[label] = _run_master("scenario1", fmi, tmp_path / label, 0.2, loop=loop, event_mode=event_mode,
                                  step=5e-5, start=["ctrl.dt=1e-4"])
    for label, (metrics, _) in runs.items():
        assert metrics["status"] == "completed" and metrics["macro_steps"] == 4000 and metrics["loop"] == loop
        assert filecmp.cmp(tmp_path / "fmi2" / "results.csv", tmp_path / label / "results.csv", shallow=False), label
    two, free, ticked = (runs[k][1]["ctrl"] for k in ("fmi2", "free", "ticked"))
    assert free[1:] == two[1:]
    # per step one fmi2SetReal of the inputs (the compiled path); fmi2DoStep per step without event mode, per tick
    # with it; the outputs read at each of the controller's steps either way
    assert free[1] - ticked[1] == 2000, (two, free, ticked)
    print(loop, {"fmi2": two, "fmi3 without event mode": free, "fmi3 ticked": ticked})


# -- a host in C -----------------------------------------------------------------------------------------------------
C_STEPS = 200
#: Float64 inputs of each unit, (a, b): a + b k before step k (tests/c_host3.c)
C_INPUTS = {"PmsmEvPlant": {"v_alpha": (20.0, 0.05), "v_beta": (-5.0, 0.1), "delta": (0.05, 0.0)},
            "RouteProfile": {}}
C_CONTROLLER = {"i_alpha": (1.0, 0.01), "i_beta": (0.5, -0.02), "omega_ref": (20.0, 0.1), "theta_meas": (0.3, 0.001),
                "omega_meas": (15.0, 0.05)}

# the same calls through fmpy's FMU3Slave in a Python process (without event mode: the units sample in fmi3DoStep),
# printed as the C host prints them
_FMPY3_HOST = r"""
import ctypes, sys
from fmpy import read_model_description
from fmpy.fmi3 import FMU3Slave
blocks = []
for line in open(sys.argv[1]).read().splitlines():
    word, *rest = line.split()
    if word == "fmu":
        blocks.append({"name": rest[0], "binary": rest[1], "in": [], "out": []})
    elif word == "steps":
        blocks[-1]["steps"], blocks[-1]["h"] = int(rest[0]), float(rest[1])
    elif word == "input":
        blocks[-1]["in"].append((int(rest[0]), float(rest[1]), float(rest[2])))
    elif word == "output":
        blocks[-1]["out"].append(int(rest[0]))
for b in blocks:
    root = b["binary"].rsplit("/binaries/", 1)[0]
    md = read_model_description(root)
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=root, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=b["name"])
    print("fmu", b["name"], fmu.getVersion())
    fmu.instantiate()
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    for k in range(b["steps"]):
        if b["in"]:
            fmu.setFloat64([vr for vr, _, _ in b["in"]], [a + s * k for _, a, s in b["in"]])
        fmu.doStep(k * b["h"], b["h"])
        print(k, 0, 0, " ".join("%.17g" % y for y in fmu.getFloat64(b["out"])))
    fmu.terminate()
    fmu.freeInstance()
"""




def test_a_c_host_runs_each_fmi3_unit_with_no_set_up(units, tmp_path):
    """tests/c_host3.c (FMI 3.0, no libpython linked), compiled with the system's C compiler against FMPy's FMI 3.0
    headers, runs every FMI 3.0 unit of the project, unzipped, with no environment but PATH, HOME and LANG: the
    controllers in event mode, their sample clock ticked before every step. Every output of every step equals
    fmpy's FMU3Slave making the same calls without event mode, bit for bit; the plant and the controllers serve
    the C host's calls on the compiled path."""
    import fmpy
    from fmpy import extract, read_model_description

    from c_fmu_support import c_compiler, host_steps

    compiler = c_compiler()
    if compiler is None:
        pytest.skip("no C compiler")
    host = tmp_path / "c_host3"
    done = subprocess.run([compiler, "-O1", "-std=c99", "-D_GNU_SOURCE", "-Wall", "-Werror",
                           f"-I{Path(fmpy.__file__).parent / 'c-code'}", str(Path(__file__).parent / "c_host3.c"),
                           "-o", str(host), "-ldl"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    blocks = []
    for name, fmu in units[1].items():
        root = Path(extract(str(fmu), str(tmp_path / name)))
        md = read_model_description(str(root))
        by_name = {v.name: v for v in md.modelVariables}
        lines = [f"fmu {name} {root / 'binaries' / fmu_build.FMI3_PLATFORM / (name + '.so')} {root / 'resources'}/ "
                 f"{md.guid}", f"steps {C_STEPS} {H!r}"]
        if fmu_build.clocked(name):
            lines.append(f"clock {fmu_build.FMI3_CLOCK_REFERENCE} 1")
        for var, (a, b) in C_INPUTS.get(name, C_CONTROLLER).items():
            lines.append(f"input {by_name[var].valueReference} {a!r} {b!r}")
        lines += [f"output {v.valueReference}" for v in md.modelVariables
                  if v.causality == "output" and v.type == "Float64"]
        blocks.append("\n".join(lines + ["run", ""]))
    spec = tmp_path / "spec.txt"
    spec.write_text("".join(blocks))
    env = {"PATH": "/usr/bin:/bin", "HOME": str(Path.home()), "LANG": "C.UTF-8"}
    c = subprocess.run([str(host), str(spec)], capture_output=True, text=True, env=env, timeout=600)
    assert c.returncode == 0, c.stdout[-3000:] + c.stderr[-3000:]
    assert "log " not in c.stdout, c.stdout[:3000]
    py = subprocess.run([sys.executable, "-c", _FMPY3_HOST, str(spec)], capture_output=True, text=True, timeout=600)
    assert py.returncode == 0, py.stderr[-3000:]
    c_runs, py_runs = host_steps(c.stdout), host_steps(py.stdout)
    assert sorted(c_runs) == sorted(units[1])
    calls = {line.split()[1]: None for line in c.stdout.splitlines() if line.startswith("fmu ")}
    current = None
    for line in c.stdout.splitlines():
        if line.startswith("fmu "):
            current = line.split()[1]
            assert line.endswith(" 3.0"), line
        elif line.startswith("calls "):
            calls[current] = tuple(int(x) for x in line.split()[1:])
    for name in units[1]:
        assert len(c_runs[name]) == C_STEPS and c_runs[name] == py_runs[name], name
        if name != fmu_build.ROUTE_FMU:
            assert calls[name][1] >= 2 * C_STEPS, (name, calls[name])  # the set and the step compiled, at least
    assert c_runs["PmsmEvPlant"][-1] != c_runs["PmsmEvPlant"][0]
    print({name: (len(c_runs[name][0]), calls[name]) for name in units[1]})
