"""The distribution bundle, and reproducible builds: the same sources give the same bytes."""

from __future__ import annotations

import hashlib
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from impedance_cosim.cli import main
from impedance_cosim.packaging.build import FMUS, REPO, build_fmu, build_ssp
from impedance_cosim.packaging.dist import (
    DATE,
    NAME,
    build_dist,
    bundle,
    expected_members,
    robot_members,
)

ARCHIVES = ("*.fmu", "*.ssp", "native/*.fmu", "fmi3/*.fmu", "fmi3/arrays/*.fmu")


@pytest.fixture(scope="module")
def two_builds(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The bundle built twice from scratch, in two temporary folders: once in this process
    with every library compiled (the build cache off), once through the command line in a
    fresh process (its libraries from the cache: compiled by an earlier build)."""
    a = tmp_path_factory.mktemp("build_a")
    b = tmp_path_factory.mktemp("build_b")
    with pytest.MonkeyPatch.context() as mp:
        mp.delenv("IMPCOSIM_BUILD_CACHE", raising=False)
        build_dist(a / "dist", a / "fmus")
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "impedance_cosim.cli",
            "dist",
            "--out",
            str(b / "dist"),
            "--fmus",
            str(b / "fmus"),
        ],  # fmt: skip
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    building, *progress, bundling, wrote, measured = done.stdout.strip().splitlines()
    assert building == f"building every FMU and archive into {b / 'fmus'} ..."
    # one line per file as it is built: seconds since the start, its name
    built = [re.fullmatch(r" +[\d.]+ s  built (\S+)", line) for line in progress]
    assert all(built), progress
    names = {m.group(1) for m in built}
    assert {"PumaPlant.fmu", "native/PumaPlant.fmu", "PaperScenario.ssp"} <= names, names
    assert bundling.startswith("bundling ") and bundling.endswith(f" files into {b / 'dist'} ...")
    assert wrote == f"wrote {b / 'dist' / (NAME + '.zip')}"
    # its size and the build's time as measured (printed, not asserted: they vary)
    assert re.fullmatch(rf"{NAME}\.zip: [\d.]+ MB \(\d+ bytes\), \d+ files; built and bundled"
                        r" in [\d.]+ s", measured), measured  # fmt: skip
    return a, b


def archives(folder: Path) -> dict[str, bytes]:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for pattern in ARCHIVES
        for p in folder.glob(pattern)
    }


@pytest.mark.slow
def test_building_twice_gives_identical_bytes(two_builds, fmu_dir: Path, native_dir: Path):
    a, b = two_builds
    first, second = archives(a / "fmus"), archives(b / "fmus")
    assert sorted(first) == sorted(expected_members())
    for name in first:
        assert first[name] == second[name], f"{name} differs between two builds"
    assert (a / "dist" / f"{NAME}.zip").read_bytes() == (b / "dist" / f"{NAME}.zip").read_bytes()
    # the test session's own build (another folder, earlier) gives the same archives too
    session = archives(fmu_dir)
    assert session and set(session) <= set(first)  # what this session built (a subset)
    for name, data in session.items():
        assert data == first[name], f"{name} differs from the session's build"


@pytest.mark.slow
def test_every_member_has_a_fixed_date_and_mode(two_builds):
    a, _ = two_builds
    zips = [*(a / "fmus").rglob("*.fmu"), *(a / "fmus").glob("*.ssp"), a / "dist" / f"{NAME}.zip"]
    python3 = list((a / "fmus" / "fmi3" / "python").glob("*.fmu"))  # with pythonfmu3 installed
    assert len(zips) == len(expected_members()) + len(python3) + 1
    for path in zips:
        with zipfile.ZipFile(path) as z:
            for info in z.infolist():
                assert info.date_time == DATE, (path.name, info.filename)
                mode = info.external_attr >> 16
                assert mode in (0o644, 0o755), (path.name, info.filename, oct(mode))
                assert (mode == 0o755) == info.filename.startswith("binaries/"), info.filename


@pytest.mark.slow
def test_bundle_contents(two_builds):
    a, _ = two_builds
    with zipfile.ZipFile(a / "dist" / f"{NAME}.zip") as z:
        names = z.namelist()
        assert names == sorted(names)
        assert all(n.startswith(f"{NAME}/") for n in names)
        files = {n.removeprefix(f"{NAME}/"): z.read(n) for n in names}
    for member in expected_members():
        assert files[f"fmus/{member}"] == (a / "fmus" / member).read_bytes(), member
    for ref in ("PumaPlant_ref.csv", "ImpedanceController_ref.csv", "PaperScenario_ref.csv"):
        source = next(REPO.glob(f"*/{ref}"))
        assert files[f"reference/{ref}"] == source.read_bytes(), ref
    assert files["LICENSE"] == (REPO / "LICENSE").read_bytes()
    readme = files["README.txt"].decode()
    for member in expected_members():
        assert f"fmus/{member}" in readme, member
    assert "BSD-2-Clause" in readme
    # it holds FMI 2.0 and FMI 3.0 FMUs, and says so (it said "as FMI 2.0 FMUs")
    title = readme.splitlines()[0]
    assert title.endswith("as FMI 2.0 and FMI 3.0 FMUs"), title
    assert "as FMI 2.0 FMUs" not in readme and "as FMI 2.0 co-simulation" not in readme
    sums = dict(line.split("  ")[::-1] for line in files["SHA256SUMS"].decode().splitlines())
    assert sorted(sums) == sorted(n for n in files if n != "SHA256SUMS")
    for name, digest in sums.items():
        assert hashlib.sha256(files[name]).hexdigest() == digest, name


@pytest.mark.slow
def test_bundle_ships_the_robot_files(two_builds):
    """The build writes the arm's URDF and MJCF (the plant's parameters), the same bytes twice,
    and the bundle ships them and lists them in its README."""
    from impedance_cosim.packaging.robot_files import mjcf, start_poses, urdf
    from impedance_cosim.physics.description import describe

    a, b = two_builds
    expected = {
        "robot/puma3.xml": mjcf(describe(), start_poses()),
        "robot/puma3.urdf": urdf(describe()),
    }
    assert sorted(robot_members()) == sorted(expected)
    with zipfile.ZipFile(a / "dist" / f"{NAME}.zip") as z:
        readme = z.read(f"{NAME}/README.txt").decode()
        for member, text in expected.items():
            assert (a / "fmus" / member).read_text() == text == (b / "fmus" / member).read_text()
            assert z.read(f"{NAME}/fmus/{member}") == text.encode(), member
            assert f"fmus/{member}" in readme, member


@pytest.mark.slow
def test_incomplete_bundle_refused(tmp_path: Path):
    out = tmp_path / "fmus"
    built = [build_fmu(spec, out) for spec in FMUS.values()] + [build_ssp(out)]  # no native
    with pytest.raises(ValueError, match="missing native/PumaPlant.fmu"):
        bundle(built, out, tmp_path / "dist")
    assert not (tmp_path / "dist" / f"{NAME}.zip").exists()


@pytest.mark.slow
def test_dist_without_a_compiler_says_so(tmp_path: Path, monkeypatch, capsys):
    monkeypatch.setenv("CC", "no-such-compiler-here")
    assert main(["dist", "--out", str(tmp_path / "dist"), "--fmus", str(tmp_path / "fmus")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("impedance-cosim dist: error: the bundle is incomplete, missing")
    assert "C compiler" in err[-1]
    assert not (tmp_path / "dist").exists() or not any((tmp_path / "dist").iterdir())


def test_dist_into_a_file_says_so(tmp_path: Path, capsys):
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("x")
    assert main(["dist", "--out", str(blocker / "dist"), "--fmus", str(tmp_path / "fmus")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("impedance-cosim dist: error: cannot write"), err
    assert "not_a_folder" in err[-1] and "Traceback" not in "".join(err)
