"""The engine as a general FMI 2.0 co-simulation master, on small FMUs written in C
(tests/c_fmus, compiled here): Integer, Enumeration, Boolean and String connections, their
recording and start values, the refusal of connections between different types, and an FMU
that asks to end the simulation. Each run is compared with fmpy.simulate_fmu on the same FMU."""

from __future__ import annotations

import json

import fmpy
import numpy as np
import pytest

from c_fmu_support import build_c_fmu, c_compiler
from fmpy_process import simulate_fmu
from pmsm_cosim.app.cli import main
from pmsm_cosim.engine.errors import CosimError
from pmsm_cosim.engine.master import Master
from pmsm_cosim.engine.recording import read_results
from pmsm_cosim.engine.ssp import load_ssp
from pmsm_cosim.engine.ssp_export import export_ssp
from pmsm_cosim.engine.system import load_system_file

H = 0.01


def _version(text: str) -> tuple[int, ...]:
    return tuple(int(p) for p in text.split(".")[:3] if p.isdigit())

TYPED = ("counter.count -> consumer.k", "counter.level -> consumer.lvl", "counter.odd -> consumer.flag",
         "counter.label -> consumer.text")
COUNTER_COLUMNS = {"count": "counter.count", "level": "counter.level", "odd": "counter.odd",
                   "counter_time": "counter.time_out"}
CONSUMER_COLUMNS = {"k_seen": "consumer.k_seen", "k_sum": "consumer.k_sum", "lvl_seen": "consumer.lvl_seen",
                    "flag_seen": "consumer.flag_seen", "text_len": "consumer.text_len",
                    "text_number": "consumer.text_number"}


@pytest.fixture(scope="session")
def c_fmus(tmp_path_factory):
    """{"Counter": path, "Consumer": path, "Stopper": path}, compiled once per session."""
    compiler = c_compiler()
    if compiler is None:
        pytest.skip("no C compiler found (cc, gcc or $CC): the C test FMUs cannot be built")
    out = tmp_path_factory.mktemp("c_fmus")
    return {name: build_c_fmu(name, out, compiler) for name in ("Counter", "Consumer", "Stopper")}


def system(tmp_path, fmus, components, connections=(), record=None, stop_time=0.2, algorithm="jacobi",
           output_interval=H, name="typed"):
    """Write a system file: components as (instance, FMU name, start table text)."""
    text = f'name = "{name}"\nconnections = [{", ".join(json.dumps(c) for c in connections)}]\n\n'
    text += (f"[experiment]\nstep_size = {H}\nstop_time = {stop_time}\noutput_interval = {output_interval}\n"
             f'algorithm = "{algorithm}"\n\n')
    for inst, fmu, start in components:
        text += f'[[components]]\nname = "{inst}"\nfmu = "{fmus[fmu]}"\n'
        text += f"start = {{ {start} }}\n\n" if start else "\n"
    text += "[record]\ntime = \"time\"\n" + "".join(f'{k} = "{v}"\n' for k, v in (record or {}).items())
    path = tmp_path / f"{name}.toml"
    path.write_text(text, encoding="utf-8")
    return path


def run(path, out, loop=None, sets=()):
    spec = load_system_file(path)
    for assignment in sets:
        spec.set_start(assignment)
    metrics = Master(spec, loop=loop).run(out, catch_sigint=False)
    return metrics, read_results(out)


def typed_system(tmp_path, c_fmus, algorithm="jacobi", order=("counter", "consumer")):
    comps = {"counter": ("counter", "Counter", 'step_by = 3, prefix = "c"'),
             "consumer": ("consumer", "Consumer", "invert = true")}
    return system(tmp_path, c_fmus, [comps[c] for c in order], TYPED, {**COUNTER_COLUMNS, **CONSUMER_COLUMNS},
                  algorithm=algorithm)


# --- typed connections ---------------------------------------------------------------------

