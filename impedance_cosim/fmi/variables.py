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
# The modelDescription attributes that say who made the FMU and under which terms (FMI 2 and 3).
METADATA = {"author": AUTHOR, "version": __version__, "copyright": COPYRIGHT, "license": LICENSE}
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

# The physical quantity of each unit (FMI TypeDefinitions: one SimpleType per unit) and the unit
# a tool should show a value in (FMI DisplayUnit: display = factor * value + offset).
QUANTITIES: dict[str, str] = {
    "1": "Dimensionless",
    "m": "Length",
    "rad": "Angle",
    "s": "Time",
    "kg": "Mass",
    "N": "Force",
    "N.m": "Torque",
    "N/m": "TranslationalStiffness",
    "N.s/m": "TranslationalDamping",
    "N.m/rad": "RotationalStiffness",
    "N.m.s/rad": "RotationalDamping",
    "kg.m2": "MomentOfInertia",
    "m/s": "Velocity",
    "m/s2": "Acceleration",
    "rad/s": "AngularVelocity",
    "rad/s2": "AngularAcceleration",
    "1/s": "Rate",
    "Hz": "Frequency",
}
DEG = 180.0 / math.pi
DISPLAY_UNITS: dict[str, tuple[str, float, float]] = {
    "rad": ("deg", DEG, 0.0),
    "rad/s": ("deg/s", DEG, 0.0),
    "rad/s2": ("deg/s2", DEG, 0.0),
    "N.m/rad": ("N.m/deg", 1.0 / DEG, 0.0),
    "N.m.s/rad": ("N.m.s/deg", 1.0 / DEG, 0.0),
}

PYTHON_TYPES = {bool: "Boolean", int: "Integer", float: "Real", str: "String"}


# How an Enumeration variable is declared in the modelDescription. Measured with libcosimpy 0.0.6:
# libcosim ignores FMI 2.0 Enumeration variables ("FMI 2.0 Enumeration variable type not
# supported, variable ... will be ignored", so an SSP binding cannot reach it) and aborts the
# process on an SSP Enumeration connector or value ("Don't know how to handle Enumeration type").
# So False: an Integer with min/max and a declared type whose description lists the items.
FMI_ENUMERATIONS = False
ENUMERATIONS: dict[str, Enumeration] = {}  # every Enumeration defined, by type name


@dataclass(frozen=True)
class Enumeration:
    """An FMI 2.0 Enumeration type: its name and items (name, description), valued 1, 2, ...
    Read and written through fmi2Get/SetInteger, so the models see the item's value."""

    name: str
    description: str
    items: tuple[tuple[str, str], ...]

    def __post_init__(self) -> None:
        ENUMERATIONS[self.name] = self

    def value(self, item: str) -> int:
        """The value of an item name (ValueError naming the choices if unknown)."""
        names = [n for n, _ in self.items]
        if item not in names:
            raise ValueError(f"must be one of {', '.join(names)} (got {item!r})")
        return names.index(item) + 1

    def item(self, value: int) -> str:
        """The item name of a value (ValueError if out of range)."""
        if not (isinstance(value, int) and 1 <= value <= len(self.items)):
            raise ValueError(f"must be one of {self.choices()} (got {value!r})")
        return self.items[value - 1][0]

    def choices(self) -> str:
        return ", ".join(f"{i + 1} ({n})" for i, (n, _) in enumerate(self.items))


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
    enumeration: Enumeration | None = None  # an Integer start value, declared as this Enumeration

    @property
    def type(self) -> str:
        """Value type (Real, Integer, Boolean, String) from the start value's Python type: how
        the value is got and set (an Enumeration through Integer)."""
        return PYTHON_TYPES[type(self.start)]

    @property
    def fmi_type(self) -> str:
        """FMI type element of the modelDescription: Enumeration for an enumeration (if
        FMI_ENUMERATIONS), else type."""
        return "Enumeration" if self.enumeration and FMI_ENUMERATIONS else self.type

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
                variability="tunable" if meta.get("tunable") else None,
                min=meta.get("min"),
                max=meta.get("max"),
                enumeration=meta.get("enumeration"),
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


SAMPLED_INPUTS = "sampled-inputs"  # output_dependencies of a sampled-data model (see below)


