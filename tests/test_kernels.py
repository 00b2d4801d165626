"""The per-step kernels (pmsm_ev.kernels) compiled with numba and as plain Python, and
their on-disk cache (pmsm_ev.accel)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pmsm_cosim.app.reference import run_reference
from pmsm_cosim.engine.recording import read_results
from pmsm_ev import accel, kernels
from pmsm_ev.kernels import layout
from pmsm_ev.params import ControllerParams, PlantParams
from pmsm_ev.plant import Plant
from pmsm_ev.results import ALL_COLUMNS
from regression_runs import CASES, ELEVATION, PARAMS

#: the runs the comparisons below make as plain Python: (observer, angle source, *extra), as ``run_here`` takes them
PLAIN_RUNS = [(observer, angle_source) for observer, angle_source in CASES + (("ekf5", "estimated"),)] + [
    (observer, "measured", "effects") for observer in ("sensored", "ekf5ab")] + [("sensored", "measured", "stationary")]
PLAIN_SCRIPT = """
import json, sys
sys.path.insert(0, sys.argv[1])
from test_kernels import run_here
print(json.dumps([run_here(*run) for run in json.loads(sys.argv[2])]))
"""


def run_here(observer: str, angle_source: str, out, *extra) -> dict:
    """The reference run of ``observer``/``angle_source`` over 2 s into ``out``, in this process; "effects" in
    ``extra``: the plant's effects on (dead time and its compensation, saturation, temperature and heating).
    How the kernels ran: {"mode": accel.describe(), "compiled": accel.compiled()}."""
    params = PARAMS
    if "effects" in extra:
        params = replace(PARAMS, plant=PlantParams(v_dc=360.0, dead_time=2e-6, sat_i_q=900.0, sat_i_d=2000.0,
                                                   T_winding=90.0, T_magnet=70.0, thermal_R=0.05,
                                                   thermal_C=2.0),
                         controller=ControllerParams(dead_time_comp=7.2))
    if "stationary" in extra:  # the drive cycles' plant: the stationary frame's RK6 on the algebraic flux model
        params = replace(PARAMS, plant=PlantParams(v_dc=360.0, dead_time=2e-6, flux_model="algebraic",
                                                   integrator="rk6_stationary", inverter_losses=True,
                                                   iron_c_h=27.98, iron_c_e=9.191e-3))
    run_reference(out, stop_time=2.0, observer=observer, angle_source=angle_source, params=params,
                  output_interval=0.001, elevation=ELEVATION)
    return {"mode": accel.describe(), "compiled": accel.compiled()}


@pytest.fixture(scope="module")
def plain_runs(tmp_path_factory) -> dict[tuple, tuple[dict, dict]]:
    """{run of PLAIN_RUNS: (how the kernels ran, its rows)}: the runs made one after the other by a process of
    their own with PMSM_EV_JIT=0 (plain Python)."""
    pytest.importorskip("numba")
    root = tmp_path_factory.mktemp("plain")
    runs = [[*run[:2], str(root / "-".join(run)), *run[2:]] for run in PLAIN_RUNS]
    r = subprocess.run([sys.executable, "-c", PLAIN_SCRIPT, str(Path(__file__).parent), json.dumps(runs)],
                       capture_output=True, text=True, timeout=600, env={**os.environ, "PMSM_EV_JIT": "0"})
    assert r.returncode == 0, r.stderr[-3000:]
    infos = json.loads(r.stdout.strip().splitlines()[-1])
    return {run: (info, read_results(root / "-".join(run))) for run, info in zip(PLAIN_RUNS, infos)}


def _run_compiled(tmp_path: Path, observer: str, angle_source: str, name: str, *extra) -> tuple[dict, dict]:
    """The run in this process, whose kernels are compiled (numba is there: the tests that call this import it)."""
    out = tmp_path / name
    info = run_here(observer, angle_source, out, *extra)
    return info, read_results(out)


@pytest.mark.parametrize("observer,angle_source", CASES + (("ekf5", "estimated"),))
def test_plain_python_and_numba_give_the_same_bits(plain_runs, tmp_path, observer, angle_source):
    """A process with PMSM_EV_JIT=0 runs the kernels as plain Python; this one, compiled: the same bits."""
    info_plain, plain = plain_runs[(observer, angle_source)]
    info_jit, jit = _run_compiled(tmp_path, observer, angle_source, "jit")
    assert not info_plain["compiled"] and info_plain["mode"].startswith("plain Python")
    assert info_jit["compiled"], info_jit["mode"]
    for col in ALL_COLUMNS:
        assert np.array_equal(plain[col], jit[col]), col
    assert np.max(np.abs(jit["omega_m"])) > 50.0  # the drive moved


def test_the_stationary_frame_gives_the_same_bits_compiled_or_not(plain_runs, tmp_path):
    """The stationary frame's RK6 on the algebraic flux model (with dead time, inverter and iron losses): the same
    bits (and another run than the default plant's)."""
    info_plain, plain = plain_runs[("sensored", "measured", "stationary")]
    assert not info_plain["compiled"]
    info_jit, jit = _run_compiled(tmp_path, "sensored", "measured", "jit", "stationary")
    assert info_jit["compiled"], info_jit["mode"]
    for col in ALL_COLUMNS:
        assert np.array_equal(plain[col], jit[col]), col
    _, default = _run_compiled(tmp_path, "sensored", "measured", "default")
    assert not np.array_equal(default["i_q"], jit["i_q"])


@pytest.mark.parametrize("observer", ["sensored", "ekf5ab"])
def test_plant_effects_give_the_same_bits_compiled_or_not(plain_runs, tmp_path, observer):
    """Dead time (and its compensation), saturation and temperature on: the same bits."""
    info_plain, plain = plain_runs[(observer, "measured", "effects")]
    assert not info_plain["compiled"] and info_plain["mode"].startswith("plain Python")
    info_jit, jit = _run_compiled(tmp_path, observer, "measured", "jit", "effects")
    assert info_jit["compiled"], info_jit["mode"]
    for col in ALL_COLUMNS:
        assert np.array_equal(plain[col], jit[col]), col
    _, off = _run_compiled(tmp_path, observer, "measured", "off")
    assert not np.array_equal(off["i_q"], jit["i_q"])  # the effects changed the run


#: the kernel modules whose smallest top-level kernel the cache test compiles (seconds, not a minute)
CACHE_PROBED = ("control", "observers", "fmu")


def test_kernels_are_cached_by_content(tmp_path):
    """The compiled kernels come from a copy of the kernels package in a directory named by the
    hash of all its files, with a fixed time stamp, in PMSM_EV_CACHE_DIR: a second process loads
    numba's cache instead of compiling."""
    pytest.importorskip("numba")
    cache = tmp_path / "cache"
    # the smallest top-level kernel of three modules made ready (a top-level kernel is compiled, or loaded, when
    # a process first needs it): their files get compiled code in the cache, without the minute that compiling
    # every kernel takes (the plant's and the units' steps, which the other tests compile anyway)
    probe = ("from pmsm_ev import accel; import inspect, json, sys; k = accel.kernels(); "
             f"mods = [sys.modules[k.__name__ + '.' + m] for m in {list(CACHE_PROBED)!r}]; "
             "tops = [[f for f in vars(m).values() if not isinstance(f, type) and hasattr(f, 'ready') "
             "and f.__module__ == m.__name__] for m in mods]; "
             "[min(fs, key=lambda f: len(inspect.getsource(f.py_func))).ready() for fs in tops]; "
             "print(json.dumps([accel.describe(), k.__file__]))")

    def load() -> list:
        r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=300,
                           env={**os.environ, "PMSM_EV_CACHE_DIR": str(cache)})
        assert r.returncode == 0, r.stderr[-3000:]
        return json.loads(r.stdout.strip().splitlines()[-1])

    mode, path = load()
    copy = Path(path).parent
    assert copy.parent == cache and copy.name.startswith("kernels_") and str(cache) in mode
    package = Path(kernels.__file__).parent
    sources = sorted(p.name for p in package.glob("*.py"))
    assert {"__init__.py", "layout.py", "plant.py", "control.py", "observers.py", "startup.py"} <= set(sources)
    assert sorted(p.name for p in copy.glob("*.py")) == sources
    for name in sources:
        assert (copy / name).read_bytes() == (package / name).read_bytes(), name
        assert int((copy / name).stat().st_mtime) == accel._STAMP
    compiled = {p.name: p.stat().st_mtime_ns for p in (copy / "__pycache__").iterdir()}
    # compiled code of each file whose kernel was made ready
    assert {n.split(".")[0] for n in compiled if n.endswith(".nbi")} >= set(CACHE_PROBED)
    assert load()[1] == path
    assert {p.name: p.stat().st_mtime_ns for p in (copy / "__pycache__").iterdir()} == compiled  # no recompiling


