"""Open a system: a system file (TOML) or an SSP 1.0 package, by its suffix."""

from __future__ import annotations

from pathlib import Path

from .errors import CosimError
from .ssp import load_ssp
from .system import SystemSpec, load_system_file


def load_system(path, fmu_dir: Path | None = None) -> SystemSpec:
    """The :class:`~pmsm_cosim.engine.system.SystemSpec` of a system file or an SSP package
    (``.ssp``); ``fmu_dir`` is the directory ``{fmus}`` stands for in a system file."""
    path = Path(path)
    if path.suffix.lower() == ".ssp":
        return load_ssp(path)
    if path.suffix == "" and not path.exists():
        raise CosimError(f"no system file {str(path)!r}")
    return load_system_file(path, fmu_dir)
