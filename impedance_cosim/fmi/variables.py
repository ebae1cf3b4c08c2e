"""FMI variable tables and the modelDescription.xml written from them.

Each model declares its interface once, as a list of Variable (the analogue of the FMI Reference
FMUs' config.h). The list order is the value-reference order. The same table registers the
variables with pythonfmu and writes the complete modelDescription.xml (units, ranges,
descriptions, ModelStructure) that pythonfmu 0.7 cannot write itself.
"""

from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Any

from impedance_cosim import __version__

# Who wrote the FMUs and under which terms (the root LICENSE; every FMU carries a copy).
AUTHOR = "The impedance-cosim authors"
COPYRIGHT = "Copyright (c) 2026, The impedance-cosim authors"
LICENSE = "BSD-2-Clause (see documentation/licenses/license.txt)"
# Base-unit exponents (kg, m, s, rad) of every unit the models use.
UNITS: dict[str, dict[str, int]] = {
    "1": {},
    "m": {"m": 1},
    "rad": {"rad": 1},
    "s": {"s": 1},
    "kg": {"kg": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N/m": {"kg": 1, "s": -2},
    "N.s/m": {"kg": 1, "s": -1},
    "N.m/rad": {"kg": 1, "m": 2, "s": -2, "rad": -1},
    "N.m.s/rad": {"kg": 1, "m": 2, "s": -1, "rad": -1},
    "kg.m2": {"kg": 1, "m": 2},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "rad/s": {"rad": 1, "s": -1},
    "rad/s2": {"rad": 1, "s": -2},
    "1/s": {"s": -1},
    "Hz": {"s": -1},
}

PYTHON_TYPES = {bool: "Boolean", int: "Integer", float: "Real", str: "String"}


@dataclass(frozen=True)
class Variable:
    """One FMI scalar variable: name, causality and start value, plus unit and documentation."""

    name: str
    causality: str  # "parameter" | "input" | "output" | "local"
    start: float | int | bool | str
    description: str
    unit: str | None = None
    variability: str | None = None  # default: fixed for parameters, continuous otherwise
    min: float | None = None
    max: float | None = None
    derivative: str | None = None  # name of the state this variable is the time derivative of

    @property
    def type(self) -> str:
        """FMI type name (Real, Integer, Boolean, String) from the start value's Python type."""
        return PYTHON_TYPES[type(self.start)]

    @property
    def fmi_variability(self) -> str:
        """FMI variability, with defaults by causality and type."""
        if self.variability:
            return self.variability
        if self.causality == "parameter":
            return "fixed"
        return "continuous" if self.type == "Real" else "discrete"


@dataclass(frozen=True)
class ModelExchange:
    """What a model offers under FMI 2.0 Model Exchange: its continuous states (Real variables of
    its table, in the order of the state vector; none for a sampled-data model with time events
    only) and how many event indicators it has."""

    states: tuple[str, ...]
    event_indicators: int = 0


PER_SECOND = {"rad": "rad/s", "rad/s": "rad/s2", "m": "m/s", "m/s": "m/s2"}


def derivative_variables(variables: list[Variable], me: ModelExchange) -> list[Variable]:
    """The state derivatives der(<state>), appended to a table for Model Exchange (locals)."""
    table = {v.name: v for v in variables}
    missing = [s for s in me.states if s not in table or table[s].type != "Real"]
    if missing:
        raise ValueError(f"Model Exchange states {missing} are not Real variables of the table")
    return [
        Variable(
            f"der({s})",
            "local",
            0.0,
            f"Time derivative of {s} ({table[s].description}), Model Exchange",
            PER_SECOND[table[s].unit] if table[s].unit else None,
            derivative=s,
        )
        for s in me.states
    ]


def parameters_of(params: Any) -> list[Variable]:
    """Parameter variables from a parameter dataclass instance (its fields' metadata)."""
    out = []
    for f in dataclasses.fields(params):
        meta = f.metadata
        out.append(
            Variable(
                name=f.name,
                causality="parameter",
                start=getattr(params, f.name),
                description=meta.get("description", f.name),
                unit=meta.get("unit") if isinstance(getattr(params, f.name), float) else None,
                min=meta.get("min"),
                max=meta.get("max"),
            )
        )
    return out


def vector(
    names: list[str], causality: str, unit: str, description: str, **kw: Any
) -> list[Variable]:
    """Variables for the components of a vector; '{i}' and '{name}' in description are filled."""
    return [
        Variable(
            n,
            causality,
            kw.get("start", 0.0),
            description.format(i=i + 1, name=n),
            unit,
            variability=kw.get("variability"),
        )
        for i, n in enumerate(names)
    ]


def _fmt(value: float | int | bool | str) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isinf(value):
            return "INF" if value > 0 else "-INF"
        return repr(value)
    return str(value)


def model_description(
    model_name: str,
    description: str,
    guid: str,
    variables: list[Variable],
    default_experiment: dict[str, float],
    generation_tool: str,
    output_dependencies: str | None = None,
    needs_execution_tool: bool = False,
    source_files: list[str] | None = None,
    model_exchange: ModelExchange | None = None,
) -> bytes:
    """Complete FMI 2.0 modelDescription.xml for a model's variable table: co-simulation, plus
    Model Exchange (state derivatives appended as der(<state>) locals) when model_exchange is given.

    output_dependencies: None means outputs may depend on every input (conservative); "" declares
    that no output depends directly on an input (no algebraic loop through this FMU); under
    Model Exchange the outputs then depend on the continuous states only."""
    if model_exchange:
        variables = [*variables, *derivative_variables(variables, model_exchange)]
    index = {v.name: i + 1 for i, v in enumerate(variables)}
    root = ET.Element(
        "fmiModelDescription",
        {
            "fmiVersion": "2.0",
            "modelName": model_name,
            "guid": guid,
            "description": description,
            "author": AUTHOR,
            "version": __version__,
            "copyright": COPYRIGHT,
            "license": LICENSE,
            "generationTool": generation_tool,
            "variableNamingConvention": "flat",
            "numberOfEventIndicators": str(
                model_exchange.event_indicators if model_exchange else 0
            ),
        },
    )
    common = {
        "modelIdentifier": model_name,
        "needsExecutionTool": _fmt(needs_execution_tool),
        "canBeInstantiatedOnlyOncePerProcess": "false",
        "canNotUseMemoryManagementFunctions": "true",
        "canGetAndSetFMUstate": "true",
        "canSerializeFMUstate": "true",
    }
    interfaces = []
    if model_exchange:
        interfaces.append(
            ET.SubElement(
                root, "ModelExchange", {**common, "completedIntegratorStepNotNeeded": "true"}
            )
        )
    interfaces.append(
        ET.SubElement(
            root,
            "CoSimulation",
            {
                **common,
                "canHandleVariableCommunicationStepSize": "true",
                "canInterpolateInputs": "false",
            },
        )
    )
    for element in interfaces if source_files else ():
        files = ET.SubElement(element, "SourceFiles")
        for name in source_files or ():
            ET.SubElement(files, "File", {"name": name})
    used = sorted({v.unit for v in variables if v.unit})
    unknown = [u for u in used if u not in UNITS]
    if unknown:
        raise ValueError(f"units {unknown} are not defined in UNITS")
    units = ET.SubElement(root, "UnitDefinitions")
    for u in used:
        unit = ET.SubElement(units, "Unit", {"name": u})
        ET.SubElement(unit, "BaseUnit", {k: str(e) for k, e in UNITS[u].items()})
    cats = ET.SubElement(root, "LogCategories")
    for name, text in LOG_CATEGORIES.items():
        ET.SubElement(cats, "Category", {"name": name, "description": text})
    ET.SubElement(root, "DefaultExperiment", {k: repr(v) for k, v in default_experiment.items()})
    mv = ET.SubElement(root, "ModelVariables")
    for vr, v in enumerate(variables):
        attrs = {
            "name": v.name,
            "valueReference": str(vr),
            "description": v.description,
            "causality": v.causality,
            "variability": v.fmi_variability,
        }
        if v.causality in ("output", "local"):
            attrs["initial"] = "calculated"
        sv = ET.SubElement(mv, "ScalarVariable", attrs)
        type_attrs: dict[str, str] = {}
        if v.derivative:
            type_attrs["derivative"] = str(index[v.derivative])
        if v.unit and v.type == "Real":
            type_attrs["unit"] = v.unit
        if v.min is not None:
            type_attrs["min"] = _fmt(v.min)
        if v.max is not None:
            type_attrs["max"] = _fmt(v.max)
        if v.causality not in ("output", "local"):
            type_attrs["start"] = _fmt(v.start)
        ET.SubElement(sv, v.type, type_attrs)
    ms = ET.SubElement(root, "ModelStructure")
    outs = ET.SubElement(ms, "Outputs")
    if output_dependencies == "" and model_exchange:
        # the knowns are the inputs and the continuous states (FMI 2.0, section 2.2.8)
        output_dependencies = " ".join(str(index[s]) for s in model_exchange.states)
    for i, v in enumerate(variables):
        if v.causality == "output":
            dep = {} if output_dependencies is None else {"dependencies": output_dependencies}
            ET.SubElement(outs, "Unknown", {"index": str(i + 1), **dep})
    if model_exchange and model_exchange.states:
        ders = ET.SubElement(ms, "Derivatives")
        for v in variables:
            if v.derivative:  # depends on states and inputs: no dependencies list (all knowns)
                ET.SubElement(ders, "Unknown", {"index": str(index[v.name])})
    inits = ET.SubElement(ms, "InitialUnknowns")
    for i, v in enumerate(variables):
        if v.causality == "output" or v.derivative:
            ET.SubElement(inits, "Unknown", {"index": str(i + 1)})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


LOG_CATEGORIES = {
    "logStatusWarning": "Messages with fmi2Warning status",
    "logStatusDiscard": "Messages with fmi2Discard status",
    "logStatusError": "Messages with fmi2Error status (bad parameter, bad input, failed step)",
    "logStatusFatal": "Messages with fmi2Fatal status",
    "logAll": "All messages",
}
