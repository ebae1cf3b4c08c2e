"""Ctrl-C (SIGINT) and SIGTERM during a run: finish the step under way, keep every row, stop.

While a `StopSignals` block is active, the first SIGINT or SIGTERM only records the signal; the
master checks it between blocks of steps (so a signal reaching compiled code or a Python FMU
never tears a step apart) and then raises `RunInterrupted` carrying the rows so far. A second
signal raises `RunInterrupted` at once, without rows (a way out of a step that hangs). Signals
reach only the main thread: elsewhere (e.g. a dask worker thread) the block changes nothing.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from typing import Any

SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM") if hasattr(signal, name))


def signal_name(signum: int) -> str:
    """ "SIGINT", "SIGTERM", ..."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


class RunInterrupted(KeyboardInterrupt):
    """A run stopped by a signal; `result` holds the rows computed before it stopped, `results`
    the runs of a sweep that finished before it (api.sweep; empty otherwise)."""

    def __init__(self, message: str, signum: int, result: Any = None, results: Any = ()) -> None:
        super().__init__(message)
        self.message = message
        self.signum = signum
        self.result = result
        self.results = list(results)


class Terminated(KeyboardInterrupt):
    """SIGTERM outside a run: unwinds like Ctrl-C, so `finally` blocks and cleanups run."""

    signum = getattr(signal, "SIGTERM", 15)


class StopSignals:
    """Record SIGINT/SIGTERM instead of raising (see module docstring). A Python FMU waiting in
    the block finds the recorded signal through the installed handler (`records_signals`,
    `signum`: impedance_cosim/fmi/host.py), so that its wait ends too."""

    records_signals = True

    def __init__(self) -> None:
        self.signum: int | None = None
        self._previous: dict[int, Any] = {}

    def _handle(self, signum: int, _frame: Any) -> None:
        if self.signum is not None:
            name = signal_name(signum)
            raise RunInterrupted(f"interrupted again ({name}): stopped at once", signum)
        self.signum = signum

    def __enter__(self) -> StopSignals:
        if threading.current_thread() is threading.main_thread():
            for s in SIGNALS:
                self._previous[s] = signal.signal(s, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for s, handler in self._previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
        self._previous.clear()


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """While active (main thread only), SIGTERM raises `Terminated` instead of killing the
    process outright, so temporary files are removed and partial results are kept; and SIGINT
    raises KeyboardInterrupt even when the process started with SIGINT ignored (a background
    job of a script: Python then installs no handler, and `kill -INT` did nothing)."""
    term = getattr(signal, "SIGTERM", None)
    if term is None or threading.current_thread() is not threading.main_thread():
        yield
        return

    def handle(_signum: int, _frame: Any) -> None:
        raise Terminated("terminated (SIGTERM)")

    previous = signal.signal(term, handle)
    previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous_int if previous_int is not None else signal.SIG_DFL)
        signal.signal(term, previous if previous is not None else signal.SIG_DFL)
