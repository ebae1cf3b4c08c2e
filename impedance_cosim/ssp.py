"""Read an SSP 1.0 archive (.ssp) into plain data, with one-line errors for malformed input.

Supports what the system needs: one system of FMU components, connectors with types and units,
connections, parameter bindings with .ssv parameter sets (on the system or on components), the
default experiment, and this project's master annotation (step size, algorithm, order).
"""

from __future__ import annotations

import tempfile
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from impedance_cosim.system import ANNOTATION_TYPE, NS

TYPES = ("Real", "Integer", "Boolean", "String", "Enumeration", "Binary")


class SspError(ValueError):
    """The SSP archive is malformed or inconsistent; the message names the problem."""


@dataclass(frozen=True)
class Connector:
    name: str
    kind: str
    type: str
    unit: str | None


@dataclass
class Component:
    name: str
    source: str  # path inside the archive
    connectors: dict[str, Connector]
    fmu: Path | None = None  # the extracted FMU file


@dataclass
class Parameter:
    name: str  # "component.variable"
    type: str
    value: str
    unit: str | None


@dataclass
class SystemDescription:
    name: str
    components: list[Component]
    connections: list[tuple[str, str, str, str]]
    parameter_sets: dict[str, list[Parameter]]  # in binding order
    units: dict[str, dict[str, float]]
    start_time: float = 0.0
    stop_time: float | None = None
    step_size: float | None = None
    algorithm: str | None = None
    order: list[str] = field(default_factory=list)
    folder: Path | None = None  # where the archive was extracted
    _extracted: Any = field(default=None, repr=False)  # owns a temporary folder

    def component(self, name: str) -> Component:
        for c in self.components:
            if c.name == name:
                return c
        raise SspError(f"no component named {name!r} (have {[c.name for c in self.components]})")


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _connectors(element: ET.Element) -> dict[str, Connector]:
    out = {}
    for c in element.findall("ssd:Connectors/ssd:Connector", NS):
        typed = [t for t in c if _local(t.tag) in TYPES]
        kind_type = _local(typed[0].tag) if typed else "Real"
        unit = typed[0].get("unit") if typed else None
        out[c.get("name")] = Connector(c.get("name"), c.get("kind"), kind_type, unit)
    return out


def _parameter_set(root: ET.Element, prefix: str) -> tuple[str, list[Parameter]]:
    params = []
    for p in root.findall("ssv:Parameters/ssv:Parameter", NS):
        typed = [t for t in p if _local(t.tag) in TYPES]
        if not typed:
            raise SspError(f"parameter {p.get('name')!r} has no value")
        t = typed[0]
        params.append(
            Parameter(prefix + p.get("name"), _local(t.tag), t.get("value"), t.get("unit"))
        )
    return root.get("name") or "", params


def _bindings(element: ET.Element, prefix: str, archive: zipfile.ZipFile) -> list:
    sets = []
    for b in element.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS):
        pfx = prefix + (b.get("prefix") or "")
        source = b.get("source")
        if source is not None:
            try:
                root = ET.fromstring(archive.read(source))
            except KeyError:
                raise SspError(f"parameter set {source} is missing from the archive") from None
            except ET.ParseError as exc:
                raise SspError(f"parameter set {source} is not valid XML: {exc}") from None
            sets.append(_parameter_set(root, pfx))
        for inline in b.findall("ssd:ParameterValues/ssv:ParameterSet", NS):
            sets.append(_parameter_set(inline, pfx))
    return sets


