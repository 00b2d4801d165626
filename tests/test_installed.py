"""The package as a user installs it: an sdist and a wheel built from this checkout, the wheel built from the
sdist installed into a fresh virtual environment outside the checkout (not editable), and the CLI run from
there. Every other test runs on the editable install, which maps each import package to its folder and so
finds any subpackage the distribution's package list leaves out (the failure this test was written for:
``pip install .`` then ``pmsm-cosim run scenario1`` gave "No module named 'pmsm_cosim.app.metrics'")."""

import json
import os
import shutil
import site
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

import pmsm_ev

ROOT = Path(__file__).resolve().parents[1]
IMPORT_PACKAGES = ("pmsm_ev", "pmsm_ev_fmus", "pmsm_cosim")


def _run(cmd, cwd, env=None, timeout=600):
    done = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, f"{cmd} exited {done.returncode}:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done.stdout


def _source_packages() -> set[str]:
    """Every folder with an __init__.py under the three roots, as an import name: what must be installed."""
    roots = {"pmsm_ev": ROOT / "src" / "pmsm_ev", "pmsm_cosim": ROOT / "orchestrator" / "pmsm_cosim",
             "pmsm_ev_fmus": ROOT / "fmus"}
    found = set()
    for name, folder in roots.items():
        for init in folder.rglob("__init__.py"):
            rel = init.parent.relative_to(folder).parts
            if not any(part.startswith(".") or part == "__pycache__" for part in rel):
                found.add(".".join((name, *rel)))
    return found


pytestmark = pytest.mark.skipif(not (ROOT / ".git").exists(), reason="needs the checkout's git to list its files")


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(venv's bin folder, a work folder outside the checkout, the built sdist) with the package installed
    from an sdist of this checkout. The venv sees the test environment's site-packages for the dependencies
    (no download); the package itself is the venv's own (checked below)."""
    tmp = tmp_path_factory.mktemp("installed")
    # the checkout's files as a clean clone has them (tracked, or new and not ignored): no egg-info, build/ or
    # caches of this checkout's own installs, whose file lists would hide a package the configuration misses
    listed = _run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT)
    tree = tmp / "tree"
    for rel in filter(None, listed.split("\0")):
        if (ROOT / rel).is_file():
            (tree / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / rel, tree / rel)
    dist = tmp / "dist"
    # the sdist with setuptools' own backend, in this interpreter (no network)
    _run([sys.executable, "-c", f"from setuptools import build_meta; build_meta.build_sdist({str(dist)!r})"],
         cwd=tree)
    (sdist,) = dist.glob("*.tar.gz")
    venv = tmp / "venv"
    _run([sys.executable, "-m", "venv", "--system-site-packages", venv], cwd=tmp)
    bin_dir = venv / "bin"
    # where the tests run in a virtual environment, --system-site-packages gives its base interpreter's packages,
    # not its own: its site-packages as plain paths after the venv's own (a path line of a .pth file; the .pth
    # files there, the checkout's editable install among them, are not run)
    purelib = _run([bin_dir / "python", "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                   cwd=tmp).strip()
    (Path(purelib) / "test-environment.pth").write_text("".join(f"{p}\n" for p in site.getsitepackages()))
    # pip builds a wheel from the sdist (the wheel a user would get), then installs it: not editable
    _run([bin_dir / "python", "-m", "pip", "install", "--no-deps", "--no-input", "-q", sdist], cwd=tmp)
    work = tmp / "work"
    work.mkdir()
    return bin_dir, work, sdist


def test_sdist_carries_every_package_and_the_data(installed):
    _, _, sdist = installed
    with tarfile.open(sdist) as tar:
        names = {Path(*Path(n).parts[1:]).as_posix() for n in tar.getnames()}
    for package in _source_packages():
        root, *rest = package.split(".")
        folder = {"pmsm_ev": "src/pmsm_ev", "pmsm_cosim": "orchestrator/pmsm_cosim", "pmsm_ev_fmus": "fmus"}[root]
        assert "/".join([folder, *rest, "__init__.py"]) in names, package
    assert "orchestrator/pmsm_cosim/app/scenarios/scenario1.toml" in names
    assert "fmus/lean_binding.c" in names


def test_installed_not_editable_with_every_package(installed):
    bin_dir, work, _ = installed
    site = (bin_dir.parent / "lib").resolve()
    code = ("import importlib, json, sys; names = json.loads(sys.argv[1]); "
            "print(json.dumps({n: importlib.import_module(n).__file__ for n in names}))")
    files = json.loads(_run([bin_dir / "python", "-c", code, json.dumps(sorted(_source_packages()))], cwd=work))
    for name, file in files.items():
        assert Path(file).resolve().is_relative_to(site), f"{name} imported from {file}, not from the venv"


def test_installed_cli_version_build_run(installed):
    """`pmsm-cosim --version`, `build`, `run scenario1 --stop-time 1`, each from the installed package."""
    bin_dir, work, _ = installed
    cli = bin_dir / "pmsm-cosim"
    assert _run([cli, "--version"], cwd=work).split() == ["pmsm-cosim", pmsm_ev.__version__]
    env = {**os.environ, "PMSM_COSIM_FMU_DIR": str(work / "fmus")}
    built = _run([cli, "build", "PmsmEvPlant", "FocEkf5"], cwd=work, env=env)
    assert (work / "fmus" / "PmsmEvPlant.fmu").is_file() and (work / "fmus" / "FocEkf5.fmu").is_file(), built
    # the FMU carries the installed sources of the physics
    with zipfile.ZipFile(work / "fmus" / "PmsmEvPlant.fmu") as z:
        assert any(n.startswith("resources/pmsm_ev_") and n.endswith("/plant.py") for n in z.namelist())
    out = _run([cli, "run", "scenario1", "--stop-time", "1", "--out", work / "run"], cwd=work, env=env)
    assert "completed: 10000 steps" in out
    rows = (work / "run" / "results.csv").read_text().splitlines()
    assert len(rows) == 102  # a header and 101 rows every 10 ms over 0..1 s
    assert (work / "run" / "metrics.json").is_file()
