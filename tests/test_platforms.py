"""Every platform in the native FMUs, tested by running it: the C host (tests/c_host/host.c, no
Python in the process) cross-compiled for win64 and run under wine, and for aarch64 Linux and run
under qemu-aarch64, runs the 20 s closed loop (controller + plant) from each FMU archive's own
binaries/<platform>/ libraries and must agree with the linux64 run.

Where a cross compiler or emulator is absent the tests skip and say which Debian package adds it;
with IMPCOSIM_REQUIRE_PLATFORMS=1 (set by .ci/run) they fail instead."""

from __future__ import annotations

import os
import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from impedance_cosim.cosim.system.paper import CONNECTIONS
from impedance_cosim.packaging import toolchains
from impedance_cosim.packaging.build import FMUS, build_native_fmu

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

REQUIRE = os.environ.get("IMPCOSIM_REQUIRE_PLATFORMS") == "1"
HOST = Path(__file__).parent / "c_host" / "host.c"
HOST3 = Path(__file__).parent / "c_host" / "host3.c"
PLANT, CONTROLLER = "PumaPlant.fmu", "ImpedanceController.fmu"
STEPS = 8000  # 20 s at 400 Hz
# Worst difference to the linux64 run, relative to each signal's range (measured 2026-12-01):
# win64 under wine 3.5e-13 (MinGW/msvcrt's sin, cos, atan2, log, pow give other bits than glibc's
# for some inputs: bit-identity is out of reach; the bound leaves ~300x margin); aarch64 under qemu
# bit-identical (glibc gives the same bits there for sin, cos, atan2, log, pow; only hypot
# differs, used in an error message only).
TOLERANCE = {"win64": 1e-10, "aarch64-linux": 0.0}
RECORD = [("plant", n) for n in ("x", "y", "contact_force", "q1", "q2", "q3")] + [
    ("controller", f"tau{i}") for i in (1, 2, 3)
]
ELF_MACHINE = {"linux64": 62, "aarch64-linux": 183}  # EM_X86_64, EM_AARCH64


def need(ok: bool, reason: str) -> None:
    """Skip (locally) or fail (in CI, IMPCOSIM_REQUIRE_PLATFORMS=1) when a tool is absent."""
    if not ok:
        (pytest.fail if REQUIRE else pytest.skip)(reason)


def need_compiler(platform: str) -> toolchains.Toolchain:
    """The platform's toolchain; skip (or fail in CI) when it is absent or cannot compile."""
    toolchain = toolchains.BY_PLATFORM[platform]
    problem = toolchain.problem()
    need(problem is None, f"{problem} (apt-get install {toolchains.packages(toolchain)})")
    return toolchain


def wine_launcher() -> str | None:
    """Debian's wine64 puts its launcher in /usr/lib/wine, not on PATH."""
    for candidate in ("wine64", "/usr/lib/wine/wine64", "wine"):
        found = shutil.which(candidate)
        if found:
            return found
    return None


@pytest.fixture(scope="module")
def wine(tmp_path_factory):
    """A command prefix running a Windows program under wine, in a prefix of this session."""
    launcher = wine_launcher()
    need(launcher is not None, "wine64 not found (apt-get install wine64)")
    env = {**os.environ, "WINEPREFIX": str(tmp_path_factory.mktemp("wineprefix")),
           "WINEDEBUG": "-all", "WINEDLLOVERRIDES": "mscoree,mshtml="}  # fmt: skip
    yield [launcher], env
    server = shutil.which("wineserver") or "/usr/lib/wine/wineserver64"
    if Path(server).exists() or shutil.which(server):
        subprocess.run([server, "-k"], env=env, capture_output=True, timeout=60)


