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

import binascii
import gc
import json
import math
import struct
import sys
from typing import Any

from pythonfmu import Boolean, Fmi2Causality, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Status

from impedance_cosim.fmi.model import FmuModel, ModelError, check_finite_outputs

_PY_VAR = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}
_CONVERT = {"Real": float, "Integer": int, "Boolean": bool, "String": str}

INSTANTIATED, INITIALIZING, STEPPING, TERMINATED = range(4)

# Serialized FMU state: magic, body length (8 bytes, big-endian), CRC-32 of the body, body
# (UTF-8 JSON of _get_fmu_state). JSON, never pickle: the bytes come from outside. (Not SHA-256:
# importing hashlib, i.e. OpenSSL, into a pythonfmu 0.7 FMU made 4 in 20 `fmpy simulate` runs
# abort at exit with "corrupted double-linked list"; binascii: 0 in 40.)
STATE_MAGIC = b"IMPCPY2\n"
STATE_HEADER = struct.Struct(">8sQI")
STATE_MAX_BYTES = 1 << 20


class ModelSlave:
    """Mixin for pythonfmu.Fmi2Slave (list it first among the bases)."""

    model_class: type[FmuModel]
    # the exporter's API (pythonfmu 0.7 here; fmi3_slave.py swaps in pythonfmu3's for FMI 3.0)
    _var_types: dict[str, Any] = _PY_VAR
    _causality: Any = Fmi2Causality
    _variability: Any = Fmi2Variability
    _error_status: Any = Fmi2Status.error
    _warning_status: Any = Fmi2Status.warning

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
        # The stepping phase's fast paths (get_real, set_real): value reference -> output index
        # of each Real output, and -> name of each Real input.
        self._real_output_index: dict[int, int] = {}
        self._real_input_name: dict[int, str] = {}
        for v in self._table:
            var_cls = self._var_types[v.type]
            if v.causality == "output":
                index = len(self._outputs)
                self._outputs.append(v.start)
                getter = self._output_getter(index)
                setter = None
            else:
                self._values[v.name] = v.start
                getter = self._value_getter(v.name)
                setter = self._value_setter(v, _CONVERT[v.type])
            var = var_cls(
                v.name,
                causality=getattr(self._causality, v.causality),
                variability=getattr(self._variability, v.fmi_variability),
                description=v.description,
                getter=getter,
                setter=setter,
            )
            self.register_variable(var)
            if v.type == "Real" and v.causality == "output":
                self._real_output_index[var.value_reference] = index
            elif v.type == "Real" and v.causality == "input":
                self._real_input_name[var.value_reference] = v.name

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

    def get_real(self, vrs: list[int]) -> list[float]:
        """fmi2GetReal. While stepping, Real outputs come straight from the last step's outputs
        (what their getters return, without a call per variable: a host reads every output every
        step); anything else takes pythonfmu's general path."""
        if self._phase == STEPPING:
            index, outputs = self._real_output_index, self._outputs
            try:
                return [float(outputs[index[vr]]) for vr in vrs]
            except KeyError:
                pass
        return super().get_real(vrs)  # type: ignore[misc]

    def set_real(self, vrs: list[int], values: list[float]) -> None:
        """fmi2SetReal. While stepping, Real inputs are stored as their setters would store
        them, without a call per variable; anything else (parameters) takes the general path."""
        if self._phase == STEPPING:
            names = self._real_input_name
            try:
                pairs = [(names[vr], float(x)) for vr, x in zip(vrs, values)]
            except KeyError:
                pairs = None
            if pairs is not None:
                self._values.update(pairs)
                return
        super().set_real(vrs, values)  # type: ignore[misc]

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
        if not math.isfinite(current_time):  # NaN would pass the model's time check
            self._report(f"doStep: communication point {current_time} is not finite")
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
            model = self.model_class(params, self._start_time, self._input_values())
            outputs = list(model.outputs())
            check_finite_outputs(self.model_class, outputs)
        except ModelError as exc:
            self._fail(str(exc))
        self.model, self._outputs = model, outputs
        self._dirty = False
        for warning in self.model.init_warnings:
            self._report(warning, warning=True)

    def _report(self, message: str, warning: bool = False) -> None:
        """Log an error (or a warning) through the FMU logger, and to stderr: pythonfmu 0.7 drops
        every log message (errors included) unless the host turned debug logging on."""
        text = f"{self.model_class.MODEL_NAME} '{self.instance_name}': {message}"
        self.log(text, self._warning_status if warning else self._error_status)
        print(f"{'warning' if warning else 'error'}: {text}", file=sys.stderr, flush=True)

    def _fail(self, message: str) -> None:
        """Report a clear error, then raise (pythonfmu then returns fmi2Fatal)."""
        self._report(message)
        _survive_fatal(type(self))
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

    @classmethod
    def _fmu_state_to_bytes(cls, state: dict[str, Any]) -> bytes:
        body = json.dumps(state).encode("utf-8")
        return STATE_HEADER.pack(STATE_MAGIC, len(body), binascii.crc32(body)) + body

    @classmethod
    def _fmu_state_from_bytes(cls, data: bytes) -> dict[str, Any]:
        """Decode and validate serialized state bytes from outside; refuse anything that
        _fmu_state_to_bytes of this model did not write. pythonfmu 0.7 turns the refusal
        (an exception) into fmi2Fatal; the reason is logged and printed to stderr."""
        try:
            return decode_state(cls.model_class, data)
        except ModelError as exc:
            print(
                f"error: {cls.model_class.MODEL_NAME}: serialized FMU state refused: {exc}",
                file=sys.stderr,
                flush=True,
            )
            _survive_fatal(cls)
            raise ModelError(f"serialized FMU state refused: {exc}") from None


