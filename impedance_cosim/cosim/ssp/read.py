"""Read an SSP 1.0 or 2.0 archive (.ssp) into plain data, with one-line errors for malformed input.

Supports what the system needs: one system of FMU components, connectors with types and units,
connections, parameter bindings with .ssv parameter sets (on the system or on components), the
default experiment, and this project's master annotation (step size, algorithm, order); and SSP
variants: further .ssd files at the archive's root, each read as the same system with the
parameter set(s) it binds (the scenarios).
The archive is treated as hostile: see archive.py (member checks, caps: the same for the FMUs in
it) and ssp_archive (safe `source` URIs).
Every problem found is an SspError naming the file and element; nothing else escapes.
"""

from __future__ import annotations

import shutil
import tempfile
import weakref
import zipfile
from pathlib import Path

from impedance_cosim.cosim.ssp import ssp2 as ssd2
from impedance_cosim.cosim.ssp.archive import (
    DEFAULT_LIMITS,
    NS,
    ArchiveError,
    Limits,
    SspError,
    check_archive,
    checked,
    extract,
    resolve_source,
)
from impedance_cosim.cosim.ssp.ssp1 import (
    Component,
    Connector,
    Parameter,
    Source,
    SystemDescription,
    bindings,
    check_connections,
    connections,
    connectors,
    experiment,
    parse_xml,
    required,
    units,
)

__all__ = ["Component", "Connector", "Limits", "Parameter", "SspError", "SystemDescription"]
__all__ += ["read_ssp"]

FMU_TYPE = "application/x-fmu-sharedlibrary"
SSD = "SystemStructure.ssd"


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
    except ArchiveError as exc:  # the shared checks (archive.py): an SspError for the reader
        if extract_to is None:
            shutil.rmtree(folder, ignore_errors=True)
        if isinstance(exc, SspError):
            raise
        raise SspError(str(exc)) from None
    except BaseException:
        if extract_to is None:
            shutil.rmtree(folder, ignore_errors=True)
        raise
    if extract_to is None:
        desc._extracted = weakref.finalize(desc, shutil.rmtree, str(folder), True)
    return desc


def _read(path: Path, folder: Path, limits: Limits, ssd: str | None) -> SystemDescription:
    where = path.name
    with checked(path, where, limits, kind="an SSP archive") as (archive, files):
        names = {f.filename for f in files}
        if SSD not in names:
            raise SspError(f"{where} has no {SSD}")
        if ssd is not None and ssd not in names:
            variants = sorted(n for n in names if _is_variant(n))
            raise SspError(f"{where} has no system description {ssd!r} (have {[SSD, *variants]})")
        infos = {f.filename: f for f in files}
        extract(archive, files, folder, where, limits)
        src = Source(archive, infos, where, limits, xml_left=4 * limits.xml_bytes, path=str(path))
        names_read = (
            [ssd] if ssd is not None else [SSD, *sorted(n for n in names if _is_variant(n))]
        )
        desc = _system(src, names_read[0], folder)
        for variant in names_read[1:]:  # SSP variants: the same system, other parameters
            other = _system(src, variant, folder)
            if (other.components, other.connections, other.units, other.clock_connections) != (
                desc.components,
                desc.connections,
                desc.units,
                desc.clock_connections,
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


def _system(src: Source, ssd: str, folder: Path) -> SystemDescription:
    """One system description of the archive: its system, bindings and experiment."""
    where, limits = src.where, src.limits
    root = parse_xml(src.archive, src.infos[ssd], where, "SystemStructureDescription.xsd", limits)
    where_ssd = where if ssd == SSD else f"{where}: {ssd}"
    system = root.find("ssd:System", NS)
    if system is None:
        raise SspError(f"malformed SSD in {where}: {ssd} has no System element")
    sysname = system.get("name") or ""
    for tag in ("System", "SignalDictionaryReference"):
        if system.find(f"ssd:Elements/ssd:{tag}", NS) is not None:
            raise SspError(f"{where_ssd}: system {sysname!r}: {tag} elements are not supported")
    ctx = f"{where_ssd}: system {sysname!r}"
    sets = bindings(system, "", ctx, src)
    version = root.get("version") or "1.0"
    components: list[Component] = []
    seen: set[str] = set()
    names = set(src.infos)
    for i, c in enumerate(system.findall("ssd:Elements/ssd:Component", NS), 1):
        name = required(c, "name", f"{where_ssd}: component #{i}")
        what = f"{where_ssd}: component {name!r}"
        if name in seen:
            raise SspError(f"{what} is declared twice")
        if c.get("type", FMU_TYPE) != FMU_TYPE:
            raise SspError(f"{what}: type {c.get('type')} is not an FMU")
        source = resolve_source(c.get("source"), names, what)
        _check_fmu(folder / source, f"{where}: {source}", limits)
        ssd2.check_checksum(c, folder / source, what)
        comp = Component(name, source, connectors(c, what), folder / source,
                         c.get("implementation", "any"))  # fmt: skip
        components.append(comp)
        seen.add(name)
        sets += bindings(c, name + ".", what, src)
    clocks: list[tuple[str, str, str, str]] = []
    desc = SystemDescription(
        name=sysname,
        components=components,
        connections=connections(system, ctx, clocks if version == "2.0" else None),
        parameter_sets={},
        units=units(root, where_ssd),
        folder=folder,
        version=version,
        system_connectors=connectors(system, ctx),
        clock_connections=clocks,
    )
    # All bindings of a system apply (SSP 1.0), in order; bindings whose sets share a name (one
    # scenario bound on each component) form one parameter set. Sets of different names are
    # offered as alternatives (this project's earlier archives: one system, one set per scenario).
    for i, (name, params, _) in enumerate(sets):
        key = name or f"set{i + 1}"
        desc.parameter_sets.setdefault(key, []).extend(params)
        desc.variants.setdefault(key, ssd)
    experiment(root, desc, where_ssd)
    check_connections(desc, where_ssd)
    ssd2.check_clocks(desc, where_ssd)
    return desc


def _check_fmu(fmu: Path, where: str, limits: Limits) -> None:
    """An FMU that is a zip is checked like the archive, by the same function and limits (it is
    extracted later by fmu_files, which checks it again); anything else is left to the FMU
    loader, which says what is wrong with it."""
    if zipfile.is_zipfile(fmu):
        check_archive(fmu, where, limits, kind="an FMU archive")
