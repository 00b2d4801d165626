"""The per-step kernels (pmsm_ev.kernels) compiled with numba and as plain Python, and
their on-disk cache (pmsm_ev.accel)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pmsm_cosim.engine.recording import read_results
from pmsm_ev import accel, kernels
from pmsm_ev.results import ALL_COLUMNS
from regression_runs import CASES

RUN_SCRIPT = """
import json, sys
from pmsm_ev import accel
from pmsm_cosim.app.reference import run_reference
sys.path.insert(0, sys.argv[3])
from regression_runs import PARAMS, ELEVATION
observer, angle_source, out = sys.argv[1], sys.argv[2], sys.argv[4]
if len(sys.argv) > 5:  # the plant's effects on: dead time and its compensation, saturation, temperature (heating)
    from dataclasses import replace
    from pmsm_ev.params import ControllerParams, PlantParams
    PARAMS = replace(PARAMS, plant=PlantParams(v_dc=360.0, dead_time=2e-6, sat_i_q=900.0, sat_i_d=2000.0,
                                               T_winding=90.0, T_magnet=70.0, thermal_R=0.05,
                                               thermal_C=2.0),
                     controller=ControllerParams(dead_time_comp=7.2))
run_reference(out, stop_time=2.0, observer=observer, angle_source=angle_source, params=PARAMS,
              output_interval=0.001, elevation=ELEVATION)
print(json.dumps({"mode": accel.describe(), "compiled": accel.compiled()}))
"""


def _run(tmp_path: Path, observer: str, angle_source: str, name: str, *extra, **env) -> tuple[dict, dict]:
    script = tmp_path / "run.py"
    script.write_text(RUN_SCRIPT)
    out = tmp_path / name
    r = subprocess.run([sys.executable, str(script), observer, angle_source, str(Path(__file__).parent), str(out),
                        *extra],
                       capture_output=True, text=True, timeout=300, env={**os.environ, **env})
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1]), read_results(out)


@pytest.mark.parametrize("observer,angle_source", CASES + (("ekf5", "estimated"),))
def test_plain_python_and_numba_give_the_same_bits(tmp_path, observer, angle_source):
    pytest.importorskip("numba")
    info_plain, plain = _run(tmp_path, observer, angle_source, "plain", PMSM_EV_JIT="0")
    info_jit, jit = _run(tmp_path, observer, angle_source, "jit")
    assert not info_plain["compiled"] and info_plain["mode"].startswith("plain Python")
    assert info_jit["compiled"], info_jit["mode"]
    for col in ALL_COLUMNS:
        assert np.array_equal(plain[col], jit[col]), col
    assert np.max(np.abs(jit["omega_m"])) > 50.0  # the drive moved


@pytest.mark.parametrize("observer", ["sensored", "ekf5ab"])
def test_plant_effects_give_the_same_bits_compiled_or_not(tmp_path, observer):
    """Dead time (and its compensation), saturation and temperature on: the same bits."""
    pytest.importorskip("numba")
    _, plain = _run(tmp_path, observer, "measured", "plain", "effects", PMSM_EV_JIT="0")
    info_jit, jit = _run(tmp_path, observer, "measured", "jit", "effects")
    assert info_jit["compiled"], info_jit["mode"]
    for col in ALL_COLUMNS:
        assert np.array_equal(plain[col], jit[col]), col
    _, off = _run(tmp_path, observer, "measured", "off")
    assert not np.array_equal(off["i_q"], jit["i_q"])  # the effects changed the run


def test_kernels_are_cached_by_content(tmp_path):
    """The compiled kernels come from a copy of kernels.py named by its hash, with a fixed time
    stamp, in PMSM_EV_CACHE_DIR: a second process loads numba's cache instead of compiling."""
    pytest.importorskip("numba")
    cache = tmp_path / "cache"
    probe = ("from pmsm_ev import accel; import json; k = accel.kernels(); "
             "print(json.dumps([accel.describe(), k.__file__]))")

    def load() -> list:
        r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=300,
                           env={**os.environ, "PMSM_EV_CACHE_DIR": str(cache)})
        assert r.returncode == 0, r.stderr[-3000:]
        return json.loads(r.stdout.strip().splitlines()[-1])

    mode, path = load()
    copy = Path(path)
    assert copy.parent == cache and copy.name.startswith("kernels_") and str(cache) in mode
    assert copy.read_bytes() == Path(kernels.__file__).read_bytes()
    compiled = {p.name: p.stat().st_mtime_ns for p in (cache / "__pycache__").iterdir()}
    assert any(name.endswith(".nbc") for name in compiled)
    assert load()[1] == path
    assert {p.name: p.stat().st_mtime_ns for p in (cache / "__pycache__").iterdir()} == compiled  # no recompiling


def test_vectors_follow_the_mode():
    v = accel.vector(3)
    if accel.compiled():
        assert isinstance(v, np.ndarray) and v.dtype == np.float64 and v.flags.c_contiguous
    else:
        assert v == [0.0, 0.0, 0.0]

