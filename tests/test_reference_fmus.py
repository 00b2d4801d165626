"""The Modelica Reference FMUs 3.0 on the master (fmus/README.md, "FMI 3.0", "Hosts that ran the FMI 3.0 units").

The Reference FMUs (github.com/modelica/Reference-FMUs) built from their sources with CMake (``-DFMI_VERSION=3``),
outside this repository; ``$PMSM_REFERENCE_FMUS3`` names the folder of the built ``BouncingBall.fmu``,
``Dahlquist.fmu``, ``Feedthrough.fmu``, ``Stair.fmu``, ``VanDerPol.fmu``, ``Clocks.fmu`` (the tests skip, saying
so, when it is not set or an FMU is missing). Each co-simulation unit runs alone on the master (``pmsm-cosim``'s
engine, a system file of one component, its default experiment's step and stop time) and under FMPy's
``simulate_fmu`` (no event mode, the output interval the master's step: the same fmi3DoStep calls), and every
recorded output is compared:

* BouncingBall, Dahlquist, Stair, VanDerPol: equal (1e-12; found 0.0), Stair's request to terminate at 9 s honoured
  by both (46 rows);
* Feedthrough, its Float64 input driven by a linear signal and its Int32, Boolean and discrete Float64 inputs given
  start values: the outputs that do not follow the driven input are equal; the continuous output that does (a direct
  feedthrough) is, in the master's row at t_n, the input set at t_n (docs/system-file.md: a row is recorded before
  step n, the signals at t_n set), in FMPy's the input of the step that ended at t_n (its recorder samples after
  fmi3DoStep, before it applies the inputs of t_n): the master's row n equals FMPy's row n + 1 (1e-12; found
  2.2e-16: the two interpolate the signal with different rounding);
* Clocks is a unit of scheduled execution only (no ``<CoSimulation>``): the master refuses it with one line, and
  FMPy's ``simulate_fmu`` does not run it either (it runs model exchange and co-simulation).
"""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import numpy as np
import pytest

ENV = "PMSM_REFERENCE_FMUS3"
FOLDER = Path(os.environ[ENV]) if os.environ.get(ENV) else None
NAMES = ("BouncingBall", "Dahlquist", "Feedthrough", "Stair", "VanDerPol", "Clocks")

#: per unit: (stop time, step [s]: its default experiment's), the outputs recorded, start values, the Float64 input a
#: linear signal drives (Feedthrough)
CASES = {"BouncingBall": (3.0, 1e-2, ["h", "v"], {}, None),
         "Dahlquist": (10.0, 0.1, ["x"], {}, None),
         "Stair": (10.0, 0.2, ["counter"], {}, None),
         "VanDerPol": (20.0, 1e-2, ["x0", "x1"], {}, None),
         "Feedthrough": (2.0, 0.1, ["Float64_continuous_output", "Float64_discrete_output", "Int32_output",
                                    "Boolean_output"],
                         {"Int32_input": 7, "Boolean_input": True, "Float64_discrete_input": 2.5},
                         "Float64_continuous_input")}
#: the driven input's signal: (time, value) points, linear between them
SIGNAL = ((0.0, 0.0), (1.0, 3.0), (2.0, -1.0))
#: the outputs that follow the driven input directly (Feedthrough's): FMPy records them one step later
FEEDTHROUGH = {"Float64_continuous_output"}


def _unit(name: str) -> Path:
    if FOLDER is None:
        pytest.skip(f"${ENV} is not set: the folder of the Reference FMUs 3.0 built from their sources (CMake, "
                    "-DFMI_VERSION=3; fmus/README.md)")
    path = FOLDER / f"{name}.fmu"
    if not path.is_file():
        pytest.skip(f"no {path} (${ENV}): build the Reference FMUs 3.0 there (fmus/README.md)")
    return path


