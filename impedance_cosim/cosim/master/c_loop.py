"""The master's stepping loop compiled from native/master/loop.c (with the machine's C compiler,
once per source version, into a user cache folder) and called through ctypes, for FMI 2.0 and
FMI 3.0 co-simulation FMUs. Without a C
compiler the master falls back to its Python loop, which computes the same rows. `stepper` binds
the master's wired components to it."""

from __future__ import annotations

import ctypes
import hashlib
import os
import subprocess
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from impedance_cosim.cosim.fmus.fmi2 import STATUS
from impedance_cosim.cosim.fmus.fmi3 import is_fmi3

SOURCE = Path(__file__).resolve().parents[3] / "native" / "master" / "loop.c"


class Comp(ctypes.Structure):
    _fields_ = [
        ("component", ctypes.c_void_p),
        ("set_real", ctypes.c_void_p),
        ("get_real", ctypes.c_void_p),
        ("do_step", ctypes.c_void_p),
        ("fmi3", ctypes.c_int),
        ("n_in", ctypes.c_int),
        ("in_vr", ctypes.POINTER(ctypes.c_uint)),
        ("in_col", ctypes.POINTER(ctypes.c_int)),
        ("n_out", ctypes.c_int),
        ("out_vr", ctypes.POINTER(ctypes.c_uint)),
        ("out_col", ctypes.c_int),
        ("get_deriv", ctypes.c_void_p),
        ("n_rate", ctypes.c_int),
        ("rate_vr", ctypes.POINTER(ctypes.c_uint)),
        ("rate_col", ctypes.POINTER(ctypes.c_int)),
    ]


class LoopError(ctypes.Structure):
    _fields_ = [
        ("comp", ctypes.c_int),
        ("status", ctypes.c_int),
        ("call", ctypes.c_int),
        ("column", ctypes.c_int),
    ]


def _cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "impedance-cosim"


@lru_cache(maxsize=1)
def load() -> ctypes.CDLL | None:
    """The compiled loop library, or None when it cannot be built (no C compiler)."""
    if not SOURCE.is_file():
        return None
    digest = hashlib.sha256(SOURCE.read_bytes()).hexdigest()[:16]
    lib_path = _cache_dir() / f"loop-{digest}.so"
    if not lib_path.is_file():
        lib_path.parent.mkdir(parents=True, exist_ok=True)
        tmp = lib_path.with_suffix(f".{os.getpid()}.tmp")
        cc = os.environ.get("CC", "gcc")
        cmd = [cc, "-std=c99", "-O2", "-fPIC", "-shared", str(SOURCE), "-lm", "-o", str(tmp)]
        try:
            done = subprocess.run(cmd, capture_output=True, text=True)
        except FileNotFoundError:
            return None
        if done.returncode != 0:
            return None
        tmp.replace(lib_path)
    lib = ctypes.CDLL(str(lib_path))
    lib.run_loop.restype = ctypes.c_long
    lib.run_loop.argtypes = [
        ctypes.POINTER(Comp), ctypes.c_int, ctypes.c_int, ctypes.c_double, ctypes.c_double,
        ctypes.c_long, ctypes.c_long, ctypes.c_double, ctypes.c_void_p, ctypes.c_int,
        ctypes.c_void_p, ctypes.POINTER(LoopError),
    ]  # fmt: skip
    return lib


MAX_IO = 256  # inputs per component the compiled loop takes (loop.c)
# The FMI functions the loop calls, per standard
FUNCTIONS = {
    False: ("fmi2SetReal", "fmi2GetReal", "fmi2DoStep", "fmi2GetRealOutputDerivatives"),
    True: ("fmi3SetFloat64", "fmi3GetFloat64", "fmi3DoStep", "fmi3GetOutputDerivatives"),
}


def unsupported(ordered: list[Any]) -> str | None:
    """Why the compiled loop cannot step these components (None: it can): it calls FMI 2.0 and
    FMI 3.0 co-simulation FMUs, not FMI 3.0 Scheduled Execution (clocks) or arrays, with at most
    MAX_IO inputs and extrapolated outputs each."""
    for s in ordered:
        if is_fmi3(s.fmu.description) and s.fmu.description.coSimulation is None:
            return f"{s.name} is an FMI 3.0 Scheduled Execution FMU (clocks)"
        if any(getattr(v, "dimensions", None) for v in s.fmu.description.modelVariables):
            return f"{s.name} has array variables (the Python loop moves them)"
        if len(s.inputs) > MAX_IO:
            return f"{s.name} has {len(s.inputs)} connected inputs (at most {MAX_IO})"
        if len(getattr(s, "rate_index", ())) > MAX_IO:  # outputs extrapolated from
            return f"{s.name} has {len(s.rate_index)} extrapolated outputs (at most {MAX_IO})"
    return None