def test_integer_enumeration_boolean_and_string_connections(tmp_path, c_fmus):
    """Jacobi: the consumer's step from t_n sees the counter's outputs at t_n, of every type."""
    m, r = run(typed_system(tmp_path, c_fmus), tmp_path / "out")
    assert m["status"] == "completed" and m["rows"] == 21
    count = 3 * np.arange(21)
    assert list(r["count"]) == list(count)
    assert list(r["level"]) == list(1 + count % 3)  # Enumeration: its integer value
    assert list(r["odd"]) == list(count % 2)  # Boolean: 0/1
    seen = count[:-1]  # what the step from t_n saw, recorded at t_{n+1}
    assert list(r["k_seen"][1:]) == list(seen) and r["k_seen"][0] == 0
    assert list(r["k_sum"][1:]) == list(np.cumsum(seen))
    assert list(r["lvl_seen"][1:]) == list(1 + seen % 3)
    assert list(r["flag_seen"][1:]) == list(1 - seen % 2)  # flag xor invert
    assert list(r["text_number"][1:]) == list(seen) and r["text_number"][0] == -1  # the String "c<count>"
    assert list(r["text_len"][1:]) == [len(f"c{k}") for k in seen]


def test_a_string_is_copied_before_the_source_is_called_again(tmp_path, c_fmus):
    """The Counter's strings are valid only until its next call; the Integer and Boolean
    gets after the String get (the connections' order) spoil them. The consumer gets the
    label all the same."""
    connections = (TYPED[3], *TYPED[:3])
    path = system(tmp_path, c_fmus, [("counter", "Counter", 'prefix = "c"'), ("consumer", "Consumer", "")],
                  connections, CONSUMER_COLUMNS, stop_time=0.05)
    for loop in (None, "plain"):  # (the default: the plain loop, the compiled one does not step Strings)
        _, r = run(path, tmp_path / str(loop), loop)
        assert list(r["text_number"]) == [-1, 0, 1, 2, 3, 4], loop
        assert list(r["text_len"]) == [0, 2, 2, 2, 2, 2], loop


def test_gauss_seidel_passes_the_freshest_typed_values(tmp_path, c_fmus):
    _, r = run(typed_system(tmp_path, c_fmus, algorithm="gauss-seidel"), tmp_path / "out")
    assert list(r["k_seen"][1:]) == list(r["count"][1:])  # the counter stepped first
    assert list(r["text_number"][1:]) == list(r["count"][1:])


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_compiled_loop_with_integer_enumeration_and_boolean_connections(tmp_path, c_fmus, algorithm):
    """The compiled loop calls fmi2GetInteger/fmi2SetInteger/fmi2GetBoolean/... by address like
    fmi2GetReal: the same rows as the plain loop. With the String connection as well the plain loop
    runs it by default (the strings are copied between the calls, in Python), with a line saying so,
    and the compiled one is refused by name."""
    comps = [("counter", "Counter", 'step_by = 3, prefix = "c"'), ("consumer", "Consumer", "invert = true")]
    columns = {**COUNTER_COLUMNS, **{k: v for k, v in CONSUMER_COLUMNS.items() if not k.startswith("text")}}
    path = system(tmp_path, c_fmus, comps, TYPED[:3], columns, algorithm=algorithm, name="typed3")
    m_comp, r_comp = run(path, tmp_path / "comp", "compiled")
    m_plain, r_plain = run(path, tmp_path / "plain", "plain")
    assert (m_comp["loop"], m_plain["loop"]) == ("compiled", "plain")
    assert (tmp_path / "comp" / "results.csv").read_bytes() == (tmp_path / "plain" / "results.csv").read_bytes()
    assert list(r_comp["k_seen"][1:]) != [0] * (len(r_comp["k_seen"]) - 1)  # the Integer values went across
    with_strings = typed_system(tmp_path, c_fmus, algorithm=algorithm)
    m_default = run(with_strings, tmp_path / "default")[0]
    assert m_default["loop"] == "plain"
    assert m_default["loop_note"] == ("the plain loop steps typed: consumer has String connections "
                                      "(copied between the calls)")
    with pytest.raises(CosimError, match=r"^the compiled loop cannot step typed: consumer has String connections"):
        run(with_strings, tmp_path / "named", "compiled")


