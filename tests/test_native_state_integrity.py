"""Integrity of the native FMUs' serialized states (issue 20): a state that is not one the FMU wrote
is refused (header, size, CRC-32 checksum), and so is one with a number that is not finite even
when its checksum has been recomputed. Mutations come from a fixed seed: bits flipped anywhere,
cut, extended, words overwritten, header fields changed (checksum fixed), every real of the body
set to NaN or +-inf (checksum fixed, so only the finiteness check can catch it), a state in the
format of older builds. Each is refused with fmi2Error / fmi3Error and a logged reason; the
instance keeps its state (outputs unchanged after every refusal, the same steps afterwards) and
the FMU state given to be overwritten is untouched; the untouched bytes still restore exactly.

Runs in a subprocess (this file is also the driver: `python test_native_state_integrity.py
VERSION FMU SEED COUNT`), so that a crash is a failed test and not a dead test run."""

from __future__ import annotations

import ctypes
import math
import random
import shutil
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import pytest
from test_platforms import (  # the same tools as the closed-loop platform tests
    host_path,
    need_compiler,
    run_command,
    wine,  # noqa: F401  (a fixture run_command asks for)
)

from impedance_cosim.packaging.toolchains import BY_PLATFORM

DT = 1 / 400
PLANT, CONTROLLER = "PumaPlant.fmu", "ImpedanceController.fmu"
OK, DISCARD, ERROR = 0, 2, 3  # the same numbers in FMI 2 and FMI 3
# the serialized state (instance.c, SerialHeader): magic[8], n_vars, body_size, guid[40], flags,
# crc (CRC-32 over the 60 bytes before it and the body), then the body (instance.h's Snapshot)
HEADER = 64
MAGIC = b"IMPCNAT2"


def fix_crc(blob: bytes) -> bytes:
    """The same bytes with the checksum recomputed (what a forger or a careful corrupter does)."""
    b = bytearray(blob)
    struct.pack_into("<I", b, 60, zlib.crc32(bytes(b[:60]) + bytes(b[HEADER:])))
    return bytes(b)


# --- the body's layout, restated in ctypes (checked against a real state by _check_layout) -------


class PyRandom(ctypes.Structure):
    _fields_ = [("mt", ctypes.c_uint32 * 624), ("index", ctypes.c_int32),
                ("has_gauss_next", ctypes.c_int32), ("gauss_next", ctypes.c_double)]  # fmt: skip


class PlantState(ctypes.Structure):
    _fields_ = [("t", ctypes.c_double), ("q", ctypes.c_double * 3), ("qd", ctypes.c_double * 3),
                ("h", ctypes.c_double), ("q_meas", ctypes.c_double * 3),
                ("in_contact", ctypes.c_int32), ("pad", ctypes.c_int32),
                ("rng", PyRandom)]  # fmt: skip
    reals = ["t", "q", "qd", "h", "q_meas", "rng.gauss_next"]


class ControllerState(ctypes.Structure):
    _fields_ = [("t", ctypes.c_double), ("start_time", ctypes.c_double),
                ("k_next", ctypes.c_int64), ("held", ctypes.c_int64),
                ("yhat", ctypes.c_double * 3), ("q_prev", ctypes.c_double * 3),
                ("tau_prev", ctypes.c_double * 3), ("f_prev", ctypes.c_double * 3),
                ("source", ctypes.c_int32), ("pad", ctypes.c_int32)]  # fmt: skip
    reals = ["t", "start_time", "yhat", "q_prev", "tau_prev", "f_prev"]


def snapshot_type(model: type[ctypes.Structure], n: int) -> tuple[type, type]:
    """instance.h's Snapshot and glue.h's Data for a model with n variables."""

    class Data(ctypes.Structure):
        _fields_ = [("r", ctypes.c_double * n), ("i", ctypes.c_int * n),
                    ("s", (ctypes.c_char * 64) * n), ("m", model),
                    ("start_time", ctypes.c_double)]  # fmt: skip

    class Snapshot(ctypes.Structure):
        _fields_ = [("d", Data), ("phase", ctypes.c_int), ("dirty", ctypes.c_int),
                    ("last_time", ctypes.c_double), ("me_time", ctypes.c_double),
                    ("me_time_set", ctypes.c_int), ("event_switches", ctypes.c_int)]  # fmt: skip

    return Snapshot, Data


