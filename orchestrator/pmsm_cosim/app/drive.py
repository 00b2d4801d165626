"""What this drive adds to the co-simulation engine: its FMUs, its scenarios, its figures of merit.

* the project's FMUs (``pmsm_ev_fmus``): where they are built (:func:`project_fmu_dir`, what
  ``{fmus}`` stands for in a system file; their FMI 3.0 units in its ``fmi3/``), building them before a run
  (:func:`ensure_fmus`) and a system's FMUs as the units of one FMI version (:func:`with_fmi`);
* the shipped scenarios (``pmsm_cosim/app/scenarios/*.toml``) by name (:func:`load_system`
  takes a name, a system file or an SSP package);
* the drive's figures of merit of a run (:func:`drive_metrics`, the ``metrics_of`` the engine's
  master calls; ``pmsm_ev.results`` computes them) and its figures (:func:`draw_figures`);
* for ``export-ssp``: the RouteProfile FMU that carries a system's route, and the copies of
  the project's FMUs that carry String parameters (:func:`export_ssp`).
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
from collections.abc import Iterator
from importlib import resources
from pathlib import Path

from pmsm_ev import __version__
from pmsm_ev.results import CONTRACT_COLUMNS
from pmsm_ev.scenarios import ROUTE_SIGNALS, Profile, ProfileError, route_to_json
from pmsm_ev_fmus import build as fmu_build

from ..engine import ssp_export
from ..engine.errors import CosimError, close_matches, one_line
from ..engine.loading import load_system as load_system_file
from ..engine.recording import read_results
from ..engine.system import SystemSpec, parse_system, read_toml
from . import cycles
from .metrics.cycle_energy import plant_params
from .metrics.identification import identification_truth, plant_settings
from .metrics.run import compute_metrics

#: where the shipped scenarios are (package data)
SCENARIO_PACKAGE = "pmsm_cosim.app"


def _packaged_scenarios() -> tuple[str, ...]:
    """Names of the system files shipped in ``pmsm_cosim/app/scenarios/``: the paper's two
    scenarios first, then their variants in name order."""
    names = sorted(p.name[:-len(".toml")] for p in (resources.files(SCENARIO_PACKAGE) / "scenarios").iterdir()
                   if p.name.endswith(".toml"))
    return tuple(sorted(names, key=lambda n: (n not in ("scenario1", "scenario2"), n)))


#: the scenarios shipped with the package (``pmsm_cosim/app/scenarios/<name>.toml``): the
#: paper's scenario1 and scenario2, their sensorless and sensor-error variants, the hill start
PACKAGED_SCENARIOS = _packaged_scenarios()


def packaged_scenario(name: str) -> Path:
    """Path of a shipped scenario file (``scenario1``, ``scenario2``, ``scenario2-noisy``, ...)."""
    if name not in PACKAGED_SCENARIOS:
        raise CosimError(f"unknown scenario {name!r}{close_matches(name, PACKAGED_SCENARIOS)}; "
                         f"choose one of {', '.join(PACKAGED_SCENARIOS)} or give a system file")
    return Path(str(resources.files(SCENARIO_PACKAGE) / "scenarios" / f"{name}.toml"))


def project_fmu_dir() -> Path:
    """Where the project's FMUs are built and found (what ``{fmus}`` stands for): the FMU
    build's default, ``pmsm_ev_fmus.build.default_out_dir()``: ``$PMSM_COSIM_FMU_DIR`` if set
    (``--fmu-dir`` on the command line sets it), else the user's cache,
    ``~/.cache/pmsm-ev-cosim/fmus/<content key>/`` on Linux."""
    return Path(fmu_build.default_out_dir()).resolve()


@contextlib.contextmanager
def fmu_dir_override(path) -> Iterator[None]:
    """The project's FMUs in ``path`` (if not None) while the block runs: it sets
    ``$PMSM_COSIM_FMU_DIR``, so that the processes a command starts (the report's runs,
    the bench's, a local Dask cluster's workers) use the same folder; restored after."""
    if path is None:
        yield
        return
    name = fmu_build.ENV_FMU_DIR
    saved = os.environ.get(name)
    os.environ[name] = str(Path(path).expanduser().resolve())
    try:
        yield
    finally:
        if saved is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = saved


def load_system(name_or_path) -> SystemSpec:
    """A shipped scenario by name, a system file or an SSP package, with ``{fmus}`` = the
    project's FMU directory."""
    path = Path(name_or_path)
    if str(path) in PACKAGED_SCENARIOS:
        path = packaged_scenario(str(path))
    elif path.suffix == "" and not path.exists():
        raise CosimError(f"no scenario or system file {str(path)!r}{close_matches(str(path), PACKAGED_SCENARIOS)}; "
                         f"shipped scenarios: {', '.join(PACKAGED_SCENARIOS)}")
    if path.suffix.lower() == ".ssp":
        return load_system_file(path, fmu_dir=project_fmu_dir())
    # a system file: the application's sections [cycle] and [road] (module cycles) expanded into what
    # the engine knows, a signal table and a component with its connections
    data = read_toml(path, "system file")
    if not isinstance(data, dict) or not ({"cycle", "road"} & set(data)):
        return load_system_file(path, fmu_dir=project_fmu_dir())
    fmu_dir = project_fmu_dir()
    part = cycles.pop_sections(data, str(path), path.resolve().parent, fmu_dir)
    spec = parse_system(data, path, fmu_dir=fmu_dir)
    cycles.apply_cycle_section(spec, part)
    return spec