def test_the_same_outputs_as_fmpy(tmp_path, c_fmus):
    """The counter alone in fmpy gives the counter's columns; the consumer in fmpy, fed the
    counter's Integer, Enumeration and Boolean outputs as inputs, gives the consumer's."""
    _, r = run(typed_system(tmp_path, c_fmus), tmp_path / "out")
    counter = simulate_fmu(str(c_fmus["Counter"]), stop_time=0.2, step_size=H, output_interval=H,
                                start_values={"step_by": 3, "prefix": "c"},
                                output=["count", "level", "odd", "time_out"])
    assert list(counter["time"]) == list(r["time"])
    for col, var in (("count", "count"), ("level", "level"), ("odd", "odd")):
        assert list(counter[var].astype(float)) == list(r[col]), col
    # the time the FMU reached, t_n + h: fmpy steps by (n + 1) h - n h, this master by h
    assert list(r["counter_time"][1:]) == [n * H + H for n in range(20)]
    assert np.allclose(counter["time_out"], r["counter_time"], rtol=1e-15, atol=0)
    if _version(fmpy.__version__) < (0, 3, 23):
        # fmpy 0.3.20-0.3.22 give a discrete input at t_n the table's value of t_(n-1) (seen at
        # the floor: the consumer's k_seen one step behind); from 0.3.23 on, the value at t_n
        pytest.skip(f"fmpy {fmpy.__version__} feeds a discrete input one step late; the consumer's "
                    f"comparison needs fmpy >= 0.3.23 (the counter's passed)")
    inputs = np.array(list(zip(counter["time"], counter["count"], counter["level"], counter["odd"])),
                      dtype=[("time", float), ("k", np.int32), ("lvl", np.int32), ("flag", np.bool_)])
    consumer = simulate_fmu(str(c_fmus["Consumer"]), stop_time=0.2, step_size=H, output_interval=H,
                                 start_values={"invert": True}, input=inputs,
                                 output=["k_seen", "k_sum", "lvl_seen", "flag_seen"])
    assert list(consumer["time"]) == list(r["time"])
    for var in ("k_seen", "k_sum", "lvl_seen", "flag_seen"):
        assert list(consumer[var].astype(float)) == list(r[var]), var


def test_typed_start_values_from_the_command_line(tmp_path, c_fmus):
    sets = ("counter.step_by=-2", "counter.prefix=abc", "consumer.invert=false")
    m, r = run(typed_system(tmp_path, c_fmus), tmp_path / "out", sets=sets)
    assert m["status"] == "completed"
    assert list(r["count"][:4]) == [0, -2, -4, -6]
    assert list(r["text_len"][1:4]) == [4, 5, 5]  # "abc0", "abc-2", "abc-4"
    assert list(r["text_number"][1:4]) == [0, 2, 4]  # the digits at the end
    assert list(r["flag_seen"][1:4]) == [0, 0, 0]  # even counts, not inverted


@pytest.mark.parametrize("value, seen", [("High", 3), ("2", 2), ("Low", 1)])
def test_an_enumeration_start_value_by_item_name_or_number(tmp_path, c_fmus, value, seen):
    path = system(tmp_path, c_fmus, [("consumer", "Consumer", "")], record={"lvl_seen": "consumer.lvl_seen"})
    _, r = run(path, tmp_path / "out", sets=(f"consumer.lvl={value}",))
    assert list(r["lvl_seen"][:3]) == [1, seen, seen]


def test_an_unknown_enumeration_item_is_refused(tmp_path, c_fmus):
    path = system(tmp_path, c_fmus, [("consumer", "Consumer", "")], record={"lvl_seen": "consumer.lvl_seen"})
    with pytest.raises(CosimError, match=r"^start value consumer\.lvl: 'Top' is not a valid Enumeration value "
                                         r"\(items: Low=1, Mid=2, High=3\)$"):
        run(path, tmp_path / "out", sets=("consumer.lvl=Top",))


