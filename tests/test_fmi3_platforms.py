"""The FMI 3.0 native FMUs on every platform they carry (FMI 3 platform tuples x86_64-linux,
x86_64-windows, aarch64-linux): the C FMI 3 host (tests/c_host/host3.c), cross-compiled and run
under wine / qemu-aarch64 on the FMU archives' own libraries, runs 4 s of the paper's closed loop
(through the first wall contact) and agrees with the x86_64-linux run within the FMI 2.0
platforms' bounds (tests/test_platforms.py, whose tool fixtures this reuses)."""

from __future__ import annotations

import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from test_platforms import (  # the same tools and bounds as for FMI 2.0
    RECORD,
    TOLERANCE,
    need_compiler,
    wine,  # noqa: F401  (a fixture run_command asks for)
)
from test_platforms import closed_loop as two_fmu_loop

from impedance_cosim.packaging import toolchains

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

PLANT, CONTROLLER = "PumaPlant.fmu", "ImpedanceController.fmu"
STEPS = 1600  # 4 s at 400 Hz: free motion, then the first contact (~3.85 s)


def closed_loop(platform: str, fmi3_dir: Path, tmp_path: Path, request) -> np.ndarray:
    return two_fmu_loop(platform, fmi3_dir, tmp_path, request, fmi=3, steps=STEPS)


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
