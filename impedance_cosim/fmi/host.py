"""What a Python FMU that waits must ask of its host process: has a stop signal come in?

A Python FMU runs in the host's interpreter, on the host's thread, so a SIGINT or SIGTERM landing
while the FMU waits (on a socket, say) runs the host's handler there. The master's handler
(impedance_cosim.util.interrupt.StopSignals) only records the signal, and Python then resumes the
wait, however long it is: a waiting FMU must look for a recorded signal itself, in short slices.
It cannot import the host's module (an FMU bundles its own renamed copy of our code, without
util/: packaging/isolate.py), so it reads the installed handler: a handler bound to an object
whose `records_signals` is true keeps the recorded signal number in that object's `signum`.
"""

from __future__ import annotations

import signal

_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM") if hasattr(signal, n))


def pending_signal() -> int | None:
    """The signal number the host's handler has recorded and not yet acted on (None if none)."""
    for s in _SIGNALS:
        owner = getattr(signal.getsignal(s), "__self__", None)
        if getattr(owner, "records_signals", False):
            signum = getattr(owner, "signum", None)
            if isinstance(signum, int):
                return signum
    return None


def signal_text(signum: int) -> str:
    """ "SIGINT", "SIGTERM", ... (the number for a signal Python has no name for)."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"