# --- figures of merit ------------------------------------------------------------------

def missing_drive_columns(columns) -> list[str]:
    """The drive's contract columns (``pmsm_ev.results.CONTRACT_COLUMNS``) missing from ``columns``."""
    present = set(columns)
    return [c for c in CONTRACT_COLUMNS if c not in present]


def drive_metrics(out_dir, columns, rows: int) -> dict:
    """The drive's figures of merit of a run in ``out_dir`` (the master's ``metrics_of``):
    ``pmsm_cosim.app.metrics.run.compute_metrics`` of its results.csv; a note instead when the recorded
    columns are not the drive's (a user's own system), nothing when no row was written."""
    missing = missing_drive_columns(columns)
    if missing:
        return {"metrics_note": "no drive metrics: the recorded columns lack " + ", ".join(missing)
                                + " (pmsm_ev.results.CONTRACT_COLUMNS)"}
    if not rows:
        return {}
    m = compute_metrics(read_results(out_dir))
    if "identification" in m:  # the plant's truth beside it, from the run's settings (metrics.json, written first)
        try:
            settings = json.loads((Path(out_dir) / "metrics.json").read_text())
            m["identification"].update(identification_truth(plant_params(settings)[0], m["identification"],
                                                            plant_settings(settings)))
        except (OSError, ValueError):
            pass
    return m


# --- the project's FMUs ------------------------------------------------------------------

def _note(message: str, quiet: bool = False) -> None:
    if not quiet:
        print(f"note: {message}", file=sys.stderr)


def _project_fmu(path: Path, folder: Path) -> bool:
    return path.parent == folder and path.name == f"{path.stem}.fmu" and path.stem in fmu_build.FMUS


def with_fmi(spec: SystemSpec, fmi: int | None) -> SystemSpec:
    """``spec`` with its project FMUs (``{fmus}/X.fmu``, ``{fmus}/fmi3/X.fmu``) as the units of FMI ``fmi``: 2, the
    FMI 2.0 units in :func:`project_fmu_dir`; 3, the FMI 3.0 units in its ``fmi3/`` (``pmsm-cosim build --fmi
    3``), made from the same FMI 2.0 stack. None: as the system says (a system may mix both). Other FMUs are
    left as they are. Changes ``spec`` and returns it."""
    if fmi is None:
        return spec
    if fmi not in fmu_build.FMI_VERSIONS:
        raise CosimError(f"--fmi {fmi}: choose one of {', '.join(map(str, fmu_build.FMI_VERSIONS))}")
    fmu_dir = project_fmu_dir()
    folders = {2: fmu_dir, 3: fmu_build.fmi3_out_dir(fmu_dir)}
    for c in spec.components:
        if any(_project_fmu(c.fmu, folder) for folder in folders.values()):
            c.fmu = folders[fmi] / c.fmu.name
    return spec


