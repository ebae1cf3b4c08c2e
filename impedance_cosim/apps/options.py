"""What the commands share on the command line: the run options, their checks and CliError."""

from __future__ import annotations

import argparse
import math
import os
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
# The FMUs and system archives an installed wheel carries (setup.py copies the built fmus/ there);
# used when there is no checkout's fmus/ beside the package (an install, not a clone), and never
# rebuilt: a clone keeps building its own fmus/ when stale.
PACKAGED_FMUS = Path(__file__).resolve().parents[1] / "_fmus"
FMUS_DIR = (
    PACKAGED_FMUS if not (REPO / "fmus").is_dir() and PACKAGED_FMUS.is_dir() else REPO / "fmus"
)
DEFAULT_SSP = FMUS_DIR / "PaperScenario.ssp"


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


def _shown(text: str) -> str:
    return text if len(text) <= 80 else f"{text[:60]}... ({len(text)} characters)"


def check_out(text: str | Path, option: str = "--out") -> Path:
    """The output folder named on the command line, checked without creating anything: not
    empty, not a file, names the file system allows, in a place that can be written."""
    text = str(text)
    if not text.strip():
        raise CliError(f"{option} is empty: give the folder to write into")
    folder = Path(text)
    try:
        here = folder.absolute()
        there = next(p for p in (here, *here.parents) if _exists(p))  # the part that exists
        limit = _name_max(there if there.is_dir() else there.parent)
        for part in here.relative_to(there).parts:
            size = len(os.fsencode(part))
            if size > limit:
                raise CliError(f"{option} {_shown(text)}: a name of {size} bytes, longer than"
                               f" the file system allows ({limit})")  # fmt: skip
        if not there.is_dir():
            where = "" if there == here else f" ({there})"
            raise CliError(f"{option} {_shown(text)} is a file, not a folder{where}")
        if not os.access(there, os.W_OK | os.X_OK):
            why = "read-only file system" if _read_only(there) else "no permission to write"
            where = "" if there == here else f" in {there}"
            raise CliError(f"{option} {_shown(text)} is not a writable folder ({why}{where})")
    except OSError as exc:
        raise CliError(f"{option} {_shown(text)} cannot be used ({exc.strerror or exc})") from None
    return folder


def _name_max(folder: Path) -> int:
    """The longest file name the file system of folder allows (255 where it cannot say)."""
    try:
        return os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, AttributeError, ValueError):  # no pathconf on Windows
        return 255


def _exists(path: Path) -> bool:
    try:
        return path.exists()
    except OSError:  # e.g. a name too long
        return False


def _read_only(path: Path) -> bool:
    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except (OSError, AttributeError):
        return False


def prepare_out(folder: Path, option: str = "--out") -> Path:
    """The output folder (see check_out), created if needed and checked writable (before any
    simulation)."""
    folder = check_out(folder, option)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise CliError(
            f"{option} {_shown(str(folder))} is not a writable folder ({exc.strerror or exc})"
        ) from None
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
    p.add_argument("--extrapolation", choices=["none", "linear"], default="none",
                   help="Jacobi only (default none): linear sets each input fed by an output"
                        " with a time derivative to y + h dy/dt (native plant;"
                        " docs/stability.md)")  # fmt: skip
    p.add_argument("--set", action="append", metavar="COMPONENT.VARIABLE=VALUE",
                   help="override a parameter, e.g. controller.K=80 (K1..K3) or "
                        "plant.q_noise=1e-4 (repeatable)")  # fmt: skip
    p.add_argument("--realtime", action="store_true",
                   help="pace the steps to the wall clock; per-step timing recorded")  # fmt: skip
    from impedance_cosim.cosim.master.realtime import add_options

    add_options(p)
    p.add_argument("--out", default=out, help=f"output folder (default {out}/)")
    every = ("write a row every SECONDS of simulated time, a multiple of the step (default:"
             " every step; the summary and figures use every step)")  # fmt: skip
    p.add_argument("--output-interval", type=finite_positive, default=None, metavar="SECONDS",
                   help=every)  # fmt: skip
    p.add_argument("--result-format", choices=["csv", "mat"], default="csv",
                   help="results file: csv (default) or mat, the MATLAB/Modelica result file"
                        " Dymola and OpenModelica write (docs/running.md)")  # fmt: skip
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--no-report", action="store_true",
                   help="skip report.html (the results as one self-contained page)")  # fmt: skip
    p.add_argument("--no-progress", action="store_true",
                   help="no progress (a bar on a terminal, else a line every 10 s)")  # fmt: skip


def output_every(interval: float | None, step: float, steps: int | None = None) -> int:
    """Rows per written row for --output-interval (1 without it); CliError unless the interval
    is a whole multiple of the communication step and, given the run's number of steps, divides
    the run length (else the last row, at the stop time, would not be written)."""
    if interval is None:
        return 1
    if not interval / step < 2**53:  # a row every 2**53 steps or more (or inf: round() fails)
        raise CliError(f"--output-interval {interval:g} s is more than 2**53 steps of"
                       f" {step:g} s: no row but the first would be written")  # fmt: skip
    every = round(interval / step)
    if every < 1 or abs(every * step - interval) > 1e-9 * max(interval, step):
        raise CliError(f"--output-interval {interval:g} s is not a multiple of the step"
                       f" {step:g} s (e.g. {step:g}, {2 * step:g}, {4 * step:g})")  # fmt: skip
    if steps is not None and steps % every:
        raise CliError(f"--output-interval {interval:g} s does not divide the run length"
                       f" {steps * step:g} s (--stop): the row at the stop time would be"
                       " lost")  # fmt: skip
    return every
