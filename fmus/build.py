"""Build the project's FMUs with pythonfmu: ``build_all`` and the CLI ``main``.

Each FMU is self-contained: its ``resources/`` holds the slave script, the ``fmus``
modules it imports and a copy of the ``pmsm_ev`` package, all renamed with an 8-hex
content hash (``pmsm_ev_<hash>``, ``pmsm_ev_fmus_<module>_<hash>``), so that

* it runs with a Python interpreter that has numpy but not this project, and
* FMUs of different builds, and the installed project, share one interpreter (one
  ``sys.modules``) without colliding.

The hash covers everything that goes into the FMU and runs there: the slave script, the
``fmus`` modules it imports (``metadata.py``, ``slave_support.py``, ...), the ``pmsm_ev``
modules and subpackages it needs, this build module and the pythonfmu version (not the
documentation folder, a copy of ``README.md`` that computes nothing), and the files of the
``data/`` folder of every bundled ``pmsm_ev`` subpackage (``pmsm_ev.cycles``: the shipped cycles
and road profiles, read with ``importlib.resources``). It is stored in
``resources/build_info.json``; ``build_all`` rebuilds an FMU only when the hash differs (or
``force``). The modelDescription is written by the slaves themselves
(``slave_support.DriveSlave.to_xml``: units, dependencies, InitialUnknowns); the build
validates every FMU with ``fmpy.validation`` before it replaces the old file.

Where the FMUs go by default (:func:`default_out_dir`): ``$PMSM_COSIM_FMU_DIR`` if set, else
a folder of the user's cache named by the content key of all the FMUs (:func:`content_key`),
``<user cache>/pmsm-ev-cosim/fmus/<key>/`` (:func:`user_cache_dir`: ``$XDG_CACHE_HOME`` or
``~/.cache`` on Linux, ``~/Library/Caches`` on macOS, ``%LOCALAPPDATA%`` on Windows): never
into the installed package (site-packages may not be writable, and is shared by every
user of an installation). A change of any bundled source gives a new folder; FMUs of the
same sources are found again by every later process. An FMU is built in a staging folder
beside its target and moved into place with one ``os.replace``, so builds that run at the
same time (pytest or Dask workers) never see or leave a half-written file.

Usage::

    python -m pmsm_ev_fmus [--out DIR] [--force] [NAME ...]
"""

from __future__ import annotations

import argparse
import ast
import functools
import hashlib
import html
import importlib
import json
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import fmpy
import pythonfmu
from fmpy.validation import validate_fmu
from pythonfmu import FmuBuilder

from pmsm_ev.cycles import load_road
from pmsm_ev.params import DT_DEFAULT
from pmsm_ev.scenarios import route_from_json, route_to_json, scenario_route

from .slave_support import BINDING_CONSTANTS, START_VALUES_FILE, WRAPPER_CHECKED, version_tuple

HERE = Path(__file__).resolve().parent
BUILD_INFO = "build_info.json"
PROJECT_MODULE_PREFIX = "pmsm_ev_fmus"
PHYSICS_PACKAGE = "pmsm_ev"

#: FMU name -> (slave script in this package, can handle a variable communication step size)
FMUS: dict[str, tuple[str, bool]] = {
    "PmsmEvPlant": ("pmsm_ev_plant.py", True),
    "FocEkf5": ("foc_ekf5.py", True),
    "FocEkf4": ("foc_ekf4.py", True),
    "FocEkf5AB": ("foc_ekf5ab.py", True),
    "FocSensored": ("foc_sensored.py", True),
    "FocSensorless": ("foc_sensorless.py", True),
    "RouteProfile": ("route_profile.py", True),
}
#: FMUs for the step-cost benchmark (``pmsm_cosim.app.bench``), not built by default: the
#: interface of PmsmEvPlant and FocEkf5 with a ``do_step`` that computes nothing
BENCH_FMUS: dict[str, tuple[str, bool]] = {
    "PassThroughPlant": ("passthrough_plant.py", True),
    "PassThroughFoc": ("passthrough_foc.py", True),
}
#: observer of each controller FMU (pmsm_ev.params.OBSERVERS)
OBSERVER_FMUS = {"ekf5": "FocEkf5", "ekf4": "FocEkf4", "ekf5ab": "FocEkf5AB", "sensored": "FocSensored",
                 "sensorless": "FocSensorless"}
#: the FMU of the scenario signals, and the route file it reads by default (resources/)
ROUTE_FMU = "RouteProfile"
ROUTE_FILE = "route.json"
#: the route RouteProfile.fmu is built with
DEFAULT_ROUTE = "scenario1"


class BuildError(RuntimeError):
    """An FMU cannot be built."""


#: the lean binding (fmus/README.md, "The lean binding"): its C source, the name pythonfmu's own library takes
#: beside it in binaries/linux64/, and the environment variable that chooses the binding of the FMUs built
#: ("lean", the default, or "pythonfmu": pythonfmu's library alone)
LEAN_SOURCE = HERE / "lean_binding.c"
INNER_LIBRARY = "pythonfmu-export.so"
ENV_BINDING = "PMSM_EV_FMU_BINDING"
BINDINGS = ("lean", "pythonfmu")
#: the FMU's loader (fmus/README.md, "Hosts that are not Python"): its C source, and the name the lean binding
#: takes behind it in binaries/linux64/ (the loader is binaries/linux64/<model>.so)
LOADER_SOURCE = HERE / "fmu_loader.c"
#: the FMI 2.0 types both C libraries include (beside them: found by ``#include "..."`` from their folder)
C_HEADER = HERE / "fmi2_binding.h"
#: the instance table the lean binding and the FMI 3.0 layer include (instance_table.h)
INSTANCE_TABLE = HERE / "instance_table.h"
#: own_directory, which the loader and the FMI 3.0 layer include (own_directory.h)
OWN_DIRECTORY = HERE / "own_directory.h"
#: the project's headers every compiled library's key covers (a change in one rebuilds them and the FMUs)
SHARED_HEADERS = (C_HEADER, INSTANCE_TABLE, OWN_DIRECTORY)
BINDING_LIBRARY = "pmsm-binding.so"
#: resources/ file naming the interpreter the FMU was built with (the loader's third choice of a Python)
BUILT_PYTHON_FILE = "build_python.txt"


def binding_requested() -> str:
    """The binding the FMUs are built with: ``$PMSM_EV_FMU_BINDING`` ("lean" by default, or "pythonfmu");
    "pythonfmu" where the lean one does not exist (not Linux on x86-64)."""
    choice = os.environ.get(ENV_BINDING, "lean").strip() or "lean"
    if choice not in BINDINGS:
        raise BuildError(f"{ENV_BINDING}={choice!r}: choose one of {', '.join(BINDINGS)}")
    if choice == "lean" and not (sys.platform.startswith("linux") and platform.machine() in ("x86_64", "AMD64")):
        return "pythonfmu"
    return choice


