"""Fuzz test of the native FMUs (issue 10): random FMI call sequences and values from a fixed
seed, run in a subprocess so that a crash or a hang is a test failure naming the seed and the
call. This file is also the driver: `python test_fuzz_native.py FMU SEED CALLS PROGRESS` (FMU may
be a comma-separated list).

The driver calls the raw fmi2* functions through ctypes: any instance/state order (terminate,
reset, free, calls after free), every type with NaN, inf, huge, negative values and unknown value
references, doStep with odd times and steps, get/set/serialize/deserialize of states including
mutated serialized bytes, and the Model Exchange functions (on instances of either kind). Only
the two work-bound parameters are kept small when set (a fuzzer that sets max_rhs_evaluations to
2^31 would just measure how long a legal huge step takes)."""

from __future__ import annotations

import ctypes
import functools
import random
import shutil
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

DT = 1 / 400
FMUS = ["PumaPlant.fmu", "ImpedanceController.fmu"]
REALS = [0.0, -0.0, 1.0, -1.0, 0.3, DT, 1e308, -1e308, float("nan"), float("inf"), float("-inf"),
         5e-324, 1e-300, 2.0**53, -2.0**63]  # fmt: skip
INTS = [0, 1, -1, 2, 7, 2**31 - 1, -(2**31), 1000, -1000]
STRINGS = [b"observer", b"difference", b"measured", b"", b"x" * 63, b"x" * 64, b"x" * 500,
           "\u00e9".encode(), b"%s%n%x", b"\xff\xfe"]  # fmt: skip
WORK_BOUNDS = ("max_rhs_evaluations", "max_samples_per_step")
ME_FUNCTIONS = ["fmi2SetTime", "fmi2SetContinuousStates", "fmi2GetContinuousStates",
                "fmi2GetDerivatives", "fmi2GetEventIndicators", "fmi2EnterEventMode",
                "fmi2NewDiscreteStates", "fmi2EnterContinuousTimeMode",
                "fmi2CompletedIntegratorStep", "fmi2GetNominalsOfContinuousStates"]  # fmt: skip


def _on_a_component(call):
    """The Fuzzer's CALL(self, c) on the component c it picks (Fuzzer.component: live, or now
    and then freed); no call while no instance is live."""

    @functools.wraps(call)
    def on_component(self) -> None:
        c = self.component()
        if c is not None:
            call(self, c)

    return on_component


