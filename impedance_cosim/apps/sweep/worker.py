"""One run of a sweep, in the process that runs it (a dask worker, or this process for serial
runs): the system archive read once per process (cached by digest), a Master per run, its row.

The functions a dask task calls (run_batch, run_point) live here: workers import
them by this module's path. A run that fails or diverges is a row with its status and reason; a
run stopped by a signal is not a row (RunInterruptedError): the sweep stops.
"""

from __future__ import annotations

import hashlib
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from impedance_cosim.apps.sweep.metrics import METRICS, run_metrics
from impedance_cosim.apps.sweep.plan import run_options
from impedance_cosim.cosim.fmus.pool import InstancePool
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions

POOL = InstancePool()  # per worker process: FMU instances reused across runs (run_batch)
_SYSTEMS: dict[str, Any] = {}  # per process: SSP digest -> SystemDescription (FMUs extracted once)


def _system(payload: bytes | str, digest: str):
    """The system of the archive (its bytes, or its path on this machine: checked against the
    digest), read and warmed up once per process (prepare_worker)."""
    system = _SYSTEMS.get(digest)
    if system is None:
        from impedance_cosim.cosim.ssp.read import read_ssp

        data = payload if isinstance(payload, bytes) else Path(payload).read_bytes()
        if hashlib.sha256(data).hexdigest() != digest:
            raise RuntimeError(f"the system archive {payload} changed since the sweep started")
        with tempfile.TemporaryDirectory(prefix="impcosim_sweep_") as tmp:
            path = Path(tmp) / "system.ssp"
            path.write_bytes(data)
            system = read_ssp(path)
        prepare_worker(system)
        _SYSTEMS[digest] = system
    return system


def prepare_worker(system: Any) -> None:
    """Take a few steps of the system (loads the FMUs' libraries and the compiled master loop),
    so that the first run in a process costs what the others do (batch sizes are measured)."""
    h = system.step_size or 1 / 400
    Master(system, RunOptions(step_size=h, stop_time=system.start_time + 10 * h)).run()


class RunInterruptedError(Exception):
    """A run stopped by SIGINT/SIGTERM: no result; the sweep stops (--resume runs it again)."""


STOP: dict[str, str | None] = {
    "signal": None
}  # set by the signal handler (command.stop_on_signals)


def _interrupted(error: str | None) -> bool:
    """The master's error for a run it stopped on a signal (see cli/master: "interrupted ...")."""
    return bool(error) and error.lower().startswith("interrupted")


def run_point(
    payload: bytes | str, digest: str, point: dict, options: dict, instances: Any = None
) -> dict[str, Any]:
    """One run of the sweep -> its table row (failures are rows); RunInterruptedError (or a
    KeyboardInterrupt) when a signal stopped it, whatever the FMUs made of the signal.
    instances: an fmu_pool.InstancePool to take the FMU instances from (run_batch)."""
    started = time.perf_counter()
    row: dict[str, Any] = dict(point)
    row.update(status="ok", error="")
    row.update({m: None for m in METRICS})
    try:
        system = _system(payload, digest)
        started = time.perf_counter()  # the first run in a process: after reading the archive
        result = Master(system, run_options(point, options), instances).run()
        if STOP["signal"] or _interrupted(result.error):
            raise RunInterruptedError(result.error or f"interrupted ({STOP['signal']})")
        row["t_end_s"] = float(result.data[-1, 0]) if len(result.data) else None
        if result.ok:
            row.update(run_metrics(result))
        else:
            row["status"] = result.status  # results.run_status: diverged or failed
            row["error"] = result.error
    except RunInterruptedError:
        raise
    except Exception as exc:  # a row, never a crashed sweep
        if STOP["signal"]:  # e.g. a Python FMU turned the KeyboardInterrupt into an FMI error
            raise RunInterruptedError(f"interrupted ({STOP['signal']})") from None
        row.update(status="failed", error=" ".join(f"{type(exc).__name__}: {exc}".split()))
    row["wall_s"] = time.perf_counter() - started
    return row


def run_batch(payload: bytes | str, digest: str, points: Sequence[dict], options: dict) -> list:
    """The rows of several points, one after another in this process (a dask task of
    execute.run_dask), with its FMU instances reused from run to run."""
    return [run_point(payload, digest, p, options, instances=POOL) for p in points]
