"""What the FMUs print to stderr while a run captures it: passed on afterwards, less their error
reports (the host gets those through the FMU logger and puts them in its one-line error). Used by
the command line and the API alike."""

from __future__ import annotations

from typing import TextIO


def echo_fmu_output(text: str, stream: TextIO) -> None:
    """Print text's lines to stream, except blank ones and the FMUs' `error: ` reports."""
    for line in text.splitlines():
        if line.strip() and not line.startswith("error: "):
            print(line, file=stream)