class Fuzzer:
    """Random FMI calls against one FMU binary (see the module docstring)."""

    def __init__(self, path: str, seed: int, progress) -> None:
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Model, FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
        from fmpy.fmi2 import defaultCallbacks as default_callbacks  # noqa: N813

        self.rng = random.Random(seed)
        self.progress = progress
        md = read_model_description(path)
        self.guid = md.guid.encode()
        self.vars = md.modelVariables
        self.n_vars = len(self.vars)
        unzip = extract(path)
        self.resources = (Path(unzip) / "resources").as_uri().encode()
        self.lib = FMU2Slave(
            guid=md.guid,
            unzipDirectory=unzip,
            modelIdentifier=md.coSimulation.modelIdentifier,
            instanceName="fuzz",
        )
        self.raw = dict(self.lib._functions)
        self.me = md.modelExchange is not None
        if self.me:  # the Model Exchange functions of the same library
            self.raw.update(
                FMU2Model(
                    guid=md.guid,
                    unzipDirectory=unzip,
                    modelIdentifier=md.modelExchange.modelIdentifier,
                    instanceName="fuzz",
                )._functions
            )
        self.ok: dict[str, int] = {}  # successful calls per function, to see what was reached
        self.f = {name: self._counted(name) for name in self.raw}
        self.messages = 0

        def log(env, name, status, category, message):
            self.messages += 1

        self.cb = fmi2CallbackFunctions()
        self.cb.logger = fmi2CallbackLoggerTYPE(log)
        self.cb.allocateMemory = default_callbacks.allocateMemory
        self.cb.freeMemory = default_callbacks.freeMemory
        self.live: list[int] = []  # component pointers
        self.dead: list[int] = []
        self.states: list[tuple[int, int]] = []  # (component, state pointer)
        self.dead_states: list[tuple[int, int]] = []
        self.blobs: list[bytes] = []
        self.t: dict[int, float] = {}

    def _counted(self, name: str):
        raw = self.raw[name]

        def call(*args):
            result = raw(*args)
            if result == 0 or (name == "fmi2Instantiate" and result):
                self.ok[name] = self.ok.get(name, 0) + 1
            return result

        return call

    # --- random values ------------------------------------------------------------------------

    def real(self) -> float:
        r = self.rng
        return r.choice(REALS) if r.random() < 0.4 else r.gauss(0.0, 10.0 ** r.uniform(-3, 3))

    def vrs(self, type_name: str) -> list[int]:
        r = self.rng
        same = [k for k, v in enumerate(self.vars) if v.type == type_name]
        inputs = [k for k in same if self.vars[k].causality == "input"]
        out = []
        for _ in range(r.choice([0, 1, 1, 1, 2, 3])):
            roll = r.random()
            if roll < 0.5 and inputs:
                out.append(r.choice(inputs))
            elif roll < 0.85 and same:
                out.append(r.choice(same))
            elif roll < 0.93:
                out.append(r.randrange(self.n_vars))  # maybe the wrong type
            else:
                out.append(r.choice([self.n_vars, self.n_vars + 1, 2**31, 2**32 - 1]))
        return out

    def component(self) -> int | None:
        r = self.rng
        if self.dead and r.random() < 0.03:
            return r.choice(self.dead)  # use after free: must be refused
        if not self.live:
            return None
        return r.choice(self.live)

    # --- calls ----------------------------------------------------------------------------------

    def instantiate(self) -> None:
        logging_on = self.rng.random() < 0.5
        kind = 0 if self.me and self.rng.random() < 0.3 else 1  # Model Exchange / co-simulation
        c = self.f["fmi2Instantiate"](
            b"fuzz", kind, self.guid, self.resources, ctypes.byref(self.cb), 0, logging_on
        )
        if c:
            self.live.append(c)
            self.t[c] = 0.0

    @_on_a_component
    def free(self, c: int) -> None:
        for s in [s for s in self.states if s[0] == c]:  # states die with their instance
            self.states.remove(s)
            self.f["fmi2FreeFMUstate"](c, ctypes.byref(ctypes.c_void_p(s[1])))
        self.f["fmi2FreeInstance"](c)
        if c in self.live:
            self.live.remove(c)
            self.dead.append(c)

    @_on_a_component
    def initialize(self, c: int) -> None:
        """The ordinary way in, so that stepping and states are reached often."""
        self.f["fmi2SetupExperiment"](c, 0, 0.0, 0.0, 0, 0.0)
        self.f["fmi2EnterInitializationMode"](c)
        self.f["fmi2ExitInitializationMode"](c)
        self.t[c] = 0.0

    @_on_a_component
    def lifecycle(self, c: int) -> None:
        r = self.rng
        name = r.choice(["fmi2SetupExperiment", "fmi2EnterInitializationMode",
                         "fmi2ExitInitializationMode", "fmi2Terminate", "fmi2Reset",
                         "fmi2SetDebugLogging", "fmi2CancelStep"])  # fmt: skip
        if name == "fmi2SetupExperiment":
            start = self.real() if r.random() < 0.3 else 0.0
            self.f[name](c, r.randint(0, 1), self.real(), start, r.randint(0, 1), self.real())
            self.t[c] = start
        elif name == "fmi2SetDebugLogging":
            self.f[name](c, r.randint(0, 1), 0, None)
        else:
            self.f[name](c)
        if name == "fmi2Reset":
            self.t[c] = 0.0

    @_on_a_component
    def set_values(self, c: int) -> None:
        r = self.rng
        type_name = r.choice(["Real", "Integer", "Boolean", "String"])
        vrs = self.vrs(type_name)
        n = len(vrs)
        vr = (ctypes.c_uint * n)(*vrs)
        if type_name == "Real":
            values = [r.gauss(0.0, 1.0) if r.random() < 0.6 else self.real() for _ in vrs]
            self.f["fmi2SetReal"](c, vr, n, (ctypes.c_double * n)(*values))
        elif type_name == "Integer":
            values = []
            for k in vrs:
                bound = k < self.n_vars and self.vars[k].name in WORK_BOUNDS
                values.append(r.randint(-5, 1000) if bound else r.choice(INTS))
            self.f["fmi2SetInteger"](c, vr, n, (ctypes.c_int * n)(*values))
        elif type_name == "Boolean":
            values = [r.choice([0, 1, 2, -1, 255]) for _ in vrs]
            self.f["fmi2SetBoolean"](c, vr, n, (ctypes.c_int * n)(*values))
        else:
            values = [r.choice(STRINGS) for _ in vrs]
            self.f["fmi2SetString"](c, vr, n, (ctypes.c_char_p * n)(*values))

    @_on_a_component
    def get_values(self, c: int) -> None:
        type_name = self.rng.choice(["Real", "Integer", "Boolean", "String"])
        vrs = self.vrs(type_name)
        n = len(vrs)
        vr = (ctypes.c_uint * n)(*vrs)
        out = {"Real": ctypes.c_double, "Integer": ctypes.c_int, "Boolean": ctypes.c_int,
               "String": ctypes.c_char_p}[type_name]  # fmt: skip
        values = (out * n)()
        status = self.f[f"fmi2Get{type_name}"](c, vr, n, values)
        if status == 0 and type_name == "String":
            for v in values:  # read every returned string to its NUL
                assert v is not None and len(v) < 64

    @_on_a_component
    def do_step(self, c: int) -> None:
        r = self.rng
        t = self.t.get(c, 0.0)
        if r.random() < 0.15:
            t = self.real()
        h = r.choice([DT, DT, DT, 0.01, 0.1, 1.0, 10.0, 0.0, -DT, 1e-300, 1e6, float("nan"),
                      float("inf"), r.expovariate(100.0)])  # fmt: skip
        status = self.f["fmi2DoStep"](c, t, h, 1)
        if status == 0:
            self.t[c] = t + h
        real = ctypes.c_double()
        self.f["fmi2GetRealStatus"](c, 2, ctypes.byref(real))  # fmi2LastSuccessfulTime

    @_on_a_component
    def me_op(self, c: int) -> None:
        """A Model Exchange call (on any instance: co-simulation ones must refuse it)."""
        from fmpy.fmi2 import fmi2EventInfo

        if not self.me:
            return
        r = self.rng
        name = r.choice(ME_FUNCTIONS)
        n = r.choice([0, 1, 6, 6, 6, 7, 100])
        if name == "fmi2SetTime":
            self.f[name](c, self.real() if r.random() < 0.3 else r.uniform(0.0, 1.0))
        elif name == "fmi2SetContinuousStates":
            values = [r.gauss(0.0, 1.0) if r.random() < 0.8 else self.real() for _ in range(n)]
            self.f[name](c, (ctypes.c_double * max(n, 1))(*values), n)
        elif name in ("fmi2EnterEventMode", "fmi2EnterContinuousTimeMode"):
            self.f[name](c)
        elif name == "fmi2NewDiscreteStates":
            info = fmi2EventInfo()
            self.f[name](c, ctypes.byref(info))
        elif name == "fmi2CompletedIntegratorStep":
            enter, terminate = ctypes.c_int(), ctypes.c_int()
            self.f[name](c, r.randint(0, 1), ctypes.byref(enter), ctypes.byref(terminate))
        else:
            self.f[name](c, (ctypes.c_double * max(n, 1))(), n)

    @_on_a_component
    def state_op(self, c: int) -> None:
        r = self.rng
        own = [s for s in self.states if s[0] == c]
        op = r.choice(["get", "get", "set", "set", "free", "serialize", "deserialize",
                       "deserialize", "set_foreign"])  # fmt: skip
        if op == "get":
            ptr = ctypes.c_void_p(r.choice(own)[1] if own and r.random() < 0.3 else None)
            if self.f["fmi2GetFMUstate"](c, ctypes.byref(ptr)) == 0 and ptr.value:
                if (c, ptr.value) not in self.states:
                    self.states.append((c, ptr.value))
        elif op == "set" and own:
            self.f["fmi2SetFMUstate"](c, ctypes.c_void_p(r.choice(own)[1]))
        elif op == "set" and self.dead_states:
            self.f["fmi2SetFMUstate"](c, ctypes.c_void_p(r.choice(self.dead_states)[1]))
        elif op == "free" and own:
            s = r.choice(own)
            self.states.remove(s)
            self.dead_states.append(s)
            self.f["fmi2FreeFMUstate"](c, ctypes.byref(ctypes.c_void_p(s[1])))
        elif op == "serialize" and own:
            s = r.choice(own)[1]
            size = ctypes.c_size_t()
            if self.f["fmi2SerializedFMUstateSize"](c, ctypes.c_void_p(s), ctypes.byref(size)):
                return
            buf = ctypes.create_string_buffer(size.value)
            if self.f["fmi2SerializeFMUstate"](c, ctypes.c_void_p(s), buf, size) == 0:
                self.blobs.append(buf.raw)
        elif op == "deserialize":
            blob = self.mutate(r.choice(self.blobs)) if self.blobs else r.randbytes(64)
            buf = ctypes.create_string_buffer(blob, len(blob))
            ptr = ctypes.c_void_p()
            if self.f["fmi2DeSerializeFMUstate"](c, buf, len(blob), ctypes.byref(ptr)) == 0:
                self.states.append((c, ptr.value))
        elif op == "set_foreign":
            junk = ctypes.create_string_buffer(r.randbytes(4096), 4096)
            self.f["fmi2SetFMUstate"](c, junk)

    def mutate(self, blob: bytes) -> bytes:
        """A serialized state, often mutated: flipped bytes, random 32-bit or 64-bit words
        (counters, enums, doubles), truncated or extended; in most mutated bodies the checksum
        is recomputed (instance.c's SerialHeader: CRC-32 at byte 60 of a 64-byte header), so
        that the checks behind it get random bodies too."""
        r = self.rng
        b = bytearray(blob)
        roll = r.random()
        if roll < 0.2:
            return bytes(b)
        if roll < 0.3:
            return bytes(b[: r.randrange(len(b))]) if r.random() < 0.5 else bytes(b) + b"\0"
        for _ in range(r.choice([1, 1, 2, 5, 50])):
            at = r.randrange(64, len(b) - 8)  # the body (the header is checked separately)
            kind = r.random()
            if kind < 0.3:
                b[at] ^= 1 << r.randrange(8)
            elif kind < 0.65:
                struct.pack_into("<i", b, at - at % 4, r.choice(INTS + [624, 625, -624, 3, 9]))
            else:
                struct.pack_into("<d", b, at - at % 8, self.real())
        if r.random() < 0.8:
            struct.pack_into("<I", b, 60, zlib.crc32(bytes(b[:60] + b[64:])))
        if r.random() < 0.05:
            b[r.randrange(64)] ^= 0xFF  # the header
        return bytes(b)

    def run(self, calls: int) -> None:
        r = self.rng
        ops = [(self.instantiate, 3), (self.free, 2), (self.initialize, 5), (self.lifecycle, 6),
               (self.set_values, 20), (self.get_values, 10), (self.do_step, 30),
               (self.state_op, 15), (self.me_op, 10)]  # fmt: skip
        funcs, weights = zip(*ops)
        for k in range(calls):
            op = r.choices(funcs, weights)[0]
            self.progress.write(f"{k} {op.__name__}\n")
            self.progress.flush()
            op()
        for c in list(self.live):
            self.f["fmi2FreeInstance"](c)
        print(f"calls={calls} instances={len(self.live) + len(self.dead)} "
              f"messages={self.messages}")  # fmt: skip
        print("ok: " + " ".join(f"{k[4:]}={v}" for k, v in sorted(self.ok.items())))


