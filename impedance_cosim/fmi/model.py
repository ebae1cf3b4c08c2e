"""The contract between a model's plain numeric code and the shared FMI layer.

A model is a class with a variable table and four operations (build from parameters, step,
outputs, state). It knows nothing about FMI; impedance_cosim.fmi.fmi2_slave wraps any such class
into a pythonfmu slave, and tests drive the class directly.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any, ClassVar, TypeVar

from impedance_cosim.fmi.variables import Variable

P = TypeVar("P")


class ModelError(ValueError):
    """Bad parameter, bad input or failed step; the message names the problem for the FMI log."""


class FmuModel:
    """Base class of the models packaged as FMUs (see module docstring)."""

    MODEL_NAME: ClassVar[str]
    DESCRIPTION: ClassVar[str]
    DEFAULT_EXPERIMENT: ClassVar[dict[str, float]] = {
        "startTime": 0.0,
        "stopTime": 20.0,
        "stepSize": 1 / 400,
    }
    # "" when no output depends directly on an input at a communication point; None otherwise.
    OUTPUT_DEPENDENCIES: ClassVar[str | None] = None
    # What initialization did that the host should know (logged as FMI warnings by the glue).
    init_warnings: tuple[str, ...] = ()

    @classmethod
    def variables(cls) -> list[Variable]:
        """The variable table: order defines value references."""
        raise NotImplementedError

    def __init__(self, parameters: dict[str, Any], start_time: float, inputs: tuple) -> None:
        """Validate the parameters (raise ModelError naming the bad one) and compute the
        initial outputs from them and the inputs."""
        raise NotImplementedError

    def do_step(self, t: float, h: float, inputs: tuple) -> None:
        """Advance from t to t + h with the given inputs; raise ModelError if that is impossible."""
        raise NotImplementedError

    def tune(self, parameters: dict[str, Any]) -> None:
        """Take new values of the tunable parameters (all parameters given) from the next step on;
        raise ModelError naming a bad value (the model then keeps the old ones)."""
        raise ModelError(f"{self.MODEL_NAME} has no tunable parameters")

    def outputs(self) -> tuple:
        """Current output values, in the order of the table's outputs."""
        raise NotImplementedError

    def get_state(self) -> dict[str, Any]:
        """Every bit of internal state as fresh JSON-compatible data (floats round-trip exactly)."""
        raise NotImplementedError

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a state from get_state (possibly after a JSON round trip: lists for tuples)."""
        raise NotImplementedError


def build_params(cls: type[P], values: dict[str, Any]) -> P:
    """Instantiate a parameter dataclass from the matching entries of a name -> value dict."""
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    return cls(**{k: v for k, v in values.items() if k in names})


def check_step(
    t: float, h: float, model_t: float, who: str, names: tuple[str, ...] = (), inputs: tuple = ()
) -> None:
    """Raise ModelError unless a step of h from t is one the model can take: its inputs (named by
    names) finite, h finite and > 0, and t the model's own time (within 1e-9 relative)."""
    check_finite_inputs(names, inputs)
    if not h > 0.0:
        raise ModelError(f"communication step must be > 0 (got {h})")
    if h == math.inf:
        raise ModelError("communication step must be finite (got inf)")
    if abs(t - model_t) > 1e-9 * max(1.0, abs(t)):
        raise ModelError(f"doStep at t={t}, but the {who} is at t={model_t}")


def check_finite_inputs(names: tuple[str, ...], values: tuple) -> None:
    """Raise ModelError naming the first non-finite input."""
    for name, v in zip(names, values):
        if not (v - v == 0.0):  # false for NaN and +-inf
            raise ModelError(f"input {name} is not finite ({v})")


@functools.cache
def output_names(model_class: type[FmuModel]) -> tuple[str, ...]:
    """The model's output names, in the order of its outputs()."""
    return tuple(v.name for v in model_class.variables() if v.causality == "output")


def check_finite_outputs(model_class: type[FmuModel], values: tuple) -> None:
    """Raise ModelError naming the first non-finite output: a step whose numbers overflowed is
    refused, so a host never reads a non-finite output after OK (as native/src/instance.c)."""
    for name, v in zip(output_names(model_class), values):
        if not (v - v == 0.0):  # false for NaN and +-inf
            raise ModelError(f"output {name} is not finite ({v}): the computation overflowed")
