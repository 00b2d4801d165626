"""The README and the FMUs' README checked against the code where a claim can be checked: the commands they
show, in code blocks and in the text, parse with the parser of the program they name (the CLI's, the FMU build's,
the monolithic reference's, the benchmarks') and name shipped scenarios, sweeps and FMUs; every option the text
names is one of the CLI's, with the defaults it states; the scenario tables name every shipped scenario and nothing
else, and every scenario named in the text ships; the FMU tables name the FMUs the build makes and what each wraps;
the sensorless unit's strategies, the one each shipped scenario runs and the figures stated of them are the code's;
the versions stated (Python, pythonfmu, fmpy) are pyproject.toml's; the repository paths and the Python names in
the text exist. And the links of the docs reach their files and headings, and the references by section name to
the READMEs and the performance pages name a heading."""

from __future__ import annotations

import argparse
import importlib
import inspect
import re
import shlex
from importlib import resources
from pathlib import Path

import pytest

from pmsm_cosim.app import bench, reference
from pmsm_cosim.app.cli import build_parser
from pmsm_cosim.app.drive import PACKAGED_SCENARIOS, packaged_scenario
from pmsm_cosim.app.report.configs import all_configs
from pmsm_ev.cycles.trace import names as cycle_names
from pmsm_ev.params import LOW_SPEED_STRATEGIES, ControllerParams, DriveParams, InjectionParams, StartupParams
from pmsm_ev_fmus import build as fmu_build
from pmsm_ev_fmus.build import FMUS, OBSERVER_FMUS

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
FMU_README = (ROOT / "fmus" / "README.md").read_text()
PERFORMANCE = (ROOT / "docs" / "performance.md").read_text()
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
SHIPPED_SWEEPS = {p.name[:-len(".toml")] for p in (resources.files("pmsm_cosim.app") / "sweeps").iterdir()
                  if p.name.endswith(".toml")}
#: the pages whose commands are checked: the two READMEs and today's performance page (its log is history: the
#: commands of its entries ran on the code of their dates)
PAGES = {"README": README, "fmus/README": FMU_README, "docs/performance": PERFORMANCE}


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(action.choices)


def _options(parser: argparse.ArgumentParser) -> set[str]:
    return {o for a in parser._actions for o in a.option_strings}


CLI = build_parser()
SUBCOMMANDS = _subparsers(CLI)
CLI_OPTIONS = _options(CLI).union(*(_options(p) for p in SUBCOMMANDS.values()))


def _bash_blocks(text: str) -> list[str]:
    return re.findall(r"^```bash\n(.*?)^```", text, flags=re.S | re.M)


def _prose(text: str) -> str:
    """The text without its fenced code blocks, each paragraph on one line (a code span may wrap)."""
    return re.sub(r"\s*\n\s*", " ", re.sub(r"^[ \t]*```.*?^[ \t]*```", "", text, flags=re.S | re.M))


def _spans(text: str) -> list[str]:
    """The code spans of the text outside its code blocks."""
    return re.findall(r"`([^`]+)`", _prose(text))


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


def _inline_commands(text: str, program: str = "pmsm-cosim") -> list[list[str]]:
    """Each command of ``program`` written as a code span in the text, as its arguments."""
    return [shlex.split(span)[1:] for span in _spans(text) if span.split()[:1] == [program]]


PLACEHOLDER = "PLACEHOLDER"


def _placeholders(args: list[str]) -> list[str]:
    """The arguments with the text's placeholders (NAME, DIR, FILE.ssp, RUN_DIR..., SCENARIO_OR_SYSTEM, T) as one
    word, keeping a file name's suffix; an option's value as 1 (a number, a directory or a pattern alike)."""
    out = []
    for word in args:
        stem, dot, suffix = word.rstrip(".").partition(".")
        if re.fullmatch(r"[A-Z][A-Z_]*", stem) and not word.startswith("-"):
            word = "1" if out and out[-1].startswith("-") else PLACEHOLDER + (dot + suffix if suffix.islower() else "")
        out.append(word)
    return out


