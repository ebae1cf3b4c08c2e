#!/usr/bin/env python3
"""Fuzz target: the readers of our own result files, fed the bytes as the file. Byte 0 picks the
reader, the rest is the file:

0. cosim.results.result.read_csv (a run's CSV, read back by the regression compare): only ValueError
   with a one-line message (not a bare UnicodeDecodeError) may come out;
1. apps.sweep.table.read_table (a sweep's table): only TableError;
2. SweepTable resume (--resume of a sweep: the table, byte 1 even, or its plan.json, odd): only
   TableError;
3. apps.stability.command._kept_table (--resume of `stability linear`): only StabilityError;
4. apps.stability.log.PartLog resume (a part's .runs.jsonl): only StabilityError;
5. apps.stability.log.Record (stability.run.json): nothing (an unreadable record is ignored).

Every message one line (CliError aside, the CLI prints them as they are)."""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

import _common  # noqa: F401 - sys.path

from impedance_cosim.apps.stability import command as stability_command
from impedance_cosim.apps.stability.bisection import StabilityError
from impedance_cosim.apps.stability.log import PartLog, Record
from impedance_cosim.apps.stability.parts import LINEAR_COLUMNS
from impedance_cosim.apps.sweep import table as sweep_table
from impedance_cosim.cosim.results import result as results

TMP = Path(tempfile.mkdtemp(prefix="impcosim-fuzz-results-"))
AXIS = "controller.K"
POINTS = [{AXIS: 10.0}, {AXIS: 50}, {AXIS: 80.5}]
NAMES = sweep_table.columns([AXIS])
PLAN = sweep_table.plan_record("0" * 64, {AXIS: [10.0, 50, 80.5]}, POINTS, {"stop": 1.0}, "grid")
STUDY_PLAN = {"ssp_sha256": "0" * 64, "velocities": [0.1, 0.2]}


def _one_line(exc: BaseException) -> None:
    assert str(exc) and "\n" not in str(exc), repr(exc)


def _sweep_resume(folder: Path, data: bytes, plan_file: bool) -> None:
    import json

    path = folder / "sweep.csv"
    if plan_file:
        sweep_table.plan_path(path).write_bytes(data)
        path.write_text(sweep_table._csv_line(NAMES))
    else:
        sweep_table.plan_path(path).write_text(json.dumps(PLAN))
        path.write_bytes(data)
    with sweep_table.SweepTable(path, NAMES, PLAN, POINTS, resume=True) as table:
        assert table.done <= {0, 1, 2}
        table.rows()


def _read(kind: int, data: bytes, folder: Path) -> None:
    """Feed DATA to reader KIND (see the module docstring) in FOLDER."""
    path = folder / "file"
    if kind == 0:
        path.write_bytes(data)
        try:
            results.read_csv(path)
        except UnicodeDecodeError as exc:
            raise AssertionError(f"undocumented {exc!r}") from None
        except ValueError as exc:
            _one_line(exc)
    elif kind == 1:
        path.write_bytes(data)
        try:
            sweep_table.read_table(path)
        except sweep_table.TableError as exc:
            _one_line(exc)
    elif kind == 2:
        try:
            _sweep_resume(folder, data[1:], bool(data[:1]) and data[0] & 1 == 1)
        except sweep_table.TableError as exc:
            _one_line(exc)
    elif kind == 3:
        path.write_bytes(data)
        try:
            stability_command._kept_table("linear", path)
        except StabilityError as exc:
            _one_line(exc)
    elif kind == 4:
        (folder / "linear.runs.jsonl").write_bytes(data)
        try:
            with PartLog(folder, "linear", STUDY_PLAN, resume=True):
                pass
        except StabilityError as exc:
            _one_line(exc)
    else:
        (folder / "stability.run.json").write_bytes(data)
        Record(folder, None, folder / "none.ssp")


def entry(data: bytes) -> None:
    if not data:
        return
    folder = Path(tempfile.mkdtemp(dir=TMP))
    try:
        _read(data[0] % 6, data[1:], folder)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def seeds() -> dict[str, bytes]:
    """One valid file per reader."""
    import json

    table = "".join(
        sweep_table._csv_line(sweep_table.row_cells(NAMES, k + 1, {**p, "status": "ok"}))
        for k, p in enumerate(POINTS)
    )
    head = sweep_table._csv_line(NAMES)
    linear = ",".join(LINEAR_COLUMNS) + "\n" + ",".join(["0.1"] * len(LINEAR_COLUMNS)) + "\n"
    head_line = {"format": "impedance-cosim stability log 1", "part": "linear", "plan": STUDY_PLAN}
    log = json.dumps(head_line) + "\n" + json.dumps({"key": [0.1], "data": {}})
    return {
        "csv": b'\x00time,plant.q1,"a,b"\n0.0,1.5,2\n0.0025,1e-300,-0.0\n',
        "table": b"\x01" + (head + table).encode(),
        "resume": b"\x02\x00" + (head + table).encode(),
        "resume-plan": b"\x02\x01" + json.dumps(PLAN).encode(),
        "linear": b"\x03" + linear.encode(),
        "log": b"\x04" + log.encode() + b"\n",
        "record": b"\x05" + json.dumps({"parts": {"linear": {"status": "finished"}}}).encode(),
    }


if __name__ == "__main__":
    _common.main(entry)
    sys.exit(0)
