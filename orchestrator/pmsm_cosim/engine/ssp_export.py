"""Writing a system as an SSP 1.0 package (the format and what goes into it: :mod:`pmsm_cosim.engine.ssp`)."""

from __future__ import annotations

import re
import shutil
import tempfile
import zipfile
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from xml.etree import ElementTree as ET

from .errors import CosimError
from .fmu import convert_start, read_description, variable_unit
from .master import Master
from .ssp import (
    FMU_TYPE,
    OMS_ANNOTATION,
    OMS_MASTER,
    OSP_ANNOTATION,
    OWN_ANNOTATION,
    PARAMETER_SET_TYPE,
    ROUTE_INSTANCE,
    SSD_NAME,
    TYPES,
    number_text,
    qname,
)
from .system import ColumnSpec, ComponentSpec, Connection, SystemSpec


@dataclass
class ExportSummary:
    path: Path
    components: list[str]
    connections: int
    parameters: int
    route: str | None  #: the instance that plays the signals, if the system has signals


def _route_instance(spec: SystemSpec) -> str:
    names = {c.name for c in spec.components}
    name, k = ROUTE_INSTANCE, 1
    while name in names:
        k += 1
        name = f"{ROUTE_INSTANCE}{k}"
    return name


def _resource_names(paths: dict[str, Path]) -> dict[str, str]:
    """instance -> ``resources/<file>.fmu``; one file per distinct FMU, names made unique."""
    by_file: dict[Path, str] = {}
    used: set[str] = set()
    out = {}
    for inst, path in paths.items():
        key = path.resolve()
        if key not in by_file:
            stem, name, k = path.stem, path.name, 1
            while name in used:
                k += 1
                name = f"{stem}_{k}.fmu"
            used.add(name)
            by_file[key] = f"resources/{name}"
        out[inst] = by_file[key]
    return out


def _unit_element(parent: ET.Element, tag: str, unit) -> None:
    element = ET.SubElement(parent, qname(tag), name=unit.name)
    base = unit.baseUnit
    attrs = {}
    if base is not None:
        for key in ("kg", "m", "s", "A", "K", "mol", "cd", "rad"):
            if getattr(base, key):
                attrs[key] = str(getattr(base, key))
        if base.factor != 1.0:
            attrs["factor"] = number_text(base.factor)
        if base.offset != 0.0:
            attrs["offset"] = number_text(base.offset)
    ET.SubElement(element, qname("ssc:BaseUnit"), attrs)


def _ssv_text(instance: str, values: list[tuple[str, str, str]]) -> bytes:
    """A parameter set: [(name, FMI type, value text)]."""
    root = ET.Element(qname("ssv:ParameterSet"), version="1.0", name=instance)
    params = ET.SubElement(root, qname("ssv:Parameters"))
    for name, kind, text in values:
        p = ET.SubElement(params, qname("ssv:Parameter"), name=name)
        ET.SubElement(p, qname(f"ssv:{kind}"), value=text)
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"


def _value_text(kind: str, value) -> str:
    if kind == "Real":
        return number_text(value)
    if kind == "Boolean":
        return "true" if value else "false"
    return str(value)