def real_offsets(model: type[ctypes.Structure], n: int) -> dict[str, int]:
    """Every double of the body by name -> offset in the serialized bytes."""
    snap, data = snapshot_type(model, n)
    d0 = HEADER + snap.d.offset
    out = {f"r[{k}]": d0 + data.r.offset + 8 * k for k in range(n)}
    out["start_time"] = d0 + data.start_time.offset
    out["last_time"], out["me_time"] = HEADER + snap.last_time.offset, HEADER + snap.me_time.offset
    for name in model.reals:
        at, typ = d0 + data.m.offset, model
        for part in name.split("."):
            at += getattr(typ, part).offset
            typ = dict(typ._fields_)[part]
        for k in range(getattr(typ, "_length_", 1)):
            out[f"m.{name}[{k}]"] = at + 8 * k
    return out


# --- the driver (runs in the subprocess) ------------------------------------------------------


class Native:
    """One instance of a native FMU (FMI 2 or 3) through fmpy's raw ctypes functions, log kept."""

    def __init__(self, version: int, path: str, params: dict) -> None:
        from fmpy import extract, read_model_description

        self.version, self.logs = version, []
        md = read_model_description(path)
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.outs = [v.valueReference for v in md.modelVariables
                     if v.causality == "output" and v.type in ("Real", "Float64")]  # fmt: skip
        kw = dict(guid=md.guid, unzipDirectory=extract(path),
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="s")  # fmt: skip
        if version == 2:
            from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
            from fmpy.fmi2 import defaultCallbacks as default  # noqa: N813

            self.fmu, self.cb = FMU2Slave(**kw), fmi2CallbackFunctions()
            self.cb.logger = fmi2CallbackLoggerTYPE(lambda *a: self.logs.append(a[-1].decode()))
            self.cb.allocateMemory, self.cb.freeMemory = default.allocateMemory, default.freeMemory
            self.fmu.instantiate(callbacks=self.cb)
            self.fmu.setupExperiment(startTime=0.0)
        else:
            from fmpy.fmi3 import FMU3Slave

            self.fmu = FMU3Slave(**kw)
            self.fmu.instantiate(logMessage=lambda *a: self.logs.append(a[-1].decode()))
        self.f, self.c = self.fmu._functions, self.fmu.component
        names = {"get": "GetFMUstate", "set": "SetFMUstate", "size": "SerializedFMUstateSize",
                 "ser": "SerializeFMUstate", "de": "DeSerializeFMUstate"}  # fmt: skip
        if version == 3:
            names = {k: v.replace("FMUstate", "FMUState").replace("DeSer", "Deser")
                     for k, v in names.items()}  # fmt: skip
        self.names = {k: f"fmi{version}{v}" for k, v in names.items()}
        for name, value in params.items():
            self.set(name, value)
        if version == 2:
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=0.0)
        self.fmu.exitInitializationMode()

    def call(self, key: str, *args) -> int:
        return self.f[self.names[key]](self.c, *args)

    def set(self, name: str, value: float) -> None:
        vr = (ctypes.c_uint * 1)(self.vr[name])
        fn = "fmi2SetReal" if self.version == 2 else "fmi3SetFloat64"
        args = (vr, 1, (ctypes.c_double * 1)(value)) + (() if self.version == 2 else (1,))
        assert self.f[fn](self.c, *args) == OK, self.logs[-1:]

    def outputs(self) -> list[float]:
        n = len(self.outs)
        vrs, vals = (ctypes.c_uint * n)(*self.outs), (ctypes.c_double * n)()
        fn = "fmi2GetReal" if self.version == 2 else "fmi3GetFloat64"
        args = (vrs, n, vals) + (() if self.version == 2 else (n,))
        assert self.f[fn](self.c, *args) == OK
        return list(vals)

    def step(self, k: int) -> int:
        if self.version == 2:
            return self.f["fmi2DoStep"](self.c, k * DT, DT, 1)
        flags = [ctypes.byref(ctypes.c_bool()) for _ in range(3)]
        last = ctypes.byref(ctypes.c_double())
        return self.f["fmi3DoStep"](self.c, k * DT, DT, True, *flags, last)

    def run(self, first: int, n: int) -> list[list[float]]:
        rows = []
        for k in range(first, first + n):
            assert self.step(k) == OK, self.logs[-1:]
            rows.append(self.outputs())
        return rows

    def get_state(self) -> ctypes.c_void_p:
        state = ctypes.c_void_p()
        assert self.call("get", ctypes.byref(state)) == OK
        return state

    def serialize(self, state: ctypes.c_void_p) -> tuple[int, bytes]:
        size = ctypes.c_size_t()
        assert self.call("size", state, ctypes.byref(size)) == OK
        buf = self.buffer(bytes(size.value))
        return self.call("ser", state, buf, size), bytes(buf)[: size.value]

    def deserialize(self, blob: bytes, into: ctypes.c_void_p) -> int:
        return self.call("de", self.buffer(blob), len(blob), ctypes.byref(into))

    def buffer(self, data: bytes) -> ctypes.Array:
        """fmi2Byte[] (char) or fmi3Byte[] (uint8_t) holding data."""
        byte = ctypes.c_char if self.version == 2 else ctypes.c_uint8
        return (byte * max(len(data), 1)).from_buffer_copy(data or b"\0")


