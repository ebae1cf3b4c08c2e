"""The paper's system as SSP 2.0 (the FMI 3.0 edition): the SSD and SSV files of system.py with
what 2.0 can say and 1.0 cannot.

- FMI 3 typed connectors and parameters (Float64 with units, Int32, Boolean, String), as the
  FMI 3.0 FMUs declare their variables (fmi/fmi3_description.py).
- The clocked controller (ImpedanceControllerClocked.fmu, Scheduled Execution) with its input
  clock `sample_clock` as a Clock connector (periodic, intervalVariability fixed: the interval is
  the parameter sample_period), its clocked inputs and outputs associated to it (ssd:Clock), and
  the clock's connection to a Clock connector of the system (SSP 2.0, Allowed Connections: a
  clock that is not `triggered` counts as an output, so it may feed a system output).
- Each component's FMU checksum (SHA3-256) as SSP 2.0 MetaData: inline SRMD
  (application/x-srmd-meta-data, SSP Traceability's SimulationResourceMetaData).
The connections, scenarios, parameter values, default experiment and master annotation are those
of system.py: both editions describe the same system and give the same rows.
The array edition (ARRAYS2, issue 37) wires the FMI 3.0 array FMUs (fmus/fmi3/arrays/,
Co-Simulation, no clock) with array connectors (ssc:Dimension size="3") for q, ft and tau.
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from impedance_cosim.cosim.system.paper import (
    COMPONENTS,
    CONNECTIONS,
    META,
    NS,
    SCENARIO_DESCRIPTIONS,
    SCENARIOS,
    SSD_ELEMENT_ORDER,
    SYSTEM_NAME,
    _literal,
    _units,
    bound_parameters,
    experiment_element,
    parameter_set_xml,
    ssd_name,
    ssv_name,
)
from impedance_cosim.fmi.fmi3_arrays import ARRAYS3, Fmi3Array
from impedance_cosim.fmi.variables import Variable
from impedance_cosim.version import __version__

VERSION = "2.0"
SRMD_NS = "http://ssp-standard.org/SSPTraceability1/SimulationResourceMetaData"
SRMD_TYPE = "application/x-srmd-meta-data"
ET.register_namespace("srmd", SRMD_NS)
FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}
# SSP's top-level meta data as in 1.0, and the tool that wrote the file
META2 = {**META, "generationTool": f"impedance_cosim {__version__} (cosim/system/ssp2.py)"}
CLOCK = "sample_clock"  # the clocked controller's input clock, and the system's clock connector


@dataclass(frozen=True)
class Component2:
    """A component of the 2.0 edition: the FMU file it uses and the FMU implementation."""

    name: str
    fmu: str
    implementation: str
    clocked: bool = False

    @property
    def source(self) -> str:
        return f"resources/{self.fmu}"


COMPONENTS2 = {
    "controller": Component2(
        "controller", "ImpedanceControllerClocked.fmu", "ScheduledExecution", clocked=True
    ),
    "plant": Component2("plant", "PumaPlant.fmu", "CoSimulation"),
}


@dataclass(frozen=True)
class Edition2:
    """One SSP 2.0 archive: its components' FMUs and, per component, the FMU's array variables
    (their elements' connectors become one array connector)."""

    components: dict[str, Component2]
    arrays: dict[str, tuple[Fmi3Array, ...]] = field(default_factory=dict)

    @property
    def clocked(self) -> bool:
        return any(c.clocked for c in self.components.values())

    def connections(self) -> list[tuple[str, str, str, str]]:
        """CONNECTIONS, those between elements k of two arrays as one between the arrays."""
        out = []
        for se, sc, ee, ec in CONNECTIONS:
            ends = (_array_of(self.arrays.get(se, ()), sc), _array_of(self.arrays.get(ee, ()), ec))
            conn = (se, ends[0].name, ee, ends[1].name) if all(ends) else (se, sc, ee, ec)
            if conn not in out:
                out.append(conn)
        return out


CLOCKED2 = Edition2(COMPONENTS2)  # PaperScenario-fmi3-ssp2.ssp
ARRAYS2 = Edition2(  # PaperScenario-fmi3-arrays-ssp2.ssp: the FMUs of fmus/fmi3/arrays/
    {
        "controller": Component2("controller", "ImpedanceController.fmu", "CoSimulation"),
        "plant": Component2("plant", "PumaPlant.fmu", "CoSimulation"),
    },
    ARRAYS3,
)


def _array_of(arrays: tuple[Fmi3Array, ...], name: str) -> Fmi3Array | None:
    return next((a for a in arrays if name in a.elements), None)


def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _typed(parent: ET.Element, prefix: str, v: Variable, value: Any = None) -> None:
    """The FMI 3 type element of a variable (ssc: in connectors, ssv: in parameter sets)."""
    attrs = {}
    if value is not None:
        if v.enumeration:  # Int32 of the enumeration's values, as the FMU declares it
            value = v.enumeration.value(value) if isinstance(value, str) else value
        attrs["value"] = _literal(value)
    if v.type == "Real" and v.unit:
        attrs["unit"] = v.unit
    ET.SubElement(parent, _q(prefix, FMI3_TYPES[v.type]), attrs)


def sha3(data: bytes) -> str:
    """The SHA3-256 checksum (hex) SRMD expects by default (checksumType SHA3-256)."""
    return hashlib.sha3_256(data).hexdigest()


def ssd2_xml(
    scenario: str, checksums: Mapping[str, str] | None = None, edition: Edition2 = CLOCKED2
) -> bytes:
    """The SSP 2.0 system description of one scenario (checksums: component -> SHA3-256 of its
    FMU, written as SRMD meta data when given) in one edition (the clocked one by default)."""
    root = ET.Element(
        _q("ssd", "SystemStructureDescription"),
        {
            "version": VERSION,
            "name": scenario,
            "description": SCENARIO_DESCRIPTIONS[scenario],
            **META2,
        },
    )
    system = ET.SubElement(
        root,
        _q("ssd", "System"),
        {
            "name": SYSTEM_NAME,
            "description": "PUMA-subset plant + observer/impedance controller (FMI 3.0; "
            + ("the controller sampled by its clock)" if edition.clocked else "array connectors)"),
        },
    )
    if edition.clocked:
        outer = ET.SubElement(system, _q("ssd", "Connectors"))
        c = ET.SubElement(
            outer,
            _q("ssd", "Connector"),
            {
                "name": CLOCK,
                "kind": "output",
                "description": "The controller's sample clock (periodic, 400 Hz)",
            },
        )
        _clock_type(c)
    elements = ET.SubElement(system, _q("ssd", "Elements"))
    used_units: set[str] = set()
    for comp in sorted(COMPONENTS, key=lambda c: SSD_ELEMENT_ORDER.index(c.name)):
        el = _component(elements, comp, scenario, used_units, edition)
        if checksums:
            _srmd(el, comp.name, edition.components[comp.name], checksums[comp.name])
    connections = ET.SubElement(system, _q("ssd", "Connections"))
    for se, sc, ee, ec in edition.connections():
        ET.SubElement(
            connections,
            _q("ssd", "Connection"),
            {"startElement": se, "startConnector": sc, "endElement": ee, "endConnector": ec},
        )
    if edition.clocked:
        ET.SubElement(
            connections,
            _q("ssd", "Connection"),
            {"startElement": "controller", "startConnector": CLOCK, "endConnector": CLOCK},
        )
    _units(root, "ssd", used_units)
    experiment_element(root)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def _component(
    elements: ET.Element, comp, scenario: str, used_units: set[str], edition: Edition2
) -> ET.Element:
    """One Component element: its connectors (the clock's too when it is clocked; an array's
    elements as one array connector) and its parameter binding to the scenario's SSV; the Real
    units it uses are added to used_units."""
    spec = edition.components[comp.name]
    arrays = edition.arrays.get(comp.name, ())
    el = ET.SubElement(
        elements,
        _q("ssd", "Component"),
        {
            "name": comp.name,
            "source": spec.source,
            "type": "application/x-fmu-sharedlibrary",
            "implementation": spec.implementation,
        },
    )
    connectors = ET.SubElement(el, _q("ssd", "Connectors"))
    params = bound_parameters(comp.name)
    variables = comp.model_class.variables()
    for v in variables:
        array = _array_of(arrays, v.name)
        if (v.causality == "parameter" and v.name not in params) or (
            array and v.name != array.elements[0]
        ):
            continue
        if array:
            _array_connector(connectors, array, [u for u in variables if u.name in array.elements])
            continue
        c = ET.SubElement(
            connectors,
            _q("ssd", "Connector"),
            {"name": v.name, "kind": v.causality, "description": v.description},
        )
        _typed(c, "ssc", v)
        if spec.clocked and v.causality in ("input", "output"):
            ET.SubElement(c, _q("ssd", "Clock"), {"name": CLOCK})
        if v.unit and v.type == "Real":
            used_units.add(v.unit)
    if spec.clocked:
        c = ET.SubElement(
            connectors,
            _q("ssd", "Connector"),
            {
                "name": CLOCK,
                "kind": "input",
                "description": "Input clock: a sample every sample_period s",
            },
        )
        _clock_type(c)
    bindings = ET.SubElement(el, _q("ssd", "ParameterBindings"))
    ET.SubElement(
        bindings,
        _q("ssd", "ParameterBinding"),
        {"source": f"resources/{ssv_name(scenario, comp.name)}"},
    )
    return el


def _array_connector(connectors: ET.Element, array: Fmi3Array, elements: list[Variable]) -> None:
    """An array connector: Float64 (with the unit its elements share, if any), one ssc:Dimension
    of fixed size, as the array FMU declares the variable (fmi/fmi3_arrays.py)."""
    kind = elements[0].causality
    c = ET.SubElement(
        connectors,
        _q("ssd", "Connector"),
        {"name": array.name, "kind": kind, "description": array.description},
    )
    units = {v.unit for v in elements}
    ET.SubElement(c, _q("ssc", "Float64"), {"unit": units.pop()} if len(units) == 1 else {})
    ET.SubElement(c, _q("ssc", "Dimension"), {"size": str(len(elements))})


def _clock_type(connector: ET.Element) -> None:
    """The clock as the FMU declares it: periodic with a fixed interval (the FMU's parameter
    sample_period, which it reports after initialization), priority 0."""
    ET.SubElement(connector, _q("ssc", "Clock"), {"intervalVariability": "fixed", "priority": "0"})


def _srmd(element: ET.Element, name: str, spec: Component2, checksum: str) -> None:
    """SSP 2.0 MetaData on a component: the SHA3-256 of its FMU, inline SRMD."""
    meta = ET.SubElement(element, _q("ssc", "MetaData"), {"kind": "general", "type": SRMD_TYPE})
    content = ET.SubElement(meta, _q("ssc", "Content"))
    ET.SubElement(
        content,
        f"{{{SRMD_NS}}}SimulationResourceMetaData",
        {
            "version": "1.0.0",
            "name": f"{name}: {spec.fmu}",
            "data": spec.source,
            "checksum": checksum,
            "checksumType": "SHA3-256",
        },
    )


def ssv2_xml(scenario: str, component: str) -> bytes:
    """One component's values in a scenario's parameter set, as SSP 2.0 (FMI 3 types)."""
    return parameter_set_xml(scenario, component, {"version": VERSION, **META2}, _typed)


def archive_files(fmus: Mapping[str, bytes], edition: Edition2 = CLOCKED2) -> dict[str, bytes]:
    """Every member of the 2.0 archive of an edition (path -> content): the three scenarios as
    variants (SystemStructure.ssd the default), their parameter sets, and the FMUs (component ->
    FMU bytes), each SSD carrying the FMUs' checksums."""
    checksums = {name: sha3(data) for name, data in fmus.items()}
    files = {ssd_name(s): ssd2_xml(s, checksums, edition) for s in SCENARIOS}
    for s in SCENARIOS:
        for comp in COMPONENTS:
            files[f"resources/{ssv_name(s, comp.name)}"] = ssv2_xml(s, comp.name)
    for name, data in fmus.items():
        files[edition.components[name].source] = data
    return files