def test_a_kernel_is_compiled_for_its_one_signature_when_first_needed():
    """A top-level kernel (``kernel(signature)``) is compiled, or loaded from numba's cache, when a process first
    calls it: then for its signature alone, as ``njit(signature)`` would have at once (an int argument is
    converted to the float64 it declares, not compiled for anew)."""
    k = accel.kernels()
    if not accel.compiled():
        pytest.skip("the kernels run as plain Python")
    fn = k.sample_instant
    assert fn(3, 0, 1, 0) == fn(3.0, 0.0, 1.0, 0.0)
    assert len(fn.overloads) == 1 and fn.ready() is fn
    assert [str(t) for t in next(iter(fn.overloads))] == ["float64"] * 4


def test_a_change_in_any_kernel_file_gives_another_cache(tmp_path):
    """The cache's key covers every file of the package: a caller in startup.py inlines the kernels of
    control.py, so a change in control.py alone must not reuse startup.py's compiled code."""
    sources = accel._SOURCES
    digest = accel._digest(sources, "0")
    for name in sources:
        changed = {**sources, name: sources[name] + b"\n"}
        assert accel._digest(changed, "0") != digest, name
    assert accel._digest({**sources, "extra.py": b""}, "0") != digest
    assert accel._digest(sources, "1") != digest  # and numba's version


