"""A sweep's table on disk: every finished run appended (and flushed) as it finishes, the whole
table sorted by run and renamed into place at the end, a lock against a second sweep writing the
same table, and resuming from a table without redoing its finished runs.

The columns: run number, swept values, status, error, metrics (metrics.METRICS), wall time.
Beside `sweep.csv` sit `sweep.plan.json` (what the table is a sweep of: archive digest, axes,
points, options; checked on --resume) and, while a sweep writes it, `sweep.csv.lock`.
Errors are TableError (a ValueError: one line from the CLI).
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import json
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from impedance_cosim.apps.sweep.metrics import METRICS
from impedance_cosim.apps.sweep.plan import Plan, archive_payload, parse_value
from impedance_cosim.util.atomic import LineFile, WriteError, atomic_write, lock_not_inherited

FINISHED = ("ok", "diverged", "failed")  # a row with one of these is not run again on --resume
PLAN_FORMAT = 1


class TableError(ValueError):
    """The table cannot be written, locked or resumed: one line."""


def format_cell(value: Any) -> str:
    """A cell: floats with 17 significant digits (repr), empty = undefined."""
    if value is None:
        return ""
    return repr(value) if isinstance(value, float) else str(value)


def row_cells(names: Sequence[str], run: int, row: Mapping[str, Any]) -> list[str]:
    """The cells of one row; `run` is the run's 1-based number in the plan."""
    return [str(run) if n == "run" else format_cell(row.get(n)) for n in names]


def _csv_line(cells: Sequence[str]) -> str:
    buf = io.StringIO()
    csv.writer(buf).writerow(cells)
    return buf.getvalue()


def replace_text(path: Path, text: str) -> None:
    """Write text to a temporary name beside path, then rename it into place (never half a file;
    a failure is a WriteError naming path)."""
    with atomic_write(path, "w", newline="") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())