#: extra compiler flags for the FMUs' C libraries (the lean binding, the loader and the FMI 3.0 layer: every library
#: ``_compiled`` makes), e.g. the sanitizers' ``-fsanitize=address,undefined`` (tests/sanitizer_support.py); part of
#: their cache key, of the FMUs' content key and of the FMI 3.0 units' hash
ENV_CFLAGS = "PMSM_EV_BINDING_CFLAGS"


def extra_cflags() -> list[str]:
    """The flags of ``$PMSM_EV_BINDING_CFLAGS`` (shell words)."""
    return shlex.split(os.environ.get(ENV_CFLAGS, ""))


def _compiled(source_path: Path, prefix: str, python_headers: bool, defines: dict[str, str] | None = None,
              headers: tuple[Path, ...] = ()) -> tuple[Path | None, str]:
    """``source_path`` compiled into a shared library (``cc``, or ``$CC``; no libpython linked), with ``defines``
    as ``-D`` definitions and the folders of ``headers`` on the include path, kept in the user's cache
    (``user_cache_dir()/binding/``) under the hash of its source, of ``SHARED_HEADERS`` and ``headers``, of the
    definitions (and of the Python headers, if it uses them): (path, "") or (None, why it cannot be built)."""
    flags = [f"-D{name}={value}" for name, value in (defines or {}).items()] + extra_cflags()
    flags += [f"-I{folder}" for folder in dict.fromkeys(str(h.parent) for h in headers)]
    # the headers it includes change it too
    source = source_path.read_bytes() + b"".join(h.read_bytes() for h in (*SHARED_HEADERS, *headers))
    include = sysconfig.get_paths()["include"] if python_headers else ""
    key = hashlib.sha256(source + include.encode() + " ".join(flags).encode()).hexdigest()[:16]
    folder = user_cache_dir() / "binding"
    target = folder / f"{prefix}-{key}.so"
    if target.is_file():
        return target, ""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{prefix}-", suffix=".so", dir=folder)
        os.close(fd)
    except OSError as exc:
        return None, f"cannot write {folder} ({exc.strerror or exc})"
    command = [os.environ.get("CC", "cc"), "-O2", "-shared", "-fPIC", "-fvisibility=hidden", "-Wall", *flags,
               *([f"-I{include}"] if include else []), str(source_path), "-o", tmp, "-ldl", "-lpthread"]
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=120)
        if done.returncode != 0:
            lines = (done.stderr or done.stdout).strip().splitlines()
            return None, f"{command[0]} failed: {lines[0] if lines else 'exit ' + str(done.returncode)}"
        os.replace(tmp, target)
        return target, ""
    except (OSError, subprocess.SubprocessError) as exc:
        return None, f"no C compiler ({command[0]}: {exc})"
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def lean_library() -> tuple[Path | None, str]:
    """The lean binding compiled for this Python (the limited API, no libpython linked), kept in the user's
    cache under the hash of its source and of the Python headers: (path, "") or (None, why it cannot be built)."""
    return _compiled(LEAN_SOURCE, "lean", True, BINDING_CONSTANTS)


def loader_library() -> tuple[Path | None, str]:
    """The FMU's loader compiled (no Python headers, no Python symbol), kept in the user's cache under the hash of
    its source: (path, "") or (None, why it cannot be built)."""
    return _compiled(LOADER_SOURCE, "loader", False)


#: the FMI 3.0 layer (fmus/README.md, "FMI 3.0"): its C source, the FMI 3.0 headers it is compiled against (FMPy's
#: copy of the standard's, fmpy/c-code/), the file name the FMU's FMI 2.0 loader takes beside it in
#: binaries/x86_64-linux/ (the layer is binaries/x86_64-linux/<model>.so), the platform folder, and the folder of the
#: FMI 3.0 units inside the folder of the FMI 2.0 ones
FMI3_SOURCE = HERE / "fmi3_layer.c"
FMI3_HEADER_NAMES = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")
FMI3_INNER_LOADER = "pmsm-fmi2.so"
FMI3_PLATFORM = "x86_64-linux"
FMI3_FOLDER = "fmi3"
#: the value reference of the independent variable ``time`` of the FMI 3.0 units (FMI 3.0 requires one; the FMI 3.0
#: layer answers it): the largest Int32, far beyond pythonfmu's value references (0, 1, ... in declaration order)
FMI3_TIME_REFERENCE = 2**31 - 1
#: the FMI versions the build makes units of
FMI_VERSIONS = (2, 3)
#: the controllers' sample clock in their FMI 3.0 units (fmus/README.md, "FMI 3.0", "The sample clock"): a periodic
#: input Clock of this name and value reference, its interval the controllers' sample period (``DT_DEFAULT``, what
#: ``dt`` = 0 samples at in the shipped scenarios), described to the FMI 3.0 layer by ``resources/FMI3_CLOCK_FILE``
FMI3_CLOCK_NAME = "sample"
FMI3_CLOCK_REFERENCE = FMI3_TIME_REFERENCE - 1
FMI3_CLOCK_FILE = "fmi3_clock.txt"
FMI3_SAMPLE_PERIOD = DT_DEFAULT


def fmi3_headers() -> tuple[Path, ...]:
    """The FMI 3.0 headers (fmi3Functions.h and the two it includes) shipped with FMPy."""
    folder = Path(fmpy.__file__).resolve().parent / "c-code"
    return tuple(folder / name for name in FMI3_HEADER_NAMES)


def fmi3_layer_library() -> tuple[Path | None, str]:
    """The FMI 3.0 layer compiled (no Python headers, no Python symbol), kept in the user's cache under the hash of
    its source and of the FMI 3.0 headers: (path, "") or (None, why it cannot be built)."""
    headers = fmi3_headers()
    missing = [str(h) for h in headers if not h.is_file()]
    if missing:
        return None, f"no FMI 3.0 header {missing[0]} (FMPy's c-code/)"
    defines = {"FMI2_LOADER": f'"{FMI3_INNER_LOADER}"', "TIME_REFERENCE": f"{FMI3_TIME_REFERENCE}U",
               "CLOCK_FILE": f'"{FMI3_CLOCK_FILE}"', "CONTINUITY_TOLERANCE": BINDING_CONSTANTS["CONTINUITY_TOLERANCE"]}
    return _compiled(FMI3_SOURCE, "fmi3", False, defines, headers)


