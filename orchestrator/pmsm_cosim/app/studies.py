"""The drive's sweeps: the hooks that give the sweep engine this drive's scenarios, FMUs and
figures of merit, and the sweep files shipped in ``pmsm_cosim/app/sweeps/``."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from pmsm_ev.params import ParameterError
from pmsm_ev.scenarios import ProfileError
from pmsm_ev_fmus.build import FMUS

from .. import sweeps
from ..engine.errors import CosimError, close_matches
from . import cycles
from .drive import PACKAGED_SCENARIOS, draw_figures, drive_metrics, ensure_fmus, load_system, project_fmu_dir
from .metrics.summary import SUMMARY_METRICS, SUMMARY_UNITS, summary_metrics

#: the sweeps shipped with the package (``pmsm_cosim/app/sweeps/<name>.toml``), found, in name order
PACKAGED_SWEEPS = tuple(sorted(p.name[:-len(".toml")] for p in (resources.files("pmsm_cosim.app") / "sweeps").iterdir()
                               if p.name.endswith(".toml")))
#: the metric a sweep file without ``metric`` plots
DEFAULT_METRIC = "speed_rms_error"


def drive_hooks() -> sweeps.SweepHooks:
    """The sweep engine's hooks for this drive (the FMU directory as it is now)."""
    return sweeps.SweepHooks(
        load_system=load_system, system_names=PACKAGED_SCENARIOS, fmu_dir=project_fmu_dir(),
        fmu_names=tuple(FMUS), prepare=ensure_fmus, metrics_of=drive_metrics, figures=draw_figures,
        metrics_for=cycles.with_trace_figures, adjust=cycles.resample,
        summary_metrics=SUMMARY_METRICS, summary_units=dict(SUMMARY_UNITS), summary_of=summary_metrics,
        run_errors=(ParameterError, ProfileError), default_metric=DEFAULT_METRIC)


def packaged_sweep(name: str) -> Path:
    """Path of a shipped sweep file."""
    return Path(str(resources.files("pmsm_cosim.app") / "sweeps" / f"{name}.toml"))


def load_sweep(path, *, samples: int | None = None, seed: int | None = None) -> sweeps.SweepSpec:
    """A sweep file, or the name of a shipped sweep, with this drive's hooks; ``samples``, ``seed``: a Monte-Carlo
    sweep drawn again (``pmsm_cosim.sweeps.redraw``)."""
    path = Path(path)
    if path.suffix == "" and not path.exists():
        if str(path) in PACKAGED_SWEEPS:
            path = packaged_sweep(str(path))
        else:
            raise CosimError(f"no sweep file {str(path)!r}{close_matches(str(path), PACKAGED_SWEEPS)}; "
                             f"shipped sweeps: {', '.join(PACKAGED_SWEEPS)}")
    return sweeps.load_sweep(path, drive_hooks(), samples=samples, seed=seed)


def parse_sweep(data: dict, path: Path | None = None, base_dir: Path | None = None) -> sweeps.SweepSpec:
    """A sweep from a TOML document, with this drive's hooks."""
    return sweeps.parse_sweep(data, path, base_dir, drive_hooks())
