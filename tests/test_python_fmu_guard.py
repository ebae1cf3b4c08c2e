"""The Python FMUs after free (issue 20): pythonfmu's C++ layer deletes the instance in
fmiXFreeInstance and trusts the pointer in every later call (a second fmi3FreeInstance killed
the host, fmi2GetReal after free returned OK with stale data). The guard our build puts in front
of it (packaging/pyfmu_guard.py) refuses such calls as the native FMUs do. Each case runs in a
child process, so a crash is a failed test, not a dead test run."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from impedance_cosim.packaging.pyfmu_guard import REAL, guard_source

PLANT, CONTROLLER = "PumaPlant.fmu", "ImpedanceController.fmu"
OK, ERROR = 0, 3

# The child: only fmpy (importing impedance_cosim here would make the FMU use this checkout's
# modules). Instantiate, step, free; then every use of the freed instance; leave without the
# library destructors (the exit is what test_a_python_fmu_host_exits_with_an_intact_heap tests).
CHILD = r"""
import ctypes, os, sys
from fmpy import extract, read_model_description
path, version = sys.argv[1], sys.argv[2]
md = read_model_description(path)
out = (ctypes.c_double * 1)()
vr = (ctypes.c_uint32 * 1)(next(v.valueReference for v in md.modelVariables
                                if v.causality == "output"))
if version == "2":
    from fmpy.fmi2 import FMU2Slave
    s = FMU2Slave(guid=md.guid, unzipDirectory=extract(path),
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="g")
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    f, c = s._functions, s.component
    get = lambda: f["fmi2GetReal"](c, vr, 1, out)
    step = lambda: f["fmi2DoStep"](c, 0.0, 0.0025, 1)
    free = lambda: f["fmi2FreeInstance"](c)
else:
    from fmpy.fmi3 import FMU3Slave
    s = FMU3Slave(guid=md.guid, unzipDirectory=extract(path),
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="g")
    s.instantiate()
    s.enterInitializationMode(startTime=0.0)
    s.exitInitializationMode()
    f, c = s._functions, s.component
    flags = [ctypes.c_bool() for _ in range(3)] + [ctypes.c_double()]
    get = lambda: f["fmi3GetFloat64"](c, vr, 1, out, 1)
    step = lambda: f["fmi3DoStep"](c, 0.0, 0.0025, True, *map(ctypes.byref, flags))
    free = lambda: f["fmi3FreeInstance"](c)
print(f"live get={get()} step={step()}", flush=True)
free()
print("freed once", flush=True)
print(f"after free get={get()} step={step()}", flush=True)
free()
print("freed twice", flush=True)
sys.stdout.flush(); sys.stderr.flush()
os._exit(0)
"""


def after_free(fmu: Path, version: int) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-c", CHILD, str(fmu), str(version)]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def python_fmus(fmu_dir, fmi3_dir) -> dict[int, Path]:
    pytest.importorskip("pythonfmu3")
    return {2: fmu_dir, 3: fmi3_dir / "python"}


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("name", [PLANT, CONTROLLER])
def test_python_fmu_refuses_calls_on_a_freed_instance(python_fmus, name, version):
    done = after_free(python_fmus[version] / name, version)
    assert done.returncode == 0, f"host died ({done.returncode}): {done.stderr[-800:]}"
    assert f"live get={OK} step={OK}" in done.stdout
    assert f"after free get={ERROR} step={ERROR}" in done.stdout, done.stdout
    assert "freed twice" in done.stdout
    get = "fmi2GetReal" if version == 2 else "fmi3GetFloat64"
    for function in (get, f"fmi{version}DoStep", f"fmi{version}FreeInstance"):
        assert f"{function} called with a freed or foreign instance: refused" in done.stderr


@pytest.mark.parametrize("version", [2, 3])
def test_the_guard_forwards_every_function_of_pythonfmus_binary(python_fmus, version, tmp_path):
    """pythonfmu's library keeps its name beside the guard; the guard exports each FMI
    function the library exports (read from the ELF symbol table), no fewer, no more."""
    if shutil.which("nm") is None:
        pytest.skip("needs nm")
    folder = "linux64" if version == 2 else "x86_64-linux"
    with zipfile.ZipFile(python_fmus[version] / PLANT) as z:
        names = set(z.namelist())
        assert f"binaries/{folder}/PumaPlant{REAL}.so" in names
        exported = {}
        for which in ("PumaPlant.so", f"PumaPlant{REAL}.so"):
            lib = tmp_path / which
            lib.write_bytes(z.read(f"binaries/{folder}/{which}"))
            nm = subprocess.run(["nm", "-D", "--defined-only", str(lib)], capture_output=True,
                                text=True, check=True).stdout  # fmt: skip
            exported[which] = set(re.findall(r" T (fmi[23]\w+)$", nm, re.M))
    assert exported["PumaPlant.so"] == exported[f"PumaPlant{REAL}.so"]
    assert len(exported["PumaPlant.so"]) == (34 if version == 2 else 75)
    assert guard_source("PumaPlant", version).count(f"FMI{version}_Export") == (
        34 if version == 2 else 75
    )


# The child for the exit: one instance, one step, free, and a normal exit (the libraries'
# exit handlers and destructors run).
EXIT_CHILD = r"""
import sys
from fmpy import extract, read_model_description
path, version = sys.argv[1], sys.argv[2]
md = read_model_description(path)
if version == "2":
    from fmpy.fmi2 import FMU2Slave as Slave
