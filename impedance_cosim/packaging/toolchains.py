"""The C compilers that build a native FMU's binaries/<platform>/ libraries: linux64 with the
machine's gcc, win64 and aarch64 Linux with Debian's cross compilers when they are installed.

Directory names: FMI 2.0 names only win32/win64/linux32/linux64/darwin32/darwin64. For 64-bit ARM
Linux it has no name, and fmpy 0.3.32 on an aarch64 machine looks for FMI 2 binaries in
`binaries/linux64` (its `platform` is 'linux64' there), where our x86_64 library already sits. We
use FMI 3.0's platform tuple `aarch64-linux` (what the Reference FMUs use for aarch64, in FMI 3),
so a host on ARM Linux loads `binaries/aarch64-linux/<id>.so` by path (e.g. fmpy's
`FMU2Slave(libraryPath=...)`). darwin64 cannot be built here: sources/ + buildDescription.xml let
a Mac tool (or fmpy's compile support) build it.

Builds are deterministic: every compiler runs in the sources folder on relative file names (no
temp path reaches the binary), without debug info, and the PE timestamp is left out."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

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
    flags: tuple[str, ...] = ()
    libs: tuple[str, ...] = ("-lm",)

    @property
    def compiler(self) -> str:
        return os.environ.get(self.env) or self.cc

    def available(self) -> bool:
        return shutil.which(self.compiler) is not None


TOOLCHAINS = (
    Toolchain("linux64", "gcc", "CC", ".so", "gcc", flags=("-fPIC",)),
    Toolchain(
        "win64",
        "x86_64-w64-mingw32-gcc",
        "IMPCOSIM_CC_WIN64",
        ".dll",
        "gcc-mingw-w64-x86-64",
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


def note_missing(toolchain: Toolchain) -> None:
    """Say once per process that a cross compiler is absent and which Debian package adds it."""
    if toolchain.platform in _noted:
        return
    _noted.add(toolchain.platform)
    print(
        f"note: {toolchain.compiler} not found: the native FMUs get no binaries/"
        f"{toolchain.platform} (on Debian/Ubuntu: apt-get install {toolchain.debian_package})",
        file=sys.stderr,
    )


def compile_library(
    toolchain: Toolchain, src: Path, c_files: list[str], out: Path, extra: tuple[str, ...] = ()
) -> None:
    """Compile the C files in folder src into the shared library out (run inside src, on
    relative names, so the build folder's path never reaches the binary: MinGW's linker, for
    one, derives the DLL's image base from the output path)."""
    cmd = [toolchain.compiler, *CFLAGS, *toolchain.flags, *extra, "-shared", "-I.", *c_files,
           *toolchain.libs, "-o", os.path.relpath(out, src)]  # fmt: skip
    try:
        done = subprocess.run(cmd, cwd=src, capture_output=True, text=True)
    except FileNotFoundError:
        raise CompileError(f"C compiler {toolchain.compiler!r} not found") from None
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
    linux64 is required, the others are noted when absent."""
    binaries = {}
    for toolchain in TOOLCHAINS:
        if toolchain.platform != "linux64" and not toolchain.available():
            note_missing(toolchain)
            continue
        folder = FMI3_PLATFORMS[toolchain.platform] if fmi_version == 3 else toolchain.platform
        name = f"binaries/{folder}/{model_identifier}{toolchain.suffix}"
        lib = Path(src).parent / name  # a DLL records its own file name: keep the final one
        lib.parent.mkdir(parents=True, exist_ok=True)
        compile_library(toolchain, src, c_files, lib)
        binaries[name] = lib.read_bytes()
    return binaries
