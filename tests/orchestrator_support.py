"""Helpers for the orchestrator's tests: toy FMUs (built once per session) and system files."""

from __future__ import annotations

import atexit
import functools
import shutil
import tempfile
from pathlib import Path

# Import the installed pythonfmu before any FMU is loaded: a pythonfmu FMU puts its
# resources/ (with a copy of pythonfmu that lacks the builder's binaries) on sys.path, and
# a builder imported from there writes FMUs without binaries.
import pythonfmu.builder  # noqa: F401,E402

TOY_SOURCES = Path(__file__).parent / "toy_fmus"


@functools.lru_cache(maxsize=None)
def toy_fmus() -> dict[str, Path]:
    """{"ToySource": path, "ToySink": path}, built with pythonfmu into a temporary directory."""
    from pythonfmu.builder import FmuBuilder

    out = Path(tempfile.mkdtemp(prefix="toy_fmus_"))
    atexit.register(shutil.rmtree, out, True)
    return {name: Path(FmuBuilder.build_FMU(TOY_SOURCES / f"{name}.py", dest=out))
            for name in ("ToySource", "ToySink")}


def toy_system(tmp_path: Path, *, order=("src", "snk"), algorithm="gauss-seidel", stop_time=0.01,
               step=1e-3, output_interval=None, src_multiple=1, snk_multiple=1, signals="",
               record=None, connections=('"src.y -> snk.u"',), snk_start="", name="toy") -> Path:
    """Write a system file of ToySource 'src' -> ToySink 'snk' and return its path."""
    fmus = toy_fmus()
    comps = {
        "src": f'[[components]]\nname = "src"\nfmu = "{fmus["ToySource"]}"\nstep_multiple = {src_multiple}\n',
        "snk": f'[[components]]\nname = "snk"\nfmu = "{fmus["ToySink"]}"\nstep_multiple = {snk_multiple}\n'
               + (f"start = {{ {snk_start} }}\n" if snk_start else ""),
    }
    record = record or {
        "time": '"time"', "y": '"src.y"', "src_calls": '"src.calls"', "last_u": '"snk.last_u"',
        "snk_calls": '"snk.calls"', "last_h": '"snk.last_h"', "last_t": '"snk.last_t"',
    }
    text = f'name = "{name}"\nconnections = [{", ".join(connections)}]\n\n'
    text += "[experiment]\n"
    text += f"step_size = {step!r}\nstop_time = {stop_time!r}\n"
    text += f"output_interval = {output_interval if output_interval is not None else step!r}\n"
    text += f'algorithm = "{algorithm}"\n\n'
    text += "\n".join(comps[c] for c in order) + "\n" + signals + "\n[record]\n"
    text += "\n".join(f"{k} = {v}" for k, v in record.items()) + "\n"
    path = tmp_path / f"{name}.toml"
    path.write_text(text, encoding="utf-8")
    return path


def project_fmus() -> dict[str, Path]:
    """The project's FMUs, built (or found up to date) by pmsm_ev_fmus.build; skip without it."""
    import pytest

    try:
        from pmsm_ev_fmus.build import build_all
    except ImportError as exc:  # the FMU build is not installed
        pytest.skip(f"pmsm_ev_fmus.build not importable: {exc}")
    return _built(build_all)


@functools.lru_cache(maxsize=None)
def _built(build_all) -> dict[str, Path]:
    return build_all()


def plateau_system(tmp_path: Path, delta_deg: float = 0.0, omega_ref: float = 200.0) -> Path:
    """Scenario 2's system with a constant elevation and a constant speed reference."""
    from importlib import resources

    text = (resources.files("pmsm_cosim.app") / "scenarios" / "scenario2.toml").read_text(encoding="utf-8")
    start, end = text.index("[signals.delta]"), text.index("[record]")
    signals = (f'[signals.delta]\nunit = "deg"\ntable = [[0.0, {delta_deg!r}]]\ndrives = "plant.delta"\n\n'
               f'[signals.omega_ref]\nunit = "rad/s"\ntable = [[0.0, {omega_ref!r}]]\ndrives = "ctrl.omega_ref"\n\n')
    text = text[:start] + signals + text[end:]
    text = text.replace('name = "scenario2"', 'name = "plateau"')
    path = tmp_path / "plateau.toml"
    path.write_text(text, encoding="utf-8")
    return path
