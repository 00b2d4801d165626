"""SSP 1.0 packages (System Structure and Parameterization, Modelica Association): a
system as one ``.ssp`` zip that other co-simulation masters run unchanged.

The format (namespaces, annotations) and reading a package; writing one is
:mod:`pmsm_cosim.engine.ssp_export`. :func:`~pmsm_cosim.engine.ssp_export.export_ssp` writes a
:class:`~pmsm_cosim.engine.system.SystemSpec` as a package:

* ``SystemStructure.ssd``: one component per instance (the FMUs under ``resources/``),
  their connectors (every output, every connected input, with units), all connections,
  the units (``ssd:Units``), the default experiment (start 0, the stop time) with the
  base step as libcosim reads it (annotation ``com.opensimulationplatform``,
  ``osp:FixedStepAlgorithm baseStepSize``; a component's step as ``osp:StepSizeHint``),
  and, in the system's annotations, the step as OMSimulator reads it (first,
  ``org.openmodelica``: ``oms:FixedStepMaster description="oms-ma" stepSize``; OMSimulator
  reads only the first annotation there and refuses annotations at the root of the SSD)
  and the annotation ``org.pmsm-ev-cosim`` with what only this master uses (coupling
  algorithm, output interval, the recorded columns);
* the scenario signals as a component: an FMU whose outputs, named as the signals, play
  them (the caller makes it: ``signal_fmu``; the drive application gives its RouteProfile
  FMU with the system's route in its resources), connected to the inputs the signals drove.
  It comes last in the stepping order, so that Gauss-Seidel reads the profile at t_n as
  the master's signals do;
* the start values as parameter values, one ``resources/<instance>.ssv`` per instance,
  except String values: fmpy and OMSimulator cannot set a String, so a String that is not
  the FMU's default travels in a copy of the FMU whose default it is
  (``resources/<FMU>_<instance>.fmu``, made by the caller's ``string_start_fmu``), as the
  signals travel in their FMU; one equal to the default is left out. (An FMU the caller
  cannot copy so keeps its String values in the ``.ssv``.)

:func:`load_ssp` reads a package into the same ``SystemSpec`` the TOML loader gives (no
signals: profiles come from FMUs; the run record of packages written before it moved
into the system's annotations is read at the root too). It checks the ``.ssd`` and
``.ssv`` files against the
SSP 1.0 schemas shipped with fmpy and refuses, in one line naming them, the SSP features
this master does not implement (sub-systems, signal dictionaries, connection
transformations, parameter mappings, components that are not FMUs, ...). Without the
``org.pmsm-ev-cosim`` annotation (a package written by another tool) the coupling is
Jacobi, the stepping order the order of the components, and every output connector is
recorded but the String ones (results.csv holds numbers).
"""

from __future__ import annotations

import atexit
import math
import shutil
import tempfile
import zipfile
from pathlib import Path, PurePosixPath
from xml.etree import ElementTree as ET

import fmpy.ssp

from .errors import CosimError, close_matches, one_line
from .system import ALGORITHMS, COLUMN_CONVERSIONS, ColumnSpec, ComponentSpec, Connection, SystemSpec, check_references

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "ssm": "http://ssp-standard.org/SSP1/SystemStructureParameterMapping",
    "ssb": "http://ssp-standard.org/SSP1/SystemStructureSignalDictionary",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
    "oms": "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd",
    "pec": "urn:pmsm-ev-cosim:ssp",
}
for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)

SSD_NAME = "SystemStructure.ssd"
FMU_TYPE = "application/x-fmu-sharedlibrary"
PARAMETER_SET_TYPE = "application/x-ssp-parameter-set"
OSP_ANNOTATION = "com.opensimulationplatform"
#: OMSimulator's annotation: it takes the kind of a system (a fixed-step master of
#: co-simulation FMUs, "oms-ma") from it and from nothing else
OMS_ANNOTATION = "org.openmodelica"
OMS_MASTER = "oms-ma"
OWN_ANNOTATION = "org.pmsm-ev-cosim"
#: the instance name of the signals' component (a suffix is added if it is taken)
ROUTE_INSTANCE = "route"
#: the connector and parameter types written and read (FMI type -> SSP element)
TYPES = ("Real", "Integer", "Boolean", "String")


