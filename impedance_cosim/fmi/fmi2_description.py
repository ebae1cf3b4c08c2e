"""The FMI 2.0 modelDescription.xml written from a model's variable table (variables.py): units,
ranges, descriptions, type definitions, log categories and ModelStructure, which pythonfmu 0.7
cannot write itself. Standard library only: bundled in the Python FMUs."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

from impedance_cosim.fmi.units import DISPLAY_UNITS, QUANTITIES, add_unit_definitions
from impedance_cosim.fmi.variables import (
    METADATA,
    SAMPLED_INPUTS,
    ModelExchange,
    Partials,
    Variable,
    full_table,
)

LOG_CATEGORIES = {
    "logStatusWarning": "Messages with fmi2Warning status",
    "logStatusDiscard": "Messages with fmi2Discard status",
    "logStatusError": "Messages with fmi2Error status (bad parameter, bad input, failed step)",
    "logStatusFatal": "Messages with fmi2Fatal status",
    "logAll": "All messages",
}


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
    naming: str = "flat",
) -> bytes:
    """Complete FMI 2.0 modelDescription.xml for a model's variable table: co-simulation, plus
    Model Exchange (state derivatives appended as der(<state>) locals) when model_exchange is given.

    output_dependencies: None means outputs may depend on every input (conservative); "" declares
    that no output depends directly on an input (no algebraic loop through this FMU); under
    Model Exchange the outputs then depend on the continuous states only. SAMPLED_INPUTS: every
    output depends on every input, but only at sample instants (dependenciesKind "discrete").
    naming: the variableNamingConvention ("structured" for names like plant.q1: the closed loop)."""
    variables = full_table(variables, model_exchange)
    index = {v.name: i + 1 for i, v in enumerate(variables)}
    n_indicators = model_exchange.event_indicators if model_exchange else 0
    root = description_root(("2.0", "guid", guid), model_name, description, generation_tool,
                            naming, numberOfEventIndicators=str(n_indicators))  # fmt: skip
    partials = _interfaces(root, model_name, needs_execution_tool, model_exchange, source_files)
    used = sorted({v.unit for v in variables if v.unit})
    unknown = [u for u in used if u not in QUANTITIES]
    if unknown:
        raise ValueError(f"units {unknown} have no quantity in QUANTITIES")
    add_unit_definitions(root, used)
    _type_definitions(root, used, variables)
    add_log_categories(root, "fmi2")
    ET.SubElement(root, "DefaultExperiment", {k: repr(v) for k, v in default_experiment.items()})
    _model_variables(root, variables, index)
    _model_structure(root, variables, index, output_dependencies, model_exchange, partials)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def description_root(
    identity: tuple[str, str, str],
    model_name: str,
    description: str,
    generation_tool: str,
    naming: str,
    **extra: str,
) -> ET.Element:
    """The fmiModelDescription element of either version: identity is (fmiVersion, the name of
    its identifying attribute: guid or instantiationToken, its value)."""
    version, key, value = identity
    return ET.Element(
        "fmiModelDescription",
        {
            "fmiVersion": version,
            "modelName": model_name,
            key: value,
            "description": description,
            **METADATA,
            "generationTool": generation_tool,
            "variableNamingConvention": naming,
            **extra,
        },
    )


def add_log_categories(root: ET.Element, prefix: str) -> None:
    """The LogCategories, their statuses named as the version's (prefix fmi2 or fmi3) are."""
    cats = ET.SubElement(root, "LogCategories")
    for name, text in LOG_CATEGORIES.items():
        description = text.replace("fmi2", prefix)
        ET.SubElement(cats, "Category", {"name": name, "description": description})


def variable_attributes(v: Variable, vr: int) -> dict[str, str]:
    """The attributes every variable element of either version starts with."""
    return {
        "name": v.name,
        "valueReference": str(vr),
        "description": v.description,
        "causality": v.causality,
        "variability": v.fmi_variability,
    }