def _check_command(args: list[str]) -> None:
    """The command parses with the CLI's own parser (exit 2 on an unknown option) and names what ships."""
    if args in ([], ["--version"]) or (len(args) == 1 and args[0] in SUBCOMMANDS):
        assert not args or args[0] in SUBCOMMANDS or args[0] in _options(CLI)
        return
    args = _placeholders(args)
    if args[0] == "export-ssp" and not {"-o", "--output"} & set(args):
        args += ["-o", f"{PLACEHOLDER}.ssp"]  # the text names the package written, not where it goes
    parsed = CLI.parse_args(args)
    named = {"run": "system", "export-ssp": "system", "sweep": "sweep", "info": "fmu"}.get(parsed.command)
    value = getattr(parsed, named) if named else PLACEHOLDER
    if value.startswith(PLACEHOLDER) or Path(value).suffix:
        return  # a placeholder of the text, or a file
    if parsed.command in ("run", "export-ssp"):
        assert value in PACKAGED_SCENARIOS
    elif parsed.command == "sweep":
        assert value in SHIPPED_SWEEPS
    else:
        assert value in FMUS


def _table_rows(text: str, header: str) -> list[str]:
    """The rows (as lists of cells) of every table whose header row begins with ``header``."""
    rows, inside = [], False
    for line in text.splitlines():
        if line.startswith(header):
            inside = True
        elif inside and line.startswith("|---"):
            continue
        elif inside and line.startswith("|"):
            rows.append(line.split("|")[1:-1])
        else:
            inside = False
    return rows


def _expand(cell: str) -> set[str]:
    """The names of a table cell: `a`, `b`, and a cycle family written `wltc3b-x`, ... `us06-x`."""
    found = set(re.findall(r"`([^`]+)`", cell))
    for suffix in re.findall(r"`[a-z0-9]+(-[a-z-]+)`, \.\.\.", cell):
        found |= {f"{cycle}{suffix}" for cycle in cycle_names()}
    return found


def _each(pattern: str, text: str) -> list[tuple[str, ...]]:
    """The groups of each place ``pattern`` matches the text (paragraphs on one line): the claims checked."""
    found = [m if isinstance(m, tuple) else (m,) for m in re.findall(pattern, _prose(text))]
    assert found, f"the claim {pattern!r} is not made"
    return found


def _one(pattern: str, text: str) -> tuple[str, ...]:
    """The groups of the one place ``pattern`` matches the text: the claim checked."""
    found = _each(pattern, text)
    assert len(found) == 1, f"the claim {pattern!r} is made {len(found)} times, not once"
    return found[0]


COMMANDS = _commands(README)
ALL_COMMANDS = [(page, args) for page, text in PAGES.items()
                for args in _commands(text) + _inline_commands(text)]


def test_the_readme_shows_the_commands_of_its_quick_start():
    assert ["run", "scenario1"] in COMMANDS
    assert 'pip install -e ".[test]" && pmsm-cosim run scenario1' in README


@pytest.mark.parametrize("page,args", ALL_COMMANDS, ids=[f"{p}: {' '.join(a)}" for p, a in ALL_COMMANDS])
def test_each_command_shown_parses_and_names_what_ships(page, args):
    _check_command(args)


def test_the_commands_are_found():
    """Code blocks and code spans of each page: a parser of the text that finds nothing checks nothing."""
    assert len(COMMANDS) >= 25 and len(_inline_commands(README)) >= 10 and len(_inline_commands(FMU_README)) >= 5


#: options the text names that are not this project's: the configure option of CPython's build
FOREIGN_OPTIONS = {"--enable-shared"}


@pytest.mark.parametrize("page", ["README", "fmus/README"])
def test_every_option_the_text_names_is_the_clis(page):
    named = {span.split()[0].split("=")[0] for span in _spans(PAGES[page]) if span.startswith("--")}
    assert named, "no option found in the text"
    assert named - FOREIGN_OPTIONS <= CLI_OPTIONS, named - FOREIGN_OPTIONS - CLI_OPTIONS


def test_the_commands_that_take_fmu_dir_are_the_clis():
    (listed,) = _one(r"`--fmu-dir DIR` \(every command that uses the FMUs: ((?:`[\w-]+`(?:, )?)+)\)", README)
    taking = {name for name, parser in SUBCOMMANDS.items() if "--fmu-dir" in _options(parser)}
    assert set(re.findall(r"`([\w-]+)`", listed)) == taking


@pytest.mark.parametrize("pattern,command,dest", [
    (r"`--jobs N` at a time \(default (\d+)\)", "report", "jobs"),
    (r"after `--from` seconds \(default (\d+),", "compare", "t_from"),
], ids=["report --jobs", "compare --from"])
def test_the_option_defaults_stated_are_the_clis(pattern, command, dest):
    (stated,) = _one(pattern, README)
    assert float(stated) == SUBCOMMANDS[command].get_default(dest)