def read_ssp(path: str | Path, extract_to: Path | None = None) -> SystemDescription:
    """Validate (SSP 1.0 schemas, via fmpy) and read an .ssp archive, extracting it to a folder."""
    path = Path(path)
    if not path.is_file():
        raise SspError(f"{path} does not exist (run `impedance-cosim build`)")
    if not zipfile.is_zipfile(path):
        raise SspError(f"{path} is not an SSP archive (not a zip file)")
    from fmpy.ssp.ssd import read_ssd

    try:
        read_ssd(str(path), validate=True)
    except KeyError:
        raise SspError(f"{path.name} has no SystemStructure.ssd") from None
    except Exception as exc:  # fmpy raises bare Exceptions on schema errors
        lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
        detail = lines[1] if len(lines) > 1 else (lines[0] if lines else repr(exc))
        raise SspError(f"malformed SSD in {path.name}: {detail}") from None
    with zipfile.ZipFile(path) as archive:
        root = ET.fromstring(archive.read("SystemStructure.ssd"))
        system = root.find("ssd:System", NS)
        if system.find("ssd:Elements/ssd:System", NS) is not None:
            raise SspError("nested systems are not supported")
        components = []
        sets = _bindings(system, "", archive)
        for c in system.findall("ssd:Elements/ssd:Component", NS):
            comp_type = c.get("type", "application/x-fmu-sharedlibrary")
            if comp_type != "application/x-fmu-sharedlibrary":
                raise SspError(f"component {c.get('name')}: type {comp_type} is not an FMU")
            if c.get("source") not in archive.namelist():
                raise SspError(
                    f"component {c.get('name')}: {c.get('source')} is missing from the archive"
                )
            components.append(Component(c.get("name"), c.get("source"), _connectors(c)))
            sets += _bindings(c, c.get("name") + ".", archive)
        keep = None if extract_to else tempfile.TemporaryDirectory(prefix="impcosim_ssp_")
        folder = extract_to or Path(keep.name)  # removed with the SystemDescription
        archive.extractall(folder)
    for comp in components:
        comp.fmu = folder / comp.source
    connections = [
        (e.get("startElement"), e.get("startConnector"), e.get("endElement"), e.get("endConnector"))
        for e in system.findall("ssd:Connections/ssd:Connection", NS)
    ]
    units = {}
    for u in root.findall("ssd:Units/ssc:Unit", NS):
        base = u.find("ssc:BaseUnit", NS)
        units[u.get("name")] = {
            k: float(v) for k, v in (base.attrib if base is not None else {}).items()
        }
    desc = SystemDescription(
        name=system.get("name"),
        components=components,
        connections=connections,
        parameter_sets={},
        units=units,
        folder=folder,
    )
    desc._extracted = keep
    for i, (name, params) in enumerate(sets):
        desc.parameter_sets[name or f"set{i + 1}"] = params
    exp = root.find("ssd:DefaultExperiment", NS)
    if exp is not None:
        desc.start_time = float(exp.get("startTime", 0.0))
        desc.stop_time = float(exp.get("stopTime")) if exp.get("stopTime") else None
        for ann in exp.findall("ssd:Annotations/ssc:Annotation", NS):
            master = ann.find("master")
            if ann.get("type") == ANNOTATION_TYPE and master is not None:
                desc.step_size = float(master.get("stepSize")) if master.get("stepSize") else None
                desc.algorithm = master.get("algorithm")
                desc.order = (master.get("order") or "").split()
    _check_connections(desc)
    return desc


def _check_connections(desc: SystemDescription) -> None:
    """Every connection joins existing connectors, output to input, of the same type and unit."""
    names = {c.name: c for c in desc.components}
    for se, sc, ee, ec in desc.connections:
        if se not in names or ee not in names:
            missing = se if se not in names else ee
            raise SspError(f"connection {se}.{sc} -> {ee}.{ec}: no component {missing!r}")
        start, end = names[se].connectors.get(sc), names[ee].connectors.get(ec)
        if start is None or end is None:
            bad = f"{se}.{sc}" if start is None else f"{ee}.{ec}"
            raise SspError(f"connection {se}.{sc} -> {ee}.{ec}: connector {bad} is not declared")
        if start.kind != "output" or end.kind != "input":
            raise SspError(
                f"connection {se}.{sc} -> {ee}.{ec} must go from an output to an input"
                f" (got {start.kind} -> {end.kind})"
            )
        if start.type != end.type:
            raise SspError(f"connection {se}.{sc} -> {ee}.{ec}: type {start.type} != {end.type}")
        if start.unit != end.unit:
            raise SspError(
                f"connection {se}.{sc} -> {ee}.{ec}: unit mismatch ({start.unit} -> {end.unit})"
            )
