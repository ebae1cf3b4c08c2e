"""Set-up of the LocalCluster's worker processes: they ignore SIGINT. A Ctrl-C in a terminal
reaches every process of the foreground group; the sweep's main process owns it (keeps the
table, closes the cluster), the workers would otherwise each print a KeyboardInterrupt traceback.
"""

from __future__ import annotations

import signal
import threading

from distributed.diagnostics.plugin import WorkerPlugin


class IgnoreSigint(WorkerPlugin):
    """Registered on a LocalCluster's workers (also on a worker restarted after a crash)."""

    name = "impedance-cosim-ignore-sigint"

    def setup(self, worker) -> None:
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)
