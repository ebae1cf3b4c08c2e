"""The master's stepping loop compiled from native/master/loop.c (with the machine's C compiler,
once per source version, into a user cache folder) and called through ctypes. Without a C
compiler the master falls back to its Python loop, which computes the same rows."""

from __future__ import annotations

import ctypes
import hashlib
import os
import subprocess
from functools import lru_cache
from pathlib import Path

SOURCE = Path(__file__).resolve().parents[2] / "native" / "master" / "loop.c"


class Comp(ctypes.Structure):
    _fields_ = [
        ("component", ctypes.c_void_p),
        ("set_real", ctypes.c_void_p),
        ("get_real", ctypes.c_void_p),
        ("do_step", ctypes.c_void_p),
        ("n_in", ctypes.c_int),
        ("in_vr", ctypes.POINTER(ctypes.c_uint)),
        ("in_col", ctypes.POINTER(ctypes.c_int)),
        ("n_out", ctypes.c_int),
        ("out_vr", ctypes.POINTER(ctypes.c_uint)),
        ("out_col", ctypes.c_int),
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
        ctypes.POINTER(LoopError),
    ]  # fmt: skip
    return lib