def _type_definitions(root: ET.Element, units: list[str], variables: list[Variable]) -> None:
    """TypeDefinitions: one Real SimpleType per unit used (its quantity, unit and display unit)
    and every Enumeration the variables declare."""
    types = ET.SubElement(root, "TypeDefinitions")
    for u in units:
        attrs = {"quantity": QUANTITIES[u], "unit": u}
        if u in DISPLAY_UNITS:
            attrs["displayUnit"] = DISPLAY_UNITS[u][0]
        ET.SubElement(ET.SubElement(types, "SimpleType", {"name": QUANTITIES[u]}), "Real", attrs)
    enums = {v.enumeration.name: v.enumeration for v in variables if v.enumeration}
    for e in enums.values():
        if not FMI_ENUMERATIONS:  # an Integer type documenting the values
            text = f"{e.description}: {e.choices()}"
            st = ET.SubElement(types, "SimpleType", {"name": e.name, "description": text})
            ET.SubElement(st, "Integer", {"min": "1", "max": str(len(e.items))})
            continue
        st = ET.SubElement(types, "SimpleType", {"name": e.name, "description": e.description})
        items = ET.SubElement(st, "Enumeration")
        for k, (name, text) in enumerate(e.items, 1):
            ET.SubElement(items, "Item", {"name": name, "value": str(k), "description": text})


def _fmt(value: float | int | bool | str) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isinf(value):
            return "INF" if value > 0 else "-INF"
        return repr(value)
    return str(value)


def add_unit_definitions(root: ET.Element, used: list[str]) -> None:
    """<UnitDefinitions> of the named units (SI base-unit exponents, display units), the same
    element in FMI 2.0 and 3.0; a unit missing from UNITS is a ValueError."""
    unknown = [u for u in used if u not in UNITS]
    if unknown:
        raise ValueError(f"units {unknown} are not defined in UNITS")
    units = ET.SubElement(root, "UnitDefinitions")
    for u in used:
        unit = ET.SubElement(units, "Unit", {"name": u})
        ET.SubElement(unit, "BaseUnit", {k: str(e) for k, e in UNITS[u].items()})
        if u in DISPLAY_UNITS:
            name, factor, offset = DISPLAY_UNITS[u]
            display = {"name": name, "factor": repr(factor), "offset": repr(offset)}
            ET.SubElement(unit, "DisplayUnit", display)


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
    Model Exchange the outputs then depend on the continuous states only. SAMPLED_INPUTS: every
    output depends on every input, but only at sample instants (dependenciesKind "discrete")."""
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
            **METADATA,
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
    unknown = [u for u in used if u not in QUANTITIES]
    if unknown:
        raise ValueError(f"units {unknown} have no quantity in QUANTITIES")
    add_unit_definitions(root, used)
    _type_definitions(root, used, variables)
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
        if v.enumeration:
            type_attrs["declaredType"] = v.enumeration.name
            if not FMI_ENUMERATIONS:
                type_attrs.update(min="1", max=str(len(v.enumeration.items)))
        if v.unit and v.type == "Real":
            type_attrs["declaredType"] = QUANTITIES[v.unit]
        if v.derivative:
            type_attrs["derivative"] = str(index[v.derivative])
        if v.unit and v.type == "Real":
            type_attrs["unit"] = v.unit
            if v.unit in DISPLAY_UNITS:
                type_attrs["displayUnit"] = DISPLAY_UNITS[v.unit][0]
        if v.min is not None:
            type_attrs["min"] = _fmt(v.min)
        if v.max is not None:
            type_attrs["max"] = _fmt(v.max)
        if v.causality not in ("output", "local"):
            type_attrs["start"] = _fmt(v.start)
        ET.SubElement(sv, v.fmi_type, type_attrs)
    ms = ET.SubElement(root, "ModelStructure")
    outs = ET.SubElement(ms, "Outputs")
    if output_dependencies == "" and model_exchange:
        # the knowns are the inputs and the continuous states (FMI 2.0, section 2.2.8)
        output_dependencies = " ".join(str(index[s]) for s in model_exchange.states)
    if output_dependencies == SAMPLED_INPUTS:
        inputs = [str(i + 1) for i, v in enumerate(variables) if v.causality == "input"]
        deps = {"dependencies": " ".join(inputs),
                "dependenciesKind": " ".join(["discrete"] * len(inputs))}  # fmt: skip
    elif output_dependencies is None:
        deps = {}
    else:
        deps = {"dependencies": output_dependencies}
    for i, v in enumerate(variables):
        if v.causality == "output":
            ET.SubElement(outs, "Unknown", {"index": str(i + 1), **deps})
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
