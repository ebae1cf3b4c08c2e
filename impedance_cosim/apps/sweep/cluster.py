"""The dask cluster of a sweep: an existing scheduler (checked before use: one clear line when it
is unreachable or not dask) or a LocalCluster of single-threaded worker processes (pythonfmu FMUs
must not share threads) whose workers ignore SIGINT: a Ctrl-C in a terminal reaches every
process of the foreground group; the sweep's main process owns it (keeps the table, closes the
cluster), the workers would otherwise each print a KeyboardInterrupt traceback.

Imports distributed (~0.3 s): import this module only where a cluster is used.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import sys
import tempfile
import threading
import time
from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

from impedance_cosim.apps.sweep.plan import SweepError, cores, workers_problem


class LocalWorkerSetup(WorkerPlugin):
    """Registered on a LocalCluster's workers (also on a worker restarted after a crash), before
    any task: SIGINT ignored, and their temporary files (FMU and archive extractions) in the
    sweep's own folder, which the sweep removes once the cluster is closed: a worker leaves
    without Python's exit work (os._exit, or killed), so its own cleanup never runs."""

    name = "impedance-cosim-local-worker"

    def __init__(self, scratch: str) -> None:
        self.scratch = scratch

    def setup(self, worker) -> None:
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        os.environ["TMPDIR"] = self.scratch
        tempfile.tempdir = self.scratch


def check_scheduler(address: str, timeout: float = 3.0) -> None:
    """SweepError unless a dask scheduler answers at address within timeout seconds (a TCP
    connection, then dask's handshake and an identity call: a port that is not a scheduler fails
    within the timeout instead of hanging)."""
    import asyncio

    from distributed.comm import connect
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.security import Security

    try:
        scheme, location = parse_address(address if "://" in address else f"tcp://{address}")
        host, port = parse_host_port(location, default_port=8786)
    except (ValueError, TypeError) as exc:
        raise SweepError(f"bad scheduler address {address!r}: {exc}") from None
    if scheme not in ("tcp", "tls"):
        raise SweepError(f"scheduler address {address!r}: only tcp:// and tls:// are supported")
    started = time.monotonic()
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise SweepError(
            f"cannot reach the dask scheduler at {address} ({reason}); is `dask scheduler` "
            "running there?"
        ) from None

    async def identity() -> Any:
        security = Security().get_connection_args("client")  # tls: dask's configured certificates
        comm = await connect(f"{scheme}://{host}:{port}", timeout=timeout, **security)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    left = max(timeout - (time.monotonic() - started), 0.1)
    try:
        reply = asyncio.run(asyncio.wait_for(identity(), left))
    except Exception as exc:  # e.g. MemoryError: garbage can ask for any amount of memory
        if isinstance(exc, TimeoutError | asyncio.TimeoutError):
            detail = f"no dask answer within {timeout:g} s"
        else:
            detail = f"its answer is not dask's: {type(exc).__name__}"
    else:
        kind = reply.get("type") if isinstance(reply, dict) else None
        if kind == "Scheduler":
            return
        detail = f"it answers as {kind!r}"
    raise SweepError(f"{address} accepts connections but is not a dask scheduler ({detail})")


# Workers of a LocalCluster are forked where the OS allows it safely (Linux): a spawned worker
# starts a new interpreter and imports distributed, which kept both cores busy while the cluster
# started (0.8 s spawned, 0.1 s forked, timing dask_client's start on 2 cores); the 692-run study
# including the start went from 1.78-1.97x to 2.13-2.22x (benchmarks/run_all.py). A forked
# worker starts from this process, so it drops what belongs to it: the signal handlers (below)
# and the locks (util.atomic.lock_not_inherited).
START_METHOD = "fork" if sys.platform == "linux" else "spawn"


def _forked_worker_signals() -> None:
    """In a forked child: Ctrl-C is the main process's, SIGTERM ends the worker (its default)."""
    with contextlib.suppress(ValueError, OSError):
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


if START_METHOD == "fork":
    os.register_at_fork(after_in_child=_forked_worker_signals)

