"""The result of a run: in memory (RunResult, the recorded signals and why the run stopped) and
on disk.

Results CSV written as a run goes: rows are appended to a temporary file beside the target
and written out after every block; closing the stream (also on an exception or an interruption)
renames it into place, so the CSV at the target name is always whole, and holds every row
computed before the run stopped. A write that fails (a full disk) leaves no file at the target
name: the rows that fit, cut back to the last whole row, are renamed to `<target>.partial`, and
the WriteError's one line names the target, its folder and that file.

Format: a header of names ("time" first), then one row per line, each value the shortest text
that reads back to the same double (Python's repr). fmpy.util.read_csv reads it."""

from __future__ import annotations

import csv
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import orjson

from impedance_cosim.util import atomic

MAX_RESULT_BYTES = 2**30  # the recorded rows of one run must fit in this (refused before running)
Sink = Callable[[list[str], np.ndarray], None]  # (column names, new rows), see Master.run


STATUSES = ("ok", "diverged", "failed")  # a finished run is one of these (see RunResult.status)


@dataclass(frozen=True)
class Divergence:
    """Why a run diverged: a signal left the bound (or became non-finite) at time t. A diverged
    run is a result (its rows up to t are the data), not a failure of the tools."""

    t: float
    signal: str
    value: float
    limit: float

    def __str__(self) -> str:
        what = f"beyond {_short(self.limit)}" if np.isfinite(self.value) else "not finite"
        return f"diverged at t = {self.t:.6g} s: {self.signal} {what} ({_short(self.value, 4)})"


def _short(value: float, digits: int = 6) -> str:
    """A number as %g without the exponent's padding: 1e6, -1.071e6 (not 1e+06)."""
    return f"{value:.{digits}g}".replace("e+0", "e").replace("e+", "e").replace("e-0", "e-")


@dataclass
class RunResult:
    """Recorded signals (rows up to where the run stopped) and why it stopped: `status` "ok",
    "diverged" (`divergence` says where; its rows are the result) or "failed" (`error`)."""

    names: list[str]
    data: np.ndarray
    step_size: float
    algorithm: str
    parameter_set: str
    error: str | None = None
    wall_time: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)
    divergence: Divergence | None = None

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.data[:, self.names.index(name)]
        except ValueError:
            raise KeyError(f"no recorded signal {name!r}") from None

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def status(self) -> str:
        """ "ok" (reached the stop time), "diverged" (a signal left the bound) or "failed"."""
        return run_status(self.error, self.divergence)


def run_status(error: str | None, divergence: Divergence | None = None) -> str:
    """The one definition of a run's status: "ok" without an error, "diverged" when a signal left
    the bound (a result), "failed" otherwise (an FMU error, a tool's failure)."""
    if error is None:
        return "ok"
    return "diverged" if divergence is not None else "failed"


def exit_status(statuses: list[str]) -> int:
    """A command's exit status from its runs' statuses: 1 when any failed, 3 when none failed but
    one diverged (a result a script can tell apart), 0 when all are ok."""
    if "failed" in statuses:
        return 1
    return 3 if "diverged" in statuses else 0


def size_problem(steps: int, columns: int, stop: float, step: float) -> str | None:
    """Why a run's recorded rows would not fit in MAX_RESULT_BYTES, or None."""
    need = (steps + 1) * columns * 8
    if need <= MAX_RESULT_BYTES:
        return None
    return (
        f"stop time {stop:g} s at step {step:g} s is {steps:.3g} steps, whose results ({columns}"
        f" columns) would take {need / 2**30:.3g} GiB of memory (limit"
        f" {MAX_RESULT_BYTES / 2**30:g} GiB): use a shorter run or a longer step"
    )


class Feed:
    """Gives a sink the rows of a run it has not had yet: the header (no rows) on the first call,
    then data[written:rows] (with the extra columns beside, if any) on each later one."""

    def __init__(self, sink: Sink | None, names: list[str]) -> None:
        self.sink, self.names, self.written = sink, names, -1

    def __call__(self, data: np.ndarray, rows: int, extra: np.ndarray | None = None) -> None:
        if self.sink is None or rows == self.written:
            return
        first, self.written = max(self.written, 0), rows
        block = data[first:rows]
        if extra is not None:
            block = np.hstack((block, extra[first:rows]))
        self.sink(self.names, block)


def format_rows(data: np.ndarray) -> str:
    """Rows as CSV lines, each value exactly Python's repr (the shortest text that reads back to
    the same double). orjson writes the same shortest digits faster (docs/performance.md),
    spelled as repr spells them except for 1e-9 <= |x| < 1e-4 ("0.000012" for "1.2e-05", "1e-7"
    for "1e-07"): those values are written with repr into the places orjson left for them.
    Non-finite values (orjson: null) and anything not a 2-D float64 array take the plain repr
    path."""
    data = np.asarray(data)
    if data.ndim != 2 or data.dtype != np.float64 or not len(data) or not np.isfinite(data).all():
        return _repr_rows(data)
    size = np.abs(data)
    own = (size >= 0.9e-9) & (size < 1.1e-4)  # orjson's spelling differs (a margin either side)
    values, placed = data[own].tolist(), data  # row by row: the order of the text
    if values:
        placed = data.copy()
        placed[own] = _PLACE
    text = orjson.dumps(np.ascontiguousarray(placed), option=orjson.OPT_SERIALIZE_NUMPY)
    if values:
        pieces = text.split(_PLACE_TEXT)
        if len(pieces) != len(values) + 1:  # the placeholder value is in the data itself
            return _repr_rows(data)
        spliced = [b""] * (2 * len(pieces) - 1)
        spliced[::2], spliced[1::2] = pieces, [repr(v).encode() for v in values]
        text = b"".join(spliced)
    return text[2:-2].replace(b"],[", b"\n").decode() + "\n"