def test_vectors_follow_the_mode():
    v = accel.vector(3)
    if accel.compiled():
        assert isinstance(v, np.ndarray) and v.dtype == np.float64 and v.flags.c_contiguous
    else:
        assert v == [0.0, 0.0, 0.0]


def test_a_kernels_direct_entry_gives_the_dispatchers_numbers():
    """``accel.direct``: the compiled entry point of a kernel with one signature (no per-call dispatch),
    the same machine code: the same bits; a function that is not a compiled kernel comes back as it is."""
    k = accel.kernels()
    plant = Plant()  # its parameter vector filled from the defaults
    pp, energy = plant._pp, plant.energy
    fast = accel.direct(k.plant_step)
    args = (10.0, 50.0, 100.0, 0.3, 20.0, -15.0, 0.01, 1e-4)
    e1, e2 = (energy.copy(), energy.copy()) if accel.compiled() else (list(energy), list(energy))
    assert fast(*args, pp, e1) == k.plant_step(*args, pp, e2)
    assert list(e1) == list(e2) and any(e1)
    if accel.compiled():
        assert fast is not k.plant_step
        with pytest.raises(TypeError):
            fast(*args, list(pp), e1)  # no conversion: a vector must be an array
    else:
        assert fast is k.plant_step
    assert accel.direct(len) is len



# -- the vectors' layouts ---------------------------------------------------------------------------
LAYOUTS = [(layout.PLANT_PARAMS_LAYOUT, kernels.PLANT_PARAMS), (layout.UNIT_STATE_LAYOUT, kernels.UNIT_STATE),
           (layout.UNIT_PARAMS_LAYOUT, kernels.UNIT_PARAMS), (layout.PLANT_ENERGY_LAYOUT, kernels.PLANT_ENERGY)]


@pytest.mark.parametrize("table,size", LAYOUTS, ids=["plant params", "unit state", "unit params", "plant energy"])
def test_each_slot_is_a_module_constant_and_no_two_overlap(table, size):
    assert len(table) == size
    taken = [None] * size
    for slot in table.slots:
        offset = getattr(kernels, slot.name)
        assert type(offset) is int and offset == table.offsets[slot.name]
        for i in table.span(slot.name):
            assert taken[i] is None, (slot.name, taken[i])
            taken[i] = slot.name
    assert None not in taken  # and no gaps


