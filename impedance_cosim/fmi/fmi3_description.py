"""The FMI 3.0 modelDescription.xml of a model, written from the same variable table as the FMI 2.0
one (impedance_cosim.fmi.variables): same names, value references, units, ranges and
descriptions, FMI 3 type names (Float64, Int32, Boolean, String), an `independent` time variable
and, past the table, what only FMI 3 declares: the event indicators as Float64 locals and the
controller's sample clock (a periodic time-based Clock whose interval is a parameter)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

from impedance_cosim.fmi.fmi2_description import (
    add_log_categories,
    add_unit_and_range,
    description_root,
    exact_dependencies,
    variable_attributes,
    xml_value,
)
from impedance_cosim.fmi.units import DISPLAY_UNITS, QUANTITIES, add_unit_definitions
from impedance_cosim.fmi.variables import (
    SAMPLED_INPUTS,
    ModelExchange,
    Partials,
    Variable,
    full_table,
)

FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}


@dataclass(frozen=True)
class SampleClock:
    """A periodic time-based input clock ticking every `period_parameter` seconds from the start
    (Scheduled Execution: the importer activates the model partition at every tick)."""

    name: str
    period_parameter: str
    description: str


@dataclass(frozen=True)
class Extras:
    """Value references of the FMI 3-only variables, numbered after the table (which keeps the
    FMI 2.0 value references): time first, then event indicators or the clock."""

    time: int
    indicators: tuple[int, ...]
    clock: int | None


def extras(n_table: int, model_exchange: ModelExchange | None, clock: SampleClock | None) -> Extras:
    """Where time, the event indicators and the clock sit for a table of n_table variables."""
    n_ind = model_exchange.event_indicators if model_exchange else 0
    indicators = tuple(range(n_table + 1, n_table + 1 + n_ind))
    return Extras(n_table, indicators, n_table + 1 + n_ind if clock else None)


def model_description3(
    model_name: str,
    description: str,
    token: str,
    variables: list[Variable],
    default_experiment: dict[str, float],
    generation_tool: str,
    output_dependencies: str | None = None,
    model_exchange: ModelExchange | None = None,
    clock: SampleClock | None = None,
    early_return: bool = False,
    naming: str = "flat",
    cs_clock: SampleClock | None = None,
) -> bytes:
    """Complete FMI 3.0 modelDescription.xml: Co-Simulation and, with
    model_exchange, Model Exchange; with clock, Scheduled Execution instead of both, the model's
    inputs and outputs then clocked by it. output_dependencies as in the FMI 2.0 writer;
    early_return: fmi3DoStep may return early at the plant's contact, calls the intermediate
    update there and signals the event (event mode in Co-Simulation) if the importer asks;
    naming: the variableNamingConvention, as in the FMI 2.0 writer; cs_clock: the sample clock
    of Co-Simulation with event mode (hasEventMode, early return and intermediate update at its
    ticks), its variables not clocked: the same FMU serves importers without event mode and Model
    Exchange, which set the inputs and read the outputs outside the clock's ticks (clocked, they
    could not)."""
    table = full_table(variables, model_exchange)
    ext = extras(len(table), model_exchange, clock or cs_clock)
    vr_of = {v.name: vr for vr, v in enumerate(table)}
    root = description_root(("3.0", "instantiationToken", token), model_name, description,
                            generation_tool, naming)  # fmt: skip
    partials = _interfaces3(root, model_name, model_exchange, clock, early_return, cs_clock)
    used = sorted({v.unit for v in table if v.unit} | {"s"})
    add_unit_definitions(root, used)
    _type_definitions(root, [u for u in used if u in QUANTITIES], table)
    add_log_categories(root, "fmi3")
    ET.SubElement(root, "DefaultExperiment", {k: repr(v) for k, v in default_experiment.items()})
    mv = ET.SubElement(root, "ModelVariables")
    ET.SubElement(
        mv,
        "Float64",
        {
            "name": "time",
            "valueReference": str(ext.time),
            "description": "Simulation time",
            "causality": "independent",
            "variability": "continuous",
            "unit": "s",
        },
    )
    for vr, v in enumerate(table):
        _variable3(mv, vr, v, vr_of, ext.clock if clock else None, early_return or bool(cs_clock))
    _extra_variables3(mv, ext, clock or cs_clock)
    _model_structure3(root, table, vr_of, ext, output_dependencies, model_exchange, clock, partials)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _interfaces3(
    root: ET.Element,
    model_name: str,
    model_exchange: ModelExchange | None,
    clock: SampleClock | None,
    early_return: bool,
    cs_clock: SampleClock | None = None,
) -> Partials | None:
    """ScheduledExecution (with a clock), else ModelExchange (when given) and CoSimulation (with
    cs_clock: event mode, early return and intermediate update at its ticks); the model's
    Partials, if any (they add the directional and output derivatives)."""
    common = {
        "modelIdentifier": model_name,
        "needsExecutionTool": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false",
        "canGetAndSetFMUState": "true",
        "canSerializeFMUState": "true",
    }
    partials = model_exchange.partials if model_exchange and not clock else None
    if partials:  # native/src/partials.c: fmi3GetDirectionalDerivative (ME and CS)
        common["providesDirectionalDerivatives"] = "true"
    orders = (
        {"maxOutputDerivativeOrder": str(partials.max_output_derivative_order)} if partials else {}
    )
    if clock:
        ET.SubElement(root, "ScheduledExecution", common)
    else:
        if model_exchange:
            ET.SubElement(
                root, "ModelExchange", {**common, "needsCompletedIntegratorStep": "false"}
            )
        ET.SubElement(
            root,
            "CoSimulation",
            {
                **common,
                "canHandleVariableCommunicationStepSize": "true",
                # the plant's contact switch and the controller's clock ticks: early return,
                # intermediate update, event mode
                **dict.fromkeys(
                    (
                        "hasEventMode",
                        "mightReturnEarlyFromDoStep",
                        "providesIntermediateUpdate",
                        "canReturnEarlyAfterIntermediateUpdate",
                    ),
                    xml_value(early_return or cs_clock is not None),
                ),
                **orders,
            },
        )
    return partials


def _variable3(
    mv: ET.Element,
    vr: int,
    v: Variable,
    vr_of: dict[str, int],
    clock: int | None,
    early_return: bool,
) -> None:
    """One variable of the table as its FMI 3.0 type element (clock: the clock's value
    reference, which clocks the inputs and outputs)."""
    attrs = variable_attributes(v, vr)
    if clock is not None and v.causality in ("input", "output"):
        attrs.update(clocks=str(clock), variability="discrete")
    if v.causality in ("output", "local"):
        attrs["initial"] = "calculated"
    if early_return and v.causality == "output":  # readable in the intermediate update
        attrs["intermediateUpdate"] = "true"
    if v.derivative:
        attrs["derivative"] = str(vr_of[v.derivative])
    enumeration = getattr(v, "enumeration", None)
    if enumeration:  # an Int32 of the enumeration's declared type (as in FMI 2.0)
        attrs.update(declaredType=enumeration.name, min="1", max=str(len(enumeration.items)))
    if v.unit and v.type == "Real" and v.unit in QUANTITIES:
        attrs["declaredType"] = QUANTITIES[v.unit]
    add_unit_and_range(attrs, v)
    start = v.causality not in ("output", "local")
    if start and v.type != "String":
        attrs["start"] = xml_value(v.start)
    element = ET.SubElement(mv, FMI3_TYPES[v.type], attrs)
    if start and v.type == "String":
        ET.SubElement(element, "Start", {"value": str(v.start)})


def _extra_variables3(mv: ET.Element, ext, clock: SampleClock | None) -> None:
    """The variables past the table: the event indicators and the clock, if any."""
    for i, vr in enumerate(ext.indicators):
        ET.SubElement(
            mv,
            "Float64",
            {
                "name": f"event_indicator{i + 1}",
                "valueReference": str(vr),
                "description": "Contact switching function (Model Exchange event indicator)",
                "causality": "local",
                "variability": "continuous",
                "initial": "calculated",
            },
        )
    if clock:
        ET.SubElement(
            mv,
            "Clock",
            {
                "name": clock.name,
                "valueReference": str(ext.clock),
                "description": clock.description,
                "causality": "input",
                "variability": "discrete",
                "intervalVariability": "fixed",
                "priority": "0",
            },
        )


def _model_structure3(
    root: ET.Element,
    table: list[Variable],
    vr_of: dict[str, int],
    ext,
    output_dependencies: str | None,
    model_exchange: ModelExchange | None,
    clock: SampleClock | None,
    partials: Partials | None,
) -> None:
    """ModelStructure: the outputs with their dependencies and, without a clock, the state
    derivatives, the initial unknowns and the event indicators."""
    ms = ET.SubElement(root, "ModelStructure")
    states = model_exchange.states if model_exchange else ()
    if output_dependencies == "" and states and not clock:
        output_dependencies = " ".join(str(vr_of[s]) for s in states)
    if output_dependencies is SAMPLED_INPUTS or output_dependencies == SAMPLED_INPUTS:
        inputs = [str(vr) for vr, v in enumerate(table) if v.causality == "input"]
        dep = {"dependencies": " ".join(inputs),
               "dependenciesKind": " ".join(["discrete"] * len(inputs))}  # fmt: skip
    else:
        dep = {} if output_dependencies is None else {"dependencies": output_dependencies}
    for vr, v in enumerate(table):
        if v.causality == "output":
            exact = exact_dependencies(partials, v.name, vr_of)
            ET.SubElement(ms, "Output", {"valueReference": str(vr), **(exact or dep)})
    if not clock:
        for vr, v in enumerate(table):
            if v.derivative:
                exact = exact_dependencies(partials, v.name, vr_of) or {}
                ET.SubElement(ms, "ContinuousStateDerivative", {"valueReference": str(vr), **exact})
    for vr, v in enumerate(table):  # clocked outputs are not initial unknowns
        if not clock and (v.causality == "output" or v.derivative):
            ET.SubElement(ms, "InitialUnknown", {"valueReference": str(vr)})
    if not clock:
        for vr in ext.indicators:
            ET.SubElement(ms, "EventIndicator", {"valueReference": str(vr)})


def _type_definitions(root: ET.Element, units: list[str], table: list[Variable]) -> None:
    """TypeDefinitions as the FMI 2.0 writer has them: a Float64Type per unit (its quantity and
    display unit), an Int32Type per enumeration (its values listed in the description)."""
    enums = {}
    for v in table:
        e = getattr(v, "enumeration", None)
        if e:
            enums[e.name] = e
    if not units and not enums:
        return
    types = ET.SubElement(root, "TypeDefinitions")
    for u in units:
        attrs = {"name": QUANTITIES[u], "quantity": QUANTITIES[u], "unit": u}
        if u in DISPLAY_UNITS:
            attrs["displayUnit"] = DISPLAY_UNITS[u][0]
        ET.SubElement(types, "Float64Type", attrs)
    for e in enums.values():
        text = f"{e.description}: {e.choices()}"
        attrs = {"name": e.name, "description": text, "min": "1", "max": str(len(e.items))}
        ET.SubElement(types, "Int32Type", attrs)


def c_config3(n_table: int, model_exchange: ModelExchange | None, clock: SampleClock | None,
              variables: list[Variable], early_return: bool = False) -> str:  # fmt: skip
    """fmi3_config.h for the FMI 3 glue: the value references of the FMI 3-only variables."""
    ext = extras(n_table, model_exchange, clock)
    lines = [
        "/* Written by impedance_cosim's FMI 3 build (variables3.c_config3): do not edit. */",
        f"#define VR_TIME {ext.time}",
        f"#define VR_INDICATOR {ext.indicators[0] if ext.indicators else n_table + 1}",
        f"#define HAS_CLOCK {1 if clock else 0}",
        f"#define HAS_EARLY_RETURN {1 if early_return else 0}",
    ]
    if clock:
        names = [v.name for v in variables]
        if clock.period_parameter not in names:
            raise ValueError(f"clock period parameter {clock.period_parameter!r} is not a variable")
        lines += [
            f"#define VR_CLOCK {ext.clock}",
            f"#define CLOCK_PERIOD_VR {names.index(clock.period_parameter)}",
        ]
    return "\n".join(lines) + "\n"
