"""pmsm_cosim: co-simulation of the sensorless PMSM electric-vehicle drive as FMI 2.0 units.

Three wings, each importing only the ones before it (``docs/architecture.md``):

* :mod:`pmsm_cosim.engine`: a fixed-step FMI 2.0 co-simulation master on fmpy (system files
  and SSP packages, the stepping loop, recording). It knows FMI and time, not motors.
* :mod:`pmsm_cosim.sweeps`: parameter sweeps and Monte-Carlo studies on Dask.
* :mod:`pmsm_cosim.app`: this drive's application: ``pmsm-cosim`` (:mod:`~pmsm_cosim.app.cli`),
  the Python API (:mod:`~pmsm_cosim.app.api`: :func:`simulate`), figures of merit, figures,
  report, compare, bench.

``from pmsm_cosim import simulate`` loads the application on first use (the engine and the
sweeps can be imported without it).
"""

from importlib import metadata as _metadata

try:  # the version's one home is pmsm_ev.__version__ (pyproject.toml's dynamic version): the installed distribution's
    __version__ = _metadata.version("pmsm-ev-cosim")
except _metadata.PackageNotFoundError:  # imported from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["simulate", "__version__"]


def __getattr__(name: str):
    if name == "simulate":  # the application's API, loaded on first use: the engine needs none of it
        from .app.api import simulate  # noqa: PLC0415 - the application, loaded on first use (see above)

        return simulate
    raise AttributeError(f"module 'pmsm_cosim' has no attribute {name!r}")
