"""Read an SSP 1.0 archive (.ssp) into plain data, with one-line errors for malformed input.

Supports what the system needs: one system of FMU components, connectors with types and units,
connections, parameter bindings with .ssv parameter sets (on the system or on components), the
default experiment, and this project's master annotation (step size, algorithm, order); and SSP
variants: further .ssd files at the archive's root, each read as the same system with the
parameter set(s) it binds (the scenarios).
The archive is treated as hostile: see ssp_archive (member checks, caps, safe `source` URIs).
Every problem found is an SspError naming the file and element; nothing else escapes.
"""

from __future__ import annotations

import functools
import math
import shutil
import tempfile
import weakref
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from impedance_cosim.cosim.ssp_archive import (
    DEFAULT_LIMITS,
    Limits,
    SspError,
    check_members,
    declared_members,
    extract,
    open_zip,
    read_member,
    resolve_source,
)
from impedance_cosim.cosim.system import ANNOTATION_TYPE, NS

__all__ = ["Component", "Connector", "Limits", "Parameter", "SspError", "SystemDescription"]
__all__ += ["read_ssp"]

TYPES = ("Real", "Integer", "Boolean", "String", "Enumeration", "Binary")
FMU_TYPE = "application/x-fmu-sharedlibrary"
SSD = "SystemStructure.ssd"


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
    variants: dict[str, str] = field(default_factory=dict)  # parameter set -> the SSD binding it
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


def read_ssp(
    path: str | Path,
    extract_to: Path | None = None,
    limits: Limits = DEFAULT_LIMITS,
    ssd: str | None = None,
) -> SystemDescription:
    """Check, extract (to a new temporary folder, or the empty folder `extract_to`) and read an
    .ssp archive. Close the result (or use it as a context manager) to remove the folder.

    Its parameter sets are those of SystemStructure.ssd and of every variant SSD beside it (each
    variant must describe the same system); with `ssd` ("difference.ssd"), of that SSD only."""
    path = Path(path)
    if not path.exists():
        raise SspError(f"{path} does not exist (run `impedance-cosim build`)")
    if not path.is_file():
        raise SspError(f"{path} is not a file")
    try:
        if extract_to is None:
            folder = Path(tempfile.mkdtemp(prefix="impcosim_ssp_"))
        else:
            folder = Path(extract_to)
            folder.mkdir(parents=True, exist_ok=True)
            if any(folder.iterdir()):
                raise SspError(f"cannot extract {path.name} into {folder}: the folder is not empty")
    except OSError as exc:
        raise SspError(f"cannot make a folder to extract {path.name} into: {exc}") from None
    try:
        desc = _read(path, folder, limits, ssd)
    except BaseException:
        if extract_to is None:
            shutil.rmtree(folder, ignore_errors=True)
        raise
    if extract_to is None:
        desc._extracted = weakref.finalize(desc, shutil.rmtree, str(folder), True)
    return desc


def _read(path: Path, folder: Path, limits: Limits, ssd: str | None) -> SystemDescription:
    where = path.name
    with open_zip(path, where, limits) as archive:
        files = check_members(archive, where, limits)
        names = {f.filename for f in files}
        if SSD not in names:
            raise SspError(f"{where} has no {SSD}")
        if ssd is not None and ssd not in names:
            variants = sorted(n for n in names if _is_variant(n))
            raise SspError(f"{where} has no system description {ssd!r} (have {[SSD, *variants]})")
        infos = {f.filename: f for f in files}
        extract(archive, files, folder, where, limits)
        src = _Source(archive, infos, where, limits, xml_left=4 * limits.xml_bytes)
        names_read = (
            [ssd] if ssd is not None else [SSD, *sorted(n for n in names if _is_variant(n))]
        )
        desc = _system(src, names_read[0], folder)
        for variant in names_read[1:]:  # SSP variants: the same system, other parameters
            other = _system(src, variant, folder)
            if (other.components, other.connections, other.units) != (
                desc.components,
                desc.connections,
                desc.units,
            ):
                raise SspError(f"{where}: variant {variant} describes another system than {SSD}"
                               " (components, connections or units differ); this reader takes"
                               " variants that differ only in their parameters")  # fmt: skip
            for key, params in other.parameter_sets.items():
                if key in desc.parameter_sets:
                    raise SspError(f"{where}: {variant}: parameter set name {key!r} is also used"
                                   f" in {desc.variants[key]}")  # fmt: skip
                desc.parameter_sets[key] = params
                desc.variants[key] = variant
    return desc