@pytest.mark.parametrize("connection, message", [
    ("counter.count -> consumer.u", "counter.count is an Integer, consumer.u is a Real: a connection joins "
                                    "variables of the same type (no conversion)"),
    ("counter.label -> consumer.k", "counter.label is a String, consumer.k is an Integer: "),
    ("counter.odd -> consumer.k", "counter.odd is a Boolean, consumer.k is an Integer: "),
    ("counter.count -> consumer.lvl", "counter.count is an Integer, consumer.lvl is an Enumeration: "),
    ("counter.level -> consumer.other", "counter.level is an Enumeration, consumer.other is an Enumeration: their "
                                        "enumeration types have different items (Level: Low=1, Mid=2, High=3; "
                                        "Other: A=1, B=2)"),
])
def test_a_connection_between_different_types_is_refused(tmp_path, c_fmus, connection, message):
    path = system(tmp_path, c_fmus, [("counter", "Counter", ""), ("consumer", "Consumer", "")], (connection,))
    with pytest.raises(CosimError) as exc:
        Master(load_system_file(path))
    text = str(exc.value)
    assert f"connection {connection}: {message}" in text and "\n" not in text


def test_a_string_cannot_be_recorded(tmp_path, c_fmus):
    path = system(tmp_path, c_fmus, [("counter", "Counter", "")], record={"label": "counter.label"})
    with pytest.raises(CosimError, match=r"record\.label: counter\.label is a String; only numbers can be recorded"):
        Master(load_system_file(path))


# --- termination ----------------------------------------------------------------------------

@pytest.mark.parametrize("loop", ["compiled", "plain"])
def test_a_termination_request_ends_the_run_as_completed(tmp_path, c_fmus, loop):
    path = system(tmp_path, c_fmus, [("stopper", "Stopper", ""), ("counter", "Counter", "")],
                  record={"y": "stopper.y", "steps": "stopper.steps", "count": "counter.count"}, stop_time=1.0,
                  algorithm="gauss-seidel", name="stop")
    m, r = run(path, tmp_path / "out", loop)
    assert m["status"] == "completed"
    assert (m["terminated_by"], m["terminated_at"], m["macro_steps"], m["rows"]) == ("stopper", 0.5, 50, 51)
    assert json.loads((tmp_path / "out" / "metrics.json").read_text())["terminated_by"] == "stopper"
    assert r["time"][-1] == 0.5 and list(r["count"]) == list(range(51))
    ref = simulate_fmu(str(c_fmus["Stopper"]), stop_time=1.0, step_size=H, output_interval=H,
                            output=["y", "steps"])
    # fmpy records the time the FMU reached once more when it stops: the same row twice
    assert ref["time"][-1] == ref["time"][-2] == 0.5
    assert list(ref["time"][:-1]) == list(r["time"])
    assert list(ref["steps"][:-1].astype(float)) == list(r["steps"]) == list(range(51))
    assert np.allclose(ref["y"][:-1], r["y"], rtol=1e-15, atol=0)  # t_n + h (fmpy: t_n + ((n + 1) h - n h))


@pytest.mark.parametrize("loop", ["compiled", "plain"])
def test_a_termination_inside_a_step_records_the_row_where_the_fmu_ended(tmp_path, c_fmus, loop):
    """The FMU ends the simulation inside its step (Stair: at 9.0 s in its step from 8.8 s): one more row at
    fmi2LastSuccessfulTime with the outputs there, as fmpy records it; terminated_at is that time."""
    path = system(tmp_path, c_fmus, [("stopper", "Stopper", "stop_at = 0.504, inside = true")],
                  record={"y": "stopper.y", "steps": "stopper.steps"}, stop_time=1.0, name="stop")
    m, r = run(path, tmp_path / "out", loop)
    assert (m["status"], m["terminated_by"], m["terminated_at"], m["macro_steps"]) == ("completed", "stopper",
                                                                                       0.504, 50)
    assert m["rows"] == 52 and list(r["time"][-2:]) == [0.5, 0.504]
    assert (r["y"][-1], r["steps"][-1], r["steps"][-2]) == (0.504, 51, 50)
    ref = simulate_fmu(str(c_fmus["Stopper"]), stop_time=1.0, step_size=H, output_interval=H,
                       output=["y", "steps"], start_values={"stop_at": 0.504, "inside": True})
    assert (ref["time"][-1], ref["y"][-1], ref["steps"][-1]) == (0.504, r["y"][-1], r["steps"][-1])


