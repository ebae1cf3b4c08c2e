"""What the master checks and gathers before a run: the algorithm, step size and stop time, the
FMUs against the SSD's connectors, and the parameter values (the chosen parameter set, then the
user's overrides) checked against the FMUs' variables and units."""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from controller_model.parameters import VELOCITY_SOURCE
from impedance_cosim.cosim.fmus.files import FmuArchiveError, FmuError, check_fmu, model_description
from impedance_cosim.cosim.fmus.fmi2 import fmi_value
from impedance_cosim.cosim.fmus.fmi3 import element_names, ssp_type
from impedance_cosim.cosim.ssp.read import SystemDescription
from impedance_cosim.cosim.ssp.ssp2 import REALS, implementation_problem

ALGORITHMS = ("gauss-seidel", "jacobi")
# The enumeration types of our models, by declared type name: a parameter set's or --set's item
# name (velocity_source="observer") resolves through them. Any other FMU's Integer takes numbers.
ENUMERATIONS = {e.name: e for e in (VELOCITY_SOURCE,)}


class MasterError(RuntimeError):
    """The system cannot be run as configured (bad parameter name, missing connector...)."""


class NoStepError(MasterError, ValueError):
    """A stop time that gives no communication step at all (also a ValueError: a bad argument)."""


def split_name(name: str) -> tuple[str, str]:
    """ "component.variable" -> (component, variable), with a clear error."""
    if "." not in name:
        raise MasterError(f"parameter {name!r} must be written component.variable")
    comp, var = name.split(".", 1)
    return comp, var


def real_outputs(description: Any) -> list[str]:
    """Names of an FMU's Real outputs, in model order (the recorded signals; an FMI 3.0 array
    q of n elements as q[1] .. q[n])."""
    return [
        name
        for v in description.modelVariables
        if v.causality == "output" and ssp_type(v.type) == "Real"
        for name in element_names(v)
    ]


def connector_problems(comp, fmu_vars: Mapping[str, Any], fmu_name: str) -> list[str]:
    """How an FMU's variables (name -> fmpy ScalarVariable) differ from a component's SSD
    connectors: a missing variable, another causality, type or unit (one line each)."""
    problems = []
    for c in comp.connectors.values():
        v = fmu_vars.get(c.name)
        where = f"{comp.name}.{c.name}"
        if v is None:
            problems.append(f"{where}: no such variable in {fmu_name}")
            continue
        if v.causality != c.kind:
            problems.append(f"{where}: causality {v.causality} in the FMU, {c.kind} in the SSD")
        if v.type != c.type and ssp_type(v.type) != c.type:  # SSP 1.0 Real = FMI 3 Float64
            problems.append(f"{where}: type {v.type} in the FMU, {c.type} in the SSD")
        if c.type in REALS and (v.unit or None) != (c.unit or None):
            problems.append(f"{where}: unit {v.unit} in the FMU, {c.unit} in the SSD")
        if len(element_names(v)) != c.size:  # SSP 2.0 array connectors
            problems.append(f"{where}: {len(element_names(v))} elements in the FMU,"
                            f" {c.size} in the SSD")  # fmt: skip
        fmu_interval = getattr(v, "intervalVariability", None)
        if c.type == "Clock" and c.interval != fmu_interval:  # SSP 2.0 ssc:Clock
            problems.append(f"{where}: intervalVariability {fmu_interval} in the FMU,"
                            f" {c.interval} in the SSD")  # fmt: skip
    return problems


def step_count(start_time: float, stop_time: float | None, step_size: float | None) -> float:
    """The number of communication steps from start to stop (a whole number, as a float),
    after checking that the step size and the stop time make sense."""
    if step_size is None or not 0 < step_size < math.inf:
        raise MasterError(f"step size must be a finite number > 0 (got {step_size})")
    if stop_time is None or not start_time < stop_time < math.inf:
        raise MasterError(f"stop time must be finite and > start time (got {stop_time})")
    steps = (stop_time - start_time) / step_size
    if not math.isfinite(steps):
        raise MasterError(f"stop time {stop_time:g} s at step {step_size:g} s is too"
                          " many steps")  # fmt: skip
    if abs(steps - round(steps)) > 1e-9 * max(1.0, steps):
        raise MasterError(
            f"the run length {stop_time - start_time:g} s is not a whole number of"
            f" {step_size:g} s steps"
        )
    if round(steps) < 1:  # e.g. 1e-300 s: no step at all, so no result to speak of
        raise NoStepError(f"the run length {stop_time - start_time:g} s is shorter than one"
                          f" {step_size:g} s step")  # fmt: skip
    return steps


