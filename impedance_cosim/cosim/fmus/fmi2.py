"""One FMU instance driven through fmpy's FMU2Slave: names instead of value references, every
status checked, every log message kept, state save/restore. The building block of the master
(and of the tests that drive the FMUs by hand). Checks and extraction of FMU files: fmu_files.py."""

from __future__ import annotations

import contextlib
import ctypes
import math
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from fmpy import calloc, free
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)

from impedance_cosim.cosim.fmus.files import FmuError, extractions
from impedance_cosim.cosim.leave import exit_process as exit_process
from impedance_cosim.cosim.leave import fmu_library_loaded as fmu_library_loaded
from impedance_cosim.cosim.leave import leaked_libraries

STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
# pythonfmu's C++ layer logs, after the FMU's own message, "Fatal py exception encountered:
# [getReal] PyObject_CallMethod unknown error": its own words, not the model's.
PYTHONFMU_NOISE = ("py exception encountered", "PyObject_CallMethod")
INT32 = (-(2**31), 2**31 - 1)  # range of fmi2Integer


# The libraries left loaded after fmi2Fatal, and leaving the process safely: cosim/leave.py
# (standard library only, for the command line's quick answers); named here too for the callers.
_leaked_libraries = leaked_libraries


class FmuInstance:
    """An instantiated co-simulation FMU (see module docstring)."""

    def __init__(self, fmu: str | Path, instance_name: str, logging_on: bool = True) -> None:
        path = Path(fmu).resolve()
        if not path.is_file():
            raise FileNotFoundError(f"FMU {path} does not exist (run `impedance-cosim build`)")
        self.path = path
        self.name = instance_name
        self._alive = False
        self._extraction, self.description, unzip_dir = extractions.acquire(path)
        try:
            self._load(unzip_dir, logging_on)
        except BaseException:
            self._release()
            raise

    def _open(self, cls: type, unzip_dir: str, interface: Any) -> Any:
        """fmpy's object (cls) over the library of the FMU's interface; FmuError naming the FMU
        when the library does not load."""
        try:
            return cls(
                guid=self.description.guid,
                unzipDirectory=unzip_dir,
                modelIdentifier=interface.modelIdentifier,
                instanceName=self.name,
            )
        except Exception as exc:  # fmpy raises bare Exceptions when the library does not load
            text = str(exc).replace(unzip_dir + "/", "")
            raise FmuError(
                f"{self.name}: cannot load the binary of {self.path.name}: {text}"
            ) from None

    def _load(self, unzip_dir: str, logging_on: bool) -> None:
        self.variables = {v.name: v for v in self.description.modelVariables}
        self.messages: list[tuple[str, str, str]] = []  # (status, category, message)
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.slave = self._open(FMU2Slave, unzip_dir, self.description.coSimulation)
        self.fatal = False  # an fmi2Fatal status was returned: no further call is allowed
        try:
            self._call("instantiate", callbacks=self._callbacks, loggingOn=logging_on)
        except FmuError:
            with contextlib.suppress(Exception):
                self.slave.freeLibrary()
            raise
        self._alive = True
        self._do_step = self.slave._functions["fmi2DoStep"]  # raw ctypes: we check the status

    # --- logging and status ---------------------------------------------------------------------

    def _log(self, _env, _instance, status, category, message) -> None:
        text = message.decode("utf-8", "replace") if message else ""
        cat = category.decode("utf-8", "replace") if category else ""
        self.messages.append((STATUS[status] if 0 <= status < 6 else str(status), cat, text))

    def errors(self) -> list[str]:
        """Messages logged with Error or Fatal status (what went wrong, in the FMU's words),
        less pythonfmu's own report of the same exception (PYTHONFMU_NOISE), when the FMU said
        something itself."""
        found = [" ".join(m.split()) for s, _, m in self.messages if s in ("Error", "Fatal")]
        own = [m for m in found if not any(n in m for n in PYTHONFMU_NOISE)]
        return own or found

    def error_detail(self) -> str:
        """The last error messages, for the one-line FmuError of a failed call."""
        return "; ".join(self.errors()[-3:]) or "no message logged"

    def _call(self, method: str, *args: Any, **kwargs: Any) -> Any:
        try:
            return getattr(self.slave, method)(*args, **kwargs)
        except FMICallException as exc:
            self.fatal |= exc.status == 4
            detail = self.error_detail()
            raise FmuError(f"{self.name}: {exc} ({detail})") from None
        except Exception as exc:  # instantiate() raises a bare Exception
            detail = self.error_detail()
            raise FmuError(f"{self.name}: {method} failed: {exc} ({detail})") from None

    # --- variables ------------------------------------------------------------------------------

    def vr(self, name: str) -> int:
        """Value reference of a variable, with a clear error for an unknown name."""
        try:
            return self.variables[name].valueReference
        except KeyError:
            raise KeyError(f"{self.path.name} has no variable {name!r}") from None

    def set(self, values: Mapping[str, Any]) -> None:
        """Set variables by name, converting to each variable's FMI type."""
        groups: dict[str, tuple[list[int], list[Any]]] = {}
        for name, value in values.items():
            var = self.variables.get(name)
            if var is None:
                raise KeyError(f"{self.path.name} has no variable {name!r}")
            vrs, vals = groups.setdefault(var.type, ([], []))
            vrs.append(var.valueReference)
            vals.append(fmi_value(var.type, value, name))
        for kind, (vrs, vals) in groups.items():
            self._call(f"set{kind}", vrs, vals)

    def get(self, names: Iterable[str]) -> list[Any]:
        """Values of the named variables, in order."""
        names = list(names)
        out: list[Any] = [None] * len(names)
        groups: dict[str, tuple[list[int], list[int]]] = {}
        for i, name in enumerate(names):
            var = self.variables.get(name)
            if var is None:
                raise KeyError(f"{self.path.name} has no variable {name!r}")
            vrs, idx = groups.setdefault(var.type, ([], []))
            vrs.append(var.valueReference)
            idx.append(i)
        for kind, (vrs, idx) in groups.items():
            for i, v in zip(idx, self._call(f"get{kind}", vrs), strict=True):
                out[i] = v.decode("utf-8") if isinstance(v, bytes) else v
        return out

    def real_getter(self, names: Iterable[str]):
        """A fast reader of Real variables (preallocated ctypes arrays): returns a function that
        returns the current values as a list."""
        vrs = [self.vr(n) for n in names]
        n = len(vrs)
        vr_arr = (ctypes.c_uint * n)(*vrs)
        val_arr = (ctypes.c_double * n)()
        fn, comp = self.slave._functions["fmi2GetReal"], self.slave.component  # raw ctypes

        def read() -> list[float]:
            status = fn(comp, vr_arr, n, val_arr)
            if status > 1:
                self.fatal |= status == 4
                detail = self.error_detail()
                raise FmuError(f"{self.name}: fmi2GetReal failed ({STATUS[status]}: {detail})")
            return list(val_arr)

        return read

    def real_setter(self, names: Iterable[str]):
        """A fast writer of Real variables: returns a function taking a sequence of values."""
        vrs = [self.vr(n) for n in names]
        n = len(vrs)
        vr_arr = (ctypes.c_uint * n)(*vrs)
        val_arr = (ctypes.c_double * n)()
        fn, comp = self.slave._functions["fmi2SetReal"], self.slave.component  # raw ctypes

        def write(values) -> None:
            val_arr[:] = values
            status = fn(comp, vr_arr, n, val_arr)
            if status > 1:
                self.fatal |= status == 4
                detail = self.error_detail()
                raise FmuError(f"{self.name}: fmi2SetReal failed ({STATUS[status]}: {detail})")

        return write

    # --- lifecycle ------------------------------------------------------------------------------

    def setup(self, start_time: float = 0.0, stop_time: float | None = None) -> None:
        """fmi2SetupExperiment."""
        self._call("setupExperiment", startTime=start_time, stopTime=stop_time)

    def enter_initialization(self) -> None:
        self._call("enterInitializationMode")

    def exit_initialization(self) -> None:
        self._call("exitInitializationMode")

    def step(self, t: float, h: float) -> None:
        """fmi2DoStep; raises FmuError with the FMU's messages unless it returns OK/Warning."""
        status = self._do_step(self.slave.component, t, h, 1)
        if status > 1:
            self.fatal |= status == 4
            detail = self.error_detail()
            raise FmuError(f"{self.name}: doStep at t={t} returned {STATUS[status]} ({detail})")

    # fmpy's names of the FMU state functions (FMI 3.0 spells them otherwise: FmuInstance3)
    _STATE_CALLS = {
        "get": "getFMUstate",
        "set": "setFMUstate",
        "free": "freeFMUstate",
        "serialize": "serializeFMUstate",
        "deserialize": "deSerializeFMUstate",
    }

    def get_state(self) -> Any:
        return self._call(self._STATE_CALLS["get"])

    def set_state(self, state: Any) -> None:
        self._call(self._STATE_CALLS["set"], state)

    def free_state(self, state: Any) -> None:
        self._call(self._STATE_CALLS["free"], state)

    def serialize_state(self, state: Any) -> bytes:
        return bytes(self._call(self._STATE_CALLS["serialize"], state))

    def deserialize_state(self, data: bytes) -> Any:
        return self._call(self._STATE_CALLS["deserialize"], bytes(data))

    def reset(self) -> None:
        """fmi2Reset: back to the state after instantiation (start values), ready for reuse."""
        self._call("reset")

    def terminate(self) -> None:
        if self.fatal:
            raise FmuError(f"{self.name}: not terminated: the FMU returned fmi2Fatal")
        self._call("terminate")

    def free(self) -> None:
        """Free the instance (and unload the library, as fmpy does). Safe to call twice.

        After fmi2Fatal the standard allows no further call, so the instance is left alone (with
        pythonfmu 0.7, freeing it then releases Python objects twice and crashes the process
        later). Its library then stays loaded, so its extraction folder is kept (a second copy of
        a pythonfmu library loaded from a new folder corrupts the heap) until the process exits."""
        if self._alive:
            self._alive = False
            if self.fatal:
                self._extraction = None  # still in use: never pruned, removed at exit
                _leaked_libraries.append(self.name)
                return
            self.slave.freeInstance()
        self._release()

    def _release(self) -> None:
        """Give back the extraction folder (see fmu_files.Extractions)."""
        key, self._extraction = getattr(self, "_extraction", None), None
        if key is not None:
            extractions.release(key)


