"""A build on a machine with an optional tool broken, and a build that fails (issue 20): a cross
compiler that is on PATH but cannot compile (gcc-aarch64-linux-gnu without libc6-dev-arm64-cross)
is one note naming the Debian packages and its platform is skipped, so the first command still
works; IMPCOSIM_REQUIRE_PLATFORMS=1 makes it an error. A failed build leaves its output folder as
it was (no half-built fmus/). The broken compiler is a script on PATH that fails, as gcc does
without its C library."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from impedance_cosim.packaging import build_fmi3, toolchains
from impedance_cosim.packaging.build import FMUS, build_native_fmu
from impedance_cosim.packaging.build_all import STAGE_PREFIX, build_all

pytestmark = pytest.mark.skipif(
    toolchains.BY_PLATFORM["linux64"].problem() is not None, reason="needs a working gcc"
)
CLI = [sys.executable, "-m", "impedance_cosim.cli"]
CROSS = "aarch64-linux-gnu-gcc"  # the name build looks for on PATH (toolchains.TOOLCHAINS)
FAKE = """#!/bin/sh
echo "$*" >> {log}
echo "probe.c:1:10: fatal error: math.h: No such file or directory" >&2
echo "compilation terminated." >&2
exit 1
"""


def broken_cross_compiler(tmp_path: Path) -> tuple[dict[str, str], Path]:
    """An environment whose PATH starts with a failing aarch64-linux-gnu-gcc; the file that
    logs each call of it."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    log = tmp_path / "calls.log"
    fake = bin_dir / CROSS
    fake.write_text(FAKE.format(log=log))
    fake.chmod(0o755)
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}"}
    env.pop("IMPCOSIM_CC_AARCH64", None)
    env.pop("IMPCOSIM_REQUIRE_PLATFORMS", None)
    return env, log


def platforms(fmu: Path) -> set[str]:
    with zipfile.ZipFile(fmu) as z:
        return {n.split("/")[1] for n in z.namelist() if n.startswith("binaries/")}


def archives(folder: Path) -> list[str]:
    """Every file under folder, relative (the staging folder's files included)."""
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


def test_a_broken_cross_compiler_is_one_note_and_its_platform_skipped(
    tmp_path, monkeypatch, capsys
):
    """Probed once per process (one call for two FMUs), one note naming both packages, the
    FMUs built with every other platform."""
    env, log = broken_cross_compiler(tmp_path)
    for name in ("PATH", "IMPCOSIM_CC_AARCH64", "IMPCOSIM_REQUIRE_PLATFORMS"):
        monkeypatch.delenv(name, raising=False)
        if name in env:
            monkeypatch.setenv(name, env[name])
    monkeypatch.setattr(toolchains, "_noted", set())
    monkeypatch.setattr(toolchains, "_verdicts", {})
    plant = build_native_fmu(FMUS["plant"], tmp_path / "out")
    controller = build_native_fmu(FMUS["controller"], tmp_path / "out")
    err = capsys.readouterr().err
    notes = [line for line in err.splitlines() if CROSS in line]
    assert len(notes) == 1, err
    assert notes[0].startswith(f"note: {CROSS} cannot compile a test program")
    assert "math.h: No such file or directory" in notes[0]
    assert "no binaries/aarch64-linux" in notes[0]
    assert "apt-get install gcc-aarch64-linux-gnu libc6-dev-arm64-cross" in notes[0]
    assert len(log.read_text().splitlines()) == 1  # the probe, once, never the FMUs' compile
    for fmu in (plant, controller):
        assert "linux64" in platforms(fmu) and "aarch64-linux" not in platforms(fmu)


