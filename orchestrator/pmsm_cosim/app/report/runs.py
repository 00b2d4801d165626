"""Running the report's configurations: one ``pmsm-cosim run`` per configuration in its own
process, reused when its settings and FMU builds are unchanged."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from pmsm_ev_fmus.build import build_all, read_build_info

from ...engine.errors import CosimError, one_line
from ..drive import project_fmu_dir
from .configs import FLYING_SPEED, KEY_FILE, Config, select

# --- running ---------------------------------------------------------------------------

def _fmu_hashes(names) -> dict[str, str]:
    try:
        paths = build_all(out_dir=project_fmu_dir(), names=sorted(names))
    except Exception as exc:
        raise CosimError(f"building the FMUs failed: {type(exc).__name__}: {one_line(exc)}") from None
    return {n: (read_build_info(p) or {}).get("hash", "?") for n, p in paths.items()}


def _key(cfg: Config, stop_time, flying_csv: Path, hashes: dict[str, str]) -> dict:
    args = cfg.run_args(stop_time, flying_csv)
    # the flying-start profile by its content, not its path
    args = [f"omega_ref=<constant {FLYING_SPEED!r}>" if a.startswith("omega_ref=") else a for a in args]
    return {"config": cfg.id, "args": args, "fmu_hashes": {k: hashes[v] for k, v in cfg.fmus().items()}}


def _read_json(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def reusable(run_dir: Path, key: dict, ignore_hashes: bool = False) -> bool:
    """A completed run made with these settings (and FMU builds, unless ``ignore_hashes``)."""
    m = _read_json(run_dir / "metrics.json")
    old = _read_json(run_dir / KEY_FILE)
    if not m or m.get("status") != "completed" or old is None:
        return False
    if ignore_hashes:
        return {k: v for k, v in old.items() if k != "fmu_hashes"} == \
               {k: v for k, v in key.items() if k != "fmu_hashes"}
    return old == key


def _run_one(cfg: Config, run_dir: Path, key: dict, stop_time, flying_csv: Path, log) -> tuple[str, float]:
    (run_dir / KEY_FILE).unlink(missing_ok=True)  # a run cut short never looks reusable
    run_dir.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "pmsm_cosim.app.cli", "run", *cfg.run_args(stop_time, flying_csv),
           "--out", str(run_dir), "--quiet", "--no-figures"]
    t0 = time.perf_counter()
    with open(run_dir / "run.log", "w", encoding="utf-8") as fh:
        fh.write(" ".join(cmd) + "\n")
        fh.flush()
        proc = subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, check=False)
    wall = time.perf_counter() - t0
    if proc.returncode == 2:
        text = (run_dir / "run.log").read_text(encoding="utf-8").strip().splitlines()
        raise CosimError(f"{cfg.id}: {text[-1] if text else 'pmsm-cosim run failed'}")
    m = _read_json(run_dir / "metrics.json") or {}
    status = str(m.get("status", f"exit code {proc.returncode}"))
    if status == "completed":
        (run_dir / KEY_FILE).write_text(json.dumps(key, indent=2) + "\n", encoding="utf-8")
    log(f"{cfg.id}: {status} in {wall:.0f} s")
    return status, wall


def run_configs(configs: list[Config], runs_dir: Path, jobs: int = 2, stop_time: float | None = None,
                only=None, force: bool = False, log=print) -> dict[str, Path]:
    """Make (or reuse) the run of every configuration; {config id: run directory}."""
    runs_dir = Path(runs_dir)
    runs_dir.mkdir(parents=True, exist_ok=True)
    flying_csv = runs_dir / "omega_ref_flying.csv"
    flying_csv.write_text(f"time,omega_ref\n0,{FLYING_SPEED!r}\n", encoding="ascii")
    hashes = _fmu_hashes({n for c in configs for n in c.fmus().values()})
    selected = {c.id for c in (select(configs, only) if only else configs)}
    todo = []
    for cfg in configs:
        run_dir = runs_dir / cfg.id
        key = _key(cfg, stop_time, flying_csv, hashes)
        if cfg.id in selected:
            if force or not reusable(run_dir, key):
                todo.append((cfg, run_dir, key))
        elif not reusable(run_dir, key, ignore_hashes=True):
            raise CosimError(f"{run_dir}: no completed run of {cfg.id} with these settings to reuse "
                             f"(run the report without --only first)")
    log(f"{len(configs) - len(todo)} runs reused, {len(todo)} to run, {jobs} at a time, in {runs_dir}")
    if todo:
        with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
            futures = [pool.submit(_run_one, cfg, d, k, stop_time, flying_csv, log) for cfg, d, k in todo]
            for f in futures:
                f.result()
    return {cfg.id: runs_dir / cfg.id for cfg in configs}