def qname(tag: str) -> str:
    """``"ssd:System"`` -> ``"{uri}System"``."""
    prefix, _, local = tag.partition(":")
    return f"{{{NS[prefix]}}}{local}"


def number_text(value: float) -> str:
    return repr(float(value))


# --- import ---------------------------------------------------------------------------

def schema_dir() -> Path | None:
    """The SSP 1.0 schemas fmpy ships (``fmpy/ssp/schema``), or None."""
    path = Path(fmpy.ssp.__file__).parent / "schema"
    return path if path.is_dir() else None


def schema_errors(data: bytes, schema: str) -> list[str]:
    """Problems of an XML document against one of fmpy's SSP 1.0 schemas ("line N: text");
    [] when valid (or when lxml or the schemas are not available)."""
    folder = schema_dir()
    try:
        from lxml import etree  # noqa: PLC0415 - lxml (fmpy's XML library): optional, for the schema check only
    except ImportError:
        return []
    if folder is None:
        return []
    validator = etree.XMLSchema(file=str(folder / schema))
    doc = etree.fromstring(data)
    if validator.validate(doc):
        return []
    return [f"line {e.line}: {e.message}" for e in validator.error_log]


_TEMP_DIRS: list[Path] = []


def _cleanup() -> None:
    for path in _TEMP_DIRS:
        shutil.rmtree(path, ignore_errors=True)


atexit.register(_cleanup)


def _local(element: ET.Element) -> str:
    """``{uri}Name`` -> ``prefix:Name``."""
    tag = element.tag
    if tag.startswith("{"):
        uri, _, local = tag[1:].partition("}")
        for prefix, known in NS.items():
            if known == uri:
                return f"{prefix}:{local}"
        return local
    return tag


def _parse_xml(data: bytes, where: str) -> ET.Element:
    try:
        return ET.fromstring(data)
    except ET.ParseError as exc:
        raise CosimError(f"{where}: not well-formed XML ({one_line(exc)})") from None


def _validate(data: bytes, schema: str, where: str) -> None:
    errors = schema_errors(data, schema)
    if errors:
        more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
        raise CosimError(f"{where}: not valid SSP 1.0 ({schema}): {one_line(errors[0])}{more}")


def _unsupported(where: str, what: str) -> CosimError:
    return CosimError(f"{where}: unsupported SSP feature: {what}")


def _float(text: str | None, where: str) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise CosimError(f"{where}: not a number ({text!r})") from None
    if not math.isfinite(value):
        raise CosimError(f"{where}: not a finite number ({text!r})")
    return value


def _package_file(root: Path, source: str, where: str) -> Path:
    """A file inside the extracted package, named by a relative URI."""
    if ":" in source.split("/")[0] or source.startswith("/"):
        raise _unsupported(where, f"source {source!r} outside the package (only relative paths inside the .ssp)")
    path = (root / PurePosixPath(source)).resolve()
    if root.resolve() not in path.parents or not path.is_file():
        raise CosimError(f"{where}: {source} is not in the package")
    return path


