"""`impedance-cosim fmus`: lists the FMUs this installation runs, copies them with --copy-to
(never overwriting a differing file without --force), and answers bad input in one line with
exit status 2. The build-folder check the wheel's build runs (packaging/wheel_fmus.py)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from impedance_cosim.apps import fmus_cmd
from impedance_cosim.cli import main
from impedance_cosim.packaging.wheel_fmus import NotBuiltError, archive_files, check_built

FILES = {
    "PaperScenario.ssp": b"ssp",
    "PaperScenario-native.ssp": b"ssp native",
    "PumaPlant.fmu": b"plant",
    "native/PumaPlant.fmu": b"native plant",
    "fmi3/PumaPlant.fmu": b"fmi3 plant",
    "robot/puma3.urdf": b"<robot/>",
}


@pytest.fixture
def fmus(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A build folder with a few small stand-in files, as the one the command uses."""
    folder = tmp_path / "fmus"
    for name, data in FILES.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_bytes(data)
    (folder / "README.md").write_text("not an archive")
    (folder / ".impcosim-build-x").mkdir()
    (folder / ".impcosim-build-x" / "half.fmu").write_bytes(b"staging")
    monkeypatch.setattr(fmus_cmd, "FMUS_DIR", folder)
    return folder


def test_archive_files_are_the_archives_and_robot_files(fmus: Path) -> None:
    assert archive_files(fmus) == sorted(FILES)


def test_lists_them_with_sizes(fmus: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["fmus"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[:-1] == [f"{len(d):>12,d}  {n}" for n, d in sorted(FILES.items())]
    assert lines[-1] == f"{len(FILES)} files in {fmus}"


def test_copies_them_byte_for_byte(fmus: Path, tmp_path: Path, capsys) -> None:
    dest = tmp_path / "x" / "y"
    assert main(["fmus", "--copy-to", str(dest)]) == 0
    assert {n: (dest / n).read_bytes() for n in archive_files(dest)} == FILES
    out = capsys.readouterr().out.splitlines()
    assert out[-1] == f"{len(FILES)} file(s) copied from {fmus} into {dest}"
    assert sorted(out[:-1]) == sorted(f"copied {dest / n}" for n in FILES)
    # again: the same bytes are there, nothing is copied
    assert main(["fmus", "--copy-to", str(dest)]) == 0
    assert capsys.readouterr().out.splitlines()[-1].startswith("0 file(s) copied")


def test_a_differing_file_is_kept_unless_force(fmus: Path, tmp_path: Path, capsys) -> None:
    dest = tmp_path / "x"
    (dest / "native").mkdir(parents=True)
    (dest / "native" / "PumaPlant.fmu").write_bytes(b"mine")
    assert main(["fmus", "--copy-to", str(dest)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "native/PumaPlant.fmu" in err and "--force" in err
    assert archive_files(dest) == ["native/PumaPlant.fmu"]  # nothing copied
    assert (dest / "native" / "PumaPlant.fmu").read_bytes() == b"mine"
    assert main(["fmus", "--copy-to", str(dest), "--force"]) == 0
    assert "(overwritten)" in capsys.readouterr().out
    assert {n: (dest / n).read_bytes() for n in archive_files(dest)} == FILES


def _bad(argv: list[str], capsys) -> str:
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1, captured
    assert "Traceback" not in captured.err
    return captured.err


def test_bad_input_is_one_line_and_exit_2(fmus: Path, tmp_path: Path, capsys, monkeypatch):
    afile = tmp_path / "afile"
    afile.write_text("")
    assert "is not a folder" in _bad(["fmus", "--copy-to", str(afile)], capsys)
    (tmp_path / "d" / "PumaPlant.fmu").mkdir(parents=True)
    assert "is not a file" in _bad(["fmus", "--copy-to", str(tmp_path / "d")], capsys)
    assert "--force goes with --copy-to" in _bad(["fmus", "--force"], capsys)
    with pytest.raises(SystemExit) as exc:  # argparse: one line too
        main(["fmus", "--nosuch"])
    assert exc.value.code == 2 and capsys.readouterr().err.count("\n") == 1
    monkeypatch.setattr(fmus_cmd, "FMUS_DIR", tmp_path / "none")
    assert "no FMUs in" in _bad(["fmus"], capsys)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only folder")
def test_an_unwritable_folder_is_one_line(fmus: Path, tmp_path: Path, capsys) -> None:
    dest = tmp_path / "ro"
    dest.mkdir()
    dest.chmod(0o500)
    try:
        assert "Permission denied" in _bad(["fmus", "--copy-to", str(dest)], capsys)
    finally:
        dest.chmod(0o700)


def test_the_wheel_needs_a_complete_current_build(fmus: Path, tmp_path: Path) -> None:
    repo = tmp_path / "repo"
    (repo / "native").mkdir(parents=True)
    source = repo / "native" / "model.c"
    source.write_text("")
    for name in FILES:
        os.utime(fmus / name, (1000, 1000))
    os.utime(source, (999, 999))
    assert check_built(fmus, repo) == sorted(FILES)
    os.utime(source, (1001, 1001))  # newer than the build
    with pytest.raises(NotBuiltError, match="is older than .*model.c: run `impedance-cosim b"):
        check_built(fmus, repo)
    (fmus / "native" / "PumaPlant.fmu").unlink()
    with pytest.raises(NotBuiltError, match="not a complete build .*native/PumaPlant.fmu"):
        check_built(fmus, repo)