def test_the_offsets_are_those_the_kernels_were_written_with():
    assert (kernels.P_SUBSTEPS, kernels.P_DT_V, kernels.P_SAT_AQ, kernels.P_T_BRAKE, kernels.PLANT_PARAMS) == (
        21, 22, 26, 29, 148)
    assert (kernels.E_DC, kernels.E_P_DC, kernels.E_IRON, kernels.PLANT_ENERGY) == (0, 12, 13, 31)
    # the thermal network's slots, after the battery's (``thermal_network_step``)
    assert (kernels.P_TH, kernels.P_TH_G, kernels.P_ALPHA_PSI, kernels.E_TH_T, kernels.E_TH_OVER) == (
        120, 121, 142, 24, 30)
    assert kernels.P_FLUX_MEMO == 143  # the algebraic model's memo, after the thermal network's
    # the battery's slots, after the ideal link's (0 there with the ideal link)
    assert (kernels.P_BAT, kernels.P_BAT_OCV, kernels.P_DT_K, kernels.E_BAT_SOC, kernels.E_BAT_P_DIS) == (
        56, 69, 119, 14, 23)
    assert (kernels.S_X, kernels.S_THETA_PRIOR, kernels.S_P, kernels.S_PHT, kernels.S_K, kernels.S_A,
            kernels.S_STARTED, kernels.S_MODE, kernels.S_STILL_OUT, kernels.UNIT_STATE) == (
        15, 20, 21, 46, 56, 66, 91, 92, 130, 268)
    assert (kernels.C_Q, kernels.C_C_MID, kernels.C_P0, kernels.C_T_RAMP, kernels.C_P0_ALIGNED,
            kernels.C_SLIP_FILTER, kernels.C_STILL, kernels.UNIT_PARAMS) == (35, 40, 41, 46, 60, 65, 93, 219)
    # the reference generator's slots, at the end of both unit vectors
    assert (kernels.S_I_DREF, kernels.S_T_AVAIL, kernels.C_REF_MODE, kernels.C_BRAKE_GAIN) == (131, 135, 97, 104)
    # the speed loop's feedforward, after them
    assert (kernels.S_W_REF_PREV, kernels.S_T_FF, kernels.C_FF, kernels.C_FF_T2) == (136, 138, 105, 109)
    # the sensorless unit's handover deadline and stall, after them
    assert (kernels.S_IF_DUE, kernels.S_REALIGN, kernels.C_IF_DEADLINE, kernels.C_REALIGN_MAX) == (139, 140, 110, 112)
    # the injection's hill hold, last of the injection strategy's slots
    assert (kernels.S_HOLD, kernels.C_HOLD_BRAKE) == (213, 148)
    # the I-f strategy's alignment timer and damping input, and its guard, trust, relock and stand parameters
    assert (kernels.S_RUNAWAY_T, kernels.S_ALIGN_SPEED, kernels.C_SOFT_GUARD, kernels.C_STILL_TIME) == (
        214, 215, 149, 153)
    # the measured DC link's
    assert (kernels.C_FW_MARGIN, kernels.C_P_DIS) == (154, 157)
    # the identified model's (``model_apply``), last
    assert (kernels.C_MODEL_SRC, kernels.C_MODEL0) == (169, 170)


@pytest.mark.parametrize("rows,size,message", [
    ((("S_A", 1, ""), ("S_A", 2, "")), 3, "slot S_A declared twice"),
    ((("S_A", 0, ""),), 0, "slot S_A has length 0; it must be a whole number >= 1"),
    ((("S_A", 2.0, ""),), 2, "slot S_A has length 2.0"),
    ((("C_A", 1, ""),), 1, "slot name 'C_A' is not an upper-case identifier starting with 'S_'"),
    ((("S_a", 1, ""),), 1, "slot name 'S_a'"),
    ((("S_A", 5, ""), ("S_B", 1, "")), 5, "the slots take 6 floats, the vector is declared with 5"),
])
def test_a_wrong_layout_table_is_refused_at_import(rows, size, message):
    with pytest.raises(layout.LayoutError, match="test vector: " + re.escape(message)):
        layout.Layout("test vector", "S_", rows, size)


