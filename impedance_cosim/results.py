"""Results CSV written as a run goes: rows are appended to a temporary file beside the target
and flushed after every block; closing the stream (also on an exception or an interruption)
renames it into place, so the CSV at the target name is always whole, and holds every row
computed before the run stopped.

Format: a header of names ("time" first), then one row per line, each value the shortest text
that reads back to the same double (Python's repr). fmpy.util.read_csv reads it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from impedance_cosim import atomic


def format_rows(data: np.ndarray) -> str:
    """Rows as CSV lines (repr of each value: exact round trip)."""
    return "".join(",".join(map(repr, row)) + "\n" for row in data.tolist())


class CsvStream:
    """A results CSV appended block by block (see module docstring). Use as a context manager;
    `write(names, rows)` is the sink the master calls."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.names: list[str] | None = None
        self.rows = 0
        self._tmp = atomic.temp_path(self.path)
        self._file = open(self._tmp, "w", newline="")  # noqa: SIM115 (closed in close())

    def write(self, names: list[str], rows: np.ndarray) -> None:
        """Append rows (an array with one column per name); the first call writes the header."""
        if self.names is None:
            self.names = list(names)
            self._file.write(",".join(_quote(n) for n in self.names) + "\n")
        elif list(names) != self.names:
            raise ValueError(f"{self.path.name}: columns changed during the run")
        if len(rows):
            self._file.write(format_rows(np.asarray(rows, dtype=float)))
            self.rows += len(rows)
        self._file.flush()

    def close(self) -> None:
        """Rename the rows written so far into place (nothing at all if no header was written)."""
        if self._file is None:
            return
        self._file.close()
        self._file = None
        if self.names is None:
            atomic.discard(self._tmp)
        else:
            atomic.replace(self._tmp, self.path)

    def __enter__(self) -> CsvStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_csv(path: str | Path, names: list[str], data: np.ndarray) -> None:
    """A whole results table at once, through a temporary file renamed into place."""
    with CsvStream(path) as stream:
        stream.write(names, data)


def _quote(name: str) -> str:
    if any(c in name for c in ',"\r\n'):
        return '"' + name.replace('"', '""') + '"'
    return name