def ensure_fmus(spec: SystemSpec, quiet: bool = False) -> None:
    """Build (or bring up to date) the project's FMUs a system uses (those in
    :func:`project_fmu_dir`, and its FMI 3.0 units in its ``fmi3/``), before loading it."""
    fmu_dir = project_fmu_dir()
    for fmi, folder in ((2, fmu_dir), (3, fmu_build.fmi3_out_dir(fmu_dir))):
        needed = [c for c in spec.components if c.fmu.parent == folder]
        if not needed:
            continue
        names = sorted({c.fmu.stem for c in needed if _project_fmu(c.fmu, folder)})
        if any(not c.fmu.is_file() for c in needed):
            _note(f"building FMUs into {folder} ...", quiet)
        try:
            if names:
                fmu_build.build_all(out_dir=fmu_dir, names=names, fmi=fmi)
        except Exception as exc:
            raise CosimError(f"building the FMUs failed: {type(exc).__name__}: {one_line(exc)}") from None
        for c in needed:
            if not c.fmu.is_file():
                raise CosimError(f"{c.name}: FMU not found: {c.fmu} (not among the project's built FMUs)")


def project_route_fmu(quiet: bool = False) -> Path:
    """The project's RouteProfile FMU (built or brought up to date first)."""
    name = fmu_build.ROUTE_FMU
    fmu_dir = project_fmu_dir()
    if not (fmu_dir / f"{name}.fmu").is_file():
        _note(f"building {name}.fmu into {fmu_dir} ...", quiet)
    try:
        return fmu_build.build_all(out_dir=fmu_dir, names=[name])[name]
    except Exception as exc:
        raise CosimError(f"building {name}.fmu failed: {type(exc).__name__}: {exc}") from None


def draw_figures(run_dir: Path, scenario_label, quiet: bool = False) -> list[Path] | None:
    """Figures of a run (:func:`pmsm_cosim.app.figures.make_figures`); None, with a note, if
    the run cannot be plotted (too short, not the drive's columns)."""
    from .figures import make_figures  # noqa: PLC0415 - matplotlib: heavy, only when drawing

    try:
        return make_figures(run_dir, scenario_label=scenario_label)
    except Exception as exc:  # a run too short to plot must not fail the run
        _note(f"figures skipped: {one_line(exc)}", quiet)
        return None


# --- SSP export ----------------------------------------------------------------------------

def export_ssp(spec: SystemSpec, dest, quiet: bool = False, route_fmu: Path | None = None) -> ssp_export.ExportSummary:
    """``spec`` as an SSP 1.0 package: its signals (the route ``delta``, ``omega_ref``) in a
    copy of the RouteProfile FMU (``route_fmu``, default the project's, built if needed),
    String parameters of the project's FMUs in copies of them."""
    where = f"{spec.path}: " if spec.path else ""

    def signal_fmu(spec: SystemSpec, work: Path) -> Path:
        profiles = {name: sig.profile for name, sig in spec.signals.items()}
        if not set(profiles) <= set(ROUTE_SIGNALS):
            raise CosimError(f"{where}export-ssp: the signals must be {' and '.join(ROUTE_SIGNALS)} "
                             f"(the outputs of the RouteProfile FMU that carries them), got "
                             f"{', '.join(profiles)}")
        for name in ROUTE_SIGNALS:  # one the system does not have (delta, with a road by position): an
            if name not in profiles:  # unconnected output, 0
                profiles[name] = Profile((0.0,), (0.0,), "previous", name, ROUTE_SIGNALS[name])
        for name, sig in spec.signals.items():
            if sig.unit not in ("", ROUTE_SIGNALS[name]):
                raise CosimError(f"{where}export-ssp: signal {name} is in {sig.unit!r}; "
                                 f"RouteProfile.{name} is in {ROUTE_SIGNALS[name]!r}")
        try:
            route_json = route_to_json(profiles, spec.name)
        except ProfileError as exc:
            raise CosimError(f"{where}export-ssp: {exc}") from None
        source = route_fmu if route_fmu is not None else project_route_fmu(quiet)
        return fmu_build.write_route_fmu(route_json, work / "RouteProfile.fmu", source=source)

    return ssp_export.export_ssp(spec, dest, signal_fmu=signal_fmu if spec.signals else None,
                                 carries_starts=fmu_build.takes_packaged_starts,
                                 string_start_fmu=fmu_build.write_fmu_with_starts,
                                 tool=f"pmsm-ev-cosim {__version__}")