def read_descriptions(fmu_files: Mapping[str, Path]) -> dict[str, Any]:
    """Each component's model description (fmpy), after checking its FMU file."""
    descriptions = {}
    for name, path in fmu_files.items():
        if not path.is_file():
            raise MasterError(f"component {name}: FMU {path} does not exist")
        try:
            descriptions[name] = model_description(path)
        except FmuArchiveError as exc:  # names the FMU file and the member
            raise MasterError(f"component {name}: {exc}") from None
        except Exception as exc:
            raise MasterError(f"component {name}: cannot read {path.name}: {exc}") from None
        try:
            check_fmu(path, descriptions[name])
        except FmuError as exc:
            raise MasterError(f"component {name}: {exc}") from None
    return descriptions


def collect_parameters(
    system: SystemDescription,
    parameter_set: str,
    descriptions: Mapping[str, Any],
    fmu_files: Mapping[str, Path],
    overrides: Mapping[str, Any],
    origin: str = "in overrides",
) -> dict[str, dict[str, Any]]:
    """Parameter values per component, checked against the FMUs' variables and units; also
    checks every SSD connector against its FMU. origin: where the overrides came from, as the
    message of a bad one says it ("in overrides", "given with --set")."""
    variables = {name: {v.name: v for v in md.modelVariables} for name, md in descriptions.items()}
    _check_connectors(system, variables, fmu_files)
    for comp in system.components:  # SSP 2.0's implementation attribute
        problem = implementation_problem(comp, descriptions[comp.name], fmu_files[comp.name].name)
        if problem:
            raise MasterError(problem)
    values: dict[str, dict[str, Any]] = {name: {} for name in fmu_files}
    for p in system.parameter_sets.get(parameter_set, []):
        comp, var = split_name(p.name)
        try:
            v = _parameter_variable(variables, comp, var, f"in parameter set {parameter_set!r}")
            if p.unit and v.unit and p.unit != v.unit:
                raise MasterError(f"parameter {p.name}: unit {p.unit} but the FMU's is {v.unit}")
            values[comp][var] = _value(v, p.value, p.name)
        except MasterError as exc:  # named with the archive and its .ssv member
            raise MasterError(f"{p.origin}: {exc}" if p.origin else str(exc)) from None
    for name, value in overrides.items():
        comp, var = split_name(name)
        targets = [var]
        if comp in variables and var not in variables[comp]:  # "controller.K" sets K1..K3
            vector = [f"{var}{i}" for i in (1, 2, 3)] + [f"{var}_{i}" for i in (1, 2, 3)]
            targets = [n for n in vector if n in variables[comp]] or [var]
        for t in targets:
            v = _parameter_variable(variables, comp, t, origin)
            values[comp][t] = _value(v, value, f"{comp}.{t}")
    return values


def _parameter_variable(variables, comp: str, var: str, where: str):
    if comp not in variables:
        raise MasterError(f"unknown component {comp!r} {where} (have {list(variables)})")
    v = variables[comp].get(var)
    if v is None:
        names = [n for n, x in variables[comp].items() if x.causality == "parameter"]
        close = [f"{comp}.{n}" for n in difflib.get_close_matches(var, names, n=3, cutoff=0.5)]
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        raise MasterError(f"unknown parameter {comp}.{var} {where}{hint}")
    if v.causality != "parameter":
        raise MasterError(f"{comp}.{var} is a{'n' if v.causality[0] in 'aeiou' else ''} "
                          f"{v.causality}, not a parameter")  # fmt: skip
    return v


def _value(v, value: Any, name: str) -> Any:
    enum = ENUMERATIONS.get(getattr(v.declaredType, "name", ""))
    try:
        if enum and isinstance(value, str) and not value.strip().lstrip("+-").isdigit():
            try:  # an item name of our enumerations ("difference" for velocity_source)
                value = enum.value(value.strip())
            except ValueError as exc:
                raise ValueError(f"variable {name}: {exc}") from None
        return fmi_value(v.type, value, name)
    except ValueError as exc:
        raise MasterError(str(exc)) from None


def _check_connectors(system: SystemDescription, variables, fmu_files) -> None:
    """Every SSD connector exists in its FMU with the same causality, type and unit."""
    problems = []
    for comp in system.components:
        problems += connector_problems(comp, variables[comp.name], fmu_files[comp.name].name)
    if problems:
        raise MasterError("the FMUs do not match the SSD: " + "; ".join(problems))
