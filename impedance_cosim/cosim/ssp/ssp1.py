"""The elements of an SSP 1.0 system structure description (.ssd) and parameter set (.ssv) as
plain data: components, connectors, connections, parameter bindings, units, the default
experiment and this project's master annotation. Each XML member is schema-validated (the SSP 1.0
XSDs fmpy ships) and refused with a DTD; every problem is an SspError naming file and element."""

from __future__ import annotations

import functools
import math
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from impedance_cosim.cosim.ssp import ssp2 as ssd2
from impedance_cosim.cosim.ssp.archive import (
    ANNOTATION_TYPE,
    NS,
    Limits,
    SspError,
    read_member,
    resolve_source,
)
from impedance_cosim.cosim.ssp.ssp2 import INTEGERS, REALS, TYPES


@dataclass(frozen=True)
class Connector:
    name: str
    kind: str
    type: str
    unit: str | None
    clocks: tuple[str, ...] = ()  # SSP 2.0: the clocks (connector names) it is associated to
    interval: str | None = None  # SSP 2.0 Clock connectors: the intervalVariability
    size: int = 1  # SSP 2.0 array connectors: the number of elements (1: a scalar)


@dataclass
class Component:
    name: str
    source: str  # path inside the archive
    connectors: dict[str, Connector]
    fmu: Path | None = None  # the extracted FMU file
    implementation: str = "any"  # SSP 2.0: the FMU interface to use (CoSimulation, ...)


@dataclass
class Parameter:
    name: str  # "component.variable"
    type: str
    value: str
    unit: str | None
    # where it was read, for messages: "<archive path>: resources/observer_plant.ssv"
    origin: str = field(default="", compare=False)


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
    variants: dict[str, str] = field(default_factory=dict)  # parameter set -> the SSD binding it
    version: str = "1.0"  # of SystemStructure.ssd: SSP 1.0 or 2.0
    system_connectors: dict[str, Connector] = field(default_factory=dict)
    # SSP 2.0 connections of Clock connectors, (start, connector, end, connector), "" = the system
    clock_connections: list[tuple[str, str, str, str]] = field(default_factory=list)
    folder: Path | None = None  # where the archive was extracted
    _extracted: Any = field(default=None, repr=False)  # finaliser removing an owned folder

    def component(self, name: str) -> Component:
        for c in self.components:
            if c.name == name:
                return c
        raise SspError(f"no component named {name!r} (have {[c.name for c in self.components]})")

    def close(self) -> None:
        """Remove the folder the archive was extracted to (if read_ssp made it); idempotent."""
        if self._extracted is not None:
            self._extracted()

    def __enter__(self) -> SystemDescription:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@functools.cache
def _schema(name: str) -> Any:
    import fmpy.ssp
    from lxml import etree

    return etree.XMLSchema(file=str(Path(fmpy.ssp.__file__).parent / "schema" / name))


def parse_xml(
    archive: zipfile.ZipFile, info: zipfile.ZipInfo, where: str, schema: str, limits: Limits
) -> ET.Element:
    """Parse and schema-validate one XML member (version 1.0: the SSP 1.0 XSDs fmpy ships; 2.0:
    the SSP 2.0 XSDs of pyssp-standard); no DTDs."""
    kind = "SSD" if schema.startswith("SystemStructureDescription") else "parameter set"
    bad = f"malformed {kind} in {where}: {info.filename}"
    data = read_member(archive, info, where, limits.xml_bytes)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise SspError(f"{bad} is not UTF-8 (SSP requires UTF-8)") from None
    if "<!DOCTYPE" in text or "<!ENTITY" in text:
        raise SspError(f"{bad} has a DOCTYPE or entity declaration (not allowed)")
    try:
        root = ET.fromstring(data)
    except (ET.ParseError, LookupError, ValueError) as exc:  # LookupError: unknown encoding
        raise SspError(f"{bad}: {exc}") from None
    problem = ssd2.version_problem(root)
    if problem:
        raise SspError(f"{bad}: {problem}")
    from lxml import etree

    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)
    try:
        doc = etree.fromstring(data, parser)
    except (etree.XMLSyntaxError, LookupError, ValueError) as exc:
        raise SspError(f"{bad}: {exc}") from None
    checker = ssd2.schema(schema) if root.get("version") == "2.0" else _schema(schema)
    if not checker.validate(doc):
        e = checker.error_log[0]
        message = e.message
        for prefix, uri in NS.items():
            message = message.replace("{" + uri + "}", prefix + ":")
        raise SspError(f"{bad} (line {e.line}): {message}")
    return root