def test_a_layout_saves_and_restores_named_fields_and_refuses_others():
    table = layout.Layout("test vector", "S_", (("S_A", 1, ""), ("S_B", 2, ""), ("S_TMP", 3, "", False)), 6)
    v = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    saved = table.save(v)
    assert saved == {"a": [1.0], "b": [2.0, 3.0]}  # no scratch
    w = [0.0] * 6
    table.restore(w, json.loads(json.dumps(saved)))
    assert w == [1.0, 2.0, 3.0, 0.0, 0.0, 0.0]
    with pytest.raises(layout.LayoutError, match="field 'b' of the saved state has 1 values, expected 2"):
        table.restore(w, {"a": [1.0], "b": [2.0]})
    with pytest.raises(layout.LayoutError, match="the saved state has no field 'b'"):
        table.restore(w, {"a": [1.0]})
    with pytest.raises(layout.LayoutError, match="a field 'c' that this version does not know"):
        table.restore(w, {"a": [1.0], "b": [2.0, 3.0], "c": [0.0]})
    with pytest.raises(layout.LayoutError, match="a dict of named fields"):
        table.restore(w, [1.0, 2.0, 3.0])
    assert w == [1.0, 2.0, 3.0, 0.0, 0.0, 0.0]  # a refused state changes nothing


@pytest.mark.parametrize("table,size", LAYOUTS, ids=["plant params", "unit state", "unit params", "plant energy"])
def test_each_named_entry_is_a_module_constant_inside_its_slot(table, size):
    """``Slot.parts``: a slot's named entries, in its order, cover it; each is a module-level int (numba folds it as
    it folds ``S_X + 2``) at its slot's offset plus its place there."""
    for slot in table.slots:
        if not slot.parts:
            continue
        at = table.offsets[slot.name]
        for part in slot.parts:
            name, length = (part, 1) if isinstance(part, str) else part
            offset = getattr(kernels, name)
            assert type(offset) is int and offset == at == table.parts[name], name
            at += length
        assert at == table.offsets[slot.name] + slot.length
    assert (kernels.S_I_D_HAT, kernels.S_OMEGA_HAT, kernels.S_THETA_HAT, kernels.S_TL_HAT) == (
        kernels.S_X, kernels.S_X + 2, kernels.S_X + 3, kernels.S_X + 4)


@pytest.mark.parametrize("rows,message", [
    ((layout.Slot("S_A", 2, "", parts=("S_A0",)),), "the parts of slot S_A take 1 floats, the slot 2"),
    ((layout.Slot("S_A", 2, "", parts=("S_A0", "S_A0")),), "slot S_A0 declared twice"),
    ((layout.Slot("S_A", 2, "", parts=("S_A", "S_B")),), "slot S_A declared twice"),
    ((layout.Slot("S_A", 2, "", parts=(("S_A0", 1), ("C_B", 1))),), "slot name 'C_B'"),
])
def test_a_wrong_part_is_refused_at_import(rows, message):
    with pytest.raises(layout.LayoutError, match="test vector: " + re.escape(message)):
        layout.Layout("test vector", "S_", rows, 2)


#: the kernels whose state is read by name: no offset arithmetic on a slot that names its entries, but a loop's
#: (``S_ID_N_D + j``) or a slot's whole span cleared (``S_POL + k``)
READ_BY_NAME = ("modes.py", "startup.py", "adaptation.py")


@pytest.mark.parametrize("module", READ_BY_NAME)
def test_the_kernels_read_named_entries_by_name(module):
    named = [s.name for lay in (layout.UNIT_STATE_LAYOUT, layout.UNIT_PARAMS_LAYOUT) for s in lay.slots if s.parts]
    source = (Path(kernels.__file__).parent / module).read_text()
    found = re.findall(r"\b(%s) \+ \d+\b" % "|".join(named), source)
    assert found == [], f"{module} indexes {sorted(set(found))} by arithmetic: use the names the layout declares"


def test_a_layout_resets_each_slot_to_its_declared_value():
    table = layout.Layout("test vector", "S_", (("S_A", 1, ""), layout.Slot("S_B", 2, "", reset=1.0),
                                                ("S_TMP", 1, "", False)), 4)
    v = [7.0] * 4
    table.reset(v)
    assert v == [0.0, 1.0, 1.0, 0.0]
    assert layout.UNIT_STATE_LAYOUT._slot("S_PSI_RATIO").reset == 1.0  # the one slot of the unit not reset to 0


@pytest.mark.parametrize("observer,low_speed", [("ekf5", "if"), ("ekf4", "if"), ("ekf5ab", "if"), ("sensored", "if"),
                                                ("sensorless", "if"), ("sensorless", "injection")])
