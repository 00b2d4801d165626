"""System files: the shipped scenarios equal the physics library's definitions; parsing
and its one-line errors."""

from __future__ import annotations

import math

import pytest

from pmsm_cosim.app.drive import load_system, packaged_scenario, project_fmu_dir
from pmsm_cosim.engine.errors import CosimError
from pmsm_ev.results import ALL_COLUMNS
from pmsm_ev.scenarios import SCENARIO1_DEG, SCENARIO2_DEG, elevation_profile, speed_reference

PLANT_COLUMNS = ("omega_m", "theta_e", "i_d", "i_q", "T_e", "T_L_mech", "i_alpha", "i_beta", "v_vehicle")
CTRL_COLUMNS = ("omega_hat", "theta_hat", "i_d_hat", "i_q_hat", "T_L_hat", "v_d", "v_q", "v_alpha", "v_beta",
                "i_qref")


@pytest.mark.parametrize("n, table", [(1, SCENARIO1_DEG), (2, SCENARIO2_DEG)])
def test_shipped_scenarios_equal_the_library(n, table):
    spec = load_system(f"scenario{n}")
    assert spec.path == packaged_scenario(f"scenario{n}")
    assert spec.name == f"scenario{n}"
    assert (spec.step_size, spec.stop_time, spec.output_interval, spec.algorithm) == (1e-4, 350.0, 0.01,
                                                                                      "gauss-seidel")
    # elevation: the deg table, converted value by value with math.radians (bit-identical)
    delta = spec.signals["delta"]
    assert delta.written_unit == "deg" and delta.unit == "rad"
    assert delta.profile.times == tuple(float(t) for t, _ in table)
    assert delta.profile.values == elevation_profile(n).values
    assert delta.profile.values == tuple(math.radians(d) for _, d in table)
    assert delta.profile.interpolation == "previous"
    assert delta.drives == [("plant", "delta")]
    ref = speed_reference()
    w = spec.signals["omega_ref"]
    assert (w.profile.times, w.profile.values, w.profile.interpolation) == (ref.times, ref.values, "linear")
    assert w.drives == [("ctrl", "omega_ref")]
    # components in the Gauss-Seidel order of the reference: controller, then plant
    assert [c.name for c in spec.components] == ["ctrl", "plant"]
    assert spec.components[0].fmu == project_fmu_dir() / "FocEkf5.fmu"
    assert spec.components[1].fmu == project_fmu_dir() / "PmsmEvPlant.fmu"
    assert {str(c) for c in spec.connections} == {
        "plant.i_alpha -> ctrl.i_alpha", "plant.i_beta -> ctrl.i_beta", "plant.theta_e -> ctrl.theta_meas",
        "plant.omega_m -> ctrl.omega_meas", "ctrl.v_alpha -> plant.v_alpha", "ctrl.v_beta -> plant.v_beta",
        "ctrl.T_brake -> plant.T_brake", "plant.v_bat -> ctrl.v_dc_meas", "plant.P_charge_max -> ctrl.P_charge_max",
        "plant.P_discharge_max -> ctrl.P_discharge_max"}
    # recorded columns: exactly the result contract, mapped as documented
    assert tuple(c.name for c in spec.columns) == ALL_COLUMNS
    src = {c.name: c.source for c in spec.columns}
    assert src["time"] == "time"
    assert src["delta_deg"] == "signals.delta [deg]"
    assert src["omega_ref"] == "signals.omega_ref"
    assert all(src[c] == f"plant.{c}" for c in PLANT_COLUMNS)
    assert all(src[c] == f"ctrl.{c}" for c in CTRL_COLUMNS)


def write(tmp_path, text, name="sys.toml"):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


MINIMAL = '''
name = "mini"
connections = ["a.y -> b.u"]
[experiment]
step_size = 1e-3
stop_time = 1.0
[[components]]
name = "a"
fmu = "A.fmu"
[[components]]
name = "b"
fmu = "sub/B.fmu"
[record]
time = "time"
y = "a.y"
'''


def test_minimal_system_and_defaults(tmp_path):
    spec = load_system(write(tmp_path, MINIMAL))
    assert spec.output_interval == 1e-3 and spec.algorithm == "gauss-seidel"
    assert spec.components[0].fmu == (tmp_path / "A.fmu").resolve()  # relative to the file
    assert spec.components[1].fmu == (tmp_path / "sub" / "B.fmu").resolve()
    assert [c.step_multiple for c in spec.components] == [1, 1]


