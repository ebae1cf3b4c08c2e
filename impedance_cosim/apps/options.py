"""What the commands share on the command line: the run options, their checks and CliError."""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DEFAULT_SSP = REPO / "fmus" / "PaperScenario.ssp"


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


def parse_overrides(items: list[str]) -> dict[str, str]:
    """["controller.K=80", ...] -> {"controller.K": "80"}; one-line error for a bad item."""
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise CliError(f"--set expects component.variable=value (got {item!r})")
        out[name.strip()] = value.strip()
    return out


def finite_positive(text: str) -> float:
    """argparse type of --stop and --step: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0 (got {text})")
    return value


def prepare_out(folder: Path) -> Path:
    """The output folder, created if needed and checked writable (before any simulation)."""
    if folder.exists() and not folder.is_dir():
        raise CliError(f"--out {folder} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise CliError(f"--out {folder} is not a writable folder ({exc.strerror or exc})") from None
    return folder


def add_run_options(p: argparse.ArgumentParser, out: str = "results") -> None:
    """The options of `run` (shared with the commands that run the system the same way)."""
    p.add_argument("--scenario", default=None,
                   help="parameter set of the SSD: observer (default, the paper), difference, "
                        "measured")  # fmt: skip
    p.add_argument("--ssp", default=None, help=f"system archive (default: {DEFAULT_SSP}, "
                   "built if missing or out of date)")  # fmt: skip
    p.add_argument("--stop", type=finite_positive, default=None, help="stop time [s] (default 20)")
    p.add_argument("--step", type=finite_positive, default=None,
                   help="communication step [s] (1/400)")  # fmt: skip
    p.add_argument("--algorithm", choices=["gauss-seidel", "jacobi"], default=None,
                   help="master algorithm (default gauss-seidel, controller first)")  # fmt: skip
    p.add_argument("--set", action="append", metavar="COMPONENT.VARIABLE=VALUE",
                   help="override a parameter, e.g. controller.K=80 (K1..K3) or "
                        "plant.q_noise=1e-4 (repeatable)")  # fmt: skip
    p.add_argument("--realtime", action="store_true",
                   help="pace the steps to the wall clock; per-step timing recorded")  # fmt: skip
    from impedance_cosim.cosim.realtime import add_options

    add_options(p)
    p.add_argument("--out", default=out, help=f"output folder (default {out}/)")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--no-report", action="store_true",
                   help="skip report.html (the results as one self-contained page)")  # fmt: skip
    p.add_argument("--no-progress", action="store_true",
                   help="no progress (a bar on a terminal, else a line every 10 s)")  # fmt: skip