def export_ssp(spec: SystemSpec, dest, *, signal_fmu=None, carries_starts=None, string_start_fmu=None,
               tool: str = "pmsm_cosim") -> ExportSummary:
    """Write ``spec`` as an SSP 1.0 package ``dest``.

    ``signal_fmu(spec, work_dir)`` -> the FMU file that plays the system's signals (outputs
    named as the signals; needed when the system has signals); ``carries_starts(fmu)``: can
    ``string_start_fmu(fmu, dest, values)`` write a copy of ``fmu`` at ``dest`` whose String
    parameters ``values`` (name -> text) are its defaults; ``tool`` is the SSD's
    generationTool."""
    dest = Path(dest)
    where = f"{spec.path}: " if spec.path else ""
    Master(spec).close()  # variables, causalities, units, start values, time grid

    components = list(spec.components)
    connections = list(spec.connections)
    columns = list(spec.columns)
    paths = {c.name: c.fmu for c in components}
    work = Path(tempfile.mkdtemp(prefix="pmsm-cosim-ssp-export-"))
    try:
        route = None
        if spec.signals:
            route = _route_instance(spec)
            if signal_fmu is None:
                raise CosimError(f"{where}export-ssp: the system has signals but nothing was given to carry "
                                 f"them as an FMU")
            paths[route] = Path(signal_fmu(spec, work))
            components.append(ComponentSpec(route, paths[route], 1, {}, paths[route].name))
            for name, sig in spec.signals.items():
                connections += [Connection(route, name, inst, var) for inst, var in sig.drives]
            columns = [ColumnSpec(c.name, "variable", route, c.variable, c.unit) if c.kind == "signal" else c
                       for c in columns]
        descriptions = {c.name: read_description(paths[c.name], c.name) for c in components}
        for c in connections:  # the connector types written: TYPES (no ssc:Enumeration definitions)
            sv = next((v for v in descriptions[c.src].modelVariables if v.name == c.src_var), None)
            if sv is not None and sv.type not in TYPES:
                raise CosimError(f"{where}export-ssp: connection {c}: {sv.type} connectors cannot be written "
                                 f"to an SSP package ({', '.join(TYPES)} only)")
        starts: dict[str, list[tuple[str, str, str]]] = {}  # instance -> [(name, type, text)] for its .ssv
        n_parameters = 0
        for comp in components:
            values, packaged = [], {}
            by_name = {sv.name: sv for sv in descriptions[comp.name].modelVariables}
            for var, value in comp.start.items():
                if var in comp.optional_start and var not in by_name:
                    continue  # written for the FMU this one replaced (ComponentSpec.optional_start)
                sv = by_name[var]
                if sv.type not in TYPES:
                    raise CosimError(f"{where}export-ssp: start value {comp.name}.{var}: {sv.type} "
                                     f"parameters cannot be written to an .ssv (Real, Integer, Boolean, "
                                     f"String only)")
                converted = convert_start(sv, value, f"{where}start value {comp.name}.{var}")
                if sv.type == "String" and carries_starts is not None and carries_starts(paths[comp.name]):
                    if converted != (sv.start or ""):
                        packaged[var] = converted  # travels in a copy of the FMU
                else:
                    values.append((var, sv.type, _value_text(sv.type, converted)))
            if packaged:
                source = paths[comp.name]
                paths[comp.name] = Path(string_start_fmu(source, work / f"{source.stem}_{comp.name}.fmu", packaged))
                descriptions[comp.name] = read_description(paths[comp.name], comp.name)
            if values:
                starts[comp.name] = values
            n_parameters += len(values) + len(packaged)
        resources = _resource_names(paths)

        # -- the .ssd ---------------------------------------------------------------
        # OMSimulator takes these names for its model and system: identifiers only (a hyphen,
        # as in "hill-start-if", leaves it with no model); the run record keeps the system's name
        ident = re.sub(r"\W", "_", spec.name, flags=re.ASCII)
        ident = ident if ident[:1].isalpha() else f"s_{ident}"
        root = ET.Element(qname("ssd:SystemStructureDescription"), {
            "version": "1.0", "name": ident,
            "generationTool": tool,
            "generationDateAndTime": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        })
        system = ET.SubElement(root, qname("ssd:System"), name=ident)
        if spec.description:
            system.set("description", spec.description)
        elements = ET.SubElement(system, qname("ssd:Elements"))
        connected_inputs = {(c.dst, c.dst_var) for c in connections}
        units_used: dict[str, object] = {}
        ssv_files: dict[str, bytes] = {}
        for comp in components:
            md = descriptions[comp.name]
            element = ET.SubElement(elements, qname("ssd:Component"), {
                "name": comp.name, "type": FMU_TYPE, "source": resources[comp.name],
                "implementation": "CoSimulation"})
            connectors = ET.SubElement(element, qname("ssd:Connectors"))
            for sv in md.modelVariables:
                if sv.type not in TYPES or sv.causality not in ("input", "output"):
                    continue
                if sv.causality == "input" and (comp.name, sv.name) not in connected_inputs:
                    continue  # unconnected inputs keep their start values: not part of the interface
                connector = ET.SubElement(connectors, qname("ssd:Connector"), name=sv.name, kind=sv.causality)
                typed = ET.SubElement(connector, qname(f"ssc:{sv.type}"))
                unit = variable_unit(sv)
                if sv.type == "Real" and unit:
                    typed.set("unit", unit)
                    definition = next((u for u in md.unitDefinitions if u.name == unit), None)
                    if definition is not None:
                        known = units_used.get(unit)
                        if known is not None and repr(known.baseUnit) != repr(definition.baseUnit):
                            raise CosimError(f"{where}export-ssp: unit {unit!r} is defined differently by "
                                             f"two FMUs ({comp.name})")
                        units_used[unit] = definition
                    else:
                        units_used.setdefault(unit, None)
            if comp.name in starts:
                ssv_name = f"resources/{comp.name}.ssv"
                ssv_files[ssv_name] = _ssv_text(comp.name, starts[comp.name])
                bindings = ET.SubElement(element, qname("ssd:ParameterBindings"))
                ET.SubElement(bindings, qname("ssd:ParameterBinding"), type=PARAMETER_SET_TYPE, source=ssv_name)
            if comp.step_multiple != 1:
                annotations = ET.SubElement(element, qname("ssd:Annotations"))
                annotation = ET.SubElement(annotations, qname("ssc:Annotation"), type=OSP_ANNOTATION)
                ET.SubElement(annotation, qname("osp:StepSizeHint"),
                              value=number_text(comp.step_multiple * spec.step_size))
        if connections:
            conns = ET.SubElement(system, qname("ssd:Connections"))
            for c in connections:
                ET.SubElement(conns, qname("ssd:Connection"), startElement=c.src, startConnector=c.src_var,
                              endElement=c.dst, endConnector=c.dst_var)
        system_annotations = ET.SubElement(system, qname("ssd:Annotations"))
        oms = ET.SubElement(ET.SubElement(system_annotations, qname("ssc:Annotation"), type=OMS_ANNOTATION),
                            qname("oms:Annotations"))
        ET.SubElement(ET.SubElement(oms, qname("oms:SimulationInformation")), qname("oms:FixedStepMaster"),
                      description=OMS_MASTER, stepSize=number_text(spec.step_size))
        if units_used:
            units = ET.SubElement(root, qname("ssd:Units"))
            for name, definition in sorted(units_used.items()):
                if definition is None:  # declared by name only: dimensionless as far as SSP knows
                    ET.SubElement(ET.SubElement(units, qname("ssc:Unit"), name=name), qname("ssc:BaseUnit"))
                else:
                    _unit_element(units, "ssc:Unit", definition)
        experiment = ET.SubElement(root, qname("ssd:DefaultExperiment"), startTime="0.0",
                                   stopTime=number_text(spec.stop_time))
        annotation = ET.SubElement(ET.SubElement(experiment, qname("ssd:Annotations")), qname("ssc:Annotation"),
                                   type=OSP_ANNOTATION)
        ET.SubElement(ET.SubElement(annotation, qname("osp:Algorithm")), qname("osp:FixedStepAlgorithm"),
                      baseStepSize=number_text(spec.step_size))
        annotation = ET.SubElement(system_annotations, qname("ssc:Annotation"), type=OWN_ANNOTATION)
        run = ET.SubElement(annotation, qname("pec:Run"), {
            "name": spec.name, "algorithm": spec.algorithm, "stepSize": number_text(spec.step_size),
            "outputInterval": number_text(spec.output_interval)})
        if spec.description:
            run.set("description", spec.description)
        for col in columns:
            attrs = {"name": col.name, "source": "time" if col.kind == "time" else f"{col.instance}.{col.variable}"}
            if col.unit:
                attrs["unit"] = col.unit
            ET.SubElement(run, qname("pec:Column"), attrs)
        ET.indent(root)
        ssd = ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"

        # -- the zip --------------------------------------------------------------------
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = dest.with_name(dest.name + ".tmp")
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr(SSD_NAME, ssd)
            written = set()
            for comp in components:
                if resources[comp.name] not in written:
                    z.write(paths[comp.name], resources[comp.name])
                    written.add(resources[comp.name])
            for name, data in ssv_files.items():
                z.writestr(name, data)
        tmp.replace(dest)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return ExportSummary(dest, [c.name for c in components], len(connections), n_parameters, route)