def required(element: ET.Element, attr: str, what: str) -> str:
    value = element.get(attr)
    if value is None or not value.strip():
        raise SspError(f"{what}: {_local(element.tag)} has no {attr!r} attribute")
    return value


def _number(text: str | None, what: str) -> float:
    """A finite float from an attribute, or an SspError naming it."""
    try:
        value = float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise SspError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise SspError(f"{what}: {text!r} is not a finite number")
    return value


def _local(tag: Any) -> str:
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def _typed(element: ET.Element) -> ET.Element | None:
    typed = [t for t in element if _local(t.tag) in TYPES]
    return typed[0] if typed else None


def connectors(element: ET.Element, what: str) -> dict[str, Connector]:
    out: dict[str, Connector] = {}
    for i, c in enumerate(element.findall("ssd:Connectors/ssd:Connector", NS), 1):
        name = required(c, "name", f"{what}: connector #{i}")
        kind = required(c, "kind", f"{what}: connector {name!r}")
        if name in out:
            raise SspError(f"{what}: connector {name!r} is declared twice")
        t = _typed(c)
        unit = t.get("unit") if t is not None else None
        clocks = tuple(required(k, "name", f"{what}: connector {name!r}")
                       for k in c.findall("ssd:Clock", NS))  # fmt: skip
        out[name] = Connector(name, kind, _local(t.tag) if t is not None else "Real", unit, clocks,
                              t.get("intervalVariability") if t is not None else None,
                              _size(c, f"{what}: connector {name!r}"))  # fmt: skip
    return out


def _size(connector: ET.Element, what: str) -> int:
    """The number of elements of an SSP 2.0 array connector (ssc:Dimension), 1 for a scalar:
    one dimension of fixed size is read, the others are refused."""
    dims = connector.findall("ssc:Dimension", NS)
    if not dims:
        return 1
    size = dims[0].get("size")
    if len(dims) > 1 or size is None or not size.isdigit() or int(size) < 1:
        raise SspError(f"{what}: only one ssc:Dimension with a fixed size >= 1 is supported")
    return int(size)


def _parameter_set(
    root: ET.Element, prefix: str, what: str, origin: str = ""
) -> tuple[str, list[Parameter]]:
    if _local(root.tag) != "ParameterSet":
        raise SspError(f"{what}: expected a ParameterSet, found {_local(root.tag)!r}")
    params = []
    for i, p in enumerate(root.findall("ssv:Parameters/ssv:Parameter", NS), 1):
        name = required(p, "name", f"{what}: parameter #{i}")
        t = _typed(p)
        if t is None:
            raise SspError(f"{what}: parameter {name!r} has no value")
        value = required(t, "value", f"{what}: parameter {name!r}")
        kind = _local(t.tag)
        if kind in REALS:
            try:
                float(value)
            except ValueError:
                raise SspError(f"{what}: parameter {name!r}: {value!r} is not a number") from None
        elif kind in INTEGERS and not value.strip().lstrip("+-").isdigit():
            raise SspError(f"{what}: parameter {name!r}: {value!r} is not an integer")
        params.append(Parameter(prefix + name, kind, value, t.get("unit"), origin or what))
    return root.get("name") or "", params


@dataclass
class Source:
    """The open archive being read: its checked file members, its name for messages, the caps."""

    archive: zipfile.ZipFile
    infos: dict[str, zipfile.ZipInfo]
    where: str
    limits: Limits
    xml_left: int = 0  # bytes of parameter-set XML still allowed (bounds the work per archive)
    path: str = ""  # the archive as given (where is its name), for the parameters' origin


def bindings(
    element: ET.Element, prefix: str, what: str, src: Source
) -> list[tuple[str, list[Parameter], str]]:
    sets = []
    for b in element.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS):
        pfx = prefix + (b.get("prefix") or "")
        if b.get("type", "application/x-ssp-parameter-set") != "application/x-ssp-parameter-set":
            raise SspError(f"{what}: parameter binding of type {b.get('type')!r} is not supported")
        if b.get("sourceBase", "SSD") != "SSD":
            raise SspError(f"{what}: parameter binding sourceBase={b.get('sourceBase')!r}"
                           " is not supported (only SSD)")  # fmt: skip
        if b.find("ssd:ParameterMapping", NS) is not None:
            raise SspError(f"{what}: parameter mappings are not supported")
        source = b.get("source")
        if source is not None:
            name = resolve_source(source, src.infos, f"{what}: parameter binding")
            info = src.infos[name]
            src.xml_left -= info.file_size
            if src.xml_left < 0:
                raise SspError(f"{what}: the parameter sets bound add up to more than"
                               f" {4 * src.limits.xml_bytes} bytes")  # fmt: skip
            root = parse_xml(
                src.archive, info, src.where, "SystemStructureParameterValues.xsd", src.limits
            )
            here = f"{src.where}: {name}"
            origin = f"{src.path or src.where}: {name}"  # the path the user gave
            sets.append((*_parameter_set(root, pfx, here, origin), here))
        for inline in b.findall("ssd:ParameterValues/ssv:ParameterSet", NS):
            sets.append((*_parameter_set(inline, pfx, what), what))
    return sets