def _is_variant(name: str) -> bool:
    """A further system description at the archive's root (SSP 1.0: a variant of the system)."""
    return "/" not in name and name.endswith(".ssd") and name != SSD


def _system(src: _Source, ssd: str, folder: Path) -> SystemDescription:
    """One system description of the archive: its system, bindings and experiment."""
    where, limits = src.where, src.limits
    root = _xml(src.archive, src.infos[ssd], where, "SystemStructureDescription.xsd", limits)
    where_ssd = where if ssd == SSD else f"{where}: {ssd}"
    system = root.find("ssd:System", NS)
    if system is None:
        raise SspError(f"malformed SSD in {where}: {ssd} has no System element")
    sysname = system.get("name") or ""
    for tag in ("System", "SignalDictionaryReference"):
        if system.find(f"ssd:Elements/ssd:{tag}", NS) is not None:
            raise SspError(f"{where_ssd}: system {sysname!r}: {tag} elements are not supported")
    ctx = f"{where_ssd}: system {sysname!r}"
    sets = _bindings(system, "", ctx, src)
    components: list[Component] = []
    seen: set[str] = set()
    names = set(src.infos)
    for i, c in enumerate(system.findall("ssd:Elements/ssd:Component", NS), 1):
        name = _required(c, "name", f"{where_ssd}: component #{i}")
        what = f"{where_ssd}: component {name!r}"
        if name in seen:
            raise SspError(f"{what} is declared twice")
        if c.get("type", FMU_TYPE) != FMU_TYPE:
            raise SspError(f"{what}: type {c.get('type')} is not an FMU")
        source = resolve_source(c.get("source"), names, what)
        _check_fmu(folder / source, f"{where}: {source}", limits)
        comp = Component(name, source, _connectors(c, what), fmu=folder / source)
        components.append(comp)
        seen.add(name)
        sets += _bindings(c, name + ".", what, src)
    desc = SystemDescription(
        name=sysname,
        components=components,
        connections=_connections(system, ctx),
        parameter_sets={},
        units=_units(root, where_ssd),
        folder=folder,
    )
    # All bindings of a system apply (SSP 1.0), in order; bindings whose sets share a name (one
    # scenario bound on each component) form one parameter set. Sets of different names are
    # offered as alternatives (this project's earlier archives: one system, one set per scenario).
    for i, (name, params, _) in enumerate(sets):
        key = name or f"set{i + 1}"
        desc.parameter_sets.setdefault(key, []).extend(params)
        desc.variants.setdefault(key, ssd)
    _experiment(root, desc, where_ssd)
    _check_connections(desc, where_ssd)
    return desc


@functools.cache
def _schema(name: str) -> Any:
    import fmpy.ssp
    from lxml import etree

    return etree.XMLSchema(file=str(Path(fmpy.ssp.__file__).parent / "schema" / name))


def _xml(
    archive: zipfile.ZipFile, info: zipfile.ZipInfo, where: str, schema: str, limits: Limits
) -> ET.Element:
    """Parse and schema-validate (the SSP 1.0 XSDs fmpy ships) one XML member; no DTDs."""
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
    from lxml import etree

    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)
    try:
        doc = etree.fromstring(data, parser)
    except (etree.XMLSyntaxError, LookupError, ValueError) as exc:
        raise SspError(f"{bad}: {exc}") from None
    checker = _schema(schema)
    if not checker.validate(doc):
        e = checker.error_log[0]
        message = e.message
        for prefix, uri in NS.items():
            message = message.replace("{" + uri + "}", prefix + ":")
        raise SspError(f"{bad} (line {e.line}): {message}")
    return root


def _check_fmu(fmu: Path, where: str, limits: Limits) -> None:
    """An FMU that is a zip is checked like the archive (fmpy extracts it later); anything else
    is left to the FMU loader, which says what is wrong with it."""
    if not zipfile.is_zipfile(fmu):
        return
    count = declared_members(fmu)
    if count is not None and count > limits.members:
        raise SspError(f"{where} has {count} members (limit {limits.members})")
    try:
        archive = zipfile.ZipFile(fmu)
    except Exception:  # a damaged FMU is reported by the FMU loader
        return
    with archive:
        check_members(archive, where, limits)


