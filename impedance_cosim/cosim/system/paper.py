"""The paper's system, defined once: components, connections, scenarios (parameter sets).

From this definition come the SSP 1.0 files in ssp/ (committed and checked to be up to date by the
tests), the .ssp archives the build packs, and the plain-model loop's wiring. Each scenario is a
system description of its own that binds exactly one parameter set, on each component (the
bindings of one system all apply, later ones overriding earlier ones, so alternatives cannot share
an SSD): SystemStructure.ssd is the default variant (observer), difference.ssd and measured.ssd
the others, each binding resources/<scenario>_<component>.ssv.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from controller_model.model import ControllerModel
from impedance_cosim.cosim.ssp.archive import ANNOTATION_TYPE as ANNOTATION_TYPE
from impedance_cosim.cosim.ssp.archive import NS as NS
from impedance_cosim.fmi.units import UNITS
from impedance_cosim.fmi.variables import AUTHOR, COPYRIGHT, Variable
from impedance_cosim.version import __version__
from plant_model.model import PlantModel

# SSP 1.0 top-level meta-data (ssc:ATopLevelMetaData) of the SSD and every SSV.
META = {"author": AUTHOR, "fileversion": __version__, "copyright": COPYRIGHT,
        "license": "BSD-2-Clause"}  # fmt: skip

SYSTEM_NAME = "PaperScenario"
STEP = 1 / 400
STOP = 20.0


@dataclass(frozen=True)
class ComponentDef:
    """A component of the system: instance name, FMU file name, model class."""

    name: str
    fmu: str
    model_class: type

    @property
    def source(self) -> str:
        return f"resources/{self.fmu}"

    def variables(self) -> dict[str, Variable]:
        return {v.name: v for v in self.model_class.variables()}


# Order = the Gauss-Seidel order: the controller samples first, then the plant integrates with the
# torque held (the paper's sample-and-hold).
COMPONENTS = (
    ComponentDef("controller", "ImpedanceController.fmu", ControllerModel),
    ComponentDef("plant", "PumaPlant.fmu", PlantModel),
)

# The order of the Elements in every SSD we write: the plant first. A loop-cutting importer cuts
# the loop before the first component it lists (fmu-manipulation-toolbox 2.0's fmucontainer: the
# first FMU reads its inputs from link buffers, 0.0 at initialization; the others read the
# current outputs), so it cuts where the paper's sample-and-hold does: the plant gets the held
# torque, the controller samples the plant's current outputs, and it is initialized from them.
# Our master's Gauss-Seidel order is the annotation's (COMPONENTS above), not this one; the
# container's sequential mode, Gauss-Seidel in this order, equals Master with order plant,
# controller (impedance_cosim/cosim/engines/container.py).
SSD_ELEMENT_ORDER = ("plant", "controller")

# (start element, start connector, end element, end connector)
CONNECTIONS = (
    *(("plant", f"q{i}", "controller", f"q{i}") for i in (1, 2, 3)),
    ("plant", "fx", "controller", "fx"),
    ("plant", "fy", "controller", "fy"),
    ("plant", "n", "controller", "n"),
    *(("plant", f"qd{i}", "controller", f"qd_meas{i}") for i in (1, 2, 3)),
    *(("controller", f"tau{i}", "plant", f"tau{i}") for i in (1, 2, 3)),
)

# Section 5, written out in every scenario (the wall position is shared by the plant's wall and the
# controller's trajectory switch).
PAPER_PARAMETERS: dict[str, Any] = {
    "plant.wall_x": 0.65,
    "plant.wall_k": 1.0e4,
    "plant.x0": 0.3,
    "plant.y0": 0.0,
    "plant.phi0": 0.0,
    "controller.wall_x": 0.65,
    "controller.wall_depth": 0.00196,
    "controller.traj_f": 0.1,
    **{f"controller.K{i}": 50.0 for i in (1, 2, 3)},
    **{f"controller.G{i}": 1000.0 for i in (1, 2, 3)},
    **{f"controller.B{i}": 2.0 * math.sqrt(1000.0) for i in (1, 2, 3)},
    "controller.sample_period": STEP,
}
SCENARIOS: dict[str, dict[str, Any]] = {
    "observer": {**PAPER_PARAMETERS, "controller.velocity_source": "observer"},
    "difference": {**PAPER_PARAMETERS, "controller.velocity_source": "difference"},
    "measured": {**PAPER_PARAMETERS, "controller.velocity_source": "measured"},
}
DEFAULT_SCENARIO = "observer"  # the scenario of SystemStructure.ssd (SSP's default variant)
# The scenario switch controller.velocity_source (an enumeration of the variable table) is an
# SSP Integer (the item's value) in the SSD and SSV files, as the FMUs declare it: libcosim aborts
# on SSP Enumeration types (see fmi/variables.py).
SCENARIO_DESCRIPTIONS = {
    "observer": "The paper's run: joint velocity from the reduced-order observer, eq. (9)",
    "difference": "Fig. 4 baseline: backward difference of the measured joint angles",
    "measured": "Ideal baseline: the plant's true joint velocity fed to the controller",
}


def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _type_element(parent: ET.Element, prefix: str, v: Variable, value: Any = None) -> None:
    attrs = {} if value is None else {"value": _literal(value)}
    if v.type == "Real" and v.unit:
        attrs["unit"] = v.unit
    if v.enumeration and value is not None:
        attrs["value"] = str(v.enumeration.value(value) if isinstance(value, str) else value)
    ET.SubElement(parent, _q(prefix, v.type), attrs)


def _literal(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


def parameter_variable(name: str) -> Variable:
    """The FMU variable a "component.variable" parameter name refers to (KeyError if none)."""
    element, var = name.split(".", 1)
    for c in COMPONENTS:
        if c.name == element:
            return c.variables()[var]
    raise KeyError(name)


def bound_parameters(component: str) -> set[str]:
    """The variables of a component that a scenario sets (its parameter connectors)."""
    prefix = component + "."
    return {k.removeprefix(prefix) for s in SCENARIOS.values() for k in s if k.startswith(prefix)}


def ssd_name(scenario: str) -> str:
    """The file name of a scenario's system description in the archive (SSP 1.0: the default
    variant is SystemStructure.ssd, the other variants are further .ssd files beside it)."""
    return "SystemStructure.ssd" if scenario == DEFAULT_SCENARIO else f"{scenario}.ssd"


def ssv_name(scenario: str, component: str) -> str:
    """The parameter set file of one component in one scenario (under resources/)."""
    return f"{scenario}_{component}.ssv"


def ssd_xml(scenario: str = "observer") -> bytes:
    """The system description of one scenario: the paper's system with that scenario's parameter
    set bound to each component (SSP 1.0 applies every binding of a system: one set per SSD)."""
    root = ET.Element(
        _q("ssd", "SystemStructureDescription"),
        {"version": "1.0", "name": scenario, "description": SCENARIO_DESCRIPTIONS[scenario],
         **META},
    )  # fmt: skip
    system = ET.SubElement(
        root,
        _q("ssd", "System"),
        {"name": SYSTEM_NAME, "description": "PUMA-subset plant + observer/impedance controller"},
    )
    elements = ET.SubElement(system, _q("ssd", "Elements"))
    used_units: set[str] = set()
    for comp in sorted(COMPONENTS, key=lambda c: SSD_ELEMENT_ORDER.index(c.name)):
        el = ET.SubElement(
            elements,
            _q("ssd", "Component"),
            {"name": comp.name, "source": comp.source, "type": "application/x-fmu-sharedlibrary"},
        )
        connectors = ET.SubElement(el, _q("ssd", "Connectors"))
        params = bound_parameters(comp.name)
        for v in comp.model_class.variables():
            if v.causality == "parameter" and v.name not in params:
                continue
            kind = v.causality
            c = ET.SubElement(
                connectors,
                _q("ssd", "Connector"),
                {"name": v.name, "kind": kind, "description": v.description},
            )
            _type_element(c, "ssc", v)
            if v.unit and v.type == "Real":
                used_units.add(v.unit)
        bindings = ET.SubElement(el, _q("ssd", "ParameterBindings"))
        ET.SubElement(
            bindings,
            _q("ssd", "ParameterBinding"),
            {"source": f"resources/{ssv_name(scenario, comp.name)}"},
        )
    connections_element(system)
    _units(root, "ssd", used_units)
    experiment_element(root)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def connections_element(system: ET.Element) -> ET.Element:
    """The system's Connections element, with the data connections (CONNECTIONS)."""
    connections = ET.SubElement(system, _q("ssd", "Connections"))
    for se, sc, ee, ec in CONNECTIONS:
        ET.SubElement(
            connections,
            _q("ssd", "Connection"),
            {"startElement": se, "startConnector": sc, "endElement": ee, "endConnector": ec},
        )
    return connections


