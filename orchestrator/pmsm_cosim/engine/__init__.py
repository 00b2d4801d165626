"""The co-simulation engine: FMI 2.0 co-simulation FMUs on fmpy, a fixed-step master, recording.

Imports only the standard library, numpy and fmpy (``docs/architecture.md``). Modules:
``errors`` (the one user-error type), ``signals`` (signal tables), ``system`` (system files:
the spec, TOML parsing, overrides), ``fmu`` (one FMU instance on fmpy's FMI 2 API), ``master``
(checks against the FMUs, the stepping loop, the run), ``recording`` (results.csv,
metrics.json), ``ssp`` (SSP 1.0 packages: export and import), ``loading`` (a system file or
an SSP package by its suffix), ``progress`` (progress bars on stderr).
"""

from .errors import CosimError
from .loading import load_system
from .master import Master
from .recording import ResultWriter, read_results, write_metrics
from .system import SystemSpec

__all__ = ["CosimError", "Master", "ResultWriter", "SystemSpec", "load_system", "read_results", "write_metrics"]
