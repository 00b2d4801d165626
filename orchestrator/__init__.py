"""orchestrator: a fixed-step FMI 2.0 co-simulation master on fmpy.

It knows FMI and time, not motor physics. A *system file* (TOML, see
``docs/system-file.md``) names the FMU instances, the connections between their
variables, the scenario signals that drive inputs, the time grid and the recorded
columns; :mod:`orchestrator.master` runs it with Gauss-Seidel or Jacobi coupling and
streams ``results.csv`` / ``metrics.json``; :mod:`orchestrator.cli` is ``pmsm-cosim``.

Modules: ``errors`` (the one user-error type), ``system`` (system-file parsing and
overrides), ``ssp`` (SSP 1.0 packages: export, and import as a system), ``fmu`` (one FMU
instance on fmpy's FMI 2 API), ``master`` (the stepping loop, recording, metrics),
``progress`` (the stderr progress bars), ``sweep`` (parameter sweeps and Monte-Carlo runs
on Dask distributed), ``cli``.
"""

from .errors import CosimError

__all__ = ["CosimError"]