def _required(element: ET.Element, attr: str, what: str) -> str:
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


def _connectors(element: ET.Element, what: str) -> dict[str, Connector]:
    out: dict[str, Connector] = {}
    for i, c in enumerate(element.findall("ssd:Connectors/ssd:Connector", NS), 1):
        name = _required(c, "name", f"{what}: connector #{i}")
        kind = _required(c, "kind", f"{what}: connector {name!r}")
        if name in out:
            raise SspError(f"{what}: connector {name!r} is declared twice")
        t = _typed(c)
        unit = t.get("unit") if t is not None else None
        out[name] = Connector(name, kind, _local(t.tag) if t is not None else "Real", unit)
    return out


def _parameter_set(root: ET.Element, prefix: str, what: str) -> tuple[str, list[Parameter]]:
    if _local(root.tag) != "ParameterSet":
        raise SspError(f"{what}: expected a ParameterSet, found {_local(root.tag)!r}")
    params = []
    for i, p in enumerate(root.findall("ssv:Parameters/ssv:Parameter", NS), 1):
        name = _required(p, "name", f"{what}: parameter #{i}")
        t = _typed(p)
        if t is None:
            raise SspError(f"{what}: parameter {name!r} has no value")
        value = _required(t, "value", f"{what}: parameter {name!r}")
        kind = _local(t.tag)
        if kind == "Real":
            try:
                float(value)
            except ValueError:
                raise SspError(f"{what}: parameter {name!r}: {value!r} is not a number") from None
        elif kind == "Integer" and not value.strip().lstrip("+-").isdigit():
            raise SspError(f"{what}: parameter {name!r}: {value!r} is not an integer")
        params.append(Parameter(prefix + name, kind, value, t.get("unit")))
    return root.get("name") or "", params


@dataclass
class _Source:
    """The open archive being read: its checked file members, its name for messages, the caps."""

    archive: zipfile.ZipFile
    infos: dict[str, zipfile.ZipInfo]
    where: str
    limits: Limits
    xml_left: int = 0  # bytes of parameter-set XML still allowed (bounds the work per archive)


def _bindings(
    element: ET.Element, prefix: str, what: str, src: _Source
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
            root = _xml(
                src.archive, info, src.where, "SystemStructureParameterValues.xsd", src.limits
            )
            here = f"{src.where}: {name}"
            sets.append((*_parameter_set(root, pfx, here), here))
        for inline in b.findall("ssd:ParameterValues/ssv:ParameterSet", NS):
            sets.append((*_parameter_set(inline, pfx, what), what))
    return sets


def _connections(system: ET.Element, what: str) -> list[tuple[str, str, str, str]]:
    out = []
    for i, e in enumerate(system.findall("ssd:Connections/ssd:Connection", NS), 1):
        here = f"{what}: connection #{i}"
        if e.get("startElement") is None or e.get("endElement") is None:
            raise SspError(f"{here}: connections to the system's own connectors are not supported")
        ends = tuple(
            _required(e, a, here)
            for a in ("startElement", "startConnector", "endElement", "endConnector")
        )
        if any(_local(t.tag).endswith("Transformation") for t in e):
            raise SspError(f"{here}: transformations on connections are not supported")
        out.append(ends)
    return out


def _units(root: ET.Element, where: str) -> dict[str, dict[str, float]]:
    units: dict[str, dict[str, float]] = {}
    for i, u in enumerate(root.findall("ssd:Units/ssc:Unit", NS), 1):
        name = _required(u, "name", f"{where}: unit #{i}")
        if name in units:
            raise SspError(f"{where}: unit {name!r} is defined twice")
        base = u.find("ssc:BaseUnit", NS)
        attrs = base.attrib if base is not None else {}
        units[name] = {k: _number(v, f"{where}: unit {name!r}: {k}") for k, v in attrs.items()}
    return units


def _experiment(root: ET.Element, desc: SystemDescription, where: str) -> None:
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


def _check_connections(desc: SystemDescription, where: str) -> None:
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
        if (ee, ec) in fed:
            raise SspError(f"{here}: input {ee}.{ec} is fed twice")
        fed.add((ee, ec))