_PLACE = -8.98846567431158e307  # a placeholder no result holds (one that does: the repr path)
_PLACE_TEXT = orjson.dumps(_PLACE)


def _repr_rows(data: np.ndarray) -> str:
    return "".join(",".join(map(repr, row)) + "\n" for row in data.tolist())


class CsvStream:
    """A results CSV appended block by block (see module docstring). Use as a context manager;
    `write(names, rows)` is the sink the master calls. keep_partial=False: on a failed write
    nothing is kept (for a table whose rows are still in memory, e.g. Result.to_csv). every=k:
    only every k-th row reaches the file (the first, k + 1-th, ...: --output-interval)."""

    def __init__(self, path: str | Path, keep_partial: bool = True, every: int = 1) -> None:
        self.path, self.keep_partial = Path(path), keep_partial
        self.names: list[str] | None = None
        self.rows = 0  # rows in the file
        self.every, self._seen = every, 0  # rows given to write()
        self._last: float | None = None  # the time of the last row written
        try:
            self._tmp: Path | None = atomic.temp_path(self.path)
        except OSError as exc:
            raise atomic.write_error(self.path, exc) from None
        try:
            self._file: atomic.LineFile | None = atomic.LineFile(self._tmp, self.path)
        except OSError:
            atomic.discard(self._tmp)
            raise

    def write(self, names: list[str], rows: np.ndarray) -> None:
        """Append rows (an array with one column per name); the first call writes the header.
        After a failed write (WriteError), later calls do nothing."""
        if self._file is None:
            return
        text, header = "", self.names is None
        if header:
            self.names = list(names)
            text = ",".join(_quote(n) for n in self.names) + "\n"
        elif list(names) != self.names:
            raise ValueError(f"{self.path.name}: columns changed during the run")
        rows, self._seen = every_kth(rows, self._seen, self.every), self._seen + len(rows)
        if len(rows):
            text += format_rows(np.asarray(rows, dtype=float))
        try:
            self._file.append(text)
        except atomic.WriteError as exc:
            raise self._failed(exc, header) from None
        if len(rows):
            self.rows += len(rows)
            self._last = float(rows[-1][0])

    def _failed(self, exc: atomic.WriteError, header: bool) -> atomic.WriteError:
        """After a failed write: the rows that fit to <target>.partial (or nothing), the error
        saying where they are."""
        assert self._file is not None and self._tmp is not None
        lines = self._file.kept_text.splitlines()[1 if header else 0 :]
        self._file.close()
        self._file, tmp, self._tmp = None, self._tmp, None
        rows = self.rows + len(lines)
        last = float(lines[-1].partition(",")[0]) if lines else self._last
        if not self.keep_partial or not rows:
            atomic.discard(tmp)
            return exc
        partial = self._keep_partial(tmp)
        note = f"the {rows} whole rows that fit (to t={last:.9g} s) are in {partial}"
        return exc.with_note(note)

    def _keep_partial(self, tmp: Path) -> Path:
        """Move the temporary file of rows to <target>.partial (or leave it where it is if
        that fails); where the rows now are."""
        partial = self.path.with_name(self.path.name + ".partial")
        try:
            atomic.replace(tmp, partial)
        except OSError:
            atomic.keep(tmp)
            partial = tmp
        return partial

    def close(self) -> None:
        """Rename the rows written so far into place (nothing at all if no header was written)."""
        if self._file is None or self._tmp is None:
            return
        self._file.close()
        self._file, tmp, self._tmp = None, self._tmp, None
        if self.names is None:
            atomic.discard(tmp)
            return
        try:
            atomic.replace(tmp, self.path)
        except OSError as exc:  # the rows are whole: kept under <name>.partial
            if not self.keep_partial:
                atomic.discard(tmp)
                raise atomic.write_error(self.path, exc) from None
            note = f"the {self.rows} rows are in {self._keep_partial(tmp)}"
            raise atomic.write_error(self.path, exc, note) from None
        except KeyboardInterrupt:  # the rows are whole: in place first, then stop
            if tmp.exists():
                atomic.replace(tmp, self.path)
            raise

    def __enter__(self) -> CsvStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def every_kth(rows: np.ndarray, seen: int, every: int) -> np.ndarray:
    """The rows of a block whose index in the whole run (the block starts at row `seen`) is a
    multiple of every."""
    if every == 1:
        return rows
    return np.asarray(rows)[(-seen) % every :: every]


def write_csv(path: str | Path, names: list[str], data: np.ndarray) -> None:
    """A whole results table at once, through a temporary file renamed into place; nothing at
    path when it cannot be written (a WriteError naming path)."""
    with CsvStream(path, keep_partial=False) as stream:
        stream.write(names, data)


def _quote(name: str) -> str:
    if any(c in name for c in ',"\r\n'):
        return '"' + name.replace('"', '""') + '"'
    return name


def read_csv(path: Path) -> dict[str, np.ndarray]:
    """Columns of a results CSV, by name; ValueError (one line naming the file) if it is not
    one: not UTF-8, no header, a cell that is not a number, a row of another width."""
    try:
        with open(path, newline="") as f:
            reader = csv.reader(f)
            names = [n.strip('"') for n in next(reader, [])]
            rows = [[float(v) for v in row] for row in reader]
        if not names or any(len(row) != len(names) for row in rows):
            raise ValueError("no header, or a row of another width than the header")
    except (UnicodeDecodeError, csv.Error, ValueError) as exc:
        why = " ".join(str(exc).split())[:200]
        raise ValueError(f"{Path(path).name} is not a results CSV ({why})") from None
    data = np.array(rows, dtype=float).reshape(len(rows), len(names))
    return {n: data[:, k] for k, n in enumerate(names)}
