"""fmpy's command line (`fmpy simulate ...`) run in a child process that leaves as our commands
do: pythonfmu 0.7's library destructor can abort a process that loaded a Python FMU at its exit,
after the results are written (docs/limitations.md); fmpy's CLI exits normally, so a test of what
it computed must not fail on that exit."""

from __future__ import annotations

import subprocess
import sys
from typing import Any

# fmpy.cli.main reads sys.argv; the child leaves through exit_process with main's status.
CHILD = """\
import sys
from fmpy.cli import main
from impedance_cosim.cosim.leave import exit_process
try:
    main()
    code = 0
except SystemExit as stop:
    if isinstance(stop.code, str):
        print(stop.code, file=sys.stderr)
    code = 0 if stop.code is None else stop.code if isinstance(stop.code, int) else 1
exit_process(code)
"""


def fmpy_cli(args: list[str], **kwargs: Any) -> subprocess.CompletedProcess:
    """subprocess.run of `fmpy <args>` (kwargs as subprocess.run's), leaving safely."""
    return subprocess.run([sys.executable, "-c", CHILD, *args], **kwargs)