def connections(
    system: ET.Element, what: str, clocks: list[tuple[str, str, str, str]] | None = None
) -> list[tuple[str, str, str, str]]:
    """The connections between components; those of a Clock connector (SSP 2.0, also to the
    system's own connectors: element "") go to `clocks` instead."""
    out = []
    for i, e in enumerate(system.findall("ssd:Connections/ssd:Connection", NS), 1):
        here = f"{what}: connection #{i}"
        if clocks is not None and ssd2.is_clock_connection(system, e):
            names = ("startElement", "startConnector", "endElement", "endConnector")
            clocks.append(tuple(e.get(a) or "" for a in names))
            continue
        if e.get("startElement") is None or e.get("endElement") is None:
            raise SspError(f"{here}: connections to the system's own connectors are not supported")
        ends = tuple(
            required(e, a, here)
            for a in ("startElement", "startConnector", "endElement", "endConnector")
        )
        if any(_local(t.tag).endswith("Transformation") for t in e):
            raise SspError(f"{here}: transformations on connections are not supported")
        out.append(ends)
    return out


def units(root: ET.Element, where: str) -> dict[str, dict[str, float]]:
    units: dict[str, dict[str, float]] = {}
    for i, u in enumerate(root.findall("ssd:Units/ssc:Unit", NS), 1):
        name = required(u, "name", f"{where}: unit #{i}")
        if name in units:
            raise SspError(f"{where}: unit {name!r} is defined twice")
        base = u.find("ssc:BaseUnit", NS)
        attrs = base.attrib if base is not None else {}
        units[name] = {k: _number(v, f"{where}: unit {name!r}: {k}") for k, v in attrs.items()}
    return units


def experiment(root: ET.Element, desc: SystemDescription, where: str) -> None:
    exp = root.find("ssd:DefaultExperiment", NS)
    if exp is None:
        return
    what = f"{where}: DefaultExperiment"
    desc.start_time = _number(exp.get("startTime", "0.0"), f"{what} startTime")
    if exp.get("stopTime") is not None:
        desc.stop_time = _number(exp.get("stopTime"), f"{what} stopTime")
        if not desc.stop_time > desc.start_time:
            raise SspError(f"{what}: stopTime {desc.stop_time:g} is not after startTime"
                           f" {desc.start_time:g}")  # fmt: skip
    for ann in exp.findall("ssd:Annotations/ssc:Annotation", NS):
        master = ann.find("master")
        if ann.get("type") != ANNOTATION_TYPE or master is None:
            continue
        if master.get("stepSize") is not None:
            desc.step_size = _number(master.get("stepSize"), f"{what} annotation stepSize")
            if desc.step_size <= 0:
                raise SspError(f"{what} annotation stepSize: {desc.step_size:g} is not positive")
        desc.algorithm = master.get("algorithm")
        desc.order = (master.get("order") or "").split()


def check_connections(desc: SystemDescription, where: str) -> None:
    """Every connection joins existing connectors, output to input, of the same type and unit;
    no input is fed twice."""
    names = {c.name: c for c in desc.components}
    fed: set[tuple[str, str]] = set()
    for se, sc, ee, ec in desc.connections:
        here = f"{where}: connection {se}.{sc} -> {ee}.{ec}"
        if se not in names or ee not in names:
            raise SspError(f"{here}: no component {se if se not in names else ee!r}")
        start, end = names[se].connectors.get(sc), names[ee].connectors.get(ec)
        if start is None or end is None:
            bad = f"{se}.{sc}" if start is None else f"{ee}.{ec}"
            raise SspError(f"{here}: connector {bad} is not declared")
        if start.kind != "output" or end.kind != "input":
            raise SspError(
                f"{here} must go from an output to an input (got {start.kind} -> {end.kind})"
            )
        if start.type != end.type:
            raise SspError(f"{here}: type {start.type} != {end.type}")
        if start.unit != end.unit:
            raise SspError(f"{here}: unit mismatch ({start.unit} -> {end.unit})")
        if start.size != end.size:
            raise SspError(f"{here}: {start.size} elements -> {end.size} (array connectors)")
        if (ee, ec) in fed:
            raise SspError(f"{here}: input {ee}.{ec} is fed twice")
        fed.add((ee, ec))