def _check_layout(s: Native, blob: bytes, reals: dict[str, int], model, k: int) -> None:
    """The restated layout is the FMU's: the sizes agree and the known values sit where expected."""
    n, body_size = struct.unpack_from("<II", blob, 8)
    assert blob[:8] == MAGIC and fix_crc(blob) == blob
    assert ctypes.sizeof(snapshot_type(model, n)[0]) == body_size == len(blob) - HEADER
    value = lambda name: struct.unpack_from("<d", blob, reals[name])[0]  # noqa: E731
    assert value("last_time") == value("m.t[0]") == k * DT
    assert [value(f"r[{vr}]") for vr in s.outs] == s.outputs()


def mutations(blob: bytes, reals: dict[str, int], rng: random.Random, count: int):
    """(kind, bytes, expected words of the refusal): count random ones, then one per real."""
    n = len(blob)
    old = struct.pack("<IIQ32s", 0x494D5043, *struct.unpack_from("<I", blob, 8),
                      n - HEADER, b"x") + blob[HEADER:]  # fmt: skip
    yield "format 1", old, "older build"
    yield "format 1 + 16 bytes", old + bytes(16), "older build"
    for _ in range(count):
        b, kind = bytearray(blob), rng.choice(["flip", "cut", "extend", "word", "header"])
        if kind == "flip":
            for _ in range(rng.choice([1, 1, 2, 3, 8, 50])):
                b[rng.randrange(n)] ^= 1 << rng.randrange(8)
        elif kind == "cut":
            b = b[: rng.randrange(n)]
        elif kind == "extend":
            b += rng.randbytes(rng.choice([1, 4, 8, 64]))
        elif kind == "word":
            at = rng.randrange(HEADER, n - 8)
            struct.pack_into("<Q", b, at, rng.getrandbits(64))
        else:  # a header field changed, the checksum fixed: only the header check can refuse it
            at = rng.choice([0, 4, 7, 8, 12, 16, 30, 53, 56])
            b[at] ^= 1 << rng.randrange(8)
            b = bytearray(fix_crc(bytes(b)))
        if bytes(b) != blob:
            yield kind, bytes(b), "serialized state refused"
    for name, at in reals.items():
        bad = rng.choice([math.nan, math.inf, -math.inf])
        patched = fix_crc(blob[:at] + struct.pack("<d", bad) + blob[at + 8 :])
        yield f"{name}={bad}", patched, "not finite"