def run_command(platform: str, request) -> tuple[list[str], dict | None]:
    """How to run a program built for platform on this machine."""
    if platform == "linux64":
        return [], None
    if platform == "win64":
        return request.getfixturevalue("wine")
    qemu = shutil.which("qemu-aarch64")
    need(qemu is not None, "qemu-aarch64 not found (apt-get install qemu-user)")
    sysroot = Path("/usr/aarch64-linux-gnu")
    need(
        (sysroot / "lib" / "libc.so.6").exists(),
        f"no arm64 C library in {sysroot} (apt-get install libc6-dev-arm64-cross)",
    )
    return [qemu, "-L", str(sysroot)], None


def host_path(platform: str, path: Path) -> str:
    """A file name as the host program sees it (wine maps / to drive Z:)."""
    return "Z:" + str(path).replace("/", "\\") if platform == "win64" else str(path)


def build_host(platform: str, out_dir: Path, fmi: int = 2) -> Path:
    """Compile the C host of FMI version fmi (tests/c_host/host.c, host3.c) for platform."""
    toolchain = toolchains.BY_PLATFORM[platform]
    out_dir.mkdir(parents=True, exist_ok=True)
    exe = out_dir / ("host.exe" if platform == "win64" else "host")
    headers = Path(fmpy.__file__).parent / "c-code"
    extra = ["-D__USE_MINGW_ANSI_STDIO=1", "-static-libgcc"] if platform == "win64" else ["-ldl"]
    host = HOST if fmi == 2 else HOST3
    cmd = [toolchain.compiler, "-std=c99", "-O2", "-ffp-contract=off", "-Wall", "-Wextra",
           "-Werror", f"-I{headers}", str(host), *extra, "-o", str(exe)]  # fmt: skip
    subprocess.run(cmd, check=True, capture_output=True, timeout=120)
    return exe


def host_arguments(platform: str, fmi: int, fmu: Path, unzip: Path) -> tuple[list[str], dict]:
    """The FMU extracted into unzip: the host's arguments for it (its library for platform, its
    GUID and, under FMI 2.0, its resources URI) and its value references by name."""
    md = read_model_description(str(fmu))
    with zipfile.ZipFile(fmu) as z:
        z.extractall(unzip)
    toolchain = toolchains.BY_PLATFORM[platform]
    folder = platform if fmi == 2 else toolchains.FMI3_PLATFORMS[platform]
    lib = unzip / "binaries" / folder / f"{md.coSimulation.modelIdentifier}{toolchain.suffix}"
    assert lib.is_file(), f"{fmu.name} has no {lib.relative_to(unzip)}"
    args = [host_path(platform, lib), md.guid]
    if fmi == 2:
        resources = "file:///" + host_path(platform, unzip / "resources").lstrip("/")
        args.append(resources.replace("\\", "/"))
    return args, {v.name: v.valueReference for v in md.modelVariables}


def run_host(platform: str, exe: Path, args: list[str], steps: int, links: str, record: str,
             out: Path, request) -> np.ndarray:  # fmt: skip
    """Run the C host (two FMUs A and B, `steps` steps of 1/400 s, links "A1>B2,...", the
    recorded variables "A3,B4,...") on platform; its rows (time, recorded...)."""
    prefix, env = run_command(platform, request)
    cmd = [*prefix, str(exe), *args, str(steps), "1/400", host_path(platform, out), links, record]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    return np.loadtxt(out, delimiter=",")


def closed_loop(platform: str, fmu_dir: Path, tmp_path: Path, request, fmi: int = 2,
                steps: int = STEPS) -> np.ndarray:  # fmt: skip
    """Run the closed loop (controller + plant) of the FMUs in fmu_dir with the FMU archives'
    libraries for platform in the C host built for platform; the recorded rows (time, RECORD)."""
    exe = build_host(platform, tmp_path, fmi)
    args, vrs = [], {}
    for key, fmu in (("controller", CONTROLLER), ("plant", PLANT)):  # A, B
        one, vrs[key] = host_arguments(platform, fmi, fmu_dir / fmu, tmp_path / key)
        args += one
    letter = {"controller": "A", "plant": "B"}
    links = ",".join(
        f"{letter[se]}{vrs[se][sc]}>{letter[ee]}{vrs[ee][ec]}" for se, sc, ee, ec in CONNECTIONS
    )
    record = ",".join(f"{letter[k]}{vrs[k][n]}" for k, n in RECORD)
    return run_host(platform, exe, args, steps, links, record, tmp_path / f"{platform}.csv",
                    request)  # fmt: skip


