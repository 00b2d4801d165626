"""The test suite on every Python the package claims (``requires-python = ">=3.10"``).

    pip install nox
    nox                       # pytest -q on each of Python 3.10, 3.11, 3.12, 3.13 found
    nox -s tests-3.13         # one of them
    nox -- tests/test_ssp.py  # arguments after -- go to pytest
    nox -s floors             # the oldest versions pyproject.toml allows, on Python 3.10

Each session installs the package as a new user would (``pip install -e .`` and the test
extras, in a fresh virtual environment under ``.nox/``) and runs the tests. An
interpreter is looked for on PATH (``python3.X``), then among pyenv's versions; one not
found is skipped, saying so. An extra that has no wheel for an interpreter (libcosimpy) is
left out, saying so; the tests that need it are then skipped by name. The sessions share
the FMUs in the user's cache (one folder per content of the sources and pythonfmu
version, built by the first session that needs them), so an FMU built under one Python
runs in the hosts of the others.

``floors`` installs every dependency and test extra at exactly its lower bound (``>=X`` in
pyproject.toml becomes ``==X``, markers kept) on the oldest Python claimed, then the package
without dependencies, and runs the tests: each floor is a version the suite passes on.
Its pythonfmu may differ from the other sessions', so its FMUs go to a folder of their own
in the cache (the content key includes pythonfmu's version).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import nox
import tomllib
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parent
PYTHONS = ["3.10", "3.11", "3.12", "3.13"]
#: test extras an interpreter may lack a wheel for: installed if possible, else left out
OPTIONAL = ("libcosimpy",)

nox.options.sessions = ["tests"]
nox.options.error_on_missing_interpreters = False


def _pyenv_bins() -> list[str]:
    """bin/ of pyenv's versions for the PYTHONS not on PATH (newest patch release first)."""
    if shutil.which("pyenv") is None:
        return []
    root = Path(subprocess.run(["pyenv", "root"], capture_output=True, text=True, check=False).stdout.strip())
    found = []
    for version in PYTHONS:
        if shutil.which(f"python{version}") and "shims" not in shutil.which(f"python{version}"):
            continue
        candidates = sorted((root / "versions").glob(f"{version}.*/bin/python{version}"),
                            key=lambda p: [int(x) for x in re.findall(r"\d+", p.parent.parent.name)], reverse=True)
        if candidates:
            found.append(str(candidates[0].parent))
    return found


os.environ["PATH"] = os.pathsep.join(_pyenv_bins() + [os.environ.get("PATH", "")])


def _project() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]


def _test_extras() -> list[str]:
    return _project()["optional-dependencies"]["test"]


def floor_pins() -> list[str]:
    """Every dependency and test extra pinned to its lower bound: ``name==X[; marker]``.

    A requirement without a ``>=`` bound (or with another kind of bound) is refused: a floor
    that is not stated cannot be tested."""
    pins = []
    for text in _project()["dependencies"] + _test_extras():
        req = Requirement(text)
        lower = [spec.version for spec in req.specifier if spec.operator == ">="]
        if len(lower) != 1:
            raise ValueError(f"pyproject.toml: {text!r} has no single '>=' lower bound to test")
        pins.append(f"{req.name}=={lower[0]}" + (f"; {req.marker}" if req.marker else ""))
    return pins


def _install_optional(session: nox.Session, requirements: list[str]) -> None:
    """Install each of ``requirements`` if the interpreter has a wheel for it, else warn."""
    for requirement in requirements:
        try:
            session.install(requirement, silent=True)
        except nox.command.CommandFailed:
            session.warn(f"{requirement}: not installable on Python {session.python} here; "
                         f"the tests that need it are skipped")


@nox.session(python=PYTHONS)
def tests(session: nox.Session) -> None:
    extras = _test_extras()
    required = [r for r in extras if not r.startswith(OPTIONAL)]
    session.install("-e", ".", *required)
    _install_optional(session, [r for r in extras if r.startswith(OPTIONAL)])
    session.run("python", "-c", "import sys; print('Python', sys.version)")
    session.run("pytest", *(session.posargs or ["-q", "-rs"]))


@nox.session(python=PYTHONS[0])
def floors(session: nox.Session) -> None:
    """The suite with every dependency at its lower bound, on the oldest Python claimed."""
    pins = floor_pins()
    session.install(*(p for p in pins if not p.startswith(OPTIONAL)))
    _install_optional(session, [p for p in pins if p.startswith(OPTIONAL)])
    session.install("--no-deps", "-e", ".")
    session.run("python", "-m", "pip", "check")
    session.run("python", "-c", "import sys; print('Python', sys.version)")
    session.run("python", "-m", "pip", "freeze")
    session.run("pytest", *(session.posargs or ["-q", "-rs"]))