@pytest.mark.slow
def test_the_first_command_runs_with_a_broken_cross_compiler(tmp_path, monkeypatch, capsys):
    """`impedance-cosim run` on a fresh checkout (nothing built yet) builds and runs: exit 0."""
    from impedance_cosim.apps import run
    from impedance_cosim.cli import main

    env, _ = broken_cross_compiler(tmp_path)
    monkeypatch.setenv("PATH", env["PATH"])
    for name in ("IMPCOSIM_CC_AARCH64", "IMPCOSIM_REQUIRE_PLATFORMS"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(toolchains, "_noted", set())
    monkeypatch.setattr(toolchains, "_verdicts", {})
    ssp = tmp_path / "fmus" / "PaperScenario.ssp"
    monkeypatch.setattr(run, "DEFAULT_SSP", ssp)  # the checkout's fmus/, here a new folder
    out = tmp_path / "results"
    args = ["run", "--stop", "0.1", "--out", str(out), "--no-figures", "--no-report"]
    assert main([*args, "--no-progress"]) == 0, capsys.readouterr().err
    err = capsys.readouterr().err
    assert f"note: {CROSS} cannot compile a test program" in err
    assert "libc6-dev-arm64-cross" in err and "Traceback" not in err
    assert ssp.is_file() and (out / "observer.csv").is_file()
    assert "aarch64-linux" not in platforms(tmp_path / "fmus" / "native" / "PumaPlant.fmu")


@pytest.mark.slow
def test_require_platforms_makes_a_broken_compiler_one_error_and_nothing_built(tmp_path):
    """With IMPCOSIM_REQUIRE_PLATFORMS=1 (CI) the same compiler is one error line, exit 1, and
    the output folder holds no FMU or archive (nothing half-built). Without it, exit 0."""
    env, _ = broken_cross_compiler(tmp_path)
    out = tmp_path / "fmus"
    done = subprocess.run([*CLI, "build", "--out", str(out)], env={**env,
                          "IMPCOSIM_REQUIRE_PLATFORMS": "1"}, capture_output=True, text=True,
                          timeout=600)  # fmt: skip
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 1 and len(lines) == 1, done.stderr
    assert lines[0].startswith(f"impedance-cosim build: error: {CROSS} cannot compile")
    assert "apt-get install gcc-aarch64-linux-gnu libc6-dev-arm64-cross" in lines[0]
    assert "IMPCOSIM_REQUIRE_PLATFORMS=1" in lines[0]
    assert archives(out) == []  # not the Python FMUs built before the native ones, nor a stage
    done = subprocess.run([*CLI, "build", "--out", str(out)], env=env, capture_output=True,
                          text=True, timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr
    mentions = [line for line in done.stderr.splitlines() if CROSS in line]
    assert len(mentions) == 1 and mentions[0].startswith("note:"), done.stderr
    assert (out / "fmi3" / "PumaPlant.fmu").is_file() and (out / "PaperScenario.ssp").is_file()
    assert not any(p.name.startswith(STAGE_PREFIX) for p in out.iterdir())


@pytest.mark.parametrize("earlier", [False, True], ids=["new folder", "earlier build there"])
@pytest.mark.slow
def test_a_failed_build_leaves_the_folder_as_it_was(tmp_path, monkeypatch, earlier):
    """A failure late in the build (the FMI 3.0 system archive, after its FMUs were written)
    leaves what the folder held before, byte for byte, and no new folder or staging files."""
    out = tmp_path / "fmus"
    before: dict[str, bytes] = {}
    if earlier:
        (out / "fmi3").mkdir(parents=True)
        before = {"PumaPlant.fmu": b"an earlier build", "fmi3/notes.txt": b"kept"}
        for name, data in before.items():
            (out / name).write_bytes(data)

    def fail(*args, **kwargs):
        raise OSError(28, "No space left on device (injected)")

    monkeypatch.setattr(build_fmi3, "build_ssp", fail)
    with pytest.raises(OSError, match="injected"):
        build_all(out)
    if not earlier:
        assert not out.exists()
        return
    assert archives(out) == sorted(before)
    assert {name: (out / name).read_bytes() for name in before} == before


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.slow
def test_a_signal_during_a_build_leaves_it_whole_or_not_there(tmp_path, signum):
    """The signal is sent once the build has written its first FMU (into its staging folder);
    wherever it lands, the folder ends whole (exit 0, every archive) or as it was (exit
    128 + signal, no archive and no staging folder), never in between."""
    out = tmp_path / "fmus"
    proc = subprocess.Popen([*CLI, "build", "--out", str(out)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        deadline = time.monotonic() + 300
        while proc.poll() is None and time.monotonic() < deadline:
            if any(out.rglob("*.fmu")):  # in the staging folder (or, unstaged, in place)
                break
            time.sleep(0.05)
        proc.send_signal(signum)
        status = proc.wait(timeout=300)
    finally:
        proc.kill()
    err = proc.stderr.read()
    assert "Traceback" not in err, err
    if status == 0:  # it had finished: whole
        assert (out / "PaperScenario.ssp").is_file() and (out / "fmi3" / "PumaPlant.fmu").is_file()
        assert not any(p.name.startswith(STAGE_PREFIX) for p in out.iterdir())
    else:
        assert status == 128 + signum, err
        assert err.strip().splitlines()[-1].startswith("impedance-cosim build: interrupted"), err
        assert not out.exists() or archives(out) == []
    print(f"exit status {status}")
