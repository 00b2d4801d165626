"""The house's rules (docs/architecture.md), checked: import-linter's contracts in
pyproject.toml hold, and break when a forbidden import is added; the engine imports only the
standard library, numpy and fmpy (and lxml, fmpy's XML library); ruff is clean."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
ENGINE = ROOT / "orchestrator" / "pmsm_cosim" / "engine"
#: what the engine may import besides the standard library and itself (lxml: fmpy's XML library,
#: for the SSP schema check; tomllib, in the standard library from Python 3.11, and tomli, the
#: same parser as a package on Python 3.10, whose standard library names neither)
ENGINE_ALLOWED = {"numpy", "fmpy", "lxml", "tomllib", "tomli"}
#: and in its compiled stepping loop alone (engine/native.py, imported only when that loop runs): numba
#: and its LLVM binding
NATIVE_ALLOWED = {"numba", "llvmlite"}
#: the package folders, as pyproject.toml maps them to import names
PACKAGES = {"pmsm_ev": ROOT / "src" / "pmsm_ev", "pmsm_ev_fmus": ROOT / "fmus",
            "pmsm_cosim": ROOT / "orchestrator" / "pmsm_cosim"}


def lint_imports(cwd: Path, pythonpath: Path | None = None) -> subprocess.CompletedProcess:
    """import-linter with the contracts of ``cwd/pyproject.toml``, in a fresh process (the
    packages are found on ``pythonpath`` first, if given)."""
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(pythonpath), env.get("PYTHONPATH", "")])
    code = "import sys; from importlinter.cli import lint_imports; sys.exit(lint_imports(no_cache=True, no_logo=True))"
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=300)


def test_the_layering_contracts_hold():
    pytest.importorskip("importlinter")
    res = lint_imports(ROOT)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "7 kept, 0 broken" in res.stdout, res.stdout


def _copy_packages(dest: Path) -> None:
    for name, folder in PACKAGES.items():
        shutil.copytree(folder, dest / name, ignore=shutil.ignore_patterns("*.fmu", "__pycache__", ".build"))


@pytest.mark.parametrize("module,line,contract", [
    ("pmsm_cosim/engine/master.py", "from pmsm_ev.results import CONTRACT_COLUMNS",
     "the engine knows FMI and time, not this drive, Dask or matplotlib BROKEN"),
    ("pmsm_cosim/app/metrics/rows.py", "from ..report import document",
     "the figures of merit work on arrays, not on runs or reports BROKEN"),
    ("pmsm_cosim/engine/system.py", "from ..app import drive",
     "pmsm_cosim: the application on the sweeps on the engine BROKEN"),
    ("pmsm_cosim/sweeps/spec.py", "import pmsm_ev_fmus",
     "the sweeps know the engine, not this drive BROKEN"),
    ("pmsm_ev/plant.py", "import fmpy",
     "the physics imports no FMI, no co-simulation, no plotting BROKEN"),
    ("pmsm_cosim/engine/signals.py", "from . import master",
     "no import circles among the modules of any package BROKEN"),
])
def test_a_forbidden_import_breaks_a_contract(tmp_path, module, line, contract):
    """The contracts can fail: a copy of the packages with one forbidden import added."""
    pytest.importorskip("importlinter")
    _copy_packages(tmp_path / "pkgs")
    target = tmp_path / "pkgs" / module
    text = target.read_text(encoding="utf-8")
    head, sep, rest = text.partition("\nfrom __future__ import annotations\n")
    target.write_text(head + sep + line + "\n" + rest if sep else line + "\n" + text, encoding="utf-8")
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    res = lint_imports(tmp_path, pythonpath=tmp_path / "pkgs")
    assert res.returncode != 0, res.stdout
    # (and any contract that follows from it: the sweeps import the engine, so pmsm_ev too)
    assert contract in res.stdout, res.stdout


def _imports(path: Path) -> list[tuple[str, int]]:
    """(top-level name, line) of every absolute import in a module, nested ones included."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            found += [(alias.name.split(".")[0], node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            found.append(((node.module or "").split(".")[0], node.lineno))
    return found


def test_the_engine_imports_only_the_standard_library_numpy_and_fmpy():
    modules = sorted(ENGINE.glob("*.py"))
    assert {p.stem for p in modules} >= {"master", "system", "ssp", "fmu", "recording", "signals"}
    bad = [f"{p.name}:{line}: {name}" for p in modules for name, line in _imports(p)
           if name not in sys.stdlib_module_names and name not in ENGINE_ALLOWED and name != "__future__"
           and not (p.stem == "native" and name in NATIVE_ALLOWED)]
    assert not bad, bad


def test_the_relative_imports_of_the_engine_stay_inside_it():
    for path in ENGINE.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.level:
                assert node.level == 1, f"{path.name}:{node.lineno} leaves the engine"


def test_importing_the_engine_loads_no_drive_and_no_heavy_library():
    code = ("import sys, pmsm_cosim.engine, pmsm_cosim.sweeps; "
            "print(sorted(m for m in ('pmsm_ev', 'pmsm_ev_fmus', 'pmsm_cosim.app', 'matplotlib', 'distributed', "
            "'numba') if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]"


def test_ruff_is_clean():
    pytest.importorskip("ruff")
    res = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", str(ROOT)], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