def _bind(fmu: Path, name: str, library: Path, loader: Path) -> None:
    """Put the loader and the lean binding ``library`` in front of pythonfmu's in ``fmu``: the loader takes
    pythonfmu's ``binaries/linux64/<name>.so``, the binding is ``binaries/linux64/pmsm-binding.so`` and pythonfmu's
    library ``binaries/linux64/pythonfmu-export.so``."""
    member, inner = f"binaries/linux64/{name}.so", f"binaries/linux64/{INNER_LIBRARY}"

    def change(names):
        if member not in names:
            raise BuildError(f"{fmu}: pythonfmu wrote no {member}")
        with zipfile.ZipFile(fmu) as z:
            return {member: loader.read_bytes(), f"binaries/linux64/{BINDING_LIBRARY}": library.read_bytes(),
                    inner: z.read(member)}

    _copy_fmu(fmu, fmu, change)


#: the environment variable that names the folder of the project's FMUs (overrides the cache)
ENV_FMU_DIR = "PMSM_COSIM_FMU_DIR"
#: the project's folder in the user's cache
CACHE_NAME = "pmsm-ev-cosim"


def user_cache_dir() -> Path:
    """The project's folder in the user's cache: ``$XDG_CACHE_HOME/pmsm-ev-cosim`` (default
    ``~/.cache``) on Linux and other POSIX systems, ``~/Library/Caches/pmsm-ev-cosim`` on
    macOS, ``%LOCALAPPDATA%\\pmsm-ev-cosim`` on Windows (``$XDG_CACHE_HOME`` wins when set)."""
    xdg = os.environ.get("XDG_CACHE_HOME")
    if xdg:
        base = Path(xdg).expanduser()
    elif sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path.home() / ".cache"
    return base / CACHE_NAME


def default_out_dir() -> Path:
    """Where FMUs go by default: ``$PMSM_COSIM_FMU_DIR`` if set, else
    ``user_cache_dir()/fmus/<content_key()>`` (see the module doc)."""
    env = os.environ.get(ENV_FMU_DIR)
    if env:
        return Path(env).expanduser()
    return user_cache_dir() / "fmus" / content_key()


def physics_dir() -> Path:
    """Directory of the ``pmsm_ev`` package (editable or regular install)."""
    return Path(importlib.import_module(PHYSICS_PACKAGE).__file__).resolve().parent


def _pythonfmu_version() -> str:
    return pythonfmu.__version__


def check_pythonfmu(version: str | None = None) -> None:
    """Refuse a pythonfmu other than the versions the FMUs are checked against (``WRAPPER_CHECKED``, the
    range pyproject.toml allows): the lean binding and the slaves' lifetime code rely on its C++ wrapper's
    behaviour (its log queue, its fmi2DoStep, what it releases), which another version may change."""
    version = version or _pythonfmu_version()
    low, high = WRAPPER_CHECKED
    if not version_tuple(low) <= version_tuple(version) <= version_tuple(high):
        raise BuildError(f"pythonfmu {version} is not a version the FMUs are checked against ({low} to {high}: "
                         f"the lean binding and the slaves rely on its wrapper); install one, e.g. "
                         f"pip install 'pythonfmu=={high}'")


# -- sources and their hash ------------------------------------------------------------
@functools.lru_cache(maxsize=256)
def _import_nodes(source: str, where: str) -> tuple:
    """The ``import`` and ``from ... import`` statements of a module's source, in ``ast.walk``'s order: every
    run checks that its FMUs are up to date, and the FMUs share most of their files, so each text is parsed
    and walked once a process (the text is the key: a file that changes is parsed again)."""
    return tuple(node for node in ast.walk(ast.parse(source, where))
                 if isinstance(node, (ast.Import, ast.ImportFrom)))


def _project_imports(source: str, where: str) -> list[str]:
    """Modules of the project imported by ``source`` (only ``from X import ...`` allowed)."""
    found = []
    for node in _import_nodes(source, where):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] in (PHYSICS_PACKAGE, PROJECT_MODULE_PREFIX):
                    raise BuildError(f"{where}: write 'from {alias.name} import ...' so the build can "
                                     f"rename it (line {node.lineno})")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                raise BuildError(f"{where}: relative import on line {node.lineno}; the slave modules "
                                 f"become top-level modules in the FMU")
            root = (node.module or "").split(".")[0]
            if root in (PHYSICS_PACKAGE, PROJECT_MODULE_PREFIX):
                found.append(node.module)
    return found


def _fmus_modules(script: str) -> list[str]:
    """The slave script and the modules of this package it needs, recursively (file names)."""
    order, todo = [], [script]
    while todo:
        name = todo.pop()
        if name in order:
            continue
        path = HERE / name
        if not path.is_file():
            raise BuildError(f"missing module {path}")
        order.append(name)
        for module in _project_imports(path.read_text(encoding="utf-8"), str(path)):
            if module.startswith(PROJECT_MODULE_PREFIX + "."):
                todo.append(module.split(".", 1)[1].replace(".", "/") + ".py")
            elif module == PROJECT_MODULE_PREFIX:
                raise BuildError(f"{path}: import from a module of {PROJECT_MODULE_PREFIX}, not the package")
    return order


def _module_file(root: Path, dotted: str) -> Path | None:
    """The file of the module ``dotted`` of the package in ``root`` ("" is the package):
    ``root/a/b.py`` or ``root/a/b/__init__.py``, or None."""
    parts = [p for p in dotted.split(".") if p]
    base = root.joinpath(*parts)
    for path in ((base.parent / f"{base.name}.py") if parts else None, base / "__init__.py"):
        if path is not None and path.is_file():
            return path
    return None