else:
    from fmpy.fmi3 import FMU3Slave as Slave
s = Slave(guid=md.guid, unzipDirectory=extract(path),
          modelIdentifier=md.coSimulation.modelIdentifier, instanceName="g")
s.instantiate()
if version == "2":
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
else:
    s.enterInitializationMode(startTime=0.0)
s.exitInitializationMode()
s.doStep(0.0, 0.0025)
s.terminate()
s.freeInstance()
print("freed", flush=True)
"""


@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind not installed")
@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.slow
def test_a_python_fmu_host_exits_with_an_intact_heap(python_fmus, version):
    """pythonfmu's library empties its static PyState pointer after the C++ exit handler has
    destroyed it: a write into a freed block at every host exit, which aborted 4 of 25 runs of
    docs/running.md's API snippet ("corrupted double-linked list"). With the guard's exit
    handler, valgrind sees no access to freed memory from pythonfmu's library at exit."""
    cmd = ["valgrind", "--num-callers=8", sys.executable, "-c", EXIT_CHILD,
           str(python_fmus[version] / PLANT), str(version)]  # fmt: skip
    env = {**os.environ, "PYTHONMALLOC": "malloc"}
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0 and "freed" in done.stdout, done.stderr[-2000:]
    bad = [b for b in _valgrind_errors(done.stderr) if REAL in b]
    assert not bad, "\n\n".join(bad)


def _valgrind_errors(log: str) -> list[str]:
    """valgrind's error reports, one string each (its lines without the ==pid== prefix)."""
    blocks, current = [], []
    for line in log.splitlines():
        if not line.startswith("=="):
            continue
        text = line.split("== ", 1)[-1]
        if text.strip():
            current.append(text)
        elif current:
            blocks.append("\n".join(current))
            current = []
    return [b for b in [*blocks, "\n".join(current)] if b.startswith("Invalid")]


# --- the guard's loader on each platform, with a stand-in for pythonfmu's library --------------

FAKE = r"""
#include <stdlib.h>
#include "fmi2Functions.h"
fmi2Component fmi2Instantiate(fmi2String n, fmi2Type t, fmi2String g, fmi2String r,
                              const fmi2CallbackFunctions *f, fmi2Boolean v, fmi2Boolean l) {
    (void)n, (void)t, (void)g, (void)r, (void)f, (void)v, (void)l;
    return malloc(16);
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean b) {
    (void)c, (void)t, (void)h, (void)b;
    return fmi2Warning; /* not what the guard returns: the call got through */
}
"""