def fuzz(
    native_dir: Path,
    tmp_path: Path,
    name: str,
    seed: int,
    calls: int,
    *extra: str,
    prefix: tuple[str, ...] = (),
    timeout: float = 120,
) -> subprocess.CompletedProcess:
    """Run the driver in a subprocess; fail naming the seed and the last call on a crash/hang."""
    progress = tmp_path / f"progress-{seed}.txt"
    paths = ",".join(str(native_dir / n) for n in name.split(","))
    cmd = [*prefix, sys.executable, __file__, paths, str(seed), str(calls), str(progress), *extra]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        last = progress.read_text().splitlines()[-1:] if progress.exists() else []
        pytest.fail(f"{name}: seed {seed} hung at call {last}")
    if done.returncode != 0:
        last = progress.read_text().splitlines()[-1:] if progress.exists() else []
        pytest.fail(
            f"{name}: seed {seed} crashed (exit status {done.returncode}) at call {last}:"
            f" {done.stderr[-1500:]}"
        )
    return done


needs_cc = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")


@needs_cc
@pytest.mark.parametrize("name", FMUS)
@pytest.mark.parametrize("seed", [1, 2])
def test_fuzz_native_fmu_does_not_crash(native_dir, tmp_path, name, seed):
    done = fuzz(native_dir, tmp_path, name, seed, 3000)
    assert "calls=3000" in done.stdout
    assert "refused" in done.stderr  # the run did reach calls on freed instances


