"""The one FMI glue layer: turns an FmuModel class into a pythonfmu co-simulation slave.

A model's slave script is three lines (see plant_model/PumaPlant.py):

    class PumaPlant(ModelSlave, Fmi2Slave):
        model_class = PlantModel

The mixin registers the table's variables, builds the model when initialization needs it,
validates the FMI call sequence, reports bad parameters and inputs through the FMU logger, and
saves and restores the complete state (including the model's internal state) for rollback.

Status mapping under pythonfmu 0.7: an error during initialization raises (the FMU returns
fmi2Fatal, after logging our message with fmi2Error status); a step that cannot be taken (bad
input, integrator failure) returns fmi2Discard, the FMU keeps its state at the step's start, and
the message is logged with fmi2Error status.
"""

from __future__ import annotations

import sys
from typing import Any

from pythonfmu import Boolean, Fmi2Causality, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Status

from impedance_cosim.fmi.model import FmuModel, ModelError

_PY_VAR = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}
_CONVERT = {"Real": float, "Integer": int, "Boolean": bool, "String": str}

INSTANTIATED, INITIALIZING, STEPPING, TERMINATED = range(4)


class ModelSlave:
    """Mixin for pythonfmu.Fmi2Slave (list it first among the bases)."""

    model_class: type[FmuModel]

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)  # type: ignore[call-arg]
        cls = self.model_class
        self.modelName = cls.MODEL_NAME
        self.description = cls.DESCRIPTION
        self._table = cls.variables()
        self._values: dict[str, Any] = {}
        self._inputs = tuple(v.name for v in self._table if v.causality == "input")
        self._params = tuple(v.name for v in self._table if v.causality == "parameter")
        self._outputs: list[Any] = []
        self._phase = INSTANTIATED
        self._dirty = True
        self._start_time = 0.0
        self.model: FmuModel | None = None
        for v in self._table:
            var_cls = _PY_VAR[v.type]
            if v.causality == "output":
                index = len(self._outputs)
                self._outputs.append(v.start)
                getter = self._output_getter(index)
                setter = None
            else:
                self._values[v.name] = v.start
                getter = self._value_getter(v.name)
                setter = self._value_setter(v, _CONVERT[v.type])
            self.register_variable(
                var_cls(
                    v.name,
                    causality=getattr(Fmi2Causality, v.causality),
                    variability=getattr(Fmi2Variability, v.fmi_variability),
                    description=v.description,
                    getter=getter,
                    setter=setter,
                )
            )

    # --- variable access ----------------------------------------------------------------------

    def _value_getter(self, name: str):
        return lambda: self._values[name]

    def _value_setter(self, v: Any, convert):
        name = v.name
        tunable = v.causality == "parameter" and v.fmi_variability == "tunable"

        def setter(value: Any) -> None:
            if v.causality == "parameter" and self._phase >= STEPPING:
                if not tunable or self._phase == TERMINATED or self.model is None:
                    self._fail(f"parameter {name} is fixed: it cannot be set after initialization")
                # FMI 2.0: a tunable parameter may be set between communication points; the
                # model checks the new value and uses it from its next sample on.
                params = {n: self._values[n] for n in self._params}
                params[name] = convert(value)
                try:
                    self.model.tune(params)
                except ModelError as exc:
                    self._fail(str(exc))
            self._values[name] = convert(value)
            if self._phase <= INITIALIZING:
                self._dirty = True

        return setter

    def _output_getter(self, index: int):
        def getter() -> Any:
            if self._dirty and self._phase == INITIALIZING:
                self._build()
            return self._outputs[index]

        return getter

    # --- lifecycle ----------------------------------------------------------------------------

    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None) -> None:
        self._start_time = float(start_time)

    def enter_initialization_mode(self) -> None:
        if self._phase != INSTANTIATED:
            self._fail("enterInitializationMode called twice or after initialization")
        self._phase = INITIALIZING
        self._dirty = True

    def exit_initialization_mode(self) -> None:
        if self._phase != INITIALIZING:
            self._fail("exitInitializationMode called outside initialization mode")
        if self._dirty or self.model is None:
            self._build()
        self._phase = STEPPING

    def do_step(self, current_time: float, step_size: float) -> bool:
        if self._phase != STEPPING or self.model is None:
            self._report("doStep called before initialization finished")
            return False
        try:
            self.model.do_step(current_time, step_size, self._input_values())
        except ModelError as exc:
            self._report(f"at t={current_time}: {exc}")
            return False
        self._outputs = list(self.model.outputs())
        return True

    def terminate(self) -> None:
        self._phase = TERMINATED

    def _input_values(self) -> tuple:
        values = self._values
        return tuple(values[n] for n in self._inputs)

    def _build(self) -> None:
        params = {n: self._values[n] for n in self._params}
        try:
            self.model = self.model_class(params, self._start_time, self._input_values())
        except ModelError as exc:
            self._fail(str(exc))
        self._outputs = list(self.model.outputs())
        self._dirty = False

    def _report(self, message: str) -> None:
        """Log an error through the FMU logger, and to stderr: pythonfmu 0.7 drops every log
        message (errors included) unless the host turned debug logging on."""
        text = f"{self.model_class.MODEL_NAME} '{self.instance_name}': {message}"
        self.log(text, Fmi2Status.error)
        print(f"error: {text}", file=sys.stderr, flush=True)

    def _fail(self, message: str) -> None:
        """Report a clear error, then raise (pythonfmu then returns fmi2Fatal)."""
        self._report(message)
        raise ModelError(message)

    # --- FMU state (get/set/serialize) -------------------------------------------------------

    def _get_fmu_state(self) -> dict[str, Any]:
        return {
            "values": dict(self._values),
            "outputs": list(self._outputs),
            "phase": self._phase,
            "dirty": self._dirty,
            "start_time": self._start_time,
            "model": self.model.get_state() if self.model is not None else None,
        }

    def _set_fmu_state(self, state: dict[str, Any]) -> None:
        old_params = {n: self._values[n] for n in self._params}
        self._values = dict(state["values"])
        self._outputs = list(state["outputs"])
        self._phase = state["phase"]
        self._dirty = state["dirty"]
        self._start_time = state["start_time"]
        if state["model"] is None:
            self.model = None
            return
        params = {n: self._values[n] for n in self._params}
        if self.model is None or params != old_params:
            self.model = self.model_class(params, self._start_time, self._input_values())
        self.model.set_state(state["model"])


_HELD_NAMESPACES: list[Any] = []


def hold_slave_module(name: str) -> None:
    """Work around a pythonfmu 0.7.0 bug. Each fmi2Instantiate re-executes the slave script in its
    module's namespace and then releases one reference too many to that namespace dict, so the
    second instance in a process reads a freed dict (segfault, or "module has no attribute ''").
    The slave script calls this at top level: one extra reference per execution balances it."""
    _HELD_NAMESPACES.append(sys.modules[name].__dict__)
