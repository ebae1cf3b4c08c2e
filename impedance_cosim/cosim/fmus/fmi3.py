"""An FMI 3.0 co-simulation FMU driven through fmpy's FMU3Slave, with the interface of FmuInstance
(fmu.py): names instead of value references, every status checked, every log message kept, state
save/restore. open_fmu picks the class from the FMU's fmiVersion, so the master runs FMI 2.0 and
FMI 3.0 FMUs alike (the compiled loop steps both; Scheduled Execution needs the Python loop)."""

from __future__ import annotations

import ctypes
import math
from pathlib import Path
from typing import Any

from fmpy.fmi3 import FMU3ScheduledExecution, FMU3Slave, fmi3LogMessageCallback

from impedance_cosim.cosim.fmus.fmi2 import STATUS, FmuError, FmuInstance

# FMI 3.0 type names as the FMI 2.0 / SSP 1.0 types the rest of the code knows them by
SSP_TYPES = {"Float64": "Real", "Float32": "Real", "Int32": "Integer", "Int64": "Integer"}


def ssp_type(fmi_type: str) -> str:
    """The SSP 1.0 / FMI 2.0 type name of an FMI variable type (Float64 -> Real, Int32 ->
    Integer; FMI 2.0 names and Boolean/String/Enumeration unchanged)."""
    return SSP_TYPES.get(fmi_type, fmi_type)


def element_names(v: Any) -> list[str]:
    """The signals of an FMI variable (fmpy's ModelVariable): its name, or for a fixed-size array
    q of n elements q[1] .. q[n] (its values in serialization order, row-major)."""
    dims = getattr(v, "dimensions", None) or []
    if not dims:
        return [v.name]
    if any(d.start is None for d in dims):
        raise FmuError(f"variable {v.name}: arrays sized by a structural parameter are not supported")
    return signals(v.name, math.prod(int(d.start) for d in dims))


def signals(name: str, size: int) -> list[str]:
    """The signals of a variable or connector of size elements: name for a scalar (size 1),
    name[1] .. name[size] for an array."""
    return [name] if size == 1 else [f"{name}[{k}]" for k in range(1, size + 1)]


def is_fmi3(description: Any) -> bool:
    return str(getattr(description, "fmiVersion", "")).startswith("3")


def open_fmu(fmu: str | Path, instance_name: str, logging_on: bool = True) -> FmuInstance:
    """An instantiated co-simulation FMU of either standard (FmuInstance or FmuInstance3)."""
    from impedance_cosim.cosim.fmus.files import model_description

    try:  # checked before fmpy reads a member; parsed once per file version
        md = model_description(Path(fmu).resolve())
    except Exception:  # FmuInstance reports an unreadable archive with its own message
        return FmuInstance(fmu, instance_name, logging_on)
    if not md.fmiVersion.startswith("3"):
        return FmuInstance(fmu, instance_name, logging_on)
    if md.coSimulation is None and md.scheduledExecution is not None:
        return ClockedInstance(fmu, instance_name, logging_on)
    return FmuInstance3(fmu, instance_name, logging_on)