def decode_state(model_class: type[FmuModel], data: bytes) -> dict[str, Any]:
    """The state dict in serialized bytes, after checking header, length, checksum, JSON and
    every field against the model's variable table and a freshly built model's state."""
    if len(data) < STATE_HEADER.size or len(data) > STATE_MAX_BYTES:
        raise ModelError(f"{len(data)} bytes is not the size of a state of this FMU")
    magic, length, digest = STATE_HEADER.unpack_from(data)
    body = data[STATE_HEADER.size :]
    if magic != STATE_MAGIC:
        raise ModelError("not a state serialized by this FMU (bad magic)")
    if length != len(body) or binascii.crc32(body) != digest:
        raise ModelError("truncated or corrupted (length or checksum mismatch)")
    try:
        state = json.loads(body.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise ModelError(f"body is not valid JSON ({exc})") from None
    _check_state(model_class, state)
    return state


def _check_state(model_class: type[FmuModel], state: Any) -> None:
    """Raise ModelError unless state has exactly the shape and types _get_fmu_state writes."""
    table = model_class.variables()
    if not isinstance(state, dict) or set(state) != {
        "values", "outputs", "phase", "dirty", "start_time", "model"
    }:  # fmt: skip
        raise ModelError("not a state object of this FMU")
    values, outputs = state["values"], state["outputs"]
    inputs_params = [v for v in table if v.causality != "output"]
    if not isinstance(values, dict) or set(values) != {v.name for v in inputs_params}:
        raise ModelError("variable names do not match this FMU's")
    for v in inputs_params:
        _check_value(v.name, v.type, values[v.name])
        if v.causality == "parameter" and v.type in ("Real", "Integer"):
            x = values[v.name]
            if not math.isfinite(x) or (v.min is not None and x < v.min):
                raise ModelError(f"parameter {v.name} out of range ({x})")
    out_vars = [v for v in table if v.causality == "output"]
    if not isinstance(outputs, list) or len(outputs) != len(out_vars):
        raise ModelError("wrong number of outputs")
    for v, x in zip(out_vars, outputs):
        _check_value(v.name, v.type, x)
    phase, start_time = state["phase"], state["start_time"]
    if type(phase) is not int or not INSTANTIATED <= phase <= TERMINATED:
        raise ModelError(f"phase {phase!r} is not a phase of the FMI state machine")
    if type(state["dirty"]) is not bool:
        raise ModelError("flag 'dirty' is not a Boolean")
    if type(start_time) is not float or not math.isfinite(start_time):
        raise ModelError("start time is not a finite number")
    if state["model"] is None:
        if phase >= STEPPING:
            raise ModelError("an initialized state without its model state")
        return
    params = {v.name: values[v.name] for v in inputs_params if v.causality == "parameter"}
    inputs = tuple(values[v.name] for v in inputs_params if v.causality == "input")
    try:  # the model state must look like a fresh one and be accepted by it
        scratch = model_class(params, start_time, inputs)
        _check_like(scratch.get_state(), state["model"], "model")
        scratch.set_state(state["model"])
    except (ModelError, ValueError, TypeError, OverflowError, IndexError, KeyError) as exc:
        raise ModelError(f"model state: {exc}") from None


def _check_value(name: str, type_name: str, x: Any) -> None:
    expected = {"Real": float, "Integer": int, "Boolean": bool, "String": str}[type_name]
    if type(x) is not expected:
        raise ModelError(f"value of {name} is not of type {type_name}")


def _check_like(template: Any, x: Any, where: str) -> None:
    """x has template's structure: same keys, same list lengths, same leaf types (a None leaf
    may also be a float: the noise generator's cached deviate)."""
    if isinstance(template, dict):
        if not isinstance(x, dict) or set(x) != set(template):
            raise ModelError(f"{where}: fields do not match")
        for k in template:
            _check_like(template[k], x[k], f"{where}.{k}")
    elif isinstance(template, (list, tuple)):
        if not isinstance(x, list) or len(x) != len(template):
            raise ModelError(f"{where}: wrong length")
        for i, (t, v) in enumerate(zip(template, x)):
            _check_like(t, v, f"{where}[{i}]")
    elif template is None or type(template) is float:
        if not (type(x) is float or (template is None and x is None)):
            raise ModelError(f"{where}: not a number")
    elif type(x) is not type(template):
        raise ModelError(f"{where}: wrong type")


_HELD_NAMESPACES: list[Any] = []
_HELD_AFTER_FATAL: list[Any] = []


def _survive_fatal(cls: type) -> None:
    """Work around pythonfmu 0.7.0 before raising: on a Python exception its C++ wrapper returns
    fmi2Fatal and releases its references to the slave class, the instance and its log queue
    without forgetting them, so any later call on the instance (host misuse after fmi2Fatal, but
    common) reads freed objects and segfaults. One extra reference each keeps them alive (a small
    leak per refusal). cls is the class the wrapper holds: one per instance under pythonfmu, whose
    instances are found through the garbage collector (no registry: this path is rare)."""
    for slave in [o for o in gc.get_objects() if type(o) is cls]:
        _HELD_AFTER_FATAL.extend((cls, slave, slave.log_queue))


def hold_slave_module(name: str) -> None:
    """Work around a pythonfmu 0.7.0 bug. Each fmi2Instantiate re-executes the slave script in its
    module's namespace and then releases one reference too many to that namespace dict, so the
    second instance in a process reads a freed dict (segfault, or "module has no attribute ''").
    The slave script calls this at top level: one extra reference per execution balances it."""
    _HELD_NAMESPACES.append(sys.modules[name].__dict__)
