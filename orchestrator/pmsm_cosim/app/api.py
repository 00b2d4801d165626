"""The Python API: one call runs a scenario, a system file or an SSP package, in the manner of
``fmpy.simulate_fmu``, and gives the trajectories and the figures of merit::

    from pmsm_cosim import simulate

    result, metrics = simulate("scenario2", stop_time=20.0, controller="ekf4",
                               set={"ctrl.angle_source": "estimated"})
    result["time"], result["omega_m"]          # a numpy structured array, one field per column
    metrics["speed_rms_error"], metrics["status"]

Nothing is written unless ``output_dir`` is given (the run goes through a temporary
directory, removed before the call returns); with ``output_dir`` the files are those of
``pmsm-cosim run``: results.csv, metrics.json and, with ``figures=True``, figures/*.png.
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..engine.errors import CosimError
from ..engine.master import Master
from ..engine.recording import read_results
from ..engine.system import SystemSpec
from . import cycles, thermal_metrics
from .drive import draw_figures, drive_metrics, ensure_fmus
from .overrides import apply_overrides

#: fmpy's names (``fmpy.simulate_fmu``) for two of the overrides: ours -> fmpy's
FMPY_NAMES = {"set": "start_values", "record": "output"}


def _either(ours, fmpys, name: str):
    """The value of an override given by our name or by fmpy's, not both."""
    if ours is not None and fmpys is not None:
        raise CosimError(f"give {name}= or {FMPY_NAMES[name]}= (fmpy's name for it), not both")
    return ours if ours is not None else fmpys


def prepare(system="scenario1", *, stop_time: float | None = None, step_size: float | None = None,
            output_interval: float | None = None, algorithm: str | None = None, set=None, start_values=None,
            plant=None, controller=None, fmus: Mapping | None = None, profiles: Mapping | None = None,
            record=None, output=None, cycle=None) -> SystemSpec:
    """The system :func:`simulate` runs: ``system`` with its overrides
    (:func:`pmsm_cosim.app.overrides.apply_overrides`), a new :class:`SystemSpec` (one given
    is not changed), checked as far as it can be without the FMUs."""
    return apply_overrides(system, plant=plant, controller=controller, fmus=fmus, stop_time=stop_time,
                           step_size=step_size, output_interval=output_interval, algorithm=algorithm,
                           set=_either(set, start_values, "set"), profiles=profiles,
                           record=_either(record, output, "record"), cycle=cycle)


def simulate(system="scenario1", *, stop_time: float | None = None, step_size: float | None = None,
             output_interval: float | None = None, algorithm: str | None = None, set=None, start_values=None,
             plant=None, controller=None, fmus: Mapping | None = None, profiles: Mapping | None = None,
             record=None, output=None, output_dir=None, figures: bool = False, cycle=None) -> tuple[np.ndarray, dict]:
    """Co-simulate and return ``(result, metrics)``.

    ``system``: a shipped scenario (``"scenario1"``, ``"hill-start-if"``, ...), a system file, an
    SSP package, or a :class:`~pmsm_cosim.engine.system.SystemSpec` (not changed: the
    overrides apply to a copy). Overrides as on the command line, by one function
    (:mod:`pmsm_cosim.app.overrides`): ``stop_time``, ``step_size``, ``output_interval`` [s],
    ``algorithm``; ``set`` start values (``{"ctrl.angle_source": "estimated"}`` or
    ``["ctrl.angle_source=estimated"]``); ``plant``, ``controller`` and ``fmus`` (instance ->
    FMU) an FMU file, a shipped FMU's name or an observer's (``"ekf4"``, ``"sensorless"``);
    ``profiles`` a signal's table from a CSV file (signal -> CSV); ``record`` the columns to
    record instead of the system's (time first, then each a column of the system, e.g.
    ``"omega_m"``, or a variable ``"plant.omega_m"``, the column named as written); ``cycle`` a drive
    cycle (``"wltc3b"`` or a CSV file) as the speed reference ``omega_ref``, the stop time its duration
    unless ``stop_time`` (:mod:`pmsm_cosim.app.cycles`).

    fmpy's names are taken too (``fmpy.simulate_fmu``): ``start_values`` is ``set`` (a dict
    name -> value; with several FMUs in a system a name is ``"instance.var"``, e.g.
    ``{"plant.m_v": 1500.0}``) and ``output`` is ``record`` (a list of variable names,
    ``["plant.omega_m", "ctrl.omega_hat"]``); giving both names of one is an error.

    ``result``: a numpy structured array, one float64 field per recorded column, one row per
    output interval (the numbers of results.csv, bit for bit). ``metrics``: the drive's
    figures of merit (``pmsm_cosim.app.metrics.run.compute_metrics``; a ``metrics_note`` instead for a
    system without the drive's columns) and the run's bookkeeping (``status``,
    ``wall_time_s``, ...). A run that fails during the steps returns its rows so far with
    ``metrics["status"] = "failed: ..."``; an error in the input raises a
    :class:`~pmsm_cosim.engine.errors.CosimError` with a one-line message.
    """
    spec = prepare(system, stop_time=stop_time, step_size=step_size, output_interval=output_interval,
                   algorithm=algorithm, set=set, start_values=start_values, plant=plant, controller=controller,
                   fmus=fmus, profiles=profiles, record=record, output=output, cycle=cycle)
    ensure_fmus(spec, quiet=True)
    master = Master(spec)
    with tempfile.TemporaryDirectory(prefix="pmsm-cosim-") as tmp:
        out = Path(output_dir) if output_dir is not None else Path(tmp)
        metrics = master.run(out, metrics_of=thermal_metrics.with_thermal_figures(
            cycles.with_trace_figures(drive_metrics, spec), spec))
        columns = read_results(out) if metrics.get("rows") else {c.name: np.empty(0) for c in spec.columns}
        if figures and output_dir is not None and metrics.get("rows", 0) >= 2:
            draw_figures(out, spec.name, quiet=True)
    result = np.empty(len(next(iter(columns.values()))), dtype=[(name, "f8") for name in columns])
    for name, values in columns.items():
        result[name] = values
    return result, metrics