class FmuInstance3(FmuInstance):
    """An instantiated FMI 3.0 co-simulation FMU (see module docstring)."""

    _interface = FMU3Slave
    _STATE_CALLS = {
        "get": "getFMUState",
        "set": "setFMUState",
        "free": "freeFMUState",
        "serialize": "serializeFMUState",
        "deserialize": "deserializeFMUState",
    }

    def _load(self, unzip_dir: str, logging_on: bool) -> None:
        self.variables = {v.name: v for v in self.description.modelVariables}
        self.messages: list[tuple[str, str, str]] = []
        self._logger = fmi3LogMessageCallback(self._log3)
        interface = self.description.coSimulation or self.description.scheduledExecution
        self.slave = self._open(self._interface, unzip_dir, interface)
        self.fatal = False
        self.start_time, self.stop_time = 0.0, None
        try:
            self._call("instantiate", loggingOn=logging_on, logMessage=self._log3)
        except FmuError:
            self.slave.freeLibrary()
            raise
        self._alive = True
        self._setup_stepping()

    def _setup_stepping(self) -> None:
        self._do_step = self.slave._functions["fmi3DoStep"]  # raw ctypes: we check the status
        self._step_out = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double()]
        self._step_refs = [ctypes.byref(x) for x in self._step_out]

    def _log3(self, _env, status, category, message) -> None:
        text = message.decode("utf-8", "replace") if message else ""
        cat = category.decode("utf-8", "replace") if category else ""
        self.messages.append((STATUS[status] if 0 <= status < 6 else str(status), cat, text))

    def _fail(self, what: str, status: int) -> FmuError:
        self.fatal |= status == 4
        detail = self.error_detail()
        return FmuError(f"{self.name}: {what} ({STATUS[status]}: {detail})")

    def _whole_variables(self, names: list[str]) -> list[int]:
        """The value references of the variables names are the signals of (element_names): an
        array's elements must come whole and in order (FMI 3.0 gets and sets arrays whole)."""
        vrs, i = [], 0
        while i < len(names):
            base = names[i].split("[", 1)[0]
            self.vr(base)  # a clear error for an unknown name
            elements = element_names(self.variables[base])
            if names[i : i + len(elements)] != elements:
                raise FmuError(f"{self.name}: {base} has the elements {elements}: an array is"
                               " read and written whole, in order")  # fmt: skip
            vrs.append(self.variables[base].valueReference)
            i += len(elements)
        return vrs

    def _raw_real(self, function: str, names):
        vrs = self._whole_variables(list(names))
        n = len(names)
        vr_arr = (ctypes.c_uint32 * len(vrs))(*vrs)
        val_arr = (ctypes.c_double * n)()
        return self.slave._functions[function], self.slave.component, vr_arr, val_arr, n

    def real_getter(self, names):
        """A fast reader of Float64 variables (an array's elements: element_names): returns a
        function returning their values."""
        fn, comp, vr_arr, val_arr, n = self._raw_real("fmi3GetFloat64", names)
        nvr = len(vr_arr)

        def read() -> list[float]:
            status = fn(comp, vr_arr, nvr, val_arr, n)
            if status > 1:
                raise self._fail("fmi3GetFloat64 failed", status)
            return list(val_arr)

        return read

    def real_setter(self, names):
        """A fast writer of Float64 variables (an array's elements: element_names): returns a
        function taking the values."""
        fn, comp, vr_arr, val_arr, n = self._raw_real("fmi3SetFloat64", names)
        nvr = len(vr_arr)

        def write(values) -> None:
            val_arr[:] = values
            status = fn(comp, vr_arr, nvr, val_arr, n)
            if status > 1:
                raise self._fail("fmi3SetFloat64 failed", status)

        return write

    def setup(self, start_time: float = 0.0, stop_time: float | None = None) -> None:
        """Remembered for fmi3EnterInitializationMode (FMI 3.0 has no setupExperiment)."""
        self.start_time, self.stop_time = start_time, stop_time

    def enter_initialization(self) -> None:
        self._call("enterInitializationMode", startTime=self.start_time, stopTime=self.stop_time)

    def step(self, t: float, h: float) -> None:
        """fmi3DoStep; raises FmuError with the FMU's messages unless it returns OK/Warning."""
        status = self._do_step(self.slave.component, t, h, True, *self._step_refs)
        if status > 1:
            raise self._fail(f"doStep at t={t} returned {STATUS[status]}", status)


class ClockedInstance(FmuInstance3):
    """An FMI 3.0 Scheduled Execution FMU with one periodic input clock (the clocked
    controller), behind the same interface: step(t, h) activates the clock at every tick in
    [t, t + h) on the inputs set before the step, so the master honours the clock whatever its
    communication step. Ticks are at start + k * interval (interval from fmi3GetIntervalDecimal
    after initialization)."""

    _interface = FMU3ScheduledExecution

    def _setup_stepping(self) -> None:
        clocks = [v for v in self.description.modelVariables if v.type == "Clock"]
        if len(clocks) != 1:
            raise FmuError(f"{self.name}: {self.path.name} has {len(clocks)} clocks, not one")
        self.clock = clocks[0].valueReference
        self.ticks = 0  # activations so far
        self._next_tick = 0
        self._interval = None
        self._activate = self.slave._functions["fmi3ActivateModelPartition"]

    def exit_initialization(self) -> None:
        super().exit_initialization()
        intervals, qualifiers = (ctypes.c_double * 1)(), (ctypes.c_int * 1)()
        vrs = (ctypes.c_uint32 * 1)(self.clock)
        status = self.slave._functions["fmi3GetIntervalDecimal"](
            self.slave.component, vrs, 1, intervals, qualifiers
        )
        if status > 1 or not intervals[0] > 0.0:
            raise self._fail(f"the clock interval is not usable ({intervals[0]})", max(status, 3))
        self._interval = intervals[0]

    def step(self, t: float, h: float) -> None:
        """Every tick start + k * interval in [t, t + h), in order (fmi3ActivateModelPartition;
        fmpy's activateModelPartition would also call fmi3ExitConfigurationMode)."""
        end = t + h
        while True:
            tick = self.start_time + self._next_tick * self._interval
            if tick >= end - 1e-9 * self._interval:
                return
            status = self._activate(self.slave.component, self.clock, tick)
            if status > 1:
                raise self._fail(f"clock tick at t={tick} returned {STATUS[status]}", status)
            self._next_tick += 1
            self.ticks += 1