def _help(main) -> str:
    with pytest.raises(SystemExit) as exit_:
        main(["--help"])
    assert exit_.value.code == 0
    return main.__module__


@pytest.mark.parametrize("module,main", [("pmsm_ev_fmus", fmu_build.main),
                                         ("pmsm_cosim.app.reference", reference.main)])
def test_the_python_m_commands_shown_take_the_options_they_show(module, main, capsys):
    """``python -m pmsm_ev_fmus [--out DIR] [--force] [--fmi 2|3] [NAME ...]`` and the like: each option shown is
    one of the module's (its --help), each FMU named is built."""
    _help(main)
    options = set(re.findall(r"--[\w-]+", capsys.readouterr().out))
    shown = [m for text in (README, FMU_README) for m in re.findall(rf"python -m {re.escape(module)}((?: [^`\n#]*)?)",
                                                                   text)]
    assert shown, f"no python -m {module} in the READMEs"
    for arguments in shown:
        assert set(re.findall(r"--[\w-]+", arguments)) <= options, (arguments, options)
    if module == "pmsm_ev_fmus":
        (versions,) = re.findall(r"python -m pmsm_ev_fmus .*\[--fmi ([\d|]+)\]", FMU_README)
        assert tuple(int(v) for v in versions.split("|")) == tuple(fmu_build.FMI_VERSIONS)


def test_the_benchmarks_settings_stated_are_its_own():
    """docs/performance.md: the slices' defaults and least, the scenarios of the memory runs."""
    block = "\n".join(_bash_blocks(PERFORMANCE))
    ((slice_, least),) = re.findall(r"--slice 35 +# simulated seconds per case \(default (\d+), at least (\d+)\)",
                                    block)
    (cycle_slice,) = re.findall(r"--cycle-slice 120 # seconds of WLTC 3b in cases \(e\)-\(h\) \(default (\d+)\)",
                                block)
    assert (float(slice_), float(cycle_slice)) == (bench.DEFAULT_SLICE, bench.DEFAULT_CYCLE_SLICE)
    with pytest.raises(bench.CosimError):
        bench._check_slice(float(least) - 1e-4, "--slice")
    bench._check_slice(float(least), "--slice")
    (memory,) = _one(r"Then it runs `pmsm-cosim run (\S+) --stop-time T`", PERFORMANCE)
    (cycle_memory,) = _one(r"With `--cycle-memory` it runs `pmsm-cosim run (\S+) --cycle wltc3b", PERFORMANCE)
    assert (memory, cycle_memory) == (bench.SCENARIO, bench.CYCLE_MEMORY_SYSTEM)


def test_the_benchmark_scripts_shown_exist_and_take_the_options_shown():
    shown = [m for text in PAGES.values() for m in re.findall(r"python (benchmarks/\w+\.py)((?: --?[\w-]+(?: \w+)?)*)",
                                                               text)]
    assert shown
    for script, arguments in shown:
        source = (ROOT / script).read_text()
        for option in re.findall(r"--[\w-]+", arguments):
            assert f'"{option}"' in source, (script, option)


def test_the_scenario_tables_name_every_shipped_scenario_and_no_other():
    named = set().union(*(_expand(row[0]) for row in _table_rows(README, "| name |")))
    shown = {args[1] for args in COMMANDS if args[0] == "run" and not Path(args[1]).suffix}
    assert named <= set(PACKAGED_SCENARIOS), named - set(PACKAGED_SCENARIOS)
    assert set(PACKAGED_SCENARIOS) <= named | shown, set(PACKAGED_SCENARIOS) - named - shown


@pytest.mark.parametrize("page", ["README", "fmus/README"])
def test_every_scenario_the_text_names_ships(page):
    """Every name of the text's kind of a scenario (lower case, with hyphens) is a shipped scenario, but the CLI's
    own names."""
    names = {s for s in _spans(PAGES[page]) if re.fullmatch(r"[a-z0-9]+(?:-[a-z0-9]+)+", s)}
    assert names - {"pmsm-cosim", *SUBCOMMANDS} <= set(PACKAGED_SCENARIOS), \
        names - {"pmsm-cosim", *SUBCOMMANDS} - set(PACKAGED_SCENARIOS)


