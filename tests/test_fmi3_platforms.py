"""The FMI 3.0 native FMUs on every platform they carry (FMI 3 platform tuples x86_64-linux,
x86_64-windows, aarch64-linux): the C FMI 3 host (tests/c_host/host3.c), cross-compiled and run
under wine / qemu-aarch64 on the FMU archives' own libraries, runs 4 s of the paper's closed loop
(through the first wall contact) and agrees with the x86_64-linux run within the FMI 2.0
platforms' bounds (tests/test_platforms.py, whose tool fixtures this reuses)."""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy import read_model_description
from test_platforms import (  # the same tools and bounds as for FMI 2.0
    TOLERANCE,
    host_path,
    need_compiler,
    run_command,
    wine,  # noqa: F401  (a fixture run_command asks for)
)

from impedance_cosim.cosim.system.paper import CONNECTIONS
from impedance_cosim.packaging import toolchains

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

HOST = Path(__file__).parent / "c_host" / "host3.c"
PLANT, CONTROLLER = "PumaPlant.fmu", "ImpedanceController.fmu"
STEPS = 1600  # 4 s at 400 Hz: free motion, then the first contact (~3.85 s)
RECORD = [("plant", n) for n in ("x", "y", "contact_force", "q1", "q2", "q3")] + [
    ("controller", f"tau{i}") for i in (1, 2, 3)
]


def closed_loop(platform: str, fmi3_dir: Path, tmp_path: Path, request) -> np.ndarray:
    prefix, env = run_command(platform, request)
    tmp_path.mkdir(parents=True, exist_ok=True)
    toolchain = toolchains.BY_PLATFORM[platform]
    exe = tmp_path / ("host3.exe" if platform == "win64" else "host3")
    headers = Path(fmpy.__file__).parent / "c-code"
    extra = ["-D__USE_MINGW_ANSI_STDIO=1", "-static-libgcc"] if platform == "win64" else ["-ldl"]
    subprocess.run([toolchain.compiler, "-std=c99", "-O2", "-ffp-contract=off", "-Wall", "-Wextra",
                    "-Werror", f"-I{headers}", str(HOST), *extra, "-o", str(exe)],
                   check=True, capture_output=True, timeout=120)  # fmt: skip
    args, vrs = [], {}
    folder = toolchains.FMI3_PLATFORMS[platform]
    for key, fmu in (("controller", CONTROLLER), ("plant", PLANT)):  # A, B
        md = read_model_description(str(fmi3_dir / fmu))
        unzip = tmp_path / key
        with zipfile.ZipFile(fmi3_dir / fmu) as z:
            z.extractall(unzip)
        vrs[key] = {v.name: v.valueReference for v in md.modelVariables}
        lib = unzip / "binaries" / folder / f"{md.coSimulation.modelIdentifier}{toolchain.suffix}"
        assert lib.is_file(), f"{fmu} has no {lib.relative_to(unzip)}"
        args += [host_path(platform, lib), md.guid]
    letter = {"controller": "A", "plant": "B"}
    links = ",".join(
        f"{letter[se]}{vrs[se][sc]}>{letter[ee]}{vrs[ee][ec]}" for se, sc, ee, ec in CONNECTIONS
    )
    record = ",".join(f"{letter[k]}{vrs[k][n]}" for k, n in RECORD)
    out = tmp_path / f"{platform}.csv"
    cmd = [*prefix, str(exe), *args, str(STEPS), "1/400", host_path(platform, out), links, record]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    return np.loadtxt(out, delimiter=",")


@pytest.mark.parametrize("platform", ["win64", "aarch64-linux"])
@pytest.mark.slow
def test_fmi3_closed_loop_agrees_with_x86_64_linux(platform, fmi3_dir, tmp_path, request):
    need_compiler(platform)
    reference = closed_loop("linux64", fmi3_dir, tmp_path / "x86_64-linux", request)
    rows = closed_loop(platform, fmi3_dir, tmp_path / platform, request)
    assert rows.shape == reference.shape == (STEPS + 1, 1 + len(RECORD))
    assert reference[:, 3].max() > 1.0  # the arm did touch the wall
    scale = np.abs(reference).max(axis=0) + 1e-300
    worst = float((np.abs(rows - reference) / scale).max())
    print(f"FMI 3.0 {platform}: worst difference to x86_64-linux relative to range: {worst:.3g}")
    assert worst <= TOLERANCE[platform], worst


@pytest.mark.parametrize("platform", ["linux64", "win64", "aarch64-linux"])
@pytest.mark.parametrize("name", [PLANT, CONTROLLER, "ImpedanceControllerClocked.fmu"])
@pytest.mark.slow
def test_fmi3_sources_compile_without_warnings_or_undefined_symbols(
    platform, name, fmi3_dir, tmp_path
):
    """sources/ of each FMI 3.0 FMU, as its buildDescription.xml lists them, with -Werror (and,
    on Linux, --no-undefined: every internal function of the three fmi3_*.c files is there)."""
    import xml.etree.ElementTree as ET

    toolchain = (
        need_compiler(platform) if platform != "linux64" else toolchains.BY_PLATFORM[platform]
    )
    with zipfile.ZipFile(fmi3_dir / name) as z:
        z.extractall(tmp_path)
    src = tmp_path / "sources"
    files = [f.get("name") for f in ET.parse(src / "buildDescription.xml").iter("SourceFile")]
    strict = ("-Werror",) if platform == "win64" else ("-Werror", "-Wl,--no-undefined")
    toolchains.compile_library(toolchain, src, files, tmp_path / f"lib{toolchain.suffix}", strict)