def test_overrides(tmp_path):
    spec = load_system(write(tmp_path, MINIMAL))
    spec.set_fmu("b", tmp_path / "C.fmu")
    assert spec.components[1].fmu == (tmp_path / "C.fmu").resolve()
    spec.set_start("a.k=3")
    assert spec.components[0].start == {"k": "3"}
    with pytest.raises(CosimError, match=r"unknown instance 'aa' \(did you mean: a"):
        spec.set_start("aa.k=3")
    with pytest.raises(CosimError, match="expected INSTANCE.VAR=VALUE"):
        spec.set_start("a.k")


def test_fmu_dir_placeholder(tmp_path):
    spec = load_system(write(tmp_path, MINIMAL.replace('"A.fmu"', '"{fmus}/A.fmu"')))
    assert spec.components[0].fmu == project_fmu_dir() / "A.fmu"


def test_signal_csv_override(tmp_path):
    csv = write(tmp_path, "t,deg\n0,1\n5,2.5\n", "route.csv")
    text = MINIMAL + '\n[signals.delta]\nunit = "deg"\ntable = [[0, 0]]\ndrives = "b.d"\n'
    # [signals] after [record] is fine in TOML; keep [record] last for readability elsewhere
    spec = load_system(write(tmp_path, text))
    spec.set_signal_csv(f"delta={csv}")
    assert spec.signals["delta"].profile.values == (math.radians(1.0), math.radians(2.5))
    with pytest.raises(CosimError, match="unknown signal 'delt'"):
        spec.set_signal_csv(f"delt={csv}")


@pytest.mark.parametrize("change, message", [
    (("stop_time = 1.0", "stop_time = -1.0"), "stop_time must be a finite number > 0"),
    (("stop_time = 1.0", "stop_tme = 1.0"), r"unknown key 'stop_tme' \(did you mean: stop_time"),
    (('[experiment]', '[experiment]\nalgorithm = "newton"'), "algorithm must be one of"),
    (('"a.y -> b.u"', '"a.y => b.u"'), "expected"),
    (('"a.y -> b.u"', '"a -> b.u"'), "expected INSTANCE.VARIABLE"),
    (('"a.y -> b.u"', '"c.y -> b.u"'), r"unknown instance 'c'"),
    (('name = "b"', 'name = "a"'), "used twice"),
    (('name = "b"', 'name = "time"'), "reserved"),
    (('y = "a.y"', 'y = "signals.nope"'), "unknown signal 'nope'"),
    (('y = "a.y"', 'y = { from = "a.y", unit = "rpm" }'), "can be converted to"),
    (('y = "a.y"', 'time = "a.y"'), "TOML"),
    (("[experiment]", "[experimnt]"), "unknown key 'experimnt'"),
    (('fmu = "A.fmu"', 'fmu = "A.fmu"\nstep_multiple = 0'), "step_multiple must be a whole number >= 1"),
])
def test_errors_are_one_line_and_name_the_file(tmp_path, change, message):
    path = write(tmp_path, MINIMAL.replace(*change))
    with pytest.raises(CosimError, match=message) as exc:
        load_system(path)
    assert "\n" not in str(exc.value)
    assert str(path) in str(exc.value)


@pytest.mark.parametrize("signal, message", [
    ('table = [[0, 1]]\ncsv = "x.csv"', "exactly one of 'table'"),
    ('table = [[1, 0], [0, 1]]', "does not increase"),
    ('table = [[0, 1, 2]]', r"\[time, value\] pair"),
    ('csv = "missing.csv"', "profile file not found"),
    ('interpolation = "cubic"\ntable = [[0, 1]]', "interpolation must be one of"),
])
def test_signal_errors(tmp_path, signal, message):
    path = write(tmp_path, MINIMAL + f"\n[signals.s]\n{signal}\n")
    with pytest.raises(CosimError, match=message):
        load_system(path)


def test_missing_file_and_unknown_scenario(tmp_path):
    with pytest.raises(CosimError, match="system file not found"):
        load_system(tmp_path / "nope.toml")
    with pytest.raises(CosimError, match=r"did you mean: scenario1"):
        packaged_scenario("scenario11")