def errors_in(valgrind_log: str, library: str) -> list[str]:
    """valgrind's error reports whose stack passes through the FMU's library (the Python
    interpreter itself is not valgrind-clean, so reports only in its own code are ignored),
    except the reads of the tag at offset 0 of a freed instance or state: that read is how the
    FMU recognises a freed pointer (reading freed memory, which valgrind rightly reports)."""
    blocks, current = [], []
    for line in valgrind_log.splitlines():
        text = line.split("== ", 1)[-1] if line.startswith("==") else None
        if text is None:
            continue
        if text.strip():
            current.append(text)
        elif current:
            blocks.append("\n".join(current))
            current = []
    blocks.append("\n".join(current))

    def tag_read(b: str) -> bool:
        return b.startswith(("Invalid read of size 4", "Invalid read of size 8")) and (
            " is 0 bytes inside a block of size" in b and "free'd" in b
        )

    return [
        b
        for b in blocks
        if library in b and not b.startswith(("HEAP", "LEAK", "ERROR")) and not tag_read(b)
    ]


@needs_cc
@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind not installed")
@pytest.mark.slow
def test_fuzz_under_valgrind(native_dir, tmp_path, monkeypatch):
    """A short run: no invalid write or free, no use of uninitialised memory and no read of freed
    memory beyond the tag inside the FMU (a freed instance or state is recognised, not used)."""
    monkeypatch.setenv("PYTHONMALLOC", "malloc")  # Python's allocations visible to valgrind
    vg = ("valgrind", "--errors-for-leak-kinds=none", "--num-callers=30")
    done = fuzz(native_dir, tmp_path, ",".join(FMUS), 2, 600, prefix=vg, timeout=300)
    assert done.stdout.count("calls=600") == 2
    assert "ERROR SUMMARY" in done.stderr  # valgrind did run
    for name in FMUS:
        assert errors_in(done.stderr, name.replace(".fmu", ".so")) == []


if __name__ == "__main__":
    with open(sys.argv[4], "w") as out:
        for path in sys.argv[1].split(","):  # several FMUs: one after the other
            Fuzzer(path, int(sys.argv[2]), out).run(int(sys.argv[3]))
