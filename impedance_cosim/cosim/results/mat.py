"""Results as a MATLAB/Modelica result file (`--result-format mat`): the layout Dymola and
OpenModelica write (`dsres.mat`, trajectory format 1.1, "binTrans", MATLAB v4), which their
tools, DyMat, buildingspy and ModelicaRes read, written with scipy.io.savemat.

Its matrices: `Aclass` (what the file is), `name` and `description` (one column per variable,
padded), `dataInfo` (per variable: its matrix, its column, 0, -1), `data_1` (the run's
parameters, constant: their values at the start and the stop time, time first) and `data_2`
(one row per recorded signal, one column per recorded row, time first): every value the same
float64 bits as the CSV's. MatStream has CsvStream's interface (the master's sink), and writes
the file whole when closed, through a temporary file renamed into place; when that fails or is
interrupted, the rows go to `<name>.partial` (as many as fit) and the error says so."""

from __future__ import annotations

import signal
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from impedance_cosim.cosim.results.result import every_kth
from impedance_cosim.util import atomic

ACLASS = ("Atrajectory", "1.1", "", "binTrans")


def char_matrix(texts: list[str], transposed: bool = False) -> np.ndarray:
    """Texts as a character matrix padded with blanks (one row per text; one column if
    transposed, as binTrans stores names and descriptions)."""
    width = max(1, *(len(t) for t in texts))
    rows = np.array([list(t.ljust(width)) for t in texts], dtype="U1")
    return rows.T.copy() if transposed else rows


def mat_layout(
    names: list[str],
    data: np.ndarray,
    descriptions: Mapping[str, str] | None = None,
    parameters: Mapping[str, float] | None = None,
) -> dict[str, np.ndarray]:
    """The result file's matrices: signals `names` ("time" first) with their rows `data`,
    descriptions by name, numeric parameters by name (constant over the run)."""
    descriptions, parameters = descriptions or {}, dict(parameters or {})
    data = np.asarray(data, dtype=np.float64).reshape(-1, len(names))
    span = [data[0, 0], data[-1, 0]] if len(data) else [0.0, 0.0]
    all_names = [names[0], *parameters, *names[1:]]
    info = [[0, 1, 0, -1]]  # time: the abscissa of both matrices
    info += [[1, k + 2, 0, 0] for k in range(len(parameters))]
    info += [[2, k + 2, 0, -1] for k in range(len(names) - 1)]
    constants = np.array([span, *([v, v] for v in parameters.values())], dtype=np.float64)
    return {
        "Aclass": char_matrix(list(ACLASS)),
        "name": char_matrix(all_names, transposed=True),
        "description": char_matrix([descriptions.get(n, "") for n in all_names], True),
        "dataInfo": np.array(info, dtype=np.int32).T.copy(),
        "data_1": constants,
        "data_2": np.ascontiguousarray(data.T),
    }


def write_mat(
    path: str | Path,
    names: list[str],
    data: np.ndarray,
    descriptions: Mapping[str, str] | None = None,
    parameters: Mapping[str, float] | None = None,
) -> None:
    """The result file at path, whole or not at all (a WriteError naming path)."""
    from scipy.io import savemat

    matrices = mat_layout(names, data, descriptions, parameters)
    with atomic.atomic_path(path, suffix=".tmp.mat") as tmp:
        savemat(tmp, matrices, format="4", oned_as="column")


class MatStream:
    """The rows of a run collected block by block (the master's sink, like CsvStream) and
    written as a result file when closed (also after a failure or an interruption: the rows
    computed so far). every=k keeps every k-th row."""

    def __init__(
        self,
        path: str | Path,
        every: int = 1,
        descriptions: Mapping[str, str] | None = None,
        parameters: Mapping[str, float] | None = None,
    ) -> None:
        self.path, self.every = Path(path), every
        self.descriptions, self.parameters = descriptions, parameters
        self.names: list[str] | None = None
        self.rows, self._seen = 0, 0
        self._blocks: list[np.ndarray] = []

    def write(self, names: list[str], rows: np.ndarray) -> None:
        """Keep a block of rows (one column per name)."""
        if self.names is None:
            self.names = list(names)
        elif list(names) != self.names:
            raise ValueError(f"{self.path.name}: columns changed during the run")
        kept = every_kth(rows, self._seen, self.every)
        self._seen += len(rows)
        if len(kept):
            self._blocks.append(np.array(kept, dtype=np.float64))
            self.rows += len(kept)

    def close(self) -> None:
        """Write the file (nothing at all if no header was given). A failed or interrupted write
        keeps the rows under <name>.partial (as many as fit) and says so: a WriteError, or a
        RunInterrupted for Ctrl-C/SIGTERM."""
        if self.names is None:
            return
        blocks, self._blocks, names, self.names = self._blocks, [], self.names, None
        data = np.vstack(blocks) if blocks else np.empty((0, len(names)))
        try:
            write_mat(self.path, names, data, self.descriptions, self.parameters)
        except atomic.WriteError as exc:
            raise exc.with_note(self._keep_partial(names, data)) from None
        except KeyboardInterrupt as exc:
            from impedance_cosim.util.interrupt import RunInterrupted, signal_name

            signum = getattr(exc, "signum", signal.SIGINT)
            kept = self._keep_partial(names, data)
            raise RunInterrupted(f"interrupted ({signal_name(signum)}) while writing"
                                 f" {self.path}; {kept}", signum) from None  # fmt: skip

    def _keep_partial(self, names: list[str], data: np.ndarray) -> str:
        """The rows in <name>.partial (a result file like the whole one): all of them, else the
        first half, quarter, ... that fit; the note saying where they are."""
        partial = self.path.with_name(self.path.name + ".partial")
        n = len(data)
        while n:
            try:
                write_mat(partial, names, data[:n], self.descriptions, self.parameters)
            except atomic.WriteError:
                n //= 2
                continue
            which = f"the {n} rows" if n == len(data) else f"the first {n} of the {len(data)} rows"
            return f"{which} (to t={data[n - 1, 0]:.9g} s) are in {partial}"
        return f"the {len(data)} rows computed could not be kept"

    def __enter__(self) -> MatStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