def test_the_reports_run_counts_are_its_configurations():
    """`pmsm-cosim report  # 74 runs (..., 9 whole drive cycles)` and the paper's, the realism's and the sensorless
    sections' "(62 runs in all)"."""
    (block,) = [line for block in _bash_blocks(README) for line in block.splitlines()
                if line.split("#")[0].split() == ["pmsm-cosim", "report"]]
    runs, cycles = re.search(r"# (\d+) runs \(most of 350 s, (\d+) whole drive cycles\)", block).groups()
    (described,) = _one(r"from (?:\d+) initial rotor angles \((\d+) runs in all\)", README)
    sections = [config.section for config in all_configs()]
    assert (int(runs), int(cycles), int(described)) == (
        len(sections), sections.count("cycles"), sum(s in ("paper", "realism", "sensorless") for s in sections))


def test_the_quick_start_runs_scenario1_as_it_says():
    stop, step = _one(r"co-simulates scenario 1 \((\d+) s at a ([\d.e-]+) s step\)", README)
    (rows,) = _one(r"`results\.csv` \(signals every (\d+) ms\)", README)
    experiment = tomllib.loads(packaged_scenario("scenario1").read_text())["experiment"]
    assert (float(stop), float(step), float(rows) / 1e3) == (
        experiment["stop_time"], experiment["step_size"], experiment["output_interval"])


@pytest.mark.parametrize("text,header", [(README, "| FMU | inputs"), (FMU_README, "| FMU | wraps")],
                         ids=["README", "fmus/README"])
def test_the_fmu_tables_name_the_fmus_the_build_makes(text, header):
    named = set().union(*(set(re.findall(r"`(\w+)\.fmu`", row[0])) for row in _table_rows(text, header)))
    assert named == set(FMUS)


def test_what_each_fmu_wraps_is_what_its_slave_runs():
    for cell, wraps, _ in _table_rows(FMU_README, "| FMU | wraps"):
        (fmu,) = re.findall(r"`(\w+)\.fmu`", cell)
        observer = re.fullmatch(r' `ControlUnit\("(\w+)"\)` ', wraps)
        if observer:
            assert OBSERVER_FMUS[observer.group(1)] == fmu
        else:
            (name,) = re.findall(r"`([\w.]+)`", wraps)
            module, _, cls = name.rpartition(".")
            assert hasattr(importlib.import_module(module), cls)
            assert re.search(rf"\b{cls}\b", (ROOT / "fmus" / FMUS[fmu][0]).read_text()), (fmu, name)


def _sensorless_scenarios() -> dict[str, str]:
    """The shipped scenarios that run FocSensorless, each with its strategy at and near zero speed."""
    found = {}
    for name in PACKAGED_SCENARIOS:
        components = tomllib.loads(packaged_scenario(name).read_text()).get("components", [])
        for component in components:
            if component["fmu"].endswith("/FocSensorless.fmu"):
                found[name] = component.get("start", {}).get("low_speed", InjectionParams().low_speed)
    return found


def test_the_sensorless_units_strategies_are_the_codes():
    """FocSensorless: FOC on the EKF at speed and one of two strategies at and near zero speed, I-f the FMU's
    default and the paper scenarios', injection the other shipped sensorless drives'; the FMU says so of itself."""
    assert LOW_SPEED_STRATEGIES == ("if", "injection")
    _one(r"one of two strategies \(`low_speed`\): injection .*? or, the FMU's default, the I-f strategy", README)
    _one(r"either high-frequency injection \(.*?\) or alignment and an I-f start \(the FMU's default\)", FMU_README)
    assert InjectionParams().low_speed == "if"
    (suffix,) = _one(r"The I-f strategy ships beside each as `(-\w+)`", README)
    (paper,) = _one(r"it stays the FMU's default and the paper scenarios' \(([^)]*)\)", README)
    if_scenarios = {n for n in _sensorless_scenarios() if n.endswith(suffix)} | set(re.findall(r"`([\w-]+)`", paper))
    strategies = _sensorless_scenarios()
    assert if_scenarios <= set(strategies)
    assert {n: s for n, s in strategies.items() if n in if_scenarios} == dict.fromkeys(if_scenarios, "if")
    assert {n: s for n, s in strategies.items() if n not in if_scenarios} == \
        dict.fromkeys(set(strategies) - if_scenarios, "injection")
    # the polarity test needs the plant's algebraic flux model: every injection scenario has it
    for name, strategy in strategies.items():
        plant = [c for c in tomllib.loads(packaged_scenario(name).read_text())["components"]
                 if c["fmu"].endswith("/PmsmEvPlant.fmu")]
        assert strategy == "if" or plant[0]["start"]["flux_model"] == "algebraic", name
    # the FMU's own description (its modelDescription.xml) names both strategies
    source = (ROOT / "fmus" / FMUS["FocSensorless"][0]).read_text()
    assert all(f'\\"{strategy}\\"' in source for strategy in LOW_SPEED_STRATEGIES) and "low_speed" in source