def _parameter_set(element: ET.Element, where: str) -> list[tuple[str, object]]:
    """[(name, value)] of an ``ssv:ParameterSet``."""
    out = []
    params = element.find("ssv:Parameters", NS)
    for p in (params if params is not None else ()):
        name = p.get("name", "")
        typed = [child for child in p if _local(child) != "ssc:Annotations" and _local(child) != "ssv:Annotations"]
        if not typed:
            raise CosimError(f"{where}: parameter {name!r} has no value")
        kind = _local(typed[0])
        text = typed[0].get("value")
        if kind == "ssv:Real":
            value = _float(text, f"{where}: parameter {name}")
        elif kind == "ssv:Integer":
            try:
                value = int(text)
            except (TypeError, ValueError):
                raise CosimError(f"{where}: parameter {name}: not an Integer ({text!r})") from None
        elif kind == "ssv:Boolean":
            if text not in ("true", "false", "1", "0"):
                raise CosimError(f"{where}: parameter {name}: not a Boolean ({text!r})")
            value = text in ("true", "1")
        elif kind == "ssv:String":
            value = text if text is not None else ""
        else:
            raise _unsupported(where, f"parameter {name!r} of type {kind.partition(':')[2]} "
                                      f"(Real, Integer, Boolean, String only)")
        out.append((name, value))
    return out


def _bindings(element: ET.Element, root: Path, where: str) -> list[tuple[str, object]]:
    """The parameter values bound to a component or system, in order."""
    out = []
    bindings = element.find("ssd:ParameterBindings", NS)
    for b in (bindings if bindings is not None else ()):
        kind = b.get("type", PARAMETER_SET_TYPE)
        if kind != PARAMETER_SET_TYPE:
            raise _unsupported(where, f"parameter binding of type {kind!r}")
        if b.get("prefix"):
            raise _unsupported(where, f"parameter binding prefix {b.get('prefix')!r}")
        if b.get("sourceBase", "SSD") != "SSD":
            raise _unsupported(where, "parameter binding with sourceBase=\"component\"")
        if b.find("ssd:ParameterMapping", NS) is not None:
            raise _unsupported(where, "parameter mapping (ssm)")
        source = b.get("source")
        if source:
            path = _package_file(root, source, where)
            data = path.read_bytes()
            _validate(data, "SystemStructureParameterValues.xsd", f"{where}: {source}")
            out += _parameter_set(_parse_xml(data, f"{where}: {source}"), f"{where}: {source}")
        else:
            inline = b.find("ssd:ParameterValues/ssv:ParameterSet", NS)
            if inline is not None:
                out += _parameter_set(inline, f"{where}: inline parameter values")
    return out


def _extract(path: Path) -> Path:
    if not path.is_file():
        raise CosimError(f"{path}: SSP package not found")
    if not zipfile.is_zipfile(path):
        raise CosimError(f"{path}: not an SSP package (not a zip archive)")
    root = Path(tempfile.mkdtemp(prefix="pmsm-cosim-ssp-"))
    _TEMP_DIRS.append(root)
    try:
        with zipfile.ZipFile(path) as z:
            if SSD_NAME not in z.namelist():
                raise CosimError(f"{path}: not an SSP package (no {SSD_NAME} at its root)")
            z.extractall(root)
    except (zipfile.BadZipFile, OSError, RuntimeError, EOFError) as exc:
        raise CosimError(f"{path}: cannot read the SSP package ({one_line(exc)})") from None
    return root


