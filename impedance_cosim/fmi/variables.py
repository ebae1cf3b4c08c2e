"""FMI variable tables: each model declares its interface once, as a list of Variable (the
analogue of the FMI Reference FMUs' config.h). The list order is the value-reference order. The
same table registers the variables with pythonfmu and writes the complete modelDescription.xml
(fmi2_description.py, FMI 2.0; fmi3_description.py, FMI 3.0); the units are in units.py.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from impedance_cosim.version import __version__

# Who wrote the FMUs and under which terms (the root LICENSE; every FMU carries a copy).
AUTHOR = "The impedance-cosim authors"
COPYRIGHT = "Copyright (c) 2026, The impedance-cosim authors"
LICENSE = "BSD-2-Clause (see documentation/licenses/license.txt)"
# The modelDescription attributes that say who made the FMU and under which terms (FMI 2 and 3).
METADATA = {"author": AUTHOR, "version": __version__, "copyright": COPYRIGHT, "license": LICENSE}
PYTHON_TYPES = {bool: "Boolean", int: "Integer", float: "Real", str: "String"}


# How an Enumeration variable is declared in the modelDescription. Measured with libcosimpy 0.0.6:
# libcosim ignores FMI 2.0 Enumeration variables ("FMI 2.0 Enumeration variable type not
# supported, variable ... will be ignored", so an SSP binding cannot reach it) and aborts the
# process on an SSP Enumeration connector or value ("Don't know how to handle Enumeration type").
# So an enumeration is declared an Integer with min/max and a declared type whose description
# lists the items (model_description.py).


@dataclass(frozen=True)
class Enumeration:
    """An FMI 2.0 Enumeration type: its name and items (name, description), valued 1, 2, ...
    Read and written through fmi2Get/SetInteger, so the models see the item's value."""

    name: str
    description: str
    items: tuple[tuple[str, str], ...]

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
    partials: Partials | None = None  # exact partial derivatives the native model provides


@dataclass(frozen=True)
class Partials:
    """The exact partial derivatives a native model computes (model_partials in its model.c):
    for each unknown (an output or der(<state>)) the knowns it depends on (states, inputs) with
    their dependenciesKind, written into ModelStructure; and the highest order of the outputs'
    time derivatives it gives in co-simulation (maxOutputDerivativeOrder)."""

    dependencies: tuple[tuple[str, tuple[tuple[str, str], ...]], ...]
    max_output_derivative_order: int = 1

    def of(self, unknown: str) -> tuple[tuple[str, str], ...] | None:
        """The (known, kind) pairs of an unknown, or None if it is not listed."""
        return dict(self.dependencies).get(unknown)


PER_SECOND = {"rad": "rad/s", "rad/s": "rad/s2", "m": "m/s", "m/s": "m/s2"}


def full_table(variables: list[Variable], model_exchange: ModelExchange | None) -> list[Variable]:
    """The table as the modelDescription and both glues number it: the model's variables, then
    (Model Exchange) the der(<state>) locals."""
    if model_exchange:
        return [*variables, *derivative_variables(variables, model_exchange)]
    return list(variables)


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


SAMPLED_INPUTS = "sampled-inputs"  # output_dependencies of a sampled-data model (model_description)