def _physics_files(script: str) -> list[Path]:
    """The ``pmsm_ev`` files the slave needs, relative to the package folder: the modules
    the ``fmus`` modules import and, recursively, their relative imports, with the
    ``__init__.py`` of every package on the way. A module may be a single file
    (``plant.py``) or a package folder (``kernels/__init__.py`` and its modules)."""
    root = physics_dir()
    todo = [""]  # the package itself (its __init__.py)

    def wanted(dotted: str, names, where: str) -> None:
        if _module_file(root, dotted) is None:
            raise BuildError(f"{where}: missing module {root / dotted.replace('.', '/')}(.py)")
        todo.append(dotted)
        for name in names:  # ``from .pkg import mod``: a submodule if there is one
            if _module_file(root, f"{dotted}.{name}".strip(".")) is not None:
                todo.append(f"{dotted}.{name}".strip("."))

    for module in _fmus_modules(script):
        for node in _import_nodes((HERE / module).read_text(encoding="utf-8"), module):
            if isinstance(node, ast.ImportFrom) and not node.level and node.module:
                head, _, rest = node.module.partition(".")
                if head == PHYSICS_PACKAGE:
                    wanted(rest, [a.name for a in node.names], f"{HERE / module}:{node.lineno}")
    seen: dict[str, Path] = {}
    while todo:
        dotted = todo.pop()
        if dotted in seen:
            continue
        path = _module_file(root, dotted)
        if path is None:
            raise BuildError(f"missing module {root / dotted.replace('.', '/')}(.py)")
        seen[dotted] = path
        parts = dotted.split(".") if dotted else []
        if parts:
            todo.append(".".join(parts[:-1]))  # the enclosing package's __init__.py
        package = parts if path.name == "__init__.py" else parts[:-1]
        for node in _import_nodes(path.read_text(encoding="utf-8"), str(path)):
            if isinstance(node, ast.ImportFrom) and node.level:
                if node.level - 1 > len(package):
                    raise BuildError(f"{path}:{node.lineno}: import from outside the package")
                base = package[:len(package) - (node.level - 1)]
                target = ".".join(base + (node.module.split(".") if node.module else []))
                wanted(target, [a.name for a in node.names], f"{path}:{node.lineno}")
    data = []  # a bundled package's data/ folder travels with it (pmsm_ev.cycles: the shipped cycles and roads)
    for dotted, path in seen.items():
        folder = path.parent / "data" if path.name == "__init__.py" else None
        if folder is not None and folder.is_dir():
            data += [p for p in folder.rglob("*") if p.is_file() and "__pycache__" not in p.parts]
    return sorted(path.relative_to(root) for path in [*seen.values(), *data])


def _recipe(name: str) -> tuple[str, bool]:
    """(slave script, variable step size) of a project or benchmark FMU."""
    if name in FMUS:
        return FMUS[name]
    if name in BENCH_FMUS:
        return BENCH_FMUS[name]
    raise BuildError(f"unknown FMU {name!r}; choose from {', '.join(FMUS)}")


def source_hash(name: str) -> str:
    """SHA-256 over everything an FMU is made of (see the module doc)."""
    script, variable_step = _recipe(name)
    h = hashlib.sha256()

    def add(label: str, data: bytes) -> None:
        h.update(f"{label}\0{len(data)}\0".encode())
        h.update(data)

    add("format", b"pmsm-ev-fmus 1")
    add("fmu", f"{name} {script} {variable_step}".encode())
    add("pythonfmu", _pythonfmu_version().encode())
    add("build.py", Path(__file__).read_bytes())
    binding = binding_requested()
    add("binding", binding.encode())
    if binding == "lean":
        add("lean_binding.c", LEAN_SOURCE.read_bytes())
        add("fmu_loader.c", LOADER_SOURCE.read_bytes())
        for header in SHARED_HEADERS:
            add(header.name, header.read_bytes())
        add("cflags", " ".join(extra_cflags()).encode())
    for module in sorted(_fmus_modules(script)):
        add(f"fmus/{module}", (HERE / module).read_bytes())
    root = physics_dir()
    for rel in _physics_files(script):
        add(f"pmsm_ev/{rel.as_posix()}", (root / rel).read_bytes())
    return h.hexdigest()


_content_keys: dict[tuple, str] = {}


def _source_signature() -> tuple:
    """What the hashes depend on, cheaply: the path, size and modification time of every
    ``.py`` file of this package and of ``pmsm_ev``, and the pythonfmu version."""
    files = []
    for root in (HERE, physics_dir()):
        for path in sorted({*root.rglob("*.py"), *(p for p in root.rglob("*") if p.parent.name == "data")}):
            if ".build" in path.relative_to(root).parts:
                continue  # a build's staging folder (FMUs built into this folder with --out)
            try:
                st = path.stat()
            except OSError:
                continue
            files.append((str(path), st.st_size, st.st_mtime_ns))
    for source in (LEAN_SOURCE, LOADER_SOURCE, *SHARED_HEADERS):
        st = source.stat()
        files.append((str(source), st.st_size, st.st_mtime_ns))
    return (_pythonfmu_version(), os.environ.get(ENV_BINDING, ""), os.environ.get(ENV_CFLAGS, ""), tuple(files))


def content_key() -> str:
    """A 16-hex key of the content of all the project's FMUs (``FMUS``): a SHA-256 over
    their :func:`source_hash` es. The folder of the user's cache the FMUs are built into is
    named by it. Computed once per state of the sources in a process."""
    signature = _source_signature()
    if signature not in _content_keys:
        # the key of these sources, as a process before found it (hashing every source of the 7 FMUs takes
        # seconds): a file named by a hash of the signature in the user's cache, written atomically
        seen = user_cache_dir() / "fmus" / "keys" / hashlib.sha256(repr(signature).encode()).hexdigest()[:32]
        try:
            key = seen.read_text(encoding="ascii").strip()
        except OSError:
            key = ""
        if not re.fullmatch(r"[0-9a-f]{16}", key):
            h = hashlib.sha256()
            for name in sorted(FMUS):
                h.update(f"{name}\0{source_hash(name)}\0".encode())
            key = h.hexdigest()[:16]
            _remember(seen, key)
        _content_keys.clear()
        _content_keys[signature] = key
    return _content_keys[signature]


