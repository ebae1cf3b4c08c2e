"""The paper's system, defined once: components, connections, scenarios (parameter sets).

From this definition come the SSP 1.0 files in ssp/ (SystemStructure.ssd and one .ssv per
scenario, committed and checked to be up to date by the tests), the .ssp archives the build packs,
and the plain-model loop's wiring.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from controller_model.model import ControllerModel
from impedance_cosim import __version__
from impedance_cosim.fmi.variables import AUTHOR, COPYRIGHT, UNITS, Variable
from plant_model.model import PlantModel

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
}
for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)
ANNOTATION_TYPE = "org.impedance-cosim.master"
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


def ssd_xml() -> bytes:
    """SystemStructure.ssd of the paper's system."""
    root = ET.Element(
        _q("ssd", "SystemStructureDescription"),
        {"version": "1.0", "name": "ImpedanceControlWithoutVelocityMeasurements", **META},
    )
    system = ET.SubElement(
        root,
        _q("ssd", "System"),
        {"name": SYSTEM_NAME, "description": "PUMA-subset plant + observer/impedance controller"},
    )
    bindings = ET.SubElement(system, _q("ssd", "ParameterBindings"))
    for name in SCENARIOS:
        ET.SubElement(bindings, _q("ssd", "ParameterBinding"), {"source": f"resources/{name}.ssv"})
    elements = ET.SubElement(system, _q("ssd", "Elements"))
    used_units: set[str] = set()
    for comp in COMPONENTS:
        el = ET.SubElement(
            elements,
            _q("ssd", "Component"),
            {"name": comp.name, "source": comp.source, "type": "application/x-fmu-sharedlibrary"},
        )
        connectors = ET.SubElement(el, _q("ssd", "Connectors"))
        params = {
            k.split(".", 1)[1]
            for s in SCENARIOS.values()
            for k in s
            if k.startswith(comp.name + ".")
        }
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
    connections = ET.SubElement(system, _q("ssd", "Connections"))
    for se, sc, ee, ec in CONNECTIONS:
        ET.SubElement(
            connections,
            _q("ssd", "Connection"),
            {"startElement": se, "startConnector": sc, "endElement": ee, "endConnector": ec},
        )
    units = ET.SubElement(root, _q("ssd", "Units"))
    for u in sorted(used_units):
        unit = ET.SubElement(units, _q("ssc", "Unit"), {"name": u})
        ET.SubElement(unit, _q("ssc", "BaseUnit"), {k: str(e) for k, e in UNITS[u].items()})
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
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def ssv_xml(name: str) -> bytes:
    """The parameter set of a scenario."""
    root = ET.Element(
        _q("ssv", "ParameterSet"),
        {"version": "1.0", "name": name, "description": SCENARIO_DESCRIPTIONS[name], **META},
    )
    params = ET.SubElement(root, _q("ssv", "Parameters"))
    used_units: set[str] = set()
    for pname, value in SCENARIOS[name].items():
        v = parameter_variable(pname)
        p = ET.SubElement(params, _q("ssv", "Parameter"), {"name": pname})
        _type_element(p, "ssv", v, value)
        if v.type == "Real" and v.unit:
            used_units.add(v.unit)
    units = ET.SubElement(root, _q("ssv", "Units"))
    for u in sorted(used_units):
        unit = ET.SubElement(units, _q("ssc", "Unit"), {"name": u})
        ET.SubElement(unit, _q("ssc", "BaseUnit"), {k: str(e) for k, e in UNITS[u].items()})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def source_files() -> dict[str, bytes]:
    """The files of ssp/ (name -> content) as generated from this module."""
    files = {"SystemStructure.ssd": ssd_xml()}
    files.update({f"{name}.ssv": ssv_xml(name) for name in SCENARIOS})
    return files


def write_sources(folder: Path | None = None) -> list[Path]:
    """Write the generated SSD and SSV files into ssp/ (or folder)."""
    folder = folder or Path(__file__).resolve().parent.parent / "ssp"
    written = []
    for name, content in source_files().items():
        path = folder / name
        path.write_bytes(content)
        written.append(path)
    return written


if __name__ == "__main__":
    for p in write_sources():
        print(f"wrote {p}")
