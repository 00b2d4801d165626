"""What the report runs: the observer setups, the scenarios, one :class:`Config` per run."""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass
from pathlib import Path

from ...engine.errors import CosimError
from . import sensorless

#: the speed of the flying starts [rad/s]: the paper's constant reference (Fig. 8)
FLYING_SPEED = 200.0
#: file in each run directory with the settings the run was made with
KEY_FILE = "report-run.json"

PLANT_FMU = "PmsmEvPlant"
OBSERVER_FMUS = {"ekf5": "FocEkf5", "ekf4": "FocEkf4", "ekf5ab": "FocEkf5AB", "sensored": "FocSensored",
                 "sensorless": "FocSensorless"}


@dataclass(frozen=True)
class Setup:
    """An observer configuration: FMU, angle source, start."""

    key: str
    observer: str
    angle_source: str
    flying: bool
    label: str


SETUPS = {s.key: s for s in (
    Setup("ekf5-paper", "ekf5", "measured", False, "EKF5 paper mode"),
    Setup("ekf5-sensorless", "ekf5", "estimated", False, "EKF5 sensorless"),
    Setup("ekf5ab", "ekf5ab", "estimated", True, "EKF5 αβ sensorless, flying start"),
    Setup("ekf4-paper", "ekf4", "measured", False, "EKF4 paper mode"),
    Setup("ekf4-sensorless", "ekf4", "estimated", False, "EKF4 sensorless"),
    Setup("sensored", "sensored", "measured", False, "sensored"),
)}
#: the sensorless unit from standstill (section "Sensorless from standstill")
SENSORLESS_SETUP = Setup("sensorless", "sensorless", "estimated", False, "sensorless from standstill")

#: the whole speed range's acceleration runs (section "The whole speed range", ``speed_range``):
#: (config id, shipped scenario, setup)
SPEED_RANGE_RUNS = (
    ("accel-sensored", "acceleration", SETUPS["sensored"]),
    ("accel-ekf5ab", "acceleration-flying", Setup("ekf5ab-flying", "ekf5ab", "estimated", False,
                                                  "EKF5 αβ sensorless, flying start at 200 rad/s")),
    ("accel-sensorless", "acceleration-if", SENSORLESS_SETUP),
)

#: the drive cycles (section "Drive cycles", ``cycles``): (config id, shipped scenario, setup); the sensored
#: drive sets the reference, the sensorless unit from standstill with the I-f strategy (the ``-if`` scenarios,
#: whose start-up costs the section measures) is held to it; the injection's cycles (the shipped
#: ``-sensorless`` scenarios) are compared in docs/sensorless.md, "The cycles with injection"
CYCLE_RUNS = tuple(
    (f"cyc-{name}{suffix}", f"{name}{suffix}", setup)
    for name in ("wltc3b", "udds", "hwfet", "us06")
    for suffix, setup in (("", SETUPS["sensored"]), ("-if", SENSORLESS_SETUP))
) + (("cyc-wltc3b-hilly", "wltc3b-hilly", SETUPS["sensored"]),)

#: the paper's scenarios: (short name, shipped scenario)
PAPER_SCENARIOS = (("s1", "scenario1"), ("s2", "scenario2"))
#: the realism variants of scenario 2: (short name, shipped scenario, description)
REALISM_SCENARIOS = (
    ("noisy", "scenario2-noisy", "current-sensor noise σ = 0.1 A"),
    ("noisy1A", "scenario2-noisy1A", "current-sensor noise σ = 1 A"),
    ("offset", "scenario2-offset", "sensor offsets +2 A (a), −1 A (b)"),
    ("angle", "scenario2-angle-error", "initial angle error −0.5 rad"),
)
#: file-name part of the variants' figures
FIG_NAMES = {"noisy": "noisy", "noisy1A": "noisy1A", "offset": "offset", "angle": "initial_angle"}
REALISM_SETUPS = ("ekf5-paper", "ekf5-sensorless", "ekf5ab", "ekf4-paper")


@dataclass(frozen=True)
class Config:
    """One run of the report."""

    id: str
    scenario: str  #: shipped scenario name
    setup: Setup
    section: str  #: "paper", "realism", "sensorless", "speed-range" or "cycles"
    variant: str = ""  #: short name of the realism variant
    sets: tuple[str, ...] = ()  #: more start values (``--set``)
    stop_time: float | None = None  #: its own stop time [s]; a shorter one of the report's wins
    description: str = ""  #: the variant as the tables show it

    @property
    def label(self) -> str:
        return self.setup.label

    def fmus(self) -> dict[str, str]:
        return {"ctrl": OBSERVER_FMUS[self.setup.observer], "plant": PLANT_FMU}

    def run_args(self, stop_time: float | None, flying_csv: Path) -> list[str]:
        """Arguments of ``pmsm-cosim run`` (without ``--out``)."""
        s = self.setup
        args = [self.scenario, "--controller", s.observer]  # its FMU in the project's folder, wherever that is
        sets = []
        if s.observer not in ("sensored", "sensorless"):  # these have no angle_source
            sets.append(f"ctrl.angle_source={s.angle_source}")
        sets += self.sets
        if s.flying:
            sets += [f"plant.omega_m0={FLYING_SPEED!r}", f"ctrl.x0_omega={FLYING_SPEED!r}"]
            args += ["--profile", f"omega_ref={flying_csv}"]
        if sets:
            args += ["--set", *sets]
        if self.stop_time is not None:
            stop_time = self.stop_time if stop_time is None else min(stop_time, self.stop_time)
        if stop_time is not None:
            args += ["--stop-time", repr(float(stop_time))]
        return args


def all_configs() -> list[Config]:
    configs = [Config(f"{short}-{key}", scen, setup, "paper")
               for short, scen in PAPER_SCENARIOS for key, setup in SETUPS.items()]
    configs += [Config(f"s2-{short}-{key}", scen, SETUPS[key], "realism", short)
                for short, scen, _ in REALISM_SCENARIOS for key in REALISM_SETUPS]
    setups = {"sensorless": SENSORLESS_SETUP, "sensored": SETUPS["sensored"]}
    configs += [Config(cid, scen, setups[key], "sensorless", sets=sets, stop_time=stop, description=desc)
                for cid, scen, key, sets, stop, desc in sensorless.config_specs()]
    configs += [Config(cid, scen, setup, "speed-range") for cid, scen, setup in SPEED_RANGE_RUNS]
    configs += [Config(cid, scen, setup, "cycles") for cid, scen, setup in CYCLE_RUNS]
    return configs


CONFIGS = all_configs()


def select(configs: list[Config], patterns) -> list[Config]:
    """Configurations whose id matches one of the patterns (fnmatch; a plain word matches
    any id containing it, e.g. ``ekf5ab`` or ``s2-noisy``)."""
    pats = [p if any(ch in p for ch in "*?[") else f"*{p}*" for p in patterns]
    chosen = [c for c in configs if any(fnmatch.fnmatchcase(c.id, p) for p in pats)]
    if not chosen:
        raise CosimError(f"--only {' '.join(patterns)}: matches no configuration; ids: "
                         + ", ".join(c.id for c in configs))
    return chosen