def stepper(
    lib: ctypes.CDLL,
    ordered: list[Any],
    data: np.ndarray,
    jacobi: bool,
    start_time: float,
    step_size: float,
    divergence_limit: float,
    check_row: Callable[[list[str], np.ndarray, float], Any],
    extrapolate: bool = False,
) -> Callable[..., tuple[int, str | None]]:
    """The master's steps in the compiled loop, for its components (the master's slots, wired)
    writing into `data`: returns steps(ordered, data, names, first, count) -> (rows filled,
    error or None), like the master's Python loop. extrapolate: the Jacobi inputs y + h dy/dt,
    from the slots' rates (extrapolation.prepare), kept up to date in C."""
    offsets, col = {}, 1
    for s in ordered:
        offsets[s.name] = col
        col += len(s.outputs)
    comps = (Comp * len(ordered))()
    rates = np.zeros(col) if extrapolate else None  # per column, refreshed by the loop
    keep = []  # the ctypes arrays must outlive the loop
    for c, s in zip(comps, ordered, strict=True):
        in_vr = (ctypes.c_uint * max(1, len(s.inputs)))(*(s.fmu.vr(n) for n in s.inputs))
        in_col = (ctypes.c_int * max(1, len(s.inputs)))(
            *(offsets[ordered[j].name] + k for j, k in s.sources)
        )
        out_vr = (ctypes.c_uint * max(1, len(s.outputs)))(*(s.fmu.vr(n) for n in s.outputs))
        keep += [in_vr, in_col, out_vr]
        functions = s.fmu.slave._functions
        fmi3 = is_fmi3(s.fmu.description)
        set_name, get_name, step_name, deriv_name = FUNCTIONS[fmi3]
        if extrapolate and s.read_rates is not None:
            index = s.rate_index
            rate_vr = (ctypes.c_uint * len(index))(*(s.fmu.vr(s.outputs[k]) for k in index))
            rate_col = (ctypes.c_int * len(index))(*(offsets[s.name] + k for k in index))
            keep += [rate_vr, rate_col]
            c.get_deriv = ctypes.cast(functions[deriv_name], ctypes.c_void_p).value
            c.n_rate, c.rate_vr, c.rate_col = len(index), rate_vr, rate_col
            rates[offsets[s.name] : offsets[s.name] + len(s.outputs)] = s.rates
        c.component = s.fmu.slave.component
        c.set_real = ctypes.cast(functions[set_name], ctypes.c_void_p).value
        c.get_real = ctypes.cast(functions[get_name], ctypes.c_void_p).value
        c.do_step = ctypes.cast(functions[step_name], ctypes.c_void_p).value
        c.fmi3 = int(fmi3)
        c.n_in, c.in_vr, c.in_col = len(s.inputs), in_vr, in_col
        c.n_out, c.out_vr, c.out_col = len(s.outputs), out_vr, offsets[s.name]
    assert data.flags["C_CONTIGUOUS"] and data.dtype == np.float64

    def steps(_ordered, _data, names: list[str], first: int, count: int):
        err = LoopError()
        done = lib.run_loop(comps, len(ordered), int(jacobi), start_time, step_size,
                            first, count, divergence_limit,
                            data.ctypes.data, data.shape[1],
                            None if rates is None else rates.ctypes.data,
                            ctypes.byref(err))  # fmt: skip
        _ = keep
        if err.comp >= 0:
            s = ordered[err.comp]
            s.fmu.fatal |= err.status == 4
            set_name, get_name, step_name, deriv_name = FUNCTIONS[is_fmi3(s.fmu.description)]
            call = (set_name, step_name, get_name, deriv_name)[err.call]
            t = start_time + (first + done) * step_size
            detail = s.fmu.error_detail()
            status = STATUS[err.status] if 0 <= err.status < len(STATUS) else err.status
            return done, f"{s.name}: {call} at t={t} returned {status} ({detail})"
        if err.column >= 0:
            row = data[first + done]
            return done, check_row(names, row, row[0])
        return done, None

    return steps