def _system(name: str, fmu: Path, folder: Path) -> Path:
    stop, step, outputs, starts, driven = CASES[name]
    lines = [f'name = "{name.lower()}"', "", "[experiment]", f"step_size = {step!r}", f"stop_time = {stop!r}", "",
             "[[components]]", 'name = "u"', f"fmu = {json.dumps(str(fmu))}"]
    if starts:
        lines.append("start = { " + ", ".join(f"{k} = {json.dumps(v)}" for k, v in starts.items()) + " }")
    if driven:
        lines += ["", "[signals.w]", 'interpolation = "linear"', f"table = {json.dumps([list(p) for p in SIGNAL])}",
                  f'drives = "u.{driven}"']
    lines += ["", "[record]", 'time = "time"', *(f'{o} = "u.{o}"' for o in outputs)]
    path = folder / f"{name}.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _master(name: str, fmu: Path, folder: Path) -> tuple[dict, dict[str, np.ndarray]]:
    from pmsm_cosim.engine.master import Master
    from pmsm_cosim.engine.system import load_system_file

    out = folder / "run"
    metrics = Master(load_system_file(_system(name, fmu, folder)), note=lambda line: None).run(out,
                                                                                                catch_sigint=False)
    with open(out / "results.csv", newline="") as f:
        rows = list(csv.reader(f))
    columns = {c: np.array([float(r[i]) for r in rows[1:]]) for i, c in enumerate(rows[0])}
    return metrics, columns


def _fmpy(name: str, fmu: Path) -> dict[str, np.ndarray]:
    from fmpy import simulate_fmu

    stop, step, outputs, starts, driven = CASES[name]
    signals = None
    if driven:
        signals = np.array(list(SIGNAL), dtype=[("time", float), (driven, float)])
    result = simulate_fmu(str(fmu), stop_time=stop, output_interval=step, output=outputs, start_values=dict(starts),
                          input=signals)
    return {c: np.asarray(result[c], dtype=float) for c in result.dtype.names}


@pytest.mark.parametrize("name", list(CASES))
def test_the_master_runs_each_reference_fmu_as_fmpy_does(name, tmp_path):
    fmu = _unit(name)
    metrics, ours = _master(name, fmu, tmp_path)
    theirs = _fmpy(name, fmu)
    outputs = CASES[name][2]
    assert metrics["status"] == "completed"
    assert len(ours["time"]) == len(theirs["time"]) > 10, (len(ours["time"]), len(theirs["time"]))
    assert np.array_equal(ours["time"], theirs["time"])
    found = {}
    for column in outputs:
        if column in FEEDTHROUGH:  # the master's row n: the input of t_n; FMPy's row n + 1: the input of t_n
            found[column] = float(np.max(np.abs(ours[column][:-1] - theirs[column][1:])))
        else:
            found[column] = float(np.max(np.abs(ours[column] - theirs[column])))
        assert found[column] <= 1e-12, (name, column, found)
    if name == "Stair":  # it asks to end the simulation at 9 s (counter 10): both stop there
        assert metrics.get("terminated_at") == 9.0 and ours["time"][-1] == 9.0
    if name == "Feedthrough":  # the direct feedthrough does differ unshifted (what the shift above accounts for)
        assert float(np.max(np.abs(ours["Float64_continuous_output"] - theirs["Float64_continuous_output"]))) > 0.1
    print(name, len(ours["time"]), found)


def test_clocks_a_unit_of_scheduled_execution_only_is_refused_with_one_line(tmp_path):
    from fmpy import simulate_fmu

    from pmsm_cosim.engine.errors import CosimError
    from pmsm_cosim.engine.master import Master
    from pmsm_cosim.engine.system import load_system_file

    fmu = _unit("Clocks")
    system = tmp_path / "clocks.toml"
    system.write_text(f'[experiment]\nstep_size = 1.0\nstop_time = 10.0\n\n[[components]]\nname = "u"\n'
                      f'fmu = {json.dumps(str(fmu))}\n\n[record]\ntime = "time"\ninClock1Ticks = "u.inClock1Ticks"\n',
                      encoding="utf-8")
    with pytest.raises(CosimError) as refused:
        Master(load_system_file(system), note=lambda line: None).run(tmp_path / "run", catch_sigint=False)
    assert str(refused.value) == (f"u: {fmu}: an FMU without a co-simulation interface (no <CoSimulation>); only "
                                  "co-simulation FMUs are supported")
    with pytest.raises(Exception, match='FMI type "ModelExchange" is not supported by the FMU'):
        simulate_fmu(str(fmu), stop_time=10.0)