def read_table(path: Path) -> list[dict]:
    """Rows of a sweep table (numbers parsed, empty cells None); TableError (one line) if the
    file is not one: not UTF-8, not CSV, a row of another width than the header."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise TableError(f"cannot read {path}: {' '.join(str(exc).split())}") from None
    for n, row in enumerate(rows, start=1):
        if None in row or None in row.values():
            raise TableError(f"{path}: row {n} has another number of cells than the header")
    return [
        {
            k: (None if v == "" else v if k in ("status", "error") else parse_value(v))
            for k, v in row.items()
        }
        for row in rows
    ]


def plan_record(digest: str, axes: Mapping[str, Any], points: Sequence[Mapping], options: Mapping,
                mode: str) -> dict[str, Any]:  # fmt: skip
    """What a table is a sweep of, as stored in <table>.plan.json and compared on --resume."""
    text = json.dumps([list(p.items()) for p in points], sort_keys=True)
    return {
        "format": PLAN_FORMAT,
        "ssp_sha256": digest,
        "mode": mode,
        "axes": {k: list(v) if isinstance(v, tuple) else v for k, v in axes.items()},
        "runs": len(points),
        "points_sha256": hashlib.sha256(text.encode()).hexdigest(),
        "options": json.loads(json.dumps(dict(options))),
    }


def plan_path(table: Path) -> Path:
    return table.with_name(table.stem + ".plan.json")


def _difference(old: Mapping[str, Any], new: Mapping[str, Any]) -> str | None:
    """The first way a stored plan differs from the new one, in words; None when equal."""
    if old.get("format") != PLAN_FORMAT:
        return f"its plan file has format {old.get('format')!r}, not {PLAN_FORMAT}"
    if old.get("ssp_sha256") != new["ssp_sha256"]:
        return "the system archive differs (other FMUs or SSD)"
    if list(old.get("axes", {})) != list(new["axes"]):
        return (f"it sweeps {', '.join(old.get('axes', {})) or 'nothing'}, this command sweeps "
                f"{', '.join(new['axes'])}")  # fmt: skip
    for name, values in new["axes"].items():
        if old["axes"][name] != values:
            return f"{name} takes {old['axes'][name]}, this command {values}"
    if old.get("mode") != new["mode"] or old.get("runs") != new["runs"]:
        return f"it has {old.get('runs')} {old.get('mode')} runs, this command {new['runs']} " \
               f"{new['mode']} runs"  # fmt: skip
    if old.get("points_sha256") != new["points_sha256"]:
        return "its runs are other points (another --seed?)"
    for key in sorted(set(old.get("options", {})) | set(new["options"])):
        a, b = old.get("options", {}).get(key), new["options"].get(key)
        if a != b:
            return f"its option {key} is {a!r}, this command's {b!r}"
    return None


@contextlib.contextmanager
def _lock(path: Path):
    """An exclusive lock on path (a lock file; released by the OS if the process dies)."""
    while True:
        f = open(path, "a+")
        try:
            try:
                import fcntl

                fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except ImportError:  # Windows
                import msvcrt

                msvcrt.locking(f.fileno(), msvcrt.LK_NBLCK, 1)
        except OSError:
            f.seek(0)
            owner = f.read().strip() or "another process"
            f.close()
            raise TableError(
                f"{path.with_suffix('')} is being written by another sweep ({owner}); wait for it "
                "to finish or use another --out"
            ) from None
        try:  # the lock file may have been removed (and made anew) since we opened it
            same = os.path.samestat(os.stat(path), os.fstat(f.fileno()))
        except FileNotFoundError:
            same = False
        if same:
            break
        f.close()
    try:
        f.seek(0)
        f.truncate()
        f.write(f"pid {os.getpid()}\n")
        f.flush()
        with lock_not_inherited(f.fileno()):  # forked dask workers do not hold it
            yield
    finally:
        with contextlib.suppress(OSError):
            path.unlink()
        f.close()


class SweepTable:
    """The table of one sweep while it runs: `done` holds the finished runs found on --resume;
    `add` appends a row and flushes it; leaving the `with` block rewrites the table sorted by run.
    """

    def __init__(self, path: Path, names: Sequence[str], plan: Mapping[str, Any],
                 points: Sequence[Mapping[str, Any]], resume: bool = False) -> None:  # fmt: skip
        self.path, self.names, self.plan = Path(path), list(names), dict(plan)
        self.points, self.resume = points, resume
        self.cells: dict[int, list[str]] = {}  # run (1-based) -> cells
        self.done: set[int] = set()  # 0-based indices of the plan's points with a finished row
        self._file: Any = None
        self._stack = contextlib.ExitStack()

    def __enter__(self) -> SweepTable:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._stack.enter_context(_lock(self.path.with_name(self.path.name + ".lock")))
            try:
                self._load()
                replace_text(plan_path(self.path), json.dumps(self.plan, indent=1) + "\n")
                self._rewrite()
                self._file = LineFile(self.path)
            except BaseException:
                self._stack.close()
                raise
        except WriteError as exc:  # before any run: one line, nothing lost
            raise TableError(str(exc)) from None
        except OSError as exc:
            where = exc.filename or self.path
            raise TableError(f"cannot write the table in {where}: {exc.strerror or exc}") from None
        return self

    def __exit__(self, *exc) -> None:
        try:
            if self._file is not None:
                self._file.close()
                try:
                    self._rewrite()
                except OSError:  # the table is whole as appended (a row per line), not sorted
                    if exc[0] is None:
                        raise
        finally:
            self._stack.close()

    def add(self, index: int, row: Mapping[str, Any]) -> None:
        """Append the row of the plan's point `index` (0-based) and flush it to the OS."""
        cells = row_cells(self.names, index + 1, row)
        try:
            self._file.append(_csv_line(cells))
        except WriteError as exc:  # e.g. a full disk: stop the sweep with one line
            kept = f"it holds the {len(self.cells)} rows before this one, whole"
            raise exc.with_note(kept) from None
        self.cells[index + 1] = cells
        if row.get("status") in FINISHED:
            self.done.add(index)

    def rows(self) -> list[dict[str, Any]]:
        """The rows so far in the plan's order, parsed as read_table parses them."""
        return [
            {
                n: None if c == "" else c if n in ("status", "error") else parse_value(c)
                for n, c in zip(self.names, self.cells[k])
            }  # fmt: skip
            for k in sorted(self.cells)
        ]

    def _rewrite(self) -> None:
        lines = [_csv_line(self.names), *(_csv_line(self.cells[k]) for k in sorted(self.cells))]
        replace_text(self.path, "".join(lines))

    def _load(self) -> None:
        """Keep the finished rows of an existing table (on --resume), or refuse to overwrite the
        rows of an unfinished sweep without --resume."""
        old_plan = self._stored_plan()
        if not self.path.exists():
            return
        try:
            with open(self.path, newline="") as f:
                reader = csv.reader(f)
                header = next(reader, None)
                rows = list(reader)
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise TableError(f"cannot read {self.path}: {exc}") from None
        if not self.resume:
            total = old_plan.get("runs") if old_plan else None
            if old_plan and header is not None and len(rows) < total:
                raise TableError(
                    f"{self.path} holds {len(rows)} of {total} runs of an unfinished sweep: add "
                    "--resume to finish it, or remove it to start over"
                )
            return
        if old_plan is None:
            raise TableError(
                f"cannot resume {self.path}: no {plan_path(self.path).name} beside it to check "
                "that it is a table of this sweep (run without --resume to start over)"
            )
        why = _difference(old_plan, self.plan)
        if why:
            raise TableError(f"cannot resume {self.path}: it is another sweep: {why}")
        if header != self.names:
            raise TableError(f"cannot resume {self.path}: its columns are not this sweep's")
        axes = list(self.plan["axes"])
        status = self.names.index("status")
        for n, cells in enumerate(rows, start=2):
            if len(cells) != len(self.names):
                continue  # a row cut short (the writer was killed mid-line): run it again
            try:
                run = int(cells[0])
            except ValueError:
                continue
            if not 1 <= run <= len(self.points):
                raise TableError(f"cannot resume {self.path}: line {n}: no run {cells[0]!r}")
            point = self.points[run - 1]
            got = {a: parse_value(c) for a, c in zip(axes, cells[1:])}
            if any(got[a] != parse_value(format_cell(point[a])) for a in axes):
                raise TableError(
                    f"cannot resume {self.path}: line {n}: run {run} is not this sweep's point "
                    f"({', '.join(f'{a}={point[a]}' for a in axes)})"
                )
            if cells[status] in FINISHED:
                self.cells[run] = cells
                self.done.add(run - 1)

    def _stored_plan(self) -> dict[str, Any] | None:
        path = plan_path(self.path)
        if not path.exists():
            return None
        try:
            plan = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            raise TableError(f"cannot read {path}: {exc}") from None
        if not isinstance(plan, dict):
            raise TableError(f"{path} is not a sweep's plan")
        return plan


def columns(plan_axes: Iterable[str]) -> list[str]:
    """The table's columns: run number, swept values, status, error, metrics, wall time."""
    return ["run", *plan_axes, "status", "error", *METRICS, "wall_s"]


def open_table(path: Path, plan: Plan, resume: bool = False) -> SweepTable:
    """The plan's table at path, to use in a with-block (rows written as runs finish)."""
    options = {k: v for k, v in plan.options.items() if k != "plant_friction"}
    record = plan_record(archive_payload(plan.ssp)[1], plan.axes, plan.points, options, plan.mode)
    return SweepTable(path, columns(plan.axes), record, plan.points, resume=resume)