def experiment_element(root: ET.Element) -> None:
    """The DefaultExperiment (0 to STOP) with this project's master annotation (step, order)."""
    exp = ET.SubElement(
        root, _q("ssd", "DefaultExperiment"), {"startTime": "0.0", "stopTime": repr(STOP)}
    )
    ann = ET.SubElement(
        ET.SubElement(exp, _q("ssd", "Annotations")),
        _q("ssc", "Annotation"),
        {"type": ANNOTATION_TYPE},
    )
    ET.SubElement(
        ann,
        "master",
        {
            "stepSize": repr(STEP),
            "algorithm": "gauss-seidel",
            "order": " ".join(c.name for c in COMPONENTS),
        },
    )


def _units(root: ET.Element, prefix: str, used: set[str]) -> None:
    units = ET.SubElement(root, _q(prefix, "Units"))
    for u in sorted(used):
        unit = ET.SubElement(units, _q("ssc", "Unit"), {"name": u})
        ET.SubElement(unit, _q("ssc", "BaseUnit"), {k: str(e) for k, e in UNITS[u].items()})


def ssv_xml(scenario: str, component: str) -> bytes:
    """One component's values in a scenario's parameter set (names relative to the component)."""
    return parameter_set_xml(scenario, component, {"version": "1.0", **META}, _type_element)