HOST = r"""
#include <stdio.h>
#ifdef _WIN32
#include <windows.h>
#define OPEN(p) (void *)LoadLibraryA(p)
#define SYM(h, n) (void *)GetProcAddress((HMODULE)(h), n)
#else
#include <dlfcn.h>
#define OPEN(p) dlopen(p, RTLD_NOW | RTLD_LOCAL)
#define SYM(h, n) dlsym(h, n)
#endif
#include "fmi2FunctionTypes.h"
int main(int argc, char **argv) {
    void *lib = OPEN(argv[1]);
    if (!lib) { printf("cannot load %s\n", argv[1]); return 1; }
    fmi2InstantiateTYPE *instantiate = (fmi2InstantiateTYPE *)SYM(lib, "fmi2Instantiate");
    fmi2DoStepTYPE *step = (fmi2DoStepTYPE *)SYM(lib, "fmi2DoStep");
    fmi2FreeInstanceTYPE *release = (fmi2FreeInstanceTYPE *)SYM(lib, "fmi2FreeInstance");
    fmi2CallbackFunctions callbacks = {0};
    fmi2Component c = instantiate("x", fmi2CoSimulation, "g", "file:///r", &callbacks, 0, 0);
    printf("live=%d\n", step(c, 0.0, 0.1, 1));
    release(c);
    printf("after=%d\n", step(c, 0.0, 0.1, 1));
    release(c);
    printf("foreign=%d\n", step((fmi2Component)&callbacks, 0.0, 0.1, 1));
    printf("done\n");
    fflush(stdout);
    return argc - 2;
}
"""


@pytest.mark.parametrize("platform", ["linux64", "win64"])
@pytest.mark.slow
def test_the_guard_loads_the_library_beside_it_and_refuses_freed_instances(
    platform, tmp_path, request
):
    """The guard alone (no Python): built for each platform as the build does, in front of a
    stand-in library, driven by a small C host (under wine for win64)."""
    import fmpy

    from impedance_cosim.packaging.pyfmu_guard import guard_binaries
    from impedance_cosim.packaging.toolchains import BY_PLATFORM, compile_library

    toolchain = BY_PLATFORM[platform]
    if not toolchain.available():
        pytest.skip(f"{toolchain.compiler} not found")
    run = []
    if platform == "win64":
        launcher = next(filter(None, map(shutil.which, ("wine64", "/usr/lib/wine/wine64"))), None)
        if launcher is None:
            pytest.skip("wine64 not found")
        run = [launcher]
    src = tmp_path / "src"
    src.mkdir()
    for header in (Path(fmpy.__file__).parent / "c-code").glob("fmi2*.h"):
        shutil.copy(header, src)
    (src / "fake.c").write_text(FAKE)
    (src / "host.c").write_text(HOST)
    name = f"binaries/{platform}/Fake{toolchain.suffix}"
    (tmp_path / name).parent.mkdir(parents=True)
    compile_library(toolchain, src, ["fake.c"], tmp_path / name)
    members = guard_binaries({name: (tmp_path / name).read_bytes()}, 2)
    assert set(members) == {name, f"binaries/{platform}/Fake{REAL}{toolchain.suffix}"}
    for member, data in members.items():
        (tmp_path / member).write_bytes(data)
    host = tmp_path / ("host.exe" if platform == "win64" else "host")
    flags = [] if platform == "win64" else ["-ldl"]
    subprocess.run([toolchain.compiler, "-std=c99", "-I.", "host.c", "-o", str(host), *flags],
                   cwd=src, check=True)  # fmt: skip
    env = {"WINEPREFIX": str(tmp_path / "wine"), "WINEDEBUG": "-all"} if run else {}
    done = subprocess.run([*run, str(host), str(tmp_path / name)], capture_output=True,
                          text=True, timeout=300, env={**os.environ, **env})  # fmt: skip
    lines = done.stdout.split()
    assert lines == ["live=1", f"after={ERROR}", f"foreign={ERROR}", "done"], (done, lines)
    refusals = [ln for ln in done.stderr.splitlines() if ln.endswith("instance: refused")]
    assert refusals == [
        "fmi2DoStep called with a freed or foreign instance: refused",
        "fmi2FreeInstance called with a freed or foreign instance: refused",
        "fmi2DoStep called with a freed or foreign instance: refused",
    ], done.stderr
