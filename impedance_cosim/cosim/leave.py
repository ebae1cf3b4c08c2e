"""Leaving the process safely after FMUs were loaded (exit_process), in a module of its own that
imports only the standard library, so that `impedance-cosim --version` need not load fmpy."""

from __future__ import annotations

import atexit
import os
import sys
from typing import NoReturn

# FMU libraries left loaded after fmi2Fatal (see fmu.FmuInstance.free, which appends to it)
leaked_libraries: list[str] = []


def fmu_library_loaded() -> bool:
    """True while a library loaded from an FMU (`.../binaries/<platform>/<id>.so`) is still in
    this process. Freeing the instance does not unload a pythonfmu 0.7 library: its C++ unique
    symbols make dlclose a no-op. Without /proc: whenever fmpy was imported."""
    if leaked_libraries:
        return True
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            return any("/binaries/" in line for line in maps)
    except OSError:
        return "fmpy" in sys.modules


def exit_process(code: int) -> NoReturn:
    """Leave the process with `code`. While an FMU's library is loaded (fmu_library_loaded),
    skip the C library destructors: pythonfmu 0.7's `finalizePythonInterpreter` runs at exit on
    a static already destroyed and corrupts the heap (valgrind shows the read after every
    process that loaded a Python FMU, freed or not; glibc then aborts, exit -6, in some runs).
    Python's own exit work (atexit, flushing) still runs first."""
    if not fmu_library_loaded():
        sys.exit(code)
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)
