"""Build the C FMUs of tests/c_fmus: compile each model against fmpy's FMI 2.0 headers and
zip it, with its modelDescription.xml, into NAME.fmu."""

from __future__ import annotations

import os
import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy

C_FMUS = Path(__file__).parent / "c_fmus"
#: the FMI 2.0 headers (fmi2Functions.h, fmi2FunctionTypes.h, fmi2TypesPlatform.h) fmpy ships
FMI2_HEADERS = Path(fmpy.__file__).parent / "c-code"


def c_compiler() -> str | None:
    """The C compiler to use ($CC, else cc or gcc on the PATH), or None."""
    for name in (os.environ.get("CC"), "cc", "gcc"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def build_c_fmu(name: str, out_dir: Path, compiler: str) -> Path:
    """Compile tests/c_fmus/NAME.c into a shared library and zip NAME.fmu in ``out_dir``."""
    if not (FMI2_HEADERS / "fmi2Functions.h").is_file():
        raise FileNotFoundError(f"no FMI 2.0 headers in {FMI2_HEADERS}")
    work = out_dir / name
    binary = work / "binaries" / fmpy.platform / f"{name}{fmpy.sharedLibraryExtension}"
    binary.parent.mkdir(parents=True, exist_ok=True)
    cmd = [compiler, "-shared", "-fPIC", "-O1", "-std=c99", "-Wall", "-Wextra", "-Werror",
           f"-I{FMI2_HEADERS}", f"-I{C_FMUS}", str(C_FMUS / f"{name}.c"), "-o", str(binary), "-lm"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(f"compiling {name}.c failed:\n{done.stderr}")
    fmu = out_dir / f"{name}.fmu"
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        z.write(C_FMUS / f"{name}.xml", "modelDescription.xml")
        z.write(binary, f"binaries/{fmpy.platform}/{binary.name}")
        for src in (f"{name}.c", "fmu_base.h"):
            z.write(C_FMUS / src, f"sources/{src}")
    return fmu


def host_steps(text: str) -> dict[str, list[list[float]]]:
    """{fmu: [[outputs of step k] ...]} of what a C host (tests/c_host.c, tests/c_host3.c) or its Python twin
    printed: a line "fmu NAME" starts an FMU's steps, a line "k step_status get_status values..." is a step (both
    statuses OK), the other lines (log lines, counters) are passed over."""
    runs, current = {}, None
    for line in text.splitlines():
        word = line.split(" ", 1)[0]
        if word == "fmu":
            current = runs.setdefault(line.split()[1], [])
        elif word.isdigit():
            k, step_status, get_status, *values = line.split()
            assert (step_status, get_status) == ("0", "0"), line
            current.append([float(v) for v in values])
    return runs