DT = DriveParams().dt


@pytest.mark.parametrize("text,pattern,value", [
    (README, r"handover to field-oriented control on the EKF5 above (\d+) rad/s and back to I-f below (\d+) rad/s",
     (StartupParams().omega_up, StartupParams().omega_down)),
    (README, r"handover at (\d+) / (\d+) rad/s \(`StartupParams`\)", (StartupParams().omega_up,
                                                                     StartupParams().omega_down)),
    (README, r"a (\d+) V square wave at (\d+) kHz", (InjectionParams().inj_voltage,
                                                     (InjectionParams().inj_frequency or 1 / (2 * DT)) / 1e3)),
    (README, r"saturation \(±(\d+) A pulses", (InjectionParams().pol_current,)),
    (README, r"a \+(\d+)/−(\d+)/\+(\d+) A palindrome", (InjectionParams().pol_current,) * 3),
    (README, r"the EKF blended in from (\d+) rad/s and alone from (\d+) rad/s", (InjectionParams().inj_blend_low,
                                                                                InjectionParams().inj_blend_high)),
    (README, r"a tracking observer with three poles at -(\d+) rad/s", (InjectionParams().inj_bandwidth,)),
    (README, r"\| control period dt \| ([\d.e-]+) s", (DT,)),
    (FMU_README, r"`omega_c` \(current loops, (\d+) rad/s\), `omega_n` \(speed loop, (\d+) rad/s\), `zeta` \((\d+)\)",
     (ControllerParams().omega_c, ControllerParams().omega_n, ControllerParams().zeta)),
    (FMU_README, r"`J_load` \(the vehicle's inertia at the shaft, ([\d.]+) kg m\^2\)", (ControllerParams().J_load,)),
    (README, r"J_eq = ([\d.]+) kg m\^2", (ControllerParams().J_load + DriveParams().motor.J_m,)),
], ids=["I-f handover", "I-f handover, table", "square wave", "polarity pulses", "polarity palindrome",
        "blend", "tracking observer", "control period", "bandwidths", "J_load", "J_eq"])
def test_the_figures_stated_of_the_drive_are_its_defaults(text, pattern, value):
    for claim in _each(pattern, text):
        assert tuple(float(v) for v in claim) == pytest.approx(value, rel=0.01 if "." in pattern else 1e-12)


def test_the_python_versions_claimed_are_pyprojects_and_noxs():
    low = re.fullmatch(r">=(\d+\.\d+)", PYPROJECT["project"]["requires-python"]).group(1)
    claimed = re.search(r"supports Python (\d+\.\d+) to (\d+\.\d+)", README).groups()
    (quick_start,) = _one(r"On a machine with Python >= (\d+\.\d+)", README)
    nox = re.search(r"PYTHONS = \[(.*?)\]", (ROOT / "noxfile.py").read_text()).group(1)
    nox_versions = re.findall(r'"(\d+\.\d+)"', nox)
    assert claimed[0] == low == quick_start == nox_versions[0] and claimed[1] == nox_versions[-1]


def _pin(package: str) -> str:
    (pin,) = [d for d in PYPROJECT["project"]["dependencies"] if re.match(rf"{package}\b", d)]
    return pin


def test_the_pythonfmu_version_claimed_is_the_pin():
    low, high = re.fullmatch(r"pythonfmu>=(\S+),<=(\S+)", _pin("pythonfmu")).groups()
    assert low == high
    pinned = low
    for text in (README, FMU_README):
        assert set(re.findall(r"pythonfmu (\d+\.\d+\.\d+)", text)) <= {pinned}
    assert pinned in README and pinned in FMU_README


def test_the_fmpy_version_named_is_the_floors_series():
    """fmpy's behaviour is described of the series pyproject.toml's floor is in (``fmpy 0.3 does not read ...``)."""
    (floor,) = re.fullmatch(r"fmpy>=(\d+\.\d+)\.\d+", _pin("fmpy")).groups()
    named = set(re.findall(r"\bfmpy (\d+\.\d+)\b", _prose(README) + _prose(FMU_README)))
    assert named == {floor}