def drive(version: int, path: str, seed: int, count: int) -> None:
    name, rng = Path(path).name, random.Random(seed)
    if name == PLANT:  # moving, with encoder noise: the generator's state matters
        s, model = Native(version, path, {"q_noise": 1e-4, "tau1": 30.0, "tau2": 20.0}), PlantState
    else:
        s, model = Native(version, path, {}), ControllerState
    s.run(0, 40)
    state = s.get_state()
    status, blob = s.serialize(state)
    assert status == OK
    reals = real_offsets(model, struct.unpack_from("<I", blob, 8)[0])
    _check_layout(s, blob, reals, model, 40)
    first = s.run(40, 20)
    assert s.call("set", state) == OK
    before, kept, refused = s.outputs(), s.get_state(), 0
    for kind, bad, words in mutations(blob, reals, rng, count):
        into = kept if rng.random() < 0.5 else ctypes.c_void_p()
        into_before, logged = into.value, len(s.logs)
        status = s.deserialize(bad, into)
        if status != ERROR or len(s.logs) != logged + 1 or words not in s.logs[-1]:
            print(f"UNEXPECTED {kind}: status {status}, log {s.logs[logged:]}", flush=True)
            continue
        assert into.value == into_before  # no state made, the one given not replaced
        assert s.outputs() == before, kind  # the instance is where it was
        refused += 1
    print(f"refused={refused} reals={len(reals)}", flush=True)
    assert s.run(40, 20) == first  # the instance kept its state and keeps working
    assert s.call("set", kept) == OK and s.run(40, 20) == first  # the state given is intact
    fresh = ctypes.c_void_p()
    assert s.deserialize(blob, fresh) == OK and s.call("set", fresh) == OK
    assert s.run(40, 20) == first  # an untouched state restores exactly
    print("done", flush=True)


def drive_overflow(version: int, path: str) -> None:
    """A controller whose observer would overflow (K1 = 1e308): the step is refused with the
    reason, and the instance keeps the step's start, whose state is finite and serializes."""
    s = Native(version, path, {"K1": 1e308})
    s.run(0, 2)
    before = s.outputs()
    s.set("q1", 0.9)
    print(f"step={s.step(2)} log={s.logs[-1]}", flush=True)
    assert s.outputs() == before and all(math.isfinite(x) for x in before)
    status, _ = s.serialize(s.get_state())
    print(f"serialize={status}", flush=True)
    print("done", flush=True)


# --- the tests ------------------------------------------------------------------------------------

needs_cc = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")


def _run(*args) -> subprocess.CompletedProcess:
    cmd = [sys.executable, __file__, *map(str, args)]
    try:
        return subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the driver hung: {args}")


@needs_cc
@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("name", [PLANT, CONTROLLER])
def test_every_mutated_serialized_state_is_refused(native_dir, fmi3_dir, version, name):
    """1,500 random mutations and every real set to NaN/inf: all refused, nothing changed."""
    path = (native_dir if version == 2 else fmi3_dir) / name
    done = _run(version, path, 20, 1500)
    assert done.returncode == 0, f"host died ({done.returncode}): {done.stderr[-2000:]}"
    assert "UNEXPECTED" not in done.stdout, done.stdout[:3000]  # accepted, or for another reason
    assert "done" in done.stdout


@needs_cc
@pytest.mark.parametrize("version", [2, 3])
def test_a_step_that_would_overflow_leaves_a_finite_state(native_dir, fmi3_dir, version):
    path = (native_dir if version == 2 else fmi3_dir) / CONTROLLER
    done = _run(version, path, "overflow", 0)
    assert done.returncode == 0, f"host died ({done.returncode}): {done.stderr[-2000:]}"
    assert f"step={DISCARD}" in done.stdout and "is not finite" in done.stdout
    assert f"serialize={OK}" in done.stdout and "done" in done.stdout


STATE_HOST = Path(__file__).parent / "c_host" / "state_host.c"


