"""How the per-step kernels (the package ``pmsm_ev.kernels``) run: compiled with numba when it
is importable, plain Python otherwise.

``kernels()`` returns the package to call. With numba it is ``pmsm_ev.kernels`` compiled, loaded
from a copy of the package's files in a directory named after the SHA-256 of all of them,
``<cache dir>/kernels_<hash>/``, imported as ``pmsm_ev_kernels_<hash>``:

* numba's on-disk cache (``__pycache__`` next to each copied file) is keyed, per function, on its
  file's path and time stamp, both fixed by the content of the whole package: a change in any
  kernel file, including one that only a caller in another file inlines, gives another directory
  and so a fresh compilation (numba's own key would miss a change in a callee's file). Compiled
  code is reused by every later process, and by every FMU: a Python FMU is extracted to a new
  temporary directory per instance, so a cache keyed on its own files would never be hit
  (``NUMBA_CACHE_DIR`` alone would not help: numba keys its index on the source file's path);
* in one process the reference run and all the FMUs (each bundles its own copy of this
  package under another name) share one compiled package.

The cache directory is ``$PMSM_EV_CACHE_DIR`` or ``$XDG_CACHE_HOME/pmsm-ev-cosim``
(``~/.cache/pmsm-ev-cosim``). If it cannot be written, the kernels are compiled without a
cache (each process compiles them, a few seconds). ``PMSM_EV_JIT=0`` forces plain Python.
Both ways give the same numbers (see ``pmsm_ev.kernels``). A Python embedded in a host that is
not a Python program (``sys.orig_argv`` empty: an FMU in a C/C++ tool) compiles them too, from
the same cache: the FMU's loader never finalizes an interpreter it started, and releases one that
pythonfmu started before numba's LLVM is torn down at exit (fmus/README.md, "Hosts that are not
Python").

Vectors handed to the kernels come from ``vector(n)``: a float64 numpy array when compiled,
a list of floats otherwise (fast to index from plain Python).
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import tempfile
from pathlib import Path

from . import kernels as _source  # the plain-Python package (and the source to compile)

ENV_JIT = "PMSM_EV_JIT"
ENV_CACHE_DIR = "PMSM_EV_CACHE_DIR"
#: the time stamp given to the cached copies (numba checks it against its cache index)
_STAMP = 1_000_000_000

_loaded = None  # (module, description)


def _read_sources(directory: Path) -> dict[str, bytes]:
    """The package's ``*.py`` files, {file name: content}, by name."""
    return {path.name: path.read_bytes() for path in sorted(directory.glob("*.py"))}


#: the kernels' sources, read now: every FMU bundles this package under one content-hashed
#: name shared by all its instances in a process (sys.modules), and the instance whose
#: extracted files it was imported from may be freed, its directory deleted, before
#: another instance first calls ``kernels()``
_SOURCES = _read_sources(Path(_source.__file__).parent)


def _digest(sources: dict[str, bytes], numba_version: str) -> str:
    """The first 16 hex digits of the SHA-256 over every file (name, length, content) and numba's version."""
    h = hashlib.sha256()
    for name, data in sources.items():
        h.update(f"{name}\0{len(data)}\0".encode())
        h.update(data)
    h.update(f"numba {numba_version}".encode())
    return h.hexdigest()[:16]


def jit_requested() -> bool:
    return os.environ.get(ENV_JIT, "1").strip().lower() not in ("0", "false", "no", "off")


def cache_dir() -> Path:
    env = os.environ.get(ENV_CACHE_DIR)
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "pmsm-ev-cosim"


def _write_stamped(path: Path, data: bytes) -> None:
    """``path`` with ``data`` and the fixed time stamp (replaced atomically if it differs)."""
    try:
        current = path.read_bytes()
    except OSError:
        current = None
    if current != data:
        fd, tmp = tempfile.mkstemp(prefix=".kernels-", suffix=".tmp", dir=path.parent)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.utime(tmp, (_STAMP, _STAMP))
        os.replace(tmp, path)
    elif int(path.stat().st_mtime) != _STAMP:
        os.utime(path, (_STAMP, _STAMP))


