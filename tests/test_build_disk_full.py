"""FMUs, system archives and the dist bundle on a full disk (issue 20): whole under their final
name or not there, and one error line naming the file and its folder (exit status 1). Two fault
injections: a small tmpfs (needs root and mount; skipped with the reason otherwise) and
RLIMIT_FSIZE in a child process (a write beyond the limit fails with EFBIG; always runs)."""

from __future__ import annotations

import ast
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from impedance_cosim.packaging import archive_out
from impedance_cosim.packaging.build import REPO
from impedance_cosim.packaging.build_all import STAGE_PREFIX
from impedance_cosim.packaging.dist import NAME

CLI = [sys.executable, "-m", "impedance_cosim.cli"]


@pytest.fixture
def full_disk(tmp_path: Path):
    """A 1 MiB tmpfs (the build writes ~5 MB, the bundle ~6 MB): skipped where mount fails."""
    mnt = tmp_path / "full"
    mnt.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mnt)],
                          capture_output=True, text=True, timeout=60)  # fmt: skip
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip() or done.returncode}")
    try:
        yield mnt
    finally:
        if subprocess.run(["umount", str(mnt)], capture_output=True, timeout=60).returncode:
            subprocess.run(["umount", "-l", str(mnt)], capture_output=True, timeout=60)


def leftovers(folder: Path) -> list[str]:
    """Archives, temporary files and staging folders under folder."""
    return sorted(
        p.relative_to(folder).as_posix()
        for p in folder.rglob("*")
        if p.suffix in (".fmu", ".ssp", ".zip", ".tmp") or p.name.startswith(STAGE_PREFIX)
    )


def one_error(done: subprocess.CompletedProcess, command: str) -> str:
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 1, done.stderr
    assert lines and lines[-1].startswith(f"impedance-cosim {command}: error: "), done.stderr
    assert "Traceback" not in done.stderr and sum("error" in x for x in lines) == 1, done.stderr
    return lines[-1]


@pytest.mark.slow
def test_build_onto_a_full_disk_leaves_no_archive(full_disk):
    out = full_disk / "fmus"
    done = subprocess.run([*CLI, "build", "--out", str(out)], capture_output=True, text=True,
                          timeout=900)  # fmt: skip
    line = one_error(done, "build")
    assert "No space left on device" in line and "cannot write " in line
    name, folder = line.split("cannot write ", 1)[1].split(": No space")[0].split(" in ", 1)
    assert name.endswith((".fmu", ".ssp")) and Path(folder).is_relative_to(out), line
    assert STAGE_PREFIX not in line  # the file's final place, not the staging folder
    assert leftovers(full_disk) == []


@pytest.mark.slow
def test_dist_onto_a_full_disk_leaves_no_bundle(full_disk, tmp_path):
    argv = [*CLI, "dist", "--out", str(full_disk / "dist"), "--fmus", str(tmp_path / "fmus")]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=900)
    line = one_error(done, "dist")
    assert f"cannot write {NAME}.zip in {full_disk / 'dist'}: No space left on device" in line
    assert leftovers(full_disk) == []


CHILD = """
import resource, signal, sys
from pathlib import Path
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write beyond the limit fails with EFBIG
from impedance_cosim.packaging.build import build_ssp
limit = resource.getrlimit(resource.RLIMIT_FSIZE)[1]
resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, limit))
try:
    build_ssp(Path(sys.argv[1]), fmu_dir=Path(sys.argv[2]))
except OSError as exc:
    print(type(exc).__name__, exc)
    sys.exit(1)
"""


def test_a_file_size_limit_while_writing_an_archive(fmu_dir, tmp_path):
    """PaperScenario.ssp (~0.5 MB) under a 100 kB limit: the earlier archive stays as it was,
    no temporary file is left, and the error names the archive and its folder."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "PaperScenario.ssp").write_bytes(b"an earlier archive")
    done = subprocess.run([sys.executable, "-c", CHILD, str(out), str(fmu_dir)],
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert done.returncode == 1, done.stdout + done.stderr
    assert done.stdout.strip() == (
        f"ArchiveWriteError cannot write PaperScenario.ssp in {out}: File too large (nothing was"
        " written under that name)"
    )
    assert (out / "PaperScenario.ssp").read_bytes() == b"an earlier archive"
    assert sorted(p.name for p in out.iterdir()) == ["PaperScenario.ssp"]


def test_an_archive_that_fails_its_check_is_not_left(tmp_path):
    target = tmp_path / "x.ssp"

    def refuse(path: Path) -> None:
        assert zipfile.ZipFile(path).namelist() == ["a"]  # complete when checked
        raise ValueError("x.ssp does not validate")

    with pytest.raises(ValueError, match="does not validate"):
        with archive_out.write_zip(target, check=refuse) as z:
            z.writestr("a", b"1")
    assert list(tmp_path.iterdir()) == []


def test_every_archive_the_build_writes_goes_through_write_zip():
    """No zip opened for writing in impedance_cosim/ but in archive_out.write_zip (so every FMU,
    system archive and bundle is written to a temporary file and renamed)."""
    found = []
    for path in sorted((REPO / "impedance_cosim").rglob("*.py")):
        if path.name == "archive_out.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            func = getattr(node, "func", None)
            if isinstance(node, ast.Call) and "ZipFile" in (getattr(func, "attr", None),
                                                            getattr(func, "id", None)):  # fmt: skip
                modes = [a.value for a in node.args[1:2] if isinstance(a, ast.Constant)]
                modes += [k.value.value for k in node.keywords if k.arg == "mode"
                          and isinstance(k.value, ast.Constant)]  # fmt: skip
                if any(m != "r" for m in modes):
                    found.append(f"{path.relative_to(REPO)}:{node.lineno}")
    assert not found, f"zips written outside archive_out.write_zip: {', '.join(found)}"