def parameter_set_xml(
    scenario: str, component: str, header: dict[str, str], typed: Callable
) -> bytes:
    """The SSV of one component in a scenario, for either SSP version: header (its version and
    meta data) on the root, typed(parameter element, "ssv", variable, value) writing each value's
    type element as that version spells it."""
    root = ET.Element(
        _q("ssv", "ParameterSet"),
        {"version": header["version"], "name": scenario,
         "description": SCENARIO_DESCRIPTIONS[scenario],
         **{k: v for k, v in header.items() if k != "version"}},
    )  # fmt: skip
    params = ET.SubElement(root, _q("ssv", "Parameters"))
    used_units: set[str] = set()
    for pname, value in SCENARIOS[scenario].items():
        if not pname.startswith(component + "."):
            continue
        v = parameter_variable(pname)
        p = ET.SubElement(params, _q("ssv", "Parameter"), {"name": pname.split(".", 1)[1]})
        typed(p, "ssv", v, value)
        if v.type == "Real" and v.unit:
            used_units.add(v.unit)
    _units(root, "ssv", used_units)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def scenario_files(scenario: str) -> dict[str, bytes]:
    """The SSD and SSV files of one scenario (archive path -> content), its SSD as given by
    ssd_name: packed with the others into the multi-variant archive, or alone (its SSD then
    named SystemStructure.ssd) into that scenario's own archive."""
    files = {ssd_name(scenario): ssd_xml(scenario)}
    for comp in COMPONENTS:
        name = ssv_name(scenario, comp.name)
        files[f"resources/{name}"] = ssv_xml(scenario, comp.name)
    return files


def source_files() -> dict[str, bytes]:
    """The files of ssp/ (name -> content) as generated from this module."""
    files = {}
    for scenario in SCENARIOS:
        for path, content in scenario_files(scenario).items():
            files[path.removeprefix("resources/")] = content
    return files


def write_sources(folder: Path | None = None) -> list[Path]:
    """Write the generated SSD and SSV files into ssp/ (or folder)."""
    folder = folder or Path(__file__).resolve().parents[3] / "ssp"
    written = []
    for name, content in source_files().items():
        path = folder / name
        path.write_bytes(content)
        written.append(path)
    return written


if __name__ == "__main__":
    for p in write_sources():
        print(f"wrote {p}")