# Our local workers run one CPU-bound task at a time on few cores: slower housekeeping (ticks,
# memory and system monitors, the profiler, work stealing) took runs from 11% to 4.5% slower than
# in a plain process (32 runs on 2 cores: 1.73x -> 1.83x faster than serial).
QUIET_WORKERS = {
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "5s",
    "distributed.worker.profile.enabled": False,
    "distributed.scheduler.work-stealing": False,
}


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None, timeout: float = 3.0):
    """A dask Client: on an existing scheduler, or on a LocalCluster of single-threaded worker
    processes (this machine's cores by default); the cluster is closed on exit. A Ctrl-C/SIGTERM
    while it starts or closes is taken once that is done (a client or cluster torn half way
    leaves dask's own tracebacks on stderr)."""
    from impedance_cosim.util.interrupt import StopSignals

    if scheduler:
        check_scheduler(scheduler, timeout)
    stack = contextlib.ExitStack()
    with StopSignals() as starting:
        try:
            client = _remote(stack, scheduler, timeout) if scheduler else _local(stack, workers)
        except BaseException:
            stack.close()
            raise
    try:
        if starting.signum is not None:
            signal.raise_signal(starting.signum)  # now, to the command's own handler
        yield client
    finally:
        with StopSignals() as closing:
            stack.close()
        if closing.signum is not None:
            signal.raise_signal(closing.signum)


def _remote(stack: contextlib.ExitStack, scheduler: str, timeout: float) -> Any:
    """A Client of the scheduler, closed by stack; dask's logging off while it is open (a lost
    scheduler: our one line, not dask's tracebacks)."""
    import logging

    from distributed import Client

    try:
        client = Client(scheduler, timeout=f"{timeout}s")
    except OSError as exc:
        raise SweepError(f"cannot connect to the dask scheduler at {scheduler}: {exc}") from None
    logging.disable(logging.CRITICAL)
    stack.callback(logging.disable, logging.NOTSET)
    return stack.enter_context(client)


def local_workers(workers: int | None, runs: int | None = None) -> int:
    """The LocalCluster's size: `workers` (this machine's cores by default), no more than the
    runs to do; SweepError beyond 4 workers per core (see plan.workers_problem)."""
    problem = workers_problem(workers)
    if problem:
        raise SweepError(problem)
    n = workers or cores()
    return max(1, min(n, runs)) if runs is not None else n


def _local(stack: contextlib.ExitStack, workers: int | None) -> Any:
    """A LocalCluster and its Client, closed by stack. Its log level is CRITICAL (forked workers
    inherit it): dask's ERROR lines are races of its own shutdown (e.g. a worker's heartbeat
    when the cluster closes under a running task); a failed run is a row saying why."""
    import logging

    import dask
    from distributed import Client, LocalCluster

    n = local_workers(workers)
    scratch = tempfile.mkdtemp(prefix="impcosim_dask_")  # dask's and the workers' temporary files
    stack.callback(shutil.rmtree, scratch, ignore_errors=True)  # last: after the cluster closed
    where = {"distributed.worker.multiprocessing-method": START_METHOD,
             "temporary-directory": scratch}  # fmt: skip
    stack.enter_context(dask.config.set({**QUIET_WORKERS, **where}))
    options = {"threads_per_worker": 1, "processes": True, "dashboard_address": ":0"}
    for attempt in (1, 2):  # a worker killed while the cluster starts fails it: start again once
        try:
            cluster = LocalCluster(n_workers=n, silence_logs=logging.CRITICAL, **options)
            break
        except RuntimeError:  # "Nanny failed to start"
            if attempt == 2:
                raise
    stack.enter_context(cluster)
    client = stack.enter_context(Client(cluster))
    setup = LocalWorkerSetup(scratch)  # before any task of ours
    try:
        client.register_plugin(setup)
    except Exception:  # noqa: BLE001 (a worker lost in the broadcast: dask keeps the plugin for
        client.register_plugin(setup, idempotent=False)  # workers (re)started; again for the rest)
    return client
