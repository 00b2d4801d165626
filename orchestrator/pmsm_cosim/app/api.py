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
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from pmsm_ev_fmus.build import FMUS, OBSERVER_FMUS

from ..engine.errors import CosimError
from ..engine.master import Master
from ..engine.recording import read_results
from ..engine.system import SystemSpec, split_reference
from .drive import draw_figures, drive_metrics, ensure_fmus, load_system, project_fmu_dir

#: the instances ``plant`` and ``controller`` replace the FMU of (as ``--plant``, ``--controller``)
PLANT_INSTANCE = "plant"
CONTROLLER_INSTANCE = "ctrl"


def _fmu(value, what: str) -> Path:
    """An FMU path, a shipped FMU's name (``FocEkf4``) or an observer's (``ekf4``)."""
    text = str(value)
    if text in OBSERVER_FMUS:
        text = OBSERVER_FMUS[text]
    if text in FMUS:
        return project_fmu_dir() / f"{text}.fmu"
    path = Path(text).expanduser()
    if path.suffix.lower() != ".fmu":
        raise CosimError(f"{what}={value!r}: give an .fmu file, a shipped FMU ({', '.join(FMUS)}) or an "
                         f"observer ({', '.join(OBSERVER_FMUS)})")
    return path.resolve()


def _starts(values) -> list[tuple[str, object]]:
    """``{"ctrl.angle_source": "estimated"}`` or ``["ctrl.angle_source=estimated"]`` -> pairs."""
    if isinstance(values, Mapping):
        return list(values.items())
    if isinstance(values, str) or not isinstance(values, Iterable):
        raise CosimError(f"set={values!r}: give a dict {{'INSTANCE.VAR': value}} or a list of 'INSTANCE.VAR=VALUE'")
    pairs = []
    for text in values:
        target, sep, value = str(text).partition("=")
        if not sep:
            raise CosimError(f"set: {text!r}: expected INSTANCE.VAR=VALUE")
        pairs.append((target.strip(), value.strip()))
    return pairs


def prepare(system="scenario1", *, stop_time: float | None = None, step_size: float | None = None,
            output_interval: float | None = None, algorithm: str | None = None, set=None,
            plant=None, controller=None, fmus: Mapping | None = None,
            profiles: Mapping | None = None) -> SystemSpec:
    """The system of :func:`simulate` with its overrides, checked as far as it can be without the FMUs."""
    spec = system if isinstance(system, SystemSpec) else load_system(system)
    if plant is not None:
        spec.set_fmu(PLANT_INSTANCE, _fmu(plant, "plant"), "plant")
    if controller is not None:
        spec.set_fmu(CONTROLLER_INSTANCE, _fmu(controller, "controller"), "controller")
    for instance, fmu in (fmus or {}).items():
        spec.set_fmu(instance, _fmu(fmu, f"fmus[{instance!r}]"), f"fmus[{instance!r}]")
    for name, value in (("stop_time", stop_time), ("step_size", step_size), ("output_interval", output_interval)):
        if value is not None:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < float("inf"):
                raise CosimError(f"{name} must be a finite number > 0 s (got {value!r})")
            setattr(spec, name, float(value))
    if algorithm is not None:
        if algorithm not in ("gauss-seidel", "jacobi"):
            raise CosimError(f"algorithm must be gauss-seidel or jacobi (got {algorithm!r})")
        spec.algorithm = algorithm
    for target, value in _starts(set or {}):
        instance, variable = split_reference(str(target), f"set {target!r}")
        spec.component(instance, f"set {target!r}").start[variable] = value
    for signal, csv in (profiles or {}).items():
        spec.set_signal_csv(f"{signal}={csv}")
    return spec


def simulate(system="scenario1", *, stop_time: float | None = None, step_size: float | None = None,
             output_interval: float | None = None, algorithm: str | None = None, set=None,
             plant=None, controller=None, fmus: Mapping | None = None, profiles: Mapping | None = None,
             output_dir=None, figures: bool = False) -> tuple[np.ndarray, dict]:
    """Co-simulate and return ``(result, metrics)``.

    ``system``: a shipped scenario (``"scenario1"``, ``"hill-start"``, ...), a system file, an
    SSP package, or a :class:`~pmsm_cosim.engine.system.SystemSpec`. Overrides as on the
    command line: ``stop_time``, ``step_size``, ``output_interval`` [s], ``algorithm``;
    ``set`` start values (``{"ctrl.angle_source": "estimated"}``); ``plant``, ``controller``
    and ``fmus`` (instance -> FMU) an FMU file, a shipped FMU's name or an observer's
    (``"ekf4"``, ``"sensorless"``); ``profiles`` a signal's table from a CSV file.

    ``result``: a numpy structured array, one float64 field per recorded column, one row per
    output interval (the numbers of results.csv, bit for bit). ``metrics``: the drive's
    figures of merit (``pmsm_ev.results.compute_metrics``; a ``metrics_note`` instead for a
    system without the drive's columns) and the run's bookkeeping (``status``,
    ``wall_time_s``, ...). A run that fails during the steps returns its rows so far with
    ``metrics["status"] = "failed: ..."``; an error in the input raises a
    :class:`~pmsm_cosim.engine.errors.CosimError` with a one-line message.
    """
    spec = prepare(system, stop_time=stop_time, step_size=step_size, output_interval=output_interval,
                   algorithm=algorithm, set=set, plant=plant, controller=controller, fmus=fmus, profiles=profiles)
    ensure_fmus(spec, quiet=True)
    master = Master(spec)
    with tempfile.TemporaryDirectory(prefix="pmsm-cosim-") as tmp:
        out = Path(output_dir) if output_dir is not None else Path(tmp)
        metrics = master.run(out, metrics_of=drive_metrics)
        columns = read_results(out) if metrics.get("rows") else {c.name: np.empty(0) for c in spec.columns}
        if figures and output_dir is not None and metrics.get("rows", 0) >= 2:
            draw_figures(out, spec.name, quiet=True)
    result = np.empty(len(next(iter(columns.values()))), dtype=[(name, "f8") for name in columns])
    for name, values in columns.items():
        result[name] = values
    return result, metrics
