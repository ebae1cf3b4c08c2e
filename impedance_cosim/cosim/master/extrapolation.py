"""Input extrapolation under Jacobi (the master's `extrapolation` option): first-order hold of
the inputs fed by outputs whose FMU gives their time derivatives (maxOutputDerivativeOrder >= 1).

Jacobi step k (from t_k, length h) sets every input from the outputs at t_k. A sampled consumer
(our controller) reads its input once, at the start of its step, and its output is used only
from t_{k+1} on (by the plant's step k+1): with "none" the torque applied over [t_{k+1},
t_{k+2}] is computed from y(t_k), one sample late. With "linear" the master sets the input to
y(t_k) + h * dy/dt(t_k), the estimate of y(t_{k+1}) that the paper's sample-and-hold would have
sampled for that interval. Inputs from FMUs without derivatives stay y(t_k). The values are set
with fmi2SetReal / fmi3SetFloat64 (not fmi2SetRealInputDerivatives: our controller declares
canInterpolateInputs="false", and a sampled input has no use for a slope over its step).
Gauss-Seidel is refused: the controller, stepped first, samples the plant's outputs at its own
time t_k, so there is no delay to compensate (and the plant gets a held torque).
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable, Mapping
from typing import Any

from impedance_cosim.cosim.fmus.fmi2 import STATUS, FmuError
from impedance_cosim.cosim.fmus.fmi3 import is_fmi3
from impedance_cosim.cosim.master.setup import MasterError

EXTRAPOLATIONS = ("none", "linear")


def derivative_order(description: Any) -> int:
    """The maxOutputDerivativeOrder an FMU declares for co-simulation (0 when none)."""
    cs = getattr(description, "coSimulation", None)
    return int(getattr(cs, "maxOutputDerivativeOrder", 0) or 0) if cs is not None else 0


def check(
    extrapolation: str,
    algorithm: str,
    connections: list[tuple[str, str, str, str]],
    descriptions: Mapping[str, Any],
    files: Mapping[str, Any],
) -> None:
    """MasterError (one line) unless the extrapolation can be done for this system."""
    if extrapolation not in EXTRAPOLATIONS:
        raise MasterError(f"extrapolation must be one of {EXTRAPOLATIONS} (got {extrapolation!r})")
    if extrapolation == "none":
        return
    if algorithm != "jacobi":
        raise MasterError(f"extrapolation {extrapolation!r} needs the Jacobi algorithm (under"
                          f" {algorithm} the consumer samples its source's current outputs:"
                          " nothing is late)")  # fmt: skip
    sources = sorted({se for se, _, _, _ in connections})
    if not any(derivative_order(descriptions[s]) >= 1 for s in sources):
        shown = ", ".join(
            f"{s} ({files[s].name}: {derivative_order(descriptions[s])})" for s in sources
        )
        raise MasterError(f"extrapolation {extrapolation!r} needs output derivatives, and no"
                          f" connected FMU declares maxOutputDerivativeOrder >= 1: {shown};"
                          " use the native FMUs (fmus/PaperScenario-native.ssp)")  # fmt: skip


def derivative_reader(fmu: Any, names: list[str]) -> Callable[[], list[float]]:
    """A fast reader of the first time derivatives of the named outputs (raw ctypes,
    fmi2GetRealOutputDerivatives or fmi3GetOutputDerivatives); FmuError when refused."""
    fmi3 = is_fmi3(fmu.description)
    function = "fmi3GetOutputDerivatives" if fmi3 else "fmi2GetRealOutputDerivatives"
    n = len(names)
    vrs = (ctypes.c_uint * n)(*(fmu.vr(name) for name in names))
    orders = (ctypes.c_int * n)(*([1] * n))
    values = (ctypes.c_double * n)()
    fn, comp = fmu.slave._functions[function], fmu.slave.component
    extra = (n,) if fmi3 else ()

    def read() -> list[float]:
        status = fn(comp, vrs, n, orders, values, *extra)
        if status > 1:
            fmu.fatal |= status == 4
            raise FmuError(f"{fmu.name}: {function} failed ({STATUS[status]}:"
                           f" {fmu.error_detail()})")  # fmt: skip
        return list(values)

    return read


def prepare(ordered: list[Any]) -> None:
    """Give each wired slot `rates` (one per output, 0.0 where not extrapolated) and, for a
    source with derivatives, `read_rates` to refresh them; reads the rates at t_0."""
    used: dict[int, set[int]] = {}
    for s in ordered:
        for j, k in s.sources:
            used.setdefault(j, set()).add(k)
    for j, s in enumerate(ordered):
        s.rates = [0.0] * len(s.outputs)
        s.rate_index = sorted(used.get(j, ())) if derivative_order(s.fmu.description) else []
        names = [s.outputs[k] for k in s.rate_index]
        s.read_rates = derivative_reader(s.fmu, names) if names else None
    refresh(ordered)


def refresh(ordered: list[Any]) -> None:
    """Read the sources' output derivatives at the current communication point."""
    for s in ordered:
        if s.read_rates is not None:
            for k, d in zip(s.rate_index, s.read_rates(), strict=True):
                s.rates[k] = d


def inputs(s: Any, ordered: list[Any], h: float) -> list[float]:
    """Slot s's inputs for a step of length h: each source output plus h times its rate."""
    return [ordered[j].values[k] + h * ordered[j].rates[k] for j, k in s.sources]
