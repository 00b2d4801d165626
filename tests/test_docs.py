"""The README and the FMUs' README checked against the code where a claim can be checked: the commands they
show parse with the CLI's own parser and name shipped scenarios, sweeps and FMUs; the scenario tables name
every shipped scenario and nothing else; the FMU tables name the FMUs the build makes; the Python versions
and the pythonfmu version they state are pyproject.toml's."""

from __future__ import annotations

import re
import shlex
from importlib import resources
from pathlib import Path

import pytest

from pmsm_cosim.app.cli import build_parser
from pmsm_cosim.app.drive import PACKAGED_SCENARIOS
from pmsm_ev.cycles.trace import names as cycle_names
from pmsm_ev_fmus.build import FMUS

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
FMU_README = (ROOT / "fmus" / "README.md").read_text()
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
SHIPPED_SWEEPS = {p.name[:-len(".toml")] for p in (resources.files("pmsm_cosim.app") / "sweeps").iterdir()
                  if p.name.endswith(".toml")}


def _bash_blocks(text: str) -> list[str]:
    return re.findall(r"^```bash\n(.*?)^```", text, flags=re.S | re.M)


def _commands(text: str) -> list[list[str]]:
    """Each ``pmsm-cosim ...`` command of the bash blocks, as its arguments (comments and ``&&`` chains cut)."""
    found = []
    for block in _bash_blocks(text):
        for line in block.splitlines():
            for part in line.split("&&"):
                words = shlex.split(part, comments=True)
                if words[:1] == ["pmsm-cosim"]:
                    found.append(words[1:])
    return found


def _table_rows(text: str, header: str) -> list[str]:
    """The first cells of the rows of every table whose header row begins with ``header``."""
    cells, inside = [], False
    for line in text.splitlines():
        if line.startswith(header):
            inside = True
        elif inside and line.startswith("|---"):
            continue
        elif inside and line.startswith("|"):
            cells.append(line.split("|")[1])
        else:
            inside = False
    return cells


def _expand(cell: str) -> set[str]:
    """The names of a table cell: `a`, `b`, and a cycle family written `wltc3b-x`, ... `us06-x`."""
    found = set(re.findall(r"`([^`]+)`", cell))
    for suffix in re.findall(r"`[a-z0-9]+(-[a-z-]+)`, \.\.\.", cell):
        found |= {f"{cycle}{suffix}" for cycle in cycle_names()}
    return found


COMMANDS = _commands(README)


def test_the_readme_shows_the_commands_of_its_quick_start():
    assert ["run", "scenario1"] in COMMANDS
    assert 'pip install -e ".[test]" && pmsm-cosim run scenario1' in README


@pytest.mark.parametrize("args", COMMANDS, ids=[" ".join(a) for a in COMMANDS])
def test_each_readme_command_parses_and_names_what_ships(args):
    parsed = build_parser().parse_args(args)  # the CLI's own parser: exit 2 on an unknown option
    if parsed.command == "run" and not Path(parsed.system).suffix:
        assert parsed.system in PACKAGED_SCENARIOS
    if parsed.command == "export-ssp":
        assert parsed.system in PACKAGED_SCENARIOS
    if parsed.command == "sweep":
        assert parsed.sweep in SHIPPED_SWEEPS
    if parsed.command == "info" and not parsed.fmu.endswith(".fmu"):
        assert parsed.fmu in FMUS


def test_the_scenario_tables_name_every_shipped_scenario_and_no_other():
    named = set().union(*(_expand(cell) for cell in _table_rows(README, "| name |")))
    shown = {args[1] for args in COMMANDS if args[0] == "run" and not Path(args[1]).suffix}
    assert named <= set(PACKAGED_SCENARIOS), named - set(PACKAGED_SCENARIOS)
    assert set(PACKAGED_SCENARIOS) <= named | shown, set(PACKAGED_SCENARIOS) - named - shown


@pytest.mark.parametrize("text,header", [(README, "| FMU | inputs"), (FMU_README, "| FMU | wraps")],
                         ids=["README", "fmus/README"])
def test_the_fmu_tables_name_the_fmus_the_build_makes(text, header):
    named = set().union(*(set(re.findall(r"`(\w+)\.fmu`", cell)) for cell in _table_rows(text, header)))
    assert named == set(FMUS)


def test_the_python_versions_claimed_are_pyprojects_and_noxs():
    low = re.fullmatch(r">=(\d+\.\d+)", PYPROJECT["project"]["requires-python"]).group(1)
    claimed = re.search(r"supports Python (\d+\.\d+) to (\d+\.\d+)", README).groups()
    nox = re.search(r"PYTHONS = \[(.*?)\]", (ROOT / "noxfile.py").read_text()).group(1)
    nox_versions = re.findall(r'"(\d+\.\d+)"', nox)
    assert claimed[0] == low == nox_versions[0] and claimed[1] == nox_versions[-1]


def test_the_pythonfmu_version_claimed_is_the_pin():
    (pin,) = [d for d in PYPROJECT["project"]["dependencies"] if d.startswith("pythonfmu")]
    low, high = re.fullmatch(r"pythonfmu>=(\S+),<=(\S+)", pin).groups()
    assert low == high
    pinned = low
    for text in (README, FMU_README):
        assert set(re.findall(r"pythonfmu (\d+\.\d+\.\d+)", text)) <= {pinned}
