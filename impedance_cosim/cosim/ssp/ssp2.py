"""What reading an SSP 2.0 system description adds to the 1.0 reader (ssd.py, ssp.py): the 2.0
schemas (pyssp-standard ships them), the FMI 3 type names, Clock connectors and their
connections, and the FMU checksums of SRMD meta data (SHA3-256), checked against the archive.
Every problem is an SspError naming the file and the element."""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from impedance_cosim.cosim.ssp.archive import NS, SspError

VERSIONS = ("1.0", "2.0")
REALS = ("Real", "Float64", "Float32")
INTEGERS = ("Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")
TYPES = (*REALS, *INTEGERS, "Boolean", "String", "Enumeration", "Binary", "Clock")
SRMD = "{http://ssp-standard.org/SSPTraceability1/SimulationResourceMetaData}"
SRMD_TYPE = "application/x-srmd-meta-data"


def schema_dir() -> Path:
    """The SSP 2.0 XSDs of the installed pyssp-standard (found without importing it)."""
    spec = importlib.util.find_spec("pyssp_standard")
    if spec is None or not spec.submodule_search_locations:
        raise SspError(
            "reading an SSP 2.0 file needs pyssp-standard (pip install"
            " pyssp-standard==0.9.1): it ships the SSP 2.0 schemas"
        )
    return Path(next(iter(spec.submodule_search_locations))) / "resources" / "ssp2"


@functools.cache
def schema(name: str) -> Any:
    """The lxml schema of one SSP 2.0 XSD (SystemStructureDescription.xsd, ...)."""
    from lxml import etree

    return etree.XMLSchema(file=str(schema_dir() / name))


def version_problem(root: ET.Element) -> str | None:
    """Why the root's version attribute is not one this reader takes (None if it is)."""
    version = root.get("version")
    if version in VERSIONS:
        return None
    tag = root.tag.rsplit("}", 1)[-1]
    return f"{tag} version {version!r} is not supported (SSP 1.0 or 2.0)"


def is_clock(connector: Any) -> bool:
    return connector.type == "Clock"


def check_clocks(desc: Any, where: str) -> None:
    """Clock connections join Clock connectors (of equal intervalVariability), data connections
    no Clock; every ssd:Clock association names a Clock connector of the same element."""
    for comp in desc.components:
        for c in comp.connectors.values():
            for clock in c.clocks:
                target = comp.connectors.get(clock)
                if target is None or not is_clock(target):
                    raise SspError(
                        f"{where}: component {comp.name!r}: connector {c.name!r} is"
                        f" associated to clock {clock!r}, which is not a Clock"
                        f" connector of {comp.name!r}"
                    )
    for se, sc, ee, ec in desc.connections:
        ends = (desc.component(se).connectors.get(sc), desc.component(ee).connectors.get(ec))
        if any(e is not None and is_clock(e) for e in ends):
            raise SspError(
                f"{where}: connection {se}.{sc} -> {ee}.{ec} joins a Clock connector"
                " to a non-clock one"
            )
    for se, sc, ee, ec in desc.clock_connections:
        ends = [_end(desc, se, sc, where), _end(desc, ee, ec, where)]
        here = f"{where}: connection {se or 'system'}.{sc} -> {ee or 'system'}.{ec}"
        kinds = [e.type for e in ends]
        if kinds != ["Clock", "Clock"]:
            raise SspError(
                f"{here}: a Clock connector can only be connected to a Clock"
                f" connector (got {kinds[0]} -> {kinds[1]})"
            )
        if ends[0].interval != ends[1].interval:
            raise SspError(f"{here}: intervalVariability {ends[0].interval} != {ends[1].interval}")


def _end(desc: Any, element: str, connector: str, where: str) -> Any:
    if element:
        found = desc.component(element).connectors.get(connector)
    else:
        found = desc.system_connectors.get(connector)
    if found is None:
        owner = element or f"system {desc.name!r}"
        raise SspError(f"{where}: connector {connector!r} of {owner} is not declared")
    return found


def is_clock_connection(system: ET.Element, e: ET.Element) -> bool:
    """Whether a connection element names a Clock connector at either end (by the declared
    connector types of the system and its components)."""
    for elem, conn in (("startElement", "startConnector"), ("endElement", "endConnector")):
        owner = e.get(elem)
        holder = (
            system
            if owner is None
            else next(
                (c for c in system.findall("ssd:Elements/*", NS) if c.get("name") == owner), None
            )
        )
        if holder is None:
            continue
        for c in holder.findall("ssd:Connectors/ssd:Connector", NS):
            if c.get("name") == e.get(conn) and c.find("ssc:Clock", NS) is not None:
                return True
    return False


def check_checksum(component: ET.Element, fmu: Path, what: str) -> None:
    """The SHA3-256 of an SRMD MetaData on a component equals that of its (extracted) FMU."""
    for meta in component.findall("ssc:MetaData", NS):
        if meta.get("type") != SRMD_TYPE:
            continue
        for srmd in meta.iter(f"{SRMD}SimulationResourceMetaData"):
            expected = srmd.get("checksum")
            kind = srmd.get("checksumType", "SHA3-256")
            if expected is None:
                continue
            if kind != "SHA3-256":
                raise SspError(
                    f"{what}: MetaData checksumType {kind!r} is not supported (SRMD: SHA3-256)"
                )
            digest = hashlib.sha3_256()
            with open(fmu, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    digest.update(block)
            actual = digest.hexdigest()
            if actual != expected.lower():
                raise SspError(
                    f"{what}: {fmu.name} does not match the checksum of its MetaData"
                    f" (SHA3-256 {actual[:16]}..., expected {expected[:16]}...)"
                )


def implementation_problem(comp: Any, md: Any, fmu_name: str) -> str | None:
    """Why a component's implementation attribute (SSP 2.0) cannot be honoured with its FMU
    (fmpy model description): the FMU lacks it, or our master would run another interface
    (Co-Simulation if the FMU has it, else Scheduled Execution). None if it can."""
    want = getattr(comp, "implementation", "any")
    if want == "any":
        return None
    have = {"CoSimulation": md.coSimulation, "ModelExchange": md.modelExchange,
            "ScheduledExecution": getattr(md, "scheduledExecution", None)}  # fmt: skip
    if have.get(want) is None:
        return f"component {comp.name}: implementation {want} is not in {fmu_name}"
    used = "CoSimulation" if md.coSimulation is not None else "ScheduledExecution"
    if want != used:
        return (
            f"component {comp.name}: implementation {want}: this master runs {fmu_name} as {used}"
        )
    return None