def fmi_value(kind: str, value: Any, name: str) -> Any:
    """value (a Python value or a text literal, e.g. from an .ssv file or the command line)
    converted to the Python value of an FMI type; ValueError naming the variable if invalid."""
    kind = {"Float64": "Real", "Int32": "Integer"}.get(kind, kind)  # FMI 3.0 names
    try:
        if kind == "Real":
            number = float(value)
            if math.isinf(number) and "inf" not in str(value).lower():  # e.g. 400 digits
                most = sys.float_info.max
                raise ValueError(f"variable {name}: {_shown(value)} is out of range (a 64-bit"
                                 f" float is at most {most:.4g} in magnitude)")  # fmt: skip
            return number
        if kind in ("Integer", "Enumeration"):
            if isinstance(value, float) and not value.is_integer():
                raise ValueError(value)
            number = int(value)
            if not INT32[0] <= number <= INT32[1]:
                raise ValueError(f"variable {name}: {value!r} is beyond the 32-bit range of an"
                                 f" FMI {kind} ({INT32[0]} .. {INT32[1]})")  # fmt: skip
            return number
        if kind == "Boolean":
            if isinstance(value, str):
                text = value.strip().lower()
                if text not in ("true", "false", "1", "0"):
                    raise ValueError(value)
                return text in ("true", "1")
            return bool(value)
        return str(value)
    except (TypeError, ValueError, OverflowError) as exc:
        if str(exc).startswith("variable "):
            raise
        raise ValueError(f"variable {name}: {_shown(value)} is not a valid {kind}") from None


def _shown(value: Any) -> str:
    """A value as a message shows it: its repr, shortened when long (5000 digits)."""
    text = repr(value)
    return text if len(text) <= 60 else f"{text[:40]}... ({len(str(value))} characters)"
