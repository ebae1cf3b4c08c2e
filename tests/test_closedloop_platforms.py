"""The closed-loop FMUs on every platform they carry: the C hosts of the platform tests
(tests/c_host/host.c, host3.c: no Python in the process), cross-compiled and run under wine and
qemu-aarch64 on the archive's own binaries, run 2 s of the closed loop (an FMU with no inputs:
loaded as both of the host's FMUs, nothing connected) and agree with the x86_64 Linux run within
the platform tests' bounds. Skips without the tools, fails with IMPCOSIM_REQUIRE_PLATFORMS=1."""

from __future__ import annotations

import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from test_platforms import (  # the same tools and bounds as for the two-FMU loop
    TOLERANCE,
    build_host,
    host_arguments,
    need_compiler,
    run_host,
    wine,  # noqa: F401  (a fixture run_command asks for)
)

from impedance_cosim.packaging import toolchains
from impedance_cosim.packaging.closedloop import build_closed_loops, fmu_name

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

STEPS = 800  # 2 s at 400 Hz
RECORD = ("plant.x", "plant.y", "plant.q1", "plant.q2", "plant.q3", "controller.tau1",
          "controller.tau2", "controller.tau3", "controller.xd_hat")  # fmt: skip


@pytest.fixture(scope="module")
def closed_loops(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The closed-loop FMUs, in a folder of their own (other tests count the session's FMUs)."""
    out = tmp_path_factory.mktemp("closedloop")
    build_closed_loops(out)
    return out


def run(platform: str, fmi: int, folder: Path, tmp_path: Path, request) -> np.ndarray:
    """Rows (time, RECORD...) of the observer scenario's closed loop run by the C host (the one
    FMU given as both of the host's FMUs, nothing linked)."""
    exe = build_host(platform, tmp_path, fmi)
    fmu = folder / ("native" if fmi == 2 else "fmi3") / f"{fmu_name('observer')}.fmu"
    one, vrs = host_arguments(platform, fmi, fmu, tmp_path / "fmu")
    record = ",".join(f"A{vrs[n]}" for n in RECORD)
    return run_host(platform, exe, [*one, *one], STEPS, "", record, tmp_path / "rows.csv",
                    request)  # fmt: skip


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("platform", ["win64", "aarch64-linux"])
@pytest.mark.slow
def test_closed_loop_fmu_agrees_with_x86_64_linux(platform, fmi, closed_loops, tmp_path, request):
    need_compiler(platform)
    reference = run("linux64", fmi, closed_loops, tmp_path / "linux64", request)
    rows = run(platform, fmi, closed_loops, tmp_path / platform, request)
    assert rows.shape == reference.shape == (STEPS + 1, 1 + len(RECORD))
    assert np.abs(reference[:, 6]).max() > 1.0  # the controller did drive the arm
    scale = np.abs(reference).max(axis=0) + 1e-300
    worst = float((np.abs(rows - reference) / scale).max())
    print(f"FMI {fmi} {platform}: worst difference to x86_64-linux relative to range: {worst:.3g}")
    assert worst <= TOLERANCE[platform], worst


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("platform", ["linux64", "win64", "aarch64-linux"])
@pytest.mark.slow
def test_closed_loop_sources_compile_without_warnings(platform, fmi, closed_loops, tmp_path):
    """sources/ as buildDescription.xml lists them, with -Werror (on Linux also --no-undefined:
    the two parts' renamed model functions and the closed loop's link into one library)."""
    import xml.etree.ElementTree as ET

    toolchain = (
        need_compiler(platform) if platform != "linux64" else toolchains.BY_PLATFORM[platform]
    )
    fmu = closed_loops / ("native" if fmi == 2 else "fmi3") / f"{fmu_name('observer')}.fmu"
    with zipfile.ZipFile(fmu) as z:
        z.extractall(tmp_path)
    src = tmp_path / "sources"
    files = [f.get("name") for f in ET.parse(src / "buildDescription.xml").iter("SourceFile")]
    strict = ("-Werror",) if platform == "win64" else ("-Werror", "-Wl,--no-undefined")
    toolchains.compile_library(toolchain, src, files, tmp_path / f"lib{toolchain.suffix}", strict)
    assert (tmp_path / f"lib{toolchain.suffix}").is_file()