def load_ssp(path) -> SystemSpec:
    """The :class:`SystemSpec` of an SSP 1.0 package (see the module doc)."""
    path = Path(path)
    where = str(path)
    root_dir = _extract(path)
    data = (root_dir / SSD_NAME).read_bytes()
    root = _parse_xml(data, f"{where}: {SSD_NAME}")
    if _local(root) != "ssd:SystemStructureDescription":
        raise CosimError(f"{where}: {SSD_NAME} is not an SSP system structure description "
                         f"(root element {root.tag!r})")
    version = root.get("version", "")
    if not version.startswith("1."):
        raise CosimError(f"{where}: SSP version {version!r} is not supported (SSP 1.0)")
    _validate(data, "SystemStructureDescription.xsd", f"{where}: {SSD_NAME}")

    system = root.find("ssd:System", NS)
    sw = f"{where}: system {system.get('name')!r}"
    if system.find("ssd:SignalDictionaries", NS) is not None:
        raise _unsupported(sw, "signal dictionaries")
    system_params = _bindings(system, root_dir, sw)

    # -- experiment ----------------------------------------------------------------------
    step = stop = None
    experiment = root.find("ssd:DefaultExperiment", NS)
    if experiment is not None:
        start = _float(experiment.get("startTime", "0"), f"{where}: DefaultExperiment startTime")
        if start != 0.0:
            raise _unsupported(where, f"DefaultExperiment startTime {start:g} (runs start at 0)")
        if experiment.get("stopTime") is not None:
            stop = _float(experiment.get("stopTime"), f"{where}: DefaultExperiment stopTime")
        for annotation in experiment.findall("ssd:Annotations/ssc:Annotation", NS):
            if annotation.get("type") != OSP_ANNOTATION:
                continue
            for algorithm in annotation.findall("osp:Algorithm/*", NS):
                if _local(algorithm) != "osp:FixedStepAlgorithm":
                    raise _unsupported(where, f"algorithm {_local(algorithm)}")
                step = _float(algorithm.get("baseStepSize"), f"{where}: FixedStepAlgorithm baseStepSize")
    own_path = f"ssd:Annotations/ssc:Annotation[@type='{OWN_ANNOTATION}']/pec:Run"
    own = system.find(own_path, NS)
    if own is None:  # a package written before the run record moved into the system
        own = root.find(own_path, NS)
    algorithm, interval, name, description = "jacobi", None, root.get("name") or path.stem, \
        system.get("description", "")
    if own is not None:
        algorithm = own.get("algorithm", "jacobi")
        if algorithm not in ALGORITHMS:
            raise CosimError(f"{where}: {OWN_ANNOTATION} annotation: algorithm must be one of "
                             f"{', '.join(ALGORITHMS)} (got {algorithm!r})")
        if step is None and own.get("stepSize") is not None:
            step = _float(own.get("stepSize"), f"{where}: {OWN_ANNOTATION} stepSize")
        if own.get("outputInterval") is not None:
            interval = _float(own.get("outputInterval"), f"{where}: {OWN_ANNOTATION} outputInterval")
        name = own.get("name") or name
        description = own.get("description", description)
    for label, value in (("stop time", stop), ("base step", step), ("output interval", interval)):
        if value is not None and value <= 0:
            raise CosimError(f"{where}: {label} must be > 0 (got {value!r})")

    # -- components --------------------------------------------------------------------
    elements = system.find("ssd:Elements", NS)
    components: list[ComponentSpec] = []
    kinds: dict[tuple[str, str], str] = {}
    outputs: list[tuple[str, str, str]] = []  # (instance, connector, type) of the output connectors
    for element in (elements if elements is not None else ()):
        tag = _local(element)
        ename = element.get("name", "")
        cw = f"{where}: {ename}"
        if tag == "ssd:System":
            raise _unsupported(cw, "sub-system (nested ssd:System)")
        if tag != "ssd:Component":
            raise _unsupported(cw, tag.partition(":")[2] or tag)
        kind = element.get("type", FMU_TYPE)
        if kind != FMU_TYPE:
            raise _unsupported(cw, f"component of type {kind!r} (FMUs only)")
        if element.get("implementation", "any") == "ModelExchange":
            raise _unsupported(cw, "implementation=\"ModelExchange\" (co-simulation FMUs only)")
        if any(c.name == ename for c in components):
            raise CosimError(f"{where}: component name {ename!r} used twice")
        fmu = _package_file(root_dir, element.get("source", ""), cw)
        for connector in element.findall("ssd:Connectors/ssd:Connector", NS):
            kinds[(ename, connector.get("name"))] = connector.get("kind")
            typed = [_local(child) for child in connector if _local(child).startswith("ssc:")]
            if connector.get("kind") == "output":
                outputs.append((ename, connector.get("name"), typed[0].partition(":")[2] if typed else ""))
        multiple = 1
        for hint in element.findall(f"ssd:Annotations/ssc:Annotation[@type='{OSP_ANNOTATION}']/osp:StepSizeHint",
                                    NS):
            value = _float(hint.get("value"), f"{cw}: StepSizeHint")
            if step is not None and value > 0:
                multiple = round(value / step)
                if multiple < 1 or abs(multiple * step - value) > 1e-9 * value:
                    raise CosimError(f"{cw}: step size hint {value:g} s is not a whole multiple of the base "
                                     f"step {step:g} s")
        start = dict(_bindings(element, root_dir, cw))
        components.append(ComponentSpec(ename, fmu, multiple, start, element.get("source", "")))
    if not components:
        raise CosimError(f"{where}: the system has no components")
    by_name = {c.name: c for c in components}
    for pname, value in system_params:  # system-level values: "instance.variable"
        inst, dot, var = pname.partition(".")
        if not dot or inst not in by_name:
            raise CosimError(f"{sw}: parameter {pname!r} does not name INSTANCE.VARIABLE of a component"
                             f"{close_matches(inst, by_name)}")
        by_name[inst].start.setdefault(var, value)  # a component's own binding wins

    # -- connections ---------------------------------------------------------------------
    connections: list[Connection] = []
    for c in system.findall("ssd:Connections/ssd:Connection", NS):
        a = (c.get("startElement"), c.get("startConnector"))
        b = (c.get("endElement"), c.get("endConnector"))
        text = f"{a[0] or '(system)'}.{a[1]} -> {b[0] or '(system)'}.{b[1]}"
        if not a[0] or not b[0]:
            raise _unsupported(f"{where}: connection {text}", "connection to a connector of the system itself")
        transforms = [_local(t) for t in c if _local(t) not in ("ssc:Annotations", "ssd:Annotations",
                                                                 "ssd:ConnectionGeometry")]
        if transforms:
            raise _unsupported(f"{where}: connection {text}", transforms[0].partition(":")[2])
        for inst, _ in (a, b):
            if inst not in by_name:
                raise CosimError(f"{where}: connection {text}: unknown component {inst!r}"
                                 f"{close_matches(inst, by_name)}")
        if kinds.get(a) == "input" and kinds.get(b) == "output":
            a, b = b, a  # start/end do not say which way the data flows (SSP 1.0, 5.3.3)
        connections.append(Connection(a[0], a[1], b[0], b[1]))

    # -- recorded columns ------------------------------------------------------------------
    columns: list[ColumnSpec] = []
    if own is not None and own.findall("pec:Column", NS):
        for col in own.findall("pec:Column", NS):
            cname, source, unit = col.get("name", ""), col.get("source", ""), col.get("unit", "")
            ctx = f"{where}: {OWN_ANNOTATION} column {cname!r}"
            if not cname or "," in cname:
                raise CosimError(f"{ctx}: a column name must be non-empty and contain no comma")
            if unit and unit not in COLUMN_CONVERSIONS:
                raise CosimError(f"{ctx}: only {', '.join(COLUMN_CONVERSIONS)} can be converted to (got {unit!r})")
            if source == "time":
                columns.append(ColumnSpec(cname, "time"))
                continue
            inst, dot, var = source.partition(".")
            if not dot:
                raise CosimError(f"{ctx}: source must be \"time\" or \"INSTANCE.VARIABLE\" (got {source!r})")
            columns.append(ColumnSpec(cname, "variable", inst, var, unit))
    else:
        columns = [ColumnSpec("time", "time")] + [
            ColumnSpec(f"{inst}.{var}", "variable", inst, var) for inst, var, kind in outputs
            if kind in ("", "Real", "Integer", "Enumeration", "Boolean")]

    spec = SystemSpec(name=name, components=components, connections=connections, signals={}, columns=columns,
                      step_size=step, stop_time=stop, output_interval=interval if interval is not None else step,
                      algorithm=algorithm, description=description, path=path)
    check_references(spec)
    return spec