def _build_state_host(platform: str, out: Path) -> Path:
    from fmpy import __file__ as fmpy_init

    exe = out / ("state_host.exe" if platform == "win64" else f"state_host_{platform}")
    extra = ["-D__USE_MINGW_ANSI_STDIO=1", "-static-libgcc"] if platform == "win64" else ["-ldl"]
    subprocess.run([need_compiler(platform).compiler, "-std=c99", "-O2", "-Wall", "-Wextra",
                    "-Werror", f"-I{Path(fmpy_init).parent / 'c-code'}", str(STATE_HOST), *extra,
                    "-o", str(exe)], check=True, capture_output=True, timeout=120)  # fmt: skip
    return exe


def _platform_state_run(platform: str, native_dir: Path, tmp_path: Path, request) -> str:
    """state_host (built for platform, run under wine/qemu there) on the plant library of that
    platform in the FMU archive: its own state, mutations of it and the linux64 library's state."""
    from fmpy import read_model_description

    md = read_model_description(str(native_dir / PLANT))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    shutil.unpack_archive(native_dir / PLANT, tmp_path / "fmu", "zip")

    def run(plat: str, *args: str) -> str:
        prefix, env = run_command(plat, request)
        lib = tmp_path / "fmu" / "binaries" / plat / f"PumaPlant{BY_PLATFORM[plat].suffix}"
        inputs = f"{vr['q_noise']}=1e-4,{vr['tau1']}=30,{vr['tau2']}=20"
        files = [host_path(plat, Path(a)) if "/" in a else a for a in args]
        exe = _build_state_host(plat, tmp_path)
        argv = [*prefix, str(exe), host_path(plat, lib), md.guid, "40", inputs, *files]
        done = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stdout[-1000:] + done.stderr[-1000:]
        return done.stdout

    run("linux64", "write", str(tmp_path / "linux64.bin"))
    run(platform, "write", str(tmp_path / "own.bin"))
    blob, at = (tmp_path / "own.bin").read_bytes(), HEADER + 8 * vr["q1"]  # Data.r[q1]
    files = {"flipped": blob[:99] + bytes([blob[99] ^ 0x10]) + blob[100:], "cut": blob[:-1],
             "extended": blob + b"\0",
             "nan_output": fix_crc(blob[:at] + struct.pack("<d", math.nan) + blob[at + 8 :]),
             "format1": struct.pack("<IIQ32s", 0x494D5043, 63, len(blob) - 64, b"PumaPlant")
             + blob[48:]}  # fmt: skip
    for name, data in files.items():
        (tmp_path / f"{name}.bin").write_bytes(data)
    names = ["own", "linux64", *files]
    return run(platform, "read", *(str(tmp_path / f"{n}.bin") for n in names))


@needs_cc
@pytest.mark.parametrize("platform", ["linux64", "win64", "aarch64-linux"])
@pytest.mark.slow
def test_every_platform_refuses_bad_states_and_reads_the_others(
    platform, native_dir, tmp_path, request
):
    """The plant's library for each platform in the archive: its own state and the linux64
    library's restore (the layout is the same everywhere), each broken one is refused."""
    out = _platform_state_run(platform, native_dir, tmp_path, request)
    status = {}
    for line in out.splitlines():
        if not line.startswith("log "):
            path, result = line.split(" ", 1)
            status[path.replace("\\", "/").rsplit("/", 1)[-1]] = result
    assert status["own.bin"] == status["linux64.bin"] == "0 step=0", out
    for name in ("flipped", "cut", "extended", "nan_output", "format1"):
        assert status[f"{name}.bin"] == "3", (name, out)
    for words in ("checksum mismatch", "not finite", "older build", "truncated or extended"):
        assert words in out, (words, out)


if __name__ == "__main__":
    version, fmu, seed, count = int(sys.argv[1]), sys.argv[2], sys.argv[3], int(sys.argv[4])
    if seed == "overflow":
        drive_overflow(version, fmu)
    else:
        drive(version, fmu, int(seed), count)
