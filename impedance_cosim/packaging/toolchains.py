"""The C compilers that build a native FMU's binaries/<platform>/ libraries: linux64 with the
machine's gcc, win64 and aarch64 Linux with Debian's cross compilers when they are installed.

Directory names: FMI 2.0 names only win32/win64/linux32/linux64/darwin32/darwin64. For 64-bit ARM
Linux it has no name, and fmpy 0.3.32 on an aarch64 machine looks for FMI 2 binaries in
`binaries/linux64` (its `platform` is 'linux64' there), where our x86_64 library already sits. We
use FMI 3.0's platform tuple `aarch64-linux` (what the Reference FMUs use for aarch64, in FMI 3),
so a host on ARM Linux loads `binaries/aarch64-linux/<id>.so` by path (e.g. fmpy's
`FMU2Slave(libraryPath=...)`). darwin64 cannot be built here: sources/ + buildDescription.xml let
a Mac tool (or fmpy's compile support) build it.

Each compiler is probed once per process with a tiny compile (probe()): one that is on PATH but
cannot compile (gcc-aarch64-linux-gnu without libc6-dev-arm64-cross, which apt installs only as a
recommendation) is a note naming the Debian packages and its platform is skipped, like an absent
one; IMPCOSIM_REQUIRE_PLATFORMS=1 (CI) makes it an error.

Builds are deterministic: every compiler runs in the sources folder on relative file names (no
temp path reaches the binary), without debug info, and the PE timestamp is left out."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from impedance_cosim.packaging import build_cache

# The same flags for every platform (-fPIC only where it means something).
CFLAGS = ("-std=c99", "-O2", "-ffp-contract=off", "-fvisibility=hidden", "-Wall", "-Wextra")


class CompileError(RuntimeError):
    """A C compiler that is there failed (or vanished): the build stops, naming the platform."""


@dataclass(frozen=True)
class Toolchain:
    """One target platform: its binaries/ folder, compiler, library suffix and extra flags."""

    platform: str  # folder under binaries/
    cc: str  # compiler command (overridable by the environment variable `env`)
    env: str
    suffix: str  # shared library extension
    debian_package: str  # what adds the compiler on Debian/Ubuntu
    libc_package: str  # what adds its C library and headers (without it nothing compiles)
    flags: tuple[str, ...] = ()
    libs: tuple[str, ...] = ("-lm",)

    @property
    def compiler(self) -> str:
        return os.environ.get(self.env) or self.cc

    def available(self) -> bool:
        """The compiler is on PATH (it may still be unable to compile: see problem())."""
        return shutil.which(self.compiler) is not None

    def problem(self) -> str | None:
        """Why this toolchain cannot build here ("... not found", or a test compile's failure),
        None when it can; probed once per process and compiler (see probe())."""
        if not self.available():
            return f"{self.compiler} not found"
        return probe(self)


TOOLCHAINS = (
    Toolchain("linux64", "gcc", "CC", ".so", "gcc", "libc6-dev", flags=("-fPIC",)),
    Toolchain(
        "win64",
        "x86_64-w64-mingw32-gcc",
        "IMPCOSIM_CC_WIN64",
        ".dll",
        "gcc-mingw-w64-x86-64",
        "mingw-w64-x86-64-dev",
        # static libgcc: the DLL then imports only KERNEL32 and msvcrt (the system's C runtime);
        # no PE timestamp, so the same sources give the same bytes; -s drops the debug
        # sections that the static MinGW runtime objects bring (340 KB -> 90 KB).
        flags=("-static-libgcc", "-Wl,--no-insert-timestamp", "-s"),
        libs=(),  # the maths functions are in msvcrt/libmingwex, linked by default
    ),
    Toolchain(
        "aarch64-linux",
        "aarch64-linux-gnu-gcc",
        "IMPCOSIM_CC_AARCH64",
        ".so",
        "gcc-aarch64-linux-gnu",
        "libc6-dev-arm64-cross",  # apt installs it only as a recommendation of the compiler
        flags=("-fPIC",),
    ),
)
BY_PLATFORM = {t.platform: t for t in TOOLCHAINS}
# FMI 3.0 names the same platforms by their tuples (FMI 3.0, section 2.5.1.1).
FMI3_PLATFORMS = {
    "linux64": "x86_64-linux",
    "win64": "x86_64-windows",
    "aarch64-linux": "aarch64-linux",
}
_noted: set[str] = set()
_verdicts: dict[tuple[str, str], str | None] = {}  # (compiler path, platform) -> problem()
# What every native FMU's sources need of a C toolchain: its headers, libm, a shared library.
PROBE_SOURCE = """#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
double impcosim_probe(double x);
double impcosim_probe(double x) { char b[32]; snprintf(b, sizeof b, "%g", x);
    return sqrt(strtod(b, NULL)) + (double)strlen(b) + (double)(malloc(0) == NULL); }
"""
PROBE_TIMEOUT_S = 300.0  # a tiny compile: only a hung compiler reaches this, even under load


def require_platforms() -> bool:
    """IMPCOSIM_REQUIRE_PLATFORMS=1 (CI): a compiler that is there but cannot compile is an
    error instead of a note and a skipped platform."""
    return os.environ.get("IMPCOSIM_REQUIRE_PLATFORMS") == "1"


def probe(toolchain: Toolchain) -> str | None:
    """Compile and link a tiny shared library with the toolchain's flags; None when that works,
    else the reason in one line. Cached per process, per compiler and platform."""
    key = (shutil.which(toolchain.compiler) or toolchain.compiler, toolchain.platform)
    if key not in _verdicts:
        _verdicts[key] = _probe(toolchain)
    return _verdicts[key]


def _probe(toolchain: Toolchain) -> str | None:
    with tempfile.TemporaryDirectory(prefix="impcosim_probe_") as tmp:
        (Path(tmp) / "probe.c").write_text(PROBE_SOURCE)
        out = Path(tmp) / f"probe{toolchain.suffix}"
        try:
            compile_library(toolchain, Path(tmp), ["probe.c"], out, timeout=PROBE_TIMEOUT_S)
        except CompileError as exc:
            lines = [x.strip() for x in str(exc).splitlines()[1:] if x.strip()]
            errors = [x for x in lines if "error" in x.lower()] or lines
            detail = f" ({errors[0][:200]})" if errors else ""
            return f"{toolchain.compiler} cannot compile a test program{detail}"
        if not out.is_file() or out.stat().st_size == 0:
            return f"{toolchain.compiler} cannot compile a test program: it wrote no library"
    return None


def note_missing(toolchain: Toolchain, problem: str | None = None) -> None:
    """Say once per process that a compiler is absent or broken (problem) and which Debian
    packages add it."""
    if toolchain.platform in _noted:
        return
    _noted.add(toolchain.platform)
    problem = problem or f"{toolchain.compiler} not found"
    print(
        f"note: {problem}: the native FMUs get no binaries/{toolchain.platform} (on"
        f" Debian/Ubuntu: apt-get install {packages(toolchain)})",
        file=sys.stderr,
    )


def packages(toolchain: Toolchain) -> str:
    """The Debian packages to install: the compiler's, and its C library's when the compiler is
    there but cannot compile (e.g. gcc-aarch64-linux-gnu without libc6-dev-arm64-cross)."""
    if toolchain.available():
        return f"{toolchain.debian_package} {toolchain.libc_package}"
    return toolchain.debian_package


def broken_error(toolchain: Toolchain, problem: str) -> CompileError:
    """The error for a toolchain that cannot build and may not be skipped (linux64 always; the
    others with IMPCOSIM_REQUIRE_PLATFORMS=1)."""
    why = "" if toolchain.platform == "linux64" else "; IMPCOSIM_REQUIRE_PLATFORMS=1 is set"
    return CompileError(
        f"{problem}: cannot build binaries/{toolchain.platform} (on Debian/Ubuntu: apt-get"
        f" install {packages(toolchain)}{why})"
    )


def compile_library(
    toolchain: Toolchain,
    src: Path,
    c_files: list[str],
    out: Path,
    extra: tuple[str, ...] = (),
    timeout: float | None = None,
) -> None:
    """Compile the C files in folder src into the shared library out (run inside src, on
    relative names, so the build folder's path never reaches the binary: MinGW's linker, for
    one, derives the DLL's image base from the output path)."""
    cmd = [toolchain.compiler, *CFLAGS, *toolchain.flags, *extra, "-shared", "-I.", *c_files,
           *toolchain.libs, "-o", os.path.relpath(out, src)]  # fmt: skip
    try:
        done = subprocess.run(cmd, cwd=src, capture_output=True, text=True, timeout=timeout)
    except FileNotFoundError:
        raise CompileError(f"C compiler {toolchain.compiler!r} not found") from None
    except PermissionError:
        raise CompileError(f"C compiler {toolchain.compiler!r} cannot be run") from None
    except subprocess.TimeoutExpired:
        raise CompileError(f"{toolchain.compiler} did not finish in {timeout:g} s") from None
    if done.returncode != 0:
        raise CompileError(
            f"compiling {out.name} for {toolchain.platform} with {toolchain.compiler} failed "
            f"(exit status {done.returncode}):\n{done.stderr.strip()}"
        )


def build_binaries(
    src: Path, model_identifier: str, c_files: list[str], fmi_version: int = 2
) -> dict[str, bytes]:
    """Build the library for every platform whose compiler is present; returns
    {"binaries/<platform>/<id><suffix>": bytes} (FMI 3.0 platform tuples for fmi_version 3).
    linux64 is required; another platform whose compiler is absent, or there but unable to
    compile (probe()), is noted and skipped (a broken one is an error with require_platforms())."""
    binaries = {}
    for toolchain in TOOLCHAINS:
        problem = toolchain.problem()
        if problem is not None:
            if toolchain.platform == "linux64" or (toolchain.available() and require_platforms()):
                raise broken_error(toolchain, problem)
            note_missing(toolchain, problem)
            continue
        folder = FMI3_PLATFORMS[toolchain.platform] if fmi_version == 3 else toolchain.platform
        name = f"binaries/{folder}/{model_identifier}{toolchain.suffix}"
        lib = Path(src).parent / name  # a DLL records its own file name: keep the final one
        lib.parent.mkdir(parents=True, exist_ok=True)
        build_library(toolchain, src, c_files, lib, name)
        binaries[name] = lib.read_bytes()
    return binaries


def build_library(
    toolchain: Toolchain, src: Path, c_files: list[str], lib: Path, name: str
) -> None:
    """compile_library through the build cache (build_cache.py, when IMPCOSIM_BUILD_CACHE is
    set); name is the library's place in its archive, part of the cache key."""
    key = [name, build_cache.compiler_identity(toolchain.compiler), *CFLAGS, *toolchain.flags,
           *toolchain.libs]  # fmt: skip
    build = partial(compile_library, toolchain, src, c_files, lib)
    build_cache.cached_build(key, Path(src), c_files, lib, build)