def _stable_copy(sources: dict[str, bytes], digest: str) -> Path | None:
    """``<cache dir>/kernels_<digest>/`` with ``sources`` and a fixed time stamp, or None."""
    try:
        directory = cache_dir() / f"kernels_{digest}"
        directory.mkdir(parents=True, exist_ok=True)
        for name, data in sources.items():
            _write_stamped(directory / name, data)
        return directory
    except OSError:
        return None


def _exec(name: str, directory: Path, cache: bool):
    """Import the package in ``directory`` as ``name``, compiled (numba's cache on or off)."""
    spec = importlib.util.spec_from_file_location(name, directory / "__init__.py",
                                                  submodule_search_locations=[str(directory)])
    module = importlib.util.module_from_spec(spec)
    module.JIT, module.CACHE = True, cache  # read by its submodule jit before any kernel is defined
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)  # compiles (or loads from the cache) the kernels
    except BaseException:
        for loaded in [m for m in sys.modules if m == name or m.startswith(name + ".")]:
            del sys.modules[loaded]
        raise
    return module


def _compiled_description(module, version: str) -> str:
    where = f"cache {Path(module.__file__).parent.parent}" if module.CACHE else "no cache"
    return f"numba {version}, {where}"


def _load():
    if not jit_requested():
        return _source, f"plain Python ({ENV_JIT}=0)"
    try:
        import numba  # noqa: PLC0415 - numba: heavy (LLVM), loaded only to compile the kernels
    except Exception:  # not installed, or broken (e.g. an llvmlite that does not load)
        return _source, "plain Python (numba not available)"
    digest = _digest(_SOURCES, numba.__version__)
    name = f"pmsm_ev_kernels_{digest}"
    module = sys.modules.get(name)
    if module is not None:  # compiled already, for another copy of this package (an FMU's)
        return module, _compiled_description(module, numba.__version__)
    path = _stable_copy(_SOURCES, digest)
    try:
        module = None
        if path is not None:
            try:
                module = _exec(name, path, True)
            except RuntimeError:  # numba found no writable cache location
                module = None
        if module is None:
            module = _exec(name, Path(_source.__file__).parent, False)
        return module, _compiled_description(module, numba.__version__)
    except Exception as exc:  # a numba that cannot compile them: run them as Python
        return _source, f"plain Python (numba failed: {type(exc).__name__}: {exc})"


def kernels():
    """The kernels module to call (loaded once per process; compiled, each kernel with a signature compiled or
    loaded from numba's cache when the process first needs it: ``pmsm_ev.kernels.jit``)."""
    global _loaded
    if _loaded is None:
        _loaded = _load()
    return _loaded[0]


def describe() -> str:
    """How the kernels run in this process, e.g. ``numba 0.60.0, cache /home/u/.cache/...``."""
    kernels()
    return _loaded[1]


def compiled() -> bool:
    return kernels() is not _source


def direct(fn):
    """The fastest callable of the kernel ``fn`` (of ``kernels()``): a compiled kernel with its one
    explicit signature as its compiled entry point, which skips numba's per-call type dispatch
    (~0.15 us a call; the same machine code, so the same numbers; arguments of another type are a
    TypeError); any other ``fn`` as it is."""
    ready = getattr(fn, "ready", None)
    if ready is not None:  # a top-level kernel: its signature compiled (or loaded) first
        ready()
    overloads = getattr(fn, "overloads", None)
    if not overloads or len(overloads) != 1:
        return fn
    entry = getattr(next(iter(overloads.values())), "entry_point", None)
    return entry if callable(entry) else fn


def vector(n: int):
    """A zeroed vector of n floats for the kernels."""
    if compiled():
        import numpy as np  # noqa: PLC0415 - numpy only with compiled kernels: the FMUs' plain path needs none

        return np.zeros(n)
    return [0.0] * n
