"""benchmarks/outputs_equal.py: its comparison helpers on small synthetic files and its argument
errors (a whole two-commit comparison is left to the script itself, docs/development.md)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import benchmark_module

pytestmark = pytest.mark.slow

oe = benchmark_module("outputs_equal")


def write(folder: Path, files: dict[str, str]) -> Path:
    """FOLDER with the given files (relative name: text)."""
    for name, text in files.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)
    return folder


def run_json(started: str, wall: float, out: str, rows: int) -> str:
    """A run.json as `impedance-cosim run` writes it, with the fields that vary."""
    record = {
        "command": ["impedance-cosim", "run", "--out", out],
        "system": {"ssp": f"{out}/x.ssp", "sha256": out * 8},
        "fmus": {"plant": {"model": "PumaPlant", "guid": "{" + out + "}", "sha256": out}},
        "started": started,
        "wall_time_s": wall,
        "runs": [{"status": "ok", "rows": rows, "wall_time_s": wall, "real_time_factor": 1 / wall}],
    }
    return json.dumps(record, indent=2)


def test_equal_files_are_equal(tmp_path: Path) -> None:
    files = {"out.csv": "time,x\n0.0,1.5\n1.0,2.5\n", "sub/a.bin": "\x00\x01"}
    a, b = write(tmp_path / "a", files), write(tmp_path / "b", files)
    assert oe.compare_dirs(a, b) is None


def test_a_differing_csv_names_its_first_differing_line(tmp_path: Path) -> None:
    a = write(tmp_path / "a", {"out.csv": "time,x\n0.0,1.5\n1.0,2.5\n2.0,3.5\n"})
    b = write(tmp_path / "b", {"out.csv": "time,x\n0.0,1.5\n1.0,2.5000000000000004\n2.0,3.6\n"})
    assert oe.compare_dirs(a, b) == "out.csv: line 3: x: '2.5' != '2.5000000000000004'"


def test_a_shorter_csv_and_a_binary_file_differ(tmp_path: Path) -> None:
    assert "line 3" in oe.first_difference(b"t\n0\n1\n", b"t\n0\n", ".csv")
    assert oe.first_difference(b"abcd", b"abXd", ".fmu") == "byte offset 2"
    assert oe.first_difference(b"abc", b"abcd", ".bin") == "byte offset 3"


def test_a_file_on_one_side_only_differs(tmp_path: Path) -> None:
    a = write(tmp_path / "a", {"x.csv": "t\n", "y.json": "{}"})
    b = write(tmp_path / "b", {"x.csv": "t\n"})
    assert oe.compare_dirs(a, b) == "y.json only on the old side"


def test_run_json_without_its_varying_keys(tmp_path: Path) -> None:
    a = write(tmp_path / "a", {"run.json": run_json("2026-01-01T10:00", 0.18, "r1", 401)})
    b = write(tmp_path / "b", {"run.json": run_json("2026-01-02T11:00", 0.25, "r2", 401)})
    assert oe.compare_dirs(a, b) is None
    c = write(tmp_path / "c", {"run.json": run_json("2026-01-02T11:00", 0.25, "r2", 400)})
    assert "run.json: line" in oe.compare_dirs(a, c)
    assert '"rows": 401' in oe.compare_dirs(a, c)


def test_a_csv_without_its_wall_time_column() -> None:
    a = b"run,K,status,wall_s\n1,25,ok,0.014\n2,50,ok,0.0019\n"
    b = b"run,K,status,wall_s\n1,25,ok,0.026\n2,50,ok,0.0020\n"
    assert oe.first_difference(a, b, ".csv") is None
    c = b"run,K,status,wall_s\n1,25,ok,0.026\n2,50,diverged,0.0020\n"
    assert oe.first_difference(a, c, ".csv") == "line 3: status: 'ok' != 'diverged'"


def test_an_fmpy_result_is_complete_only_at_the_stop_time(tmp_path: Path) -> None:
    csv = tmp_path / "out.csv"
    assert not oe.output_complete(csv, 1.0)
    csv.write_text('"time","x"\n0.0,1\n0.5,2\n')
    assert not oe.output_complete(csv, 1.0)
    csv.write_text('"time","x"\n0.0,1\n0.5,2\n1.0,3\n')
    assert oe.output_complete(csv, 1.0)


def test_verdicts() -> None:
    assert oe.verdict("exit status 1: boom", None, Path("."), Path(".")).startswith("failed (old:")
    assert oe.verdict(None, None, Path(__file__).parent, Path(__file__).parent) == "equal"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["no-such-commit-0000"], "unknown commit: no-such-commit-0000"),
        (["HEAD", "no-such-commit-0000"], "unknown commit: no-such-commit-0000"),
        ([], "the following arguments are required: old"),
        (["HEAD", "--stop", "x"], "invalid float value"),
        (["HEAD", "--stop", "-1"], "--stop must be positive"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_status_2(args: list[str], message: str) -> None:
    done = subprocess.run(
        [sys.executable, oe.__file__, *args], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr.count("\n") == 1 and message in done.stderr
    assert "Traceback" not in done.stderr