def _remember(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically; nothing if the folder cannot be written."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".key-", dir=path.parent)
        with os.fdopen(fd, "w", encoding="ascii") as f:
            f.write(text + "\n")
        os.replace(tmp, path)
    except OSError:
        pass


def _bundled_module(module: str, tag: str) -> str:
    root, _, rest = module.partition(".")
    if root == PHYSICS_PACKAGE:
        return f"{PHYSICS_PACKAGE}_{tag}" + (f".{rest}" if rest else "")
    if root == PROJECT_MODULE_PREFIX:
        return f"{PROJECT_MODULE_PREFIX}_{rest.replace('.', '_')}_{tag}"
    return module


def rewrite_imports(source: str, tag: str, where: str = "<slave>") -> str:
    """``from pmsm_ev.x import`` -> ``from pmsm_ev_<tag>.x import``, and
    ``from pmsm_ev_fmus.m import`` -> ``from pmsm_ev_fmus_m_<tag> import``; nothing else."""
    lines = source.splitlines(keepends=True)
    for node in ast.walk(ast.parse(source, where)):
        if isinstance(node, ast.ImportFrom) and not node.level and node.module:
            new = _bundled_module(node.module, tag)
            if new == node.module:
                continue
            pattern = re.compile(r"^(\s*from\s+)" + re.escape(node.module) + r"(\s+import\b)")
            line = lines[node.lineno - 1]
            if not pattern.search(line):
                raise BuildError(f"{where}:{node.lineno}: cannot rewrite the import of {node.module}")
            lines[node.lineno - 1] = pattern.sub(lambda m: m.group(1) + new + m.group(2), line, count=1)
    rewritten = "".join(lines)
    for module in _project_imports(rewritten, where):
        raise BuildError(f"{where}: import of {module} left unrenamed")
    return rewritten


# -- building ------------------------------------------------------------------------
def read_build_info(fmu: Path) -> dict | None:
    """``resources/build_info.json`` of a built FMU, or None."""
    try:
        with zipfile.ZipFile(fmu) as zf:
            return json.loads(zf.read(f"resources/{BUILD_INFO}").decode("utf-8"))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return None


def is_up_to_date(name: str, out_dir=None) -> bool:
    fmu = Path(out_dir or default_out_dir()) / f"{name}.fmu"
    info = read_build_info(fmu) if fmu.is_file() else None
    return info is not None and info.get("hash") == source_hash(name)


def _stage(name: str, digest: str, stage: Path, binding: str = "pythonfmu") -> tuple[Path, list[Path], Path]:
    """Write the renamed sources into ``stage``; return (script, project files, doc dir)."""
    script, variable_step = _recipe(name)
    tag = digest[:8]
    physics = stage / f"{PHYSICS_PACKAGE}_{tag}"
    physics.mkdir()
    files: dict[str, str] = {}
    root = physics_dir()
    for rel in _physics_files(script):  # relative imports inside the package: a verbatim copy
        (physics / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(root / rel, physics / rel)
        files[f"{physics.name}/{rel.as_posix()}"] = hashlib.sha256((root / rel).read_bytes()).hexdigest()
    project_files: list[Path] = [physics]
    staged_script = None
    for module in _fmus_modules(script):
        source = (HERE / module).read_text(encoding="utf-8")
        bundled = _bundled_module(f"{PROJECT_MODULE_PREFIX}.{module[:-3]}", tag)
        target = stage / f"{bundled}.py"
        target.write_text(rewrite_imports(source, tag, str(HERE / module)), encoding="utf-8")
        files[target.name] = hashlib.sha256(target.read_bytes()).hexdigest()
        if module == script:
            staged_script = target
        else:
            project_files.append(target)
    info = {
        "fmu": name,
        "hash": digest,
        "tag": tag,
        "slave_module": staged_script.stem,
        "physics_package": physics.name,
        "project_version": importlib.import_module(PHYSICS_PACKAGE).__version__,
        "pythonfmu": _pythonfmu_version(),
        "binding": binding,
        "python_built_with": sys.version.split()[0],
        "start_values": START_VALUES_FILE,
        "files_sha256": files,
    }
    if name == ROUTE_FMU:
        route = stage / ROUTE_FILE
        route.write_text(route_to_json(scenario_route(DEFAULT_ROUTE), DEFAULT_ROUTE), encoding="utf-8")
        project_files.append(route)
    built_python = stage / BUILT_PYTHON_FILE  # the loader's third choice of a Python (fmus/fmu_loader.c)
    built_python.write_text(f"{sys.executable}\n", encoding="utf-8")
    project_files.append(built_python)
    info_path = stage / BUILD_INFO
    info_path.write_text(json.dumps(info, indent=2) + "\n", encoding="utf-8")
    project_files.append(info_path)
    doc = stage / "documentation"
    doc.mkdir()
    readme = HERE / "README.md"
    if readme.is_file():
        text = readme.read_text(encoding="utf-8")
        (doc / "README.md").write_text(text, encoding="utf-8")
        (doc / "index.html").write_text(
            f"<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{name}</title></head>"
            f"<body><pre>{html.escape(text)}</pre></body></html>\n", encoding="utf-8")
    return staged_script, project_files, doc


def build_fmu(name: str, out_dir=None, force: bool = False) -> tuple[Path, bool]:
    """Build one FMU (of ``FMUS`` or ``BENCH_FMUS``) into ``out_dir``; return (path, whether
    it was (re)built)."""
    _recipe(name)
    check_pythonfmu()
    out = Path(out_dir or default_out_dir())
    out.mkdir(parents=True, exist_ok=True)
    target = out / f"{name}.fmu"
    digest = source_hash(name)
    if not force and target.is_file() and (read_build_info(target) or {}).get("hash") == digest:
        return target, False

    # A loaded pythonfmu FMU puts its resources/ (a copy of pythonfmu without the
    # builder's binaries) on sys.path; building with that copy gives FMUs without binaries.
    if not (Path(pythonfmu.__file__).parent / "resources" / "binaries").is_dir():
        raise BuildError(f"pythonfmu imported from {Path(pythonfmu.__file__).parent} has no binaries "
                         "(an FMU's bundled copy?): build FMUs before loading any in this process")

    library, why = lean_library() if binding_requested() == "lean" else (None, "")
    loader = None
    if library is not None:
        loader, why = loader_library()
        library = library if loader is not None else None
    if why:
        print(f"warning: {name}.fmu gets pythonfmu's binding, not the lean one: {why}", file=sys.stderr)
    stage = _make_stage(out, name)
    saved_path, saved_modules = list(sys.path), set(sys.modules)
    try:
        script, project_files, doc = _stage(name, digest, stage, "lean" if library else "pythonfmu")
        built = FmuBuilder.build_FMU(
            script, dest=stage / f"{name}.fmu", project_files=project_files, documentation_folder=doc,
            canGetAndSetFMUstate=True, canSerializeFMUstate=True,
            canHandleVariableCommunicationStepSize=_recipe(name)[1])
        if library is not None:
            _bind(built, name, library, loader)
        _check(built, name)
        os.replace(built, target)
    finally:
        # pythonfmu imports the staged modules and puts the stage on sys.path: undo both
        sys.path[:] = saved_path
        tag = digest[:8]
        for module in set(sys.modules) - saved_modules:
            if module.endswith(f"_{tag}") or f"_{tag}." in module:
                del sys.modules[module]
        _drop_stage(out, stage)
    return target, True


def _make_stage(out: Path, name: str) -> Path:
    """A fresh staging directory in ``out/.build`` (same file system as the target)."""
    for _ in range(5):  # another build may remove .build between mkdir and mkdtemp
        (out / ".build").mkdir(exist_ok=True)
        try:
            return Path(tempfile.mkdtemp(prefix=f"{name}-", dir=out / ".build"))
        except FileNotFoundError:
            continue
    raise BuildError(f"cannot create a staging directory in {out / '.build'}")


def _drop_stage(out: Path, stage: Path) -> None:
    """Remove a build's staging folder (``_make_stage``) and ``out/.build`` where no other build uses it."""
    shutil.rmtree(stage, ignore_errors=True)
    try:
        (out / ".build").rmdir()
    except OSError:
        pass  # another build is using it


def _check(fmu: Path, name: str) -> None:
    problems = validate_fmu(str(fmu))
    if problems:
        raise BuildError(f"{name}.fmu does not validate: " + "; ".join(problems))


def _copy_fmu(source: Path, dest: Path, change) -> Path:
    """Write a copy of the FMU ``source`` to ``dest``; ``change(names)`` gives {member:
    new bytes} (members not in ``names`` are added)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}-", suffix=".tmp", dir=dest.parent)
    os.close(fd)
    try:
        with zipfile.ZipFile(source) as zin, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zout:
            changed = change(zin.namelist())
            for item in zin.infolist():
                zout.writestr(item, changed.pop(item.filename) if item.filename in changed else zin.read(item))
            for name, data in changed.items():
                zout.writestr(name, data)
        os.replace(tmp, dest)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return dest


def write_route_fmu(route_json: str, dest, source=None) -> Path:
    """A copy of RouteProfile.fmu (``source``, default: the one in ``default_out_dir()``,
    built if needed) whose default route, ``resources/route.json``, is ``route_json`` (the
    text of ``pmsm_ev.scenarios.route_to_json``): the route chosen when the FMU is
    packaged. The model description is unchanged."""
    route_from_json(route_json, "route")  # refuse a malformed route here, not in the FMU
    source = Path(source) if source is not None else build_fmu(ROUTE_FMU)[0]
    target = f"resources/{ROUTE_FILE}"

    def change(names):
        if target not in names:
            raise BuildError(f"{source}: not a RouteProfile FMU (no {target})")
        return {target: route_json.encode("utf-8")}

    return _copy_fmu(source, Path(dest), change)


def write_road_fmu(road_file, dest, source=None) -> Path:
    """A copy of RouteProfile.fmu (``source``, default: the one in ``default_out_dir()``, built if
    needed) with the road profile file ``road_file`` (CSV, ``pmsm_ev.cycles.load_road``) as
    ``resources/<its name>``, for the position mode (parameter ``road`` = its name). The file is
    checked first (a ``CycleError`` naming file, row and problem); the model description is unchanged."""
    road_file = Path(road_file)
    load_road(road_file)  # refuse a malformed road here, not in the FMU
    source = Path(source) if source is not None else build_fmu(ROUTE_FMU)[0]
    target = f"resources/{road_file.name}"

    def change(names):
        if f"resources/{ROUTE_FILE}" not in names:
            raise BuildError(f"{source}: not a RouteProfile FMU (no resources/{ROUTE_FILE})")
        if target in names:
            raise BuildError(f"{source}: resources/ already has a file {road_file.name!r}; rename the road file")
        return {target: road_file.read_bytes()}

    return _copy_fmu(source, Path(dest), change)


def takes_packaged_starts(fmu) -> bool:
    """Whether ``fmu`` is one of this project's FMUs that reads its parameter defaults
    from ``resources/start_values.json`` (``write_fmu_with_starts``)."""
    return (read_build_info(Path(fmu)) or {}).get("start_values") == START_VALUES_FILE


def _start_text(value) -> str:
    """A start value as the model description writes it (``true``/``false``, ``repr`` of a float)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(float(value)) if isinstance(value, float) else str(value)


def with_parameter_starts(model_description: bytes, values: dict, where: str = "modelDescription.xml") -> bytes:
    """``model_description`` (the bytes of a modelDescription.xml) with the ``start``
    attribute of each parameter in ``values`` (name -> value) set to it (FMI 2.0 or 3.0); everything else
    (elements, attributes and their order, comments) as it was. Parsed and written as XML
    (``xml.etree.ElementTree``), UTF-8 with an XML declaration."""
    try:
        root = ET.fromstring(model_description, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    except ET.ParseError as exc:
        raise BuildError(f"{where}: modelDescription.xml is not valid XML ({exc})") from None
    fmi3 = str(root.get("fmiVersion", "")).startswith("3")
    if fmi3:  # FMI 3.0: <Float64 name=... start=...>, <String name=...><Start value=.../></String>
        listed = root.find("ModelVariables")
        variables = {v.get("name"): v for v in (listed if listed is not None else ())}
    else:
        variables = {v.get("name"): v for v in root.iter("ScalarVariable")}
    for name, value in values.items():
        var = variables.get(name)
        if var is not None and fmi3:
            typed, key = (var.find("Start"), "value") if var.tag == "String" else (var, "start")
            typed = typed if typed is not None and key in typed.attrib else None
        else:
            key = "start"
            typed = None if var is None else next(
                (e for e in var if e.tag in ("Real", "Integer", "Boolean", "String") and "start" in e.attrib), None)
        if var is None or var.get("causality") != "parameter" or typed is None:
            raise BuildError(f"{where}: no parameter {name!r} with a start value")
        typed.set(key, _start_text(value))
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def write_fmu_with_starts(source, dest, values: dict) -> Path:
    """A copy of the project FMU ``source`` whose parameters ``values`` (name -> value)
    have other defaults: ``resources/start_values.json`` holds them (the slave reads it
    when it is instantiated) and the ``start`` attributes of the model description say
    so. For hosts that cannot set a parameter (fmpy and OMSimulator cannot set Strings)."""
    source, dest = Path(source), Path(dest)
    if not takes_packaged_starts(source):
        raise BuildError(f"{source}: not an FMU of this project that reads {START_VALUES_FILE} (rebuild it)")

    def change(names):
        with zipfile.ZipFile(source) as z:
            xml = z.read("modelDescription.xml")
        return {"modelDescription.xml": with_parameter_starts(xml, values, str(source)),
                f"resources/{START_VALUES_FILE}": (json.dumps(values, indent=2) + "\n").encode("utf-8")}

    return _copy_fmu(source, dest, change)


# -- FMI 3.0 ----------------------------------------------------------------------------------------------
#: FMI 2.0 attribute of <CoSimulation> -> its FMI 3.0 name (attributes FMI 3.0 does not have are dropped)
_CS_ATTRIBUTES_3 = {
    "modelIdentifier": "modelIdentifier", "needsExecutionTool": "needsExecutionTool",
    "canBeInstantiatedOnlyOncePerProcess": "canBeInstantiatedOnlyOncePerProcess",
    "canGetAndSetFMUstate": "canGetAndSetFMUState", "canSerializeFMUstate": "canSerializeFMUState",
    "providesDirectionalDerivative": "providesDirectionalDerivatives",
    "canHandleVariableCommunicationStepSize": "canHandleVariableCommunicationStepSize",
    "maxOutputDerivativeOrder": "maxOutputDerivativeOrder",
}
#: FMI 2.0 type element -> the FMI 3.0 variable element, and the attributes of the type carried over
_TYPES_3 = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}
_TYPE_ATTRIBUTES_3 = ("quantity", "unit", "displayUnit", "relativeQuantity", "unbounded", "min", "max", "nominal",
                      "start")
_VARIABLE_ATTRIBUTES_3 = ("name", "valueReference", "description", "causality", "variability", "initial")


def clocked(name: str) -> bool:
    """Whether the FMI 3.0 unit of the FMU ``name`` has the sample clock: the controllers."""
    return name in OBSERVER_FMUS.values()


def model_description_fmi3(model_description: bytes, where: str = "modelDescription.xml",
                           clock: float | None = None) -> bytes:
    """The FMI 3.0 model description of a co-simulation unit from its FMI 2.0 one (the bytes of a
    modelDescription.xml written by pythonfmu): ``fmiVersion="3.0"``, the GUID as ``instantiationToken``,
    ``<CoSimulation>`` with the same capabilities (``hasEventMode="false"``), the unit definitions, log categories
    and default experiment as they are, each variable as ``<Float64>``, ``<Int32>``, ``<Boolean>`` or ``<String>``
    with the same value reference, causality, variability, initial, start, unit and description, and the model
    structure's outputs and initial unknowns by value reference (FMI 2.0 names them by index). ``clock``: the sample
    period of a controller, declared as its periodic input Clock ``FMI3_CLOCK_NAME`` (``intervalVariability=
    "constant"``, ``intervalDecimal`` the period) and ``hasEventMode="true"``."""
    try:
        root = ET.fromstring(model_description)
    except ET.ParseError as exc:
        raise BuildError(f"{where}: modelDescription.xml is not valid XML ({exc})") from None
    if root.get("fmiVersion") != "2.0" or root.find("CoSimulation") is None:
        raise BuildError(f"{where}: not an FMI 2.0 co-simulation model description")
    out = ET.Element("fmiModelDescription")
    out.set("fmiVersion", "3.0")
    for key, value in root.attrib.items():
        if key == "guid":
            out.set("instantiationToken", value)
        elif key not in ("fmiVersion", "numberOfEventIndicators"):
            out.set(key, value)
    cs = ET.SubElement(out, "CoSimulation")
    for key, value in root.find("CoSimulation").attrib.items():
        if key in _CS_ATTRIBUTES_3:
            cs.set(_CS_ATTRIBUTES_3[key], value)
    cs.set("hasEventMode", "true" if clock else "false")
    units = root.find("UnitDefinitions")
    if units is None:
        units = ET.Element("UnitDefinitions")
    if not any(unit.get("name") == "s" for unit in units.findall("Unit")):  # the unit of time
        ET.SubElement(ET.SubElement(units, "Unit", {"name": "s"}), "BaseUnit", {"s": "1"})
    out.append(units)
    for tag in ("LogCategories", "DefaultExperiment"):
        element = root.find(tag)
        if element is not None:
            out.append(element)
    if root.find("TypeDefinitions") is not None:
        raise BuildError(f"{where}: type definitions are not carried over to FMI 3.0")
    variables = ET.SubElement(out, "ModelVariables")
    ET.SubElement(variables, "Float64", {"name": "time", "valueReference": str(FMI3_TIME_REFERENCE),
                                         "causality": "independent", "variability": "continuous",
                                         "description": "the simulation time (the independent variable)",
                                         "unit": "s"})
    if clock:
        ET.SubElement(variables, "Clock", {
            "name": FMI3_CLOCK_NAME, "valueReference": str(FMI3_CLOCK_REFERENCE), "causality": "input",
            "variability": "discrete", "intervalVariability": "constant", "intervalDecimal": repr(float(clock)),
            "description": "the controller's sample clock: in event mode each tick is one sample (the outputs "
                           "computed on the inputs of the tick, held until the next); without event mode the "
                           "unit samples at this period in fmi3DoStep"})
    references = []  # by the FMI 2.0 index (1-based): the value reference
    for var in root.find("ModelVariables").iter("ScalarVariable"):
        typed = next((e for e in var if e.tag in _TYPES_3), None)
        if typed is None or typed.get("declaredType") is not None or typed.get("derivative") is not None:
            raise BuildError(f"{where}: variable {var.get('name')!r} has a type FMI 3.0 units of this build "
                             f"do not carry over")
        new = ET.SubElement(variables, _TYPES_3[typed.tag])
        for key in _VARIABLE_ATTRIBUTES_3:
            if var.get(key) is not None:
                new.set(key, var.get(key))
        for key in _TYPE_ATTRIBUTES_3:
            value = typed.get(key)
            if value is None:
                continue
            if key == "start" and typed.tag == "String":  # FMI 3.0: <String><Start value=.../></String>
                ET.SubElement(new, "Start", {"value": value})
            else:
                new.set(key, value)
        references.append(var.get("valueReference"))
        if int(var.get("valueReference")) == FMI3_TIME_REFERENCE:
            raise BuildError(f"{where}: variable {var.get('name')!r} has the value reference of time")
    structure = ET.SubElement(out, "ModelStructure")

    def reference(index: str) -> str:
        try:
            return references[int(index) - 1]
        except (ValueError, IndexError):
            raise BuildError(f"{where}: ModelStructure names variable {index!r}, which does not exist") from None

    old = root.find("ModelStructure")
    for group, tag in (("Outputs", "Output"), ("InitialUnknowns", "InitialUnknown")):
        for unknown in old.findall(f"{group}/Unknown") if old is not None else ():
            new = ET.SubElement(structure, tag, {"valueReference": reference(unknown.get("index"))})
            if unknown.get("dependencies") is not None:
                new.set("dependencies", " ".join(reference(i) for i in unknown.get("dependencies").split()))
            if unknown.get("dependenciesKind") is not None:
                new.set("dependenciesKind", unknown.get("dependenciesKind"))
    if old is not None and old.find("Derivatives") is not None and len(old.find("Derivatives")):
        raise BuildError(f"{where}: a co-simulation unit with derivatives is not carried over to FMI 3.0")
    ET.indent(out, "\t")
    return ET.tostring(out, encoding="UTF-8", xml_declaration=True) + b"\n"


def _clock_line(model_description: bytes, where: str) -> str:
    """The FMI 3.0 layer's description of a controller's sample clock (``resources/FMI3_CLOCK_FILE``): the clock's
    value reference, its interval and the value reference of the parameter ``dt``."""
    root = ET.fromstring(model_description)
    dt = next((v.get("valueReference") for v in root.iter("ScalarVariable") if v.get("name") == "dt"), None)
    if dt is None:
        raise BuildError(f"{where}: a controller without the parameter dt (its sample period)")
    return f"{FMI3_CLOCK_REFERENCE} {FMI3_SAMPLE_PERIOD!r} {dt}\n"


def fmi3_out_dir(out_dir=None) -> Path:
    """The folder of the FMI 3.0 units: ``fmi3/`` in the folder of the FMI 2.0 ones (``out_dir``, else
    ``default_out_dir()``)."""
    return Path(out_dir or default_out_dir()) / FMI3_FOLDER


def fmi3_hash(name: str) -> str:
    """SHA-256 of what an FMI 3.0 unit is made of: its FMI 2.0 unit's (:func:`source_hash`), the FMI 3.0 layer's
    source and headers and the compiler flags."""
    h = hashlib.sha256()
    for label, data in (("format", f"pmsm-ev-fmus fmi3 2 clock {FMI3_SAMPLE_PERIOD!r}".encode()),
                        ("fmi2", source_hash(name).encode()),
                        ("fmi3_layer.c", FMI3_SOURCE.read_bytes()),
                        *((f"include/{p.name}", p.read_bytes()) for p in fmi3_headers() if p.is_file()),
                        ("cflags", " ".join(extra_cflags()).encode())):
        h.update(f"{label}\0{len(data)}\0".encode())
        h.update(data)
    return h.hexdigest()


def build_fmu3(name: str, out_dir=None, force: bool = False) -> tuple[Path, bool]:
    """Build the FMI 3.0 co-simulation unit of the FMU ``name`` into ``fmi3_out_dir(out_dir)`` (its FMI 2.0 unit
    built first into ``out_dir``, if needed); return (path, whether it was (re)built). The unit is the FMI 2.0 one's
    files with the model description in FMI 3.0 (:func:`model_description_fmi3`) and its Linux binaries in
    ``binaries/x86_64-linux/``: the FMI 3.0 layer as ``<name>.so``, in front of the FMI 2.0 loader
    (``pmsm-fmi2.so``), the lean binding and pythonfmu's library (fmus/README.md, "FMI 3.0"). It needs the lean
    build (Linux x86-64 and a C compiler)."""
    source, _ = build_fmu(name, out_dir, force)
    out = fmi3_out_dir(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    target = out / f"{name}.fmu"
    digest = fmi3_hash(name)
    with zipfile.ZipFile(source) as z:  # the FMI 2.0 unit it wraps: rebuilt (a new GUID), the 3.0 one is too
        guid = ET.fromstring(z.read("modelDescription.xml")).get("guid")
    done = (read_build_info(target) or {}) if target.is_file() else {}
    if not force and done.get("fmi3_hash") == digest and done.get("fmi2_guid") == guid:
        return target, False
    info = read_build_info(source) or {}
    if info.get("binding") != "lean":
        raise BuildError(f"{name}: the FMI 3.0 unit needs the lean build of the FMI 2.0 one (Linux x86-64 and a C "
                         f"compiler); {source} has {info.get('binding', 'no')} binding")
    layer, why = fmi3_layer_library()
    if layer is None:
        raise BuildError(f"{name}: cannot build the FMI 3.0 layer: {why}")
    old_dir, new_dir = "binaries/linux64/", f"binaries/{FMI3_PLATFORM}/"
    info.update({"fmiVersion": "3.0", "fmi3_hash": digest, "fmi2_guid": guid})
    stage = _make_stage(out, name)
    try:
        staged = stage / f"{name}.fmu"
        with zipfile.ZipFile(source) as zin, zipfile.ZipFile(staged, "w", zipfile.ZIP_DEFLATED) as zout:
            for item in zin.infolist():
                member = item.filename
                if member.startswith("binaries/"):  # FMI 2.0's platform folders; Linux's moves, below
                    if member.startswith(old_dir):
                        base = member[len(old_dir):]
                        zout.writestr(new_dir + (FMI3_INNER_LOADER if base == f"{name}.so" else base), zin.read(item))
                    continue
                data = zin.read(item)
                if member == "modelDescription.xml":
                    if clocked(name):
                        zout.writestr(f"resources/{FMI3_CLOCK_FILE}", _clock_line(data, f"{source}"))
                    data = model_description_fmi3(data, f"{source}", FMI3_SAMPLE_PERIOD if clocked(name) else None)
                elif member == f"resources/{BUILD_INFO}":
                    data = (json.dumps(info, indent=2) + "\n").encode("utf-8")
                zout.writestr(item, data)
            zout.writestr(f"{new_dir}{name}.so", layer.read_bytes())
        _check(staged, name)
        os.replace(staged, target)
    finally:
        _drop_stage(out, stage)
    return target, True


def build_all(out_dir=None, force: bool = False, names=None, fmi: int = 2) -> dict[str, Path]:
    """Build the FMUs ``names`` (default: all) into ``out_dir`` (default: ``default_out_dir()``),
    skipping those whose sources did not change unless ``force``; return name -> path. ``fmi=3``: their FMI 3.0
    units, into ``fmi3_out_dir(out_dir)`` (the FMI 2.0 ones, which they are made from, built too)."""
    names = list(FMUS) if names is None else list(names)
    unknown = [n for n in names if n not in FMUS]
    if unknown:
        raise BuildError(f"unknown FMU {', '.join(unknown)}; choose from {', '.join(FMUS)}")
    if fmi not in FMI_VERSIONS:
        raise BuildError(f"FMI version {fmi!r}: choose one of {', '.join(map(str, FMI_VERSIONS))}")
    build = build_fmu3 if fmi == 3 else build_fmu
    return {name: build(name, out_dir, force)[0] for name in names}


def main(argv=None, prog: str | None = None) -> int:
    ap = argparse.ArgumentParser(prog=prog or "python -m pmsm_ev_fmus",
                                 description="Build the FMI 2.0 (or 3.0) co-simulation FMUs of the drive (pythonfmu).")
    ap.add_argument("names", nargs="*", metavar="NAME", help=f"FMUs to build (default: all): {', '.join(FMUS)}")
    ap.add_argument("--out", default=None, help=f"output directory (default: {default_out_dir()})")
    ap.add_argument("--force", action="store_true", help="rebuild even if the sources did not change")
    ap.add_argument("--fmi", type=int, choices=FMI_VERSIONS, default=2,
                    help=f"FMI version of the units (default 2; 3: FMI 3.0 co-simulation units, into "
                         f"DIR/{FMI3_FOLDER}/, made from the FMI 2.0 ones, which are built too)")
    a = ap.parse_args(argv)
    names = a.names or list(FMUS)
    unknown = [n for n in names if n not in FMUS]
    if unknown:
        ap.error(f"unknown FMU {', '.join(unknown)}; choose from {', '.join(FMUS)}")
    for name in names:
        t0 = time.perf_counter()
        try:
            path, built = (build_fmu3 if a.fmi == 3 else build_fmu)(name, a.out, a.force)
        except (BuildError, OSError) as exc:
            print(f"error: {name}: {exc}", file=sys.stderr)
            return 1
        state = f"built in {time.perf_counter() - t0:.1f} s" if built else "up to date"
        print(f"{name}: {state}: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