@pytest.fixture(scope="module")
def linux64_run(native_dir, tmp_path_factory, request) -> np.ndarray:
    return closed_loop("linux64", native_dir, tmp_path_factory.mktemp("linux64"), request)


@pytest.mark.parametrize("platform", ["win64", "aarch64-linux"])
@pytest.mark.slow
def test_closed_loop_agrees_with_linux64(platform, native_dir, tmp_path, linux64_run, request):
    """The paper's 20 s closed loop on the platform's own binaries agrees with linux64."""
    need_compiler(platform)
    rows = closed_loop(platform, native_dir, tmp_path, request)
    assert rows.shape == linux64_run.shape == (STEPS + 1, 1 + len(RECORD))
    assert np.array_equal(rows[:, 0], linux64_run[:, 0])  # the same time grid
    assert linux64_run[:, 3].max() > 1.0  # the arm did touch the wall (contact force > 1 N)
    scale = np.abs(linux64_run).max(axis=0) + 1e-300
    worst = float((np.abs(rows - linux64_run) / scale).max())
    print(f"{platform}: worst difference to linux64 relative to range: {worst:.3g}")
    assert worst <= TOLERANCE[platform], worst


def _machine(name: str, data: bytes) -> int:
    """The machine field of an ELF or PE (DLL) file."""
    if name.endswith(".dll"):
        assert data[:2] == b"MZ"
        pe = int.from_bytes(data[0x3C:0x40], "little")
        assert data[pe : pe + 4] == b"PE\0\0"
        return int.from_bytes(data[pe + 4 : pe + 6], "little")
    assert data[:4] == b"\x7fELF" and data[4] == 2  # 64-bit
    return int.from_bytes(data[18:20], "little")


@pytest.mark.parametrize("name", [PLANT, CONTROLLER])
@pytest.mark.tools
def test_each_native_fmu_carries_every_platform(native_dir, name):
    """binaries/linux64, win64 and aarch64-linux, each for the right machine, and still valid."""
    need_compiler("win64")
    need_compiler("aarch64-linux")
    identifier = name[:-4]
    with zipfile.ZipFile(native_dir / name) as z:
        libs = {n: z.read(n) for n in z.namelist() if n.startswith("binaries/")}
    assert sorted(libs) == [
        f"binaries/aarch64-linux/{identifier}.so",
        f"binaries/linux64/{identifier}.so",
        f"binaries/win64/{identifier}.dll",
    ]
    for path, data in libs.items():
        platform = path.split("/")[1]
        expected = 0x8664 if platform == "win64" else ELF_MACHINE[platform]  # AMD64
        assert _machine(path, data) == expected, path
    assert validate_fmu(str(native_dir / name)) == []
    assert set(fmpy.supported_platforms(str(native_dir / name))) >= {"linux64", "win64"}


@pytest.mark.parametrize("name", [PLANT, CONTROLLER])
@pytest.mark.tools
def test_win64_dll_imports_only_the_system_c_runtime(native_dir, tmp_path, name):
    need_compiler("win64")
    objdump = shutil.which("x86_64-w64-mingw32-objdump")
    need(objdump is not None, "x86_64-w64-mingw32-objdump not found (binutils-mingw-w64-x86-64)")
    dll = tmp_path / "x.dll"
    with zipfile.ZipFile(native_dir / name) as z:
        dll.write_bytes(z.read(f"binaries/win64/{name[:-4]}.dll"))
    dump = subprocess.run([objdump, "-p", str(dll)], capture_output=True, text=True).stdout
    imports = {
        line.split(":")[1].strip().lower() for line in dump.splitlines() if "DLL Name:" in line
    }
    assert imports == {"kernel32.dll", "msvcrt.dll"}
    assert "fmi2DoStep" in dump and "fmi2Instantiate" in dump  # exported
    data = dll.read_bytes()
    pe = int.from_bytes(data[0x3C:0x40], "little")
    assert data[pe + 8 : pe + 12] == bytes(4)  # TimeDateStamp 0: no build time in the DLL