def _interfaces(
    root: ET.Element,
    model_name: str,
    needs_execution_tool: bool,
    model_exchange: ModelExchange | None,
    source_files: list[str] | None,
) -> Partials | None:
    """The ModelExchange (when given) and CoSimulation elements, with their source files; the
    model's Partials, if any (they add the directional and output derivatives)."""
    common = {
        "modelIdentifier": model_name,
        "needsExecutionTool": xml_value(needs_execution_tool),
        "canBeInstantiatedOnlyOncePerProcess": "false",
        "canNotUseMemoryManagementFunctions": "true",
        "canGetAndSetFMUstate": "true",
        "canSerializeFMUstate": "true",
    }
    partials = model_exchange.partials if model_exchange else None
    if partials:  # native/src/partials.c: fmi2GetDirectionalDerivative (ME and CS)
        common["providesDirectionalDerivative"] = "true"
    interfaces = []
    if model_exchange:
        interfaces.append(
            ET.SubElement(
                root, "ModelExchange", {**common, "completedIntegratorStepNotNeeded": "true"}
            )
        )
    orders = (
        {"maxOutputDerivativeOrder": str(partials.max_output_derivative_order)} if partials else {}
    )
    interfaces.append(
        ET.SubElement(
            root,
            "CoSimulation",
            {
                **common,
                "canHandleVariableCommunicationStepSize": "true",
                "canInterpolateInputs": "false",
                **orders,
            },
        )
    )
    for element in interfaces if source_files else ():
        files = ET.SubElement(element, "SourceFiles")
        for name in source_files or ():
            ET.SubElement(files, "File", {"name": name})
    return partials


def _model_variables(root: ET.Element, variables: list[Variable], index: dict[str, int]) -> None:
    """ModelVariables: one ScalarVariable per variable, value reference = its position."""
    mv = ET.SubElement(root, "ModelVariables")
    for vr, v in enumerate(variables):
        attrs = variable_attributes(v, vr)
        if v.causality in ("output", "local"):
            attrs["initial"] = "calculated"
        sv = ET.SubElement(mv, "ScalarVariable", attrs)
        type_attrs: dict[str, str] = {}
        if v.enumeration:
            type_attrs["declaredType"] = v.enumeration.name
            type_attrs.update(min="1", max=str(len(v.enumeration.items)))
        if v.unit and v.type == "Real":
            type_attrs["declaredType"] = QUANTITIES[v.unit]
        if v.derivative:
            type_attrs["derivative"] = str(index[v.derivative])
        add_unit_and_range(type_attrs, v)
        if v.causality not in ("output", "local"):
            type_attrs["start"] = xml_value(v.start)
        ET.SubElement(sv, v.type, type_attrs)


def _model_structure(
    root: ET.Element,
    variables: list[Variable],
    index: dict[str, int],
    output_dependencies: str | None,
    model_exchange: ModelExchange | None,
    partials: Partials | None,
) -> None:
    """ModelStructure: the outputs with their dependencies, the state derivatives, the initial
    unknowns."""
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
            exact = exact_dependencies(partials, v.name, index)
            ET.SubElement(outs, "Unknown", {"index": str(i + 1), **(exact or deps)})
    if model_exchange and model_exchange.states:
        ders = ET.SubElement(ms, "Derivatives")
        for v in variables:
            if v.derivative:  # without partials: depends on every known (no dependencies list)
                exact = exact_dependencies(partials, v.name, index) or {}
                ET.SubElement(ders, "Unknown", {"index": str(index[v.name]), **exact})
    inits = ET.SubElement(ms, "InitialUnknowns")
    for i, v in enumerate(variables):
        if v.causality == "output" or v.derivative:
            ET.SubElement(inits, "Unknown", {"index": str(i + 1)})


def exact_dependencies(
    partials: Partials | None, name: str, ref: dict[str, int]
) -> dict[str, str] | None:
    """dependencies and dependenciesKind of an unknown from a model's Partials (ref: variable
    name -> index (FMI 2.0) or value reference (FMI 3.0)); None when it declares none."""
    pairs = partials.of(name) if partials else None
    if pairs is None:
        return None
    if not pairs:  # depends on nothing (an empty dependenciesKind list says nothing more)
        return {"dependencies": ""}
    return {"dependencies": " ".join(str(ref[k]) for k, _ in pairs),
            "dependenciesKind": " ".join(kind for _, kind in pairs)}  # fmt: skip


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
    for e in enums.values():  # an Integer type documenting the values (fmi/variables.py)
        text = f"{e.description}: {e.choices()}"
        st = ET.SubElement(types, "SimpleType", {"name": e.name, "description": text})
        ET.SubElement(st, "Integer", {"min": "1", "max": str(len(e.items))})


def add_unit_and_range(attrs: dict[str, str], v: Variable) -> None:
    """A variable's unit, display unit, min and max as attributes, in this order (FMI 2.0 and
    3.0 write them alike)."""
    if v.unit and v.type == "Real":
        attrs["unit"] = v.unit
        if v.unit in DISPLAY_UNITS:
            attrs["displayUnit"] = DISPLAY_UNITS[v.unit][0]
    if v.min is not None:
        attrs["min"] = xml_value(v.min)
    if v.max is not None:
        attrs["max"] = xml_value(v.max)


def xml_value(value: float | int | bool | str) -> str:
    """A start, min or max value as FMI writes it (true/false, INF, the shortest float repr)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isinf(value):
            return "INF" if value > 0 else "-INF"
        return repr(value)
    return str(value)