def test_a_reset_unit_is_the_new_one_whatever_its_state_was(observer, low_speed):
    """``ControlUnit.reset`` by declaration: a unit run for a while, its state then scrambled, and reset equals a new
    unit in every saved slot (the scratch slots are written before they are read)."""
    from pmsm_ev.control_unit import ControlUnit  # noqa: PLC0415
    from pmsm_ev.params import InjectionParams  # noqa: PLC0415

    def unit():
        return ControlUnit(observer, angle_source="estimated", dt=1e-4,
                           injection=InjectionParams(low_speed=low_speed))

    new, used = unit(), unit()
    for _ in range(20):
        used.step(1.0, -0.5, 10.0, 0.3, 5.0)
    for i in range(kernels.UNIT_STATE):
        used._s[i] = 1e3 + i
    used.reset()
    assert used.get_state() == new.get_state()


def test_modes_events_and_actions_are_named_integers_declared_once():
    """Each a distinct int of its kind (the I-f strategy's and the injection's events and actions apart), declared in
    one module: the modes in ``kernels.layout``, the events, actions and the stand's states in ``kernels.machine``;
    the tables hold no other codes."""
    from pmsm_ev.kernels import machine  # noqa: PLC0415

    kinds = {"MODE_": layout, "EV_": machine, "A_": machine, "STAND_": machine}
    for prefix, home in kinds.items():
        names = [n for n in vars(home) if n.startswith(prefix) and n.isupper()
                 and not n.endswith(("_NAMES", "_TRANSITIONS", "_TABLE"))]
        values = [getattr(home, n) for n in names]
        assert names and all(type(v) is int for v in values), prefix
        assert len(set(values)) == len(values), prefix
        for module in Path(kernels.__file__).parent.glob("*.py"):
            if module.name != Path(home.__file__).name:
                defined = re.findall(r"^(%s[A-Z_]+)\s*[,=]" % prefix, module.read_text(), re.M)
                assert not set(defined) & set(names), (module.name, defined)
    codes = {getattr(machine, n) for n in vars(machine) if n.startswith(("EV_", "A_"))}
    modes = {getattr(layout, n) for n in vars(layout) if n.startswith("MODE_")}
    for mode, event, nxt, action in machine.TRANSITIONS:
        assert mode in modes and nxt in modes and event in codes and action in codes


def test_the_fmus_compiled_step_declines_without_changing_anything():
    """``pmsm_ev.kernels.fmu`` (the FMUs' compiled step, here as plain Python): a step it does not take leaves the
    buffer and the vectors as they were, so that the slave's Python step runs on the same values: a plant voltage
    at or near the DC link's limit, a step size <= 0, a plant state that is no longer finite (the energies and the
    brake slot put back), a controller's first step that rebuilds its unit."""
    k = kernels
    io = [0.0] * k.PLANT_IO
    pp = [1.0] * k.PLANT_PARAMS
    ee = [0.5] * k.PLANT_ENERGY
    io[k.PIO_U_LIM] = 100.0
    io[k.PIO_T_BRAKE] = 30.0
    for v_alpha, h in ((100.0, 1e-4), (99.99999999, 1e-4), (10.0, 0.0), (10.0, -1e-4)):
        io[k.PIO_V_ALPHA] = v_alpha
        before = (list(io), list(pp), list(ee))
        assert k.plant_fmu_step(io, pp, ee, h) == k.STEP_DECLINED
        assert (io, pp, ee) == before
    io[k.PIO_V_ALPHA] = 10.0
    io[k.PIO_OMEGA_M] = float("nan")  # the step's state is not finite: the slave's Python step raises
    before = (list(io), list(pp), list(ee))
    assert k.plant_fmu_step(io, pp, ee, 1e-4) == k.STEP_DECLINED
    assert (io[:k.PIO_SAVE], pp, ee) == (before[0][:k.PIO_SAVE], before[1], before[2])

    unit = [0.0] * k.UNIT_IO
    unit[k.UIO_UNIT_DT] = 1e-4
    unit[k.UIO_TOLERANCE] = 1e-2
    s, c = [0.0] * k.UNIT_STATE, [0.0] * k.UNIT_PARAMS
    for h in (5e-5, 0.0):  # dt 0 and a first step of another size than the unit's: rebuilt in Python
        before = (list(unit), list(s))
        assert k.unit_fmu_step(unit, s, c, 0.0, h) == k.STEP_DECLINED
        assert (unit, s) == before