@pytest.mark.parametrize("platform", ["win64", "aarch64-linux"])
@pytest.mark.slow
def test_sources_compile_without_warnings(platform, native_dir, tmp_path):
    """The FMUs' own sources/ compile with -Werror for the platform (same flags as linux64)."""
    toolchain = need_compiler(platform)
    for name in (PLANT, CONTROLLER):
        with zipfile.ZipFile(native_dir / name) as z:
            z.extractall(tmp_path / name)
        src = tmp_path / name / "sources"
        c_files = sorted(p.name for p in src.glob("*.c"))
        out = tmp_path / name / f"x{toolchain.suffix}"
        toolchains.compile_library(toolchain, src, c_files, out, extra=("-Werror",))
        assert out.stat().st_size > 0


def test_missing_cross_compilers_are_a_note_not_a_failure(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("IMPCOSIM_CC_WIN64", "no-such-mingw-gcc")
    monkeypatch.setenv("IMPCOSIM_CC_AARCH64", "no-such-aarch64-gcc")
    monkeypatch.setattr(toolchains, "_noted", set())
    plant = build_native_fmu(FMUS["plant"], tmp_path)
    controller = build_native_fmu(FMUS["controller"], tmp_path)
    err = capsys.readouterr().err
    assert err.count("no-such-mingw-gcc not found") == 1  # one note, not one per FMU
    assert err.count("no-such-aarch64-gcc not found") == 1
    assert "apt-get install gcc-mingw-w64-x86-64" in err
    assert "apt-get install gcc-aarch64-linux-gnu" in err
    for fmu in (plant, controller):
        with zipfile.ZipFile(fmu) as z:
            binaries = [n for n in z.namelist() if n.startswith("binaries/")]
        assert binaries == [f"binaries/linux64/{fmu.stem}.so"]


@pytest.mark.tools
def test_a_compiler_that_fails_on_our_sources_fails_the_build(tmp_path, monkeypatch):
    """A compiler that passes the probe but fails on the FMU's sources is an error naming the
    platform, not a silent gap (the probe's tiny compile works, ours does not)."""
    real = need_compiler("aarch64-linux").compiler
    fake = tmp_path / "bin" / "aarch64-gcc-fails-on-fmus"
    fake.parent.mkdir()
    fake.write_text(f'#!/bin/sh\ncase "$*" in *probe.c*) exec {real} "$@";; esac\nexit 1\n')
    fake.chmod(0o755)
    monkeypatch.setenv("IMPCOSIM_CC_AARCH64", str(fake))
    with pytest.raises(
        toolchains.CompileError, match="PumaPlant.so for aarch64-linux with .*fails-on-fmus"
    ):
        build_native_fmu(FMUS["plant"], tmp_path)
    assert not (tmp_path / PLANT).exists()


@pytest.mark.slow
def test_same_sources_give_byte_identical_binaries(tmp_path, monkeypatch):
    """Two builds in different folders give the same archive bytes, every platform's library
    included (no temp path, no time stamp in any of them); both compiled, not cached."""
    monkeypatch.delenv("IMPCOSIM_BUILD_CACHE", raising=False)
    first = build_native_fmu(FMUS["plant"], tmp_path / "a").read_bytes()
    second = build_native_fmu(FMUS["plant"], tmp_path / "b").read_bytes()
    assert first == second