@pytest.mark.parametrize("page", ["README", "fmus/README"])
def test_the_repository_paths_named_exist(page):
    paths = {s for s in _spans(PAGES[page])
             if re.fullmatch(r"(src|fmus|orchestrator|tests|benchmarks|docs)/[\w./-]*|noxfile\.py|pyproject\.toml", s)}
    base = {"README": ROOT, "fmus/README": ROOT / "fmus"}[page]
    assert paths
    assert [p for p in paths if not (ROOT / p).exists() and not (base / p).exists()] == []


@pytest.mark.parametrize("page", ["README", "fmus/README"])
def test_the_python_names_named_exist(page):
    """`pmsm_ev.controller.controller_gains`, `pmsm_ev_fmus.build_all(out_dir=None, force=False, names=None)`: the
    name is importable, and a call shown names the function's own parameters and defaults."""
    found = [m for m in re.findall(r"`((?:pmsm_ev|pmsm_ev_fmus|pmsm_cosim)(?:\.\w+)+)(\([^()`]*\)(?=`))?",
                                  _prose(PAGES[page]))]
    assert found
    for name, call in found:
        parts = name.split(".")
        obj, cut = importlib.import_module(parts[0]), 1
        while cut < len(parts) and hasattr(obj, "__path__"):  # a package: the next part may be its module
            try:
                obj, cut = importlib.import_module(".".join(parts[:cut + 1])), cut + 1
            except ModuleNotFoundError:
                break
        for attribute in parts[cut:]:
            obj = getattr(obj, attribute)
        if call and call != "()":
            signature = inspect.signature(obj).parameters
            for argument in call[1:-1].split(", "):
                parameter, _, default = argument.partition("=")
                assert parameter in signature, (name, parameter)
                if default:
                    assert repr(signature[parameter].default) == default, (name, parameter)


# the links of the docs and the references by section name

DOCS = [ROOT / "README.md", ROOT / "fmus" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _anchors(page: Path) -> set[str]:
    """GitHub's anchors of the page's headings (lower case, punctuation dropped, spaces as hyphens)."""
    text = re.sub(r"^[ \t]*```.*?^[ \t]*```", "", page.read_text(), flags=re.S | re.M)
    return {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-")
            for h in re.findall(r"^#{1,6} (.+)$", text, flags=re.M)}


@pytest.mark.parametrize("page", DOCS, ids=[str(p.relative_to(ROOT)) for p in DOCS])
def test_the_links_of_the_docs_reach_their_files_and_headings(page):
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists() or (anchor and file.suffix == ".md" and anchor not in _anchors(file)):
            broken.append(target)
    assert broken == []


#: the pages whose sections other files name: `docs/performance.md, "The plant's integrator"`
NAMED_PAGES = [ROOT / "README.md", ROOT / "fmus" / "README.md", ROOT / "docs" / "performance.md",
               ROOT / "docs" / "performance-log.md"]


def _headings(page: Path) -> list[str]:
    text = re.sub(r"^[ \t]*```.*?^[ \t]*```", "", page.read_text(), flags=re.S | re.M)
    return [h.strip() for h in re.findall(r"^#{1,6} (.+)$", text, flags=re.M)]


def test_the_sections_named_of_the_readmes_and_the_performance_pages_are_there():
    """A reference by name, `docs/performance.md, "The plant's integrator"` in a comment or a page, names the
    beginning of a heading of that page."""
    missing, seen = [], 0
    project = [f for d in ("src", "orchestrator", "fmus", "tests", "docs", "benchmarks") for f in (ROOT / d).rglob("*")]
    for file in project + sorted(ROOT.glob("*")):  # the project's own folders (not a virtual environment in the root)
        if not file.is_file():
            continue
        relative = file.relative_to(ROOT)
        if file.suffix not in (".py", ".md", ".toml", ".c", ".h") or any(
                part.startswith(".") or part in ("runs", "build") or part.endswith(".egg-info")
                for part in relative.parts):
            continue
        flat = re.sub(r"\s*\n\s*(?:#+ |// |\* )?", " ", file.read_text())
        for name, section in re.findall(r"([\w./-]*\w\.md)\)?, \"([^\"]{3,}?)\"", flat):
            page = next((p for p in (ROOT / name, file.parent / name, ROOT / "docs" / Path(name).name)
                         if p.exists()), None)
            if page is None or page.resolve() not in NAMED_PAGES:
                continue
            seen += 1
            if not any(h.startswith(section) for h in _headings(page)):
                missing.append(f"{relative}: {name}, {section!r}")
    assert seen >= 10
    assert missing == []