def test_a_termination_keeps_the_rows_recorded_before_it(tmp_path, c_fmus):
    path = system(tmp_path, c_fmus, [("stopper", "Stopper", "stop_at = 0.55")], record={"y": "stopper.y"},
                  stop_time=1.2, output_interval=0.04, name="stop")
    m, r = run(path, tmp_path / "out")
    assert (m["status"], m["terminated_at"], m["macro_steps"]) == ("completed", 0.55, 55)
    assert list(r["time"]) == [k * 4 * H for k in range(14)]  # 0 .. 0.52 s
    assert list(r["y"]) == [0.0] + [(4 * k - 1) * H + H for k in range(1, 14)]  # reached by the step before


def test_a_discarded_step_without_a_termination_request_fails(tmp_path, c_fmus):
    path = system(tmp_path, c_fmus, [("stopper", "Stopper", "discard_only = true")], record={"y": "stopper.y"},
                  stop_time=1.0, name="stop")
    m, r = run(path, tmp_path / "out")
    assert m["status"] == "failed: stopper: fmi2DoStep failed at t = 0.5 s: step refused"
    assert "terminated_by" not in m and m["rows"] == 51 and r["time"][-1] == 0.5


def test_cli_run_of_a_terminated_system_exits_0(tmp_path, c_fmus, capsys):
    path = system(tmp_path, c_fmus, [("stopper", "Stopper", "")], record={"y": "stopper.y"}, stop_time=1.0,
                  name="stop")
    out = tmp_path / "cli"
    assert main(["run", str(path), "--out", str(out), "--quiet", "--no-figures", "--plain-loop"]) == 0
    assert capsys.readouterr().out.startswith("completed: 50 steps")
    metrics = json.loads((out / "metrics.json").read_text())
    assert (metrics["loop"], metrics["terminated_by"], metrics["terminated_at"]) == ("plain", "stopper", 0.5)


# --- SSP ------------------------------------------------------------------------------------

def test_typed_connections_travel_in_an_ssp_package(tmp_path, c_fmus):
    """Integer, Boolean and String connectors and start values: the package runs as the
    system file does; an Enumeration connection is refused (no ssc:Enumeration definitions)."""
    spec = load_system_file(system(tmp_path, c_fmus, [("counter", "Counter", 'step_by = 3, prefix = "c"'),
                                                      ("consumer", "Consumer", "invert = true")],
                                   (TYPED[0], TYPED[2], TYPED[3]), {**COUNTER_COLUMNS, **CONSUMER_COLUMNS}))
    export_ssp(spec, tmp_path / "typed.ssp")
    Master(spec).run(tmp_path / "toml", catch_sigint=False)
    Master(load_ssp(tmp_path / "typed.ssp")).run(tmp_path / "ssp", catch_sigint=False)
    assert (tmp_path / "ssp" / "results.csv").read_bytes() == (tmp_path / "toml" / "results.csv").read_bytes()
    assert list(read_results(tmp_path / "ssp")["text_number"][1:4]) == [0, 3, 6]
    with pytest.raises(CosimError, match=r"export-ssp: connection counter\.level -> consumer\.lvl: Enumeration "
                                         r"connectors cannot be written to an SSP package"):
        export_ssp(load_system_file(typed_system(tmp_path, c_fmus)), tmp_path / "enum.ssp")
