"""AddressSanitizer and UndefinedBehaviorSanitizer for the FMUs' C code (the lean binding, the loader, the FMI 3.0
layer): the compiler flags the build takes from ``PMSM_EV_BINDING_CFLAGS``, the runtime a Python host preloads (python
is not built with ASan), the sanitizers' options and what their reports look like (tests/test_fmi_misuse.py,
tests/test_fmi3.py)."""

from __future__ import annotations

import os
import shutil
import subprocess
import zipfile
from pathlib import Path

import pytest

CC = os.environ.get("CC", "cc")
#: the runtime ASan needs first in the process (the host, python, is not built with it)
ASAN_RUNTIME = subprocess.run([CC, "-print-file-name=libasan.so"], capture_output=True, text=True).stdout.strip() \
    if shutil.which(CC) else ""
SANITIZE = "-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer -g"
#: what a sanitizer prints when it finds something
REPORTS = ("ERROR: AddressSanitizer", "runtime error:", "ERROR: LeakSanitizer", "SUMMARY: UndefinedBehaviorSanitizer")
needs_asan = pytest.mark.skipif(not os.path.isabs(ASAN_RUNTIME), reason=f"{CC} has no AddressSanitizer runtime")


def sanitized_env() -> dict[str, str]:
    """The environment of a Python host of sanitized FMUs: the ASan runtime preloaded, a report fatal."""
    return dict(os.environ, LD_PRELOAD=ASAN_RUNTIME,
                ASAN_OPTIONS="detect_leaks=0:halt_on_error=1:alloc_dealloc_mismatch=0",
                UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1")


def build_sanitized(folder: Path, names, fmi: int = 2) -> dict[str, Path]:
    """The FMUs ``names`` built into ``folder`` (FMI 3.0: ``folder/fmi3/``) with their C code sanitized."""
    import sys

    env = dict(os.environ, PMSM_EV_BINDING_CFLAGS=SANITIZE, PMSM_COSIM_FMU_DIR=str(folder))
    subprocess.run([sys.executable, "-m", "pmsm_ev_fmus", "--out", str(folder), "--fmi", str(fmi), *names], env=env,
                   check=True, capture_output=True, text=True, timeout=600)
    where = folder / "fmi3" if fmi == 3 else folder
    return {name: where / f"{name}.fmu" for name in names}


def is_sanitized(fmu: Path, member: str) -> bool:
    """Whether the library ``member`` of ``fmu`` links both sanitizers."""
    with zipfile.ZipFile(fmu) as z:
        data = z.read(member)
    return b"__asan_init" in data and b"__ubsan_handle" in data


def no_report(done: subprocess.CompletedProcess) -> None:
    found = [line for line in done.stderr.splitlines() if any(mark in line for mark in REPORTS)]
    assert not found, done.stderr[-6000:]
