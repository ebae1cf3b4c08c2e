"""Command-line interface: `impedance-cosim <subcommand>`. Only parses and dispatches: each
command lives in impedance_cosim.apps (run, sweep, stability, hil) or packaging (dist)."""

from __future__ import annotations

import argparse
import os
import signal
import sys

import impedance_cosim
from impedance_cosim.util.interrupt import signal_name, sigterm_raises

# The commands (numpy, fmpy, dask: up to a second to import) load inside main(), so that a
# Ctrl-C while they load is caught by entry() like any other interrupt.


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage block), exit status 2."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def main(argv: list[str] | None = None) -> int:
    """Entry point of the impedance-cosim command."""
    from impedance_cosim.apps import run as run_cmd
    from impedance_cosim.apps.options import REPO, add_run_options

    parser = _Parser(
        prog="impedance-cosim",
        description="Impedance control without velocity measurements, as FMI co-simulation.",
    )
    parser.add_argument("--version", action="version",
                        version=f"%(prog)s {impedance_cosim.__version__}")  # fmt: skip
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("build", help="build the FMUs and the system archive into fmus/")
    p.add_argument("--out", default=str(REPO / "fmus"),
                   help="output folder (default: the repository's fmus/)")  # fmt: skip
    p.add_argument("--only", action="append", choices=["plant", "controller", "bridge"],
                   help="build only this FMU (repeatable; skips the .ssp)")  # fmt: skip
    p.set_defaults(func=run_cmd.cmd_build)
    from impedance_cosim.packaging import dist

    dist.add_parser(sub)

    p = sub.add_parser("run", help="run a scenario of the system: CSV, summary, figures",
                       epilog=RUN_EXIT_STATUS)  # fmt: skip
    add_run_options(p)
    p.add_argument(
        "--list-parameters",
        action="store_true",
        help="list the names --set accepts, with the scenario's values, and exit",
    )
    p.set_defaults(func=run_cmd.cmd_run)
    from impedance_cosim.apps.sweep import command as sweep_command

    sweep_command.add_parser(sub)
    from impedance_cosim.apps.stability import command as stability_command

    stability_command.add_parser(sub)
    from impedance_cosim.apps.hil import add_parsers as add_hil_parsers

    add_hil_parsers(sub)

    args = parser.parse_args(argv)
    args.command_line = ["impedance-cosim", *(sys.argv[1:] if argv is None else argv)]
    with sigterm_raises():
        return _dispatch(args)


def entry() -> None:
    """The console script: main(), then leave the process safely (see fmu.exit_process). A
    Ctrl-C before a command has taken over its signals (while the modules load, the arguments
    are read) is one line and exit status 130 too, never a traceback; that path leaves through
    exit_process as well (an FMU library may already be loaded)."""
    try:
        status = main()
    except KeyboardInterrupt:
        print("impedance-cosim: interrupted (SIGINT) while starting", file=sys.stderr)
        status = 128 + signal.SIGINT
    try:
        from impedance_cosim.cosim.fmu import exit_process
    except KeyboardInterrupt:  # a second Ctrl-C while that loads: nothing of ours is loaded yet
        raise SystemExit(128 + signal.SIGINT) from None
    exit_process(status)


RUN_EXIT_STATUS = (
    "exit status: 0 every run ok; 3 a run diverged (a result: its rows, summary and Fig. 4 are"
    " written); 1 a run failed; 2 bad input; 130/143 interrupted by SIGINT/SIGTERM"
)


def _dispatch(args: argparse.Namespace) -> int:
    """Run a subcommand; every failure becomes one line on stderr and an exit status:
    2 bad input, 1 a failed run or other error, 128 + signal number when interrupted; a command
    may return 3 itself: a run diverged, which is a result (cosim.results.exit_status)."""
    from impedance_cosim.apps.options import CliError
    from impedance_cosim.cosim.fmu import FmuError
    from impedance_cosim.cosim.master import MasterError
    from impedance_cosim.cosim.ssp import SspError
    from impedance_cosim.packaging.toolchains import CompileError
    from impedance_cosim.util.atomic import FolderBusyError
    from impedance_cosim.util.interrupt import RunInterrupted

    prefix = f"impedance-cosim {args.command}:"
    try:
        return args.func(args)
    except CliError as exc:  # our own wording (may list several problems, one per line)
        print(f"{prefix} error: {exc}", file=sys.stderr)
        return 2
    except (MasterError, SspError, ValueError, FileNotFoundError) as exc:
        print(f"{prefix} error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except FolderBusyError as exc:
        print(f"{prefix} refused: {exc}", file=sys.stderr)
        return 2
    except RunInterrupted as exc:
        print(f"{prefix} {exc.message}", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt as exc:
        signum = getattr(exc, "signum", signal.SIGINT)
        print(f"{prefix} interrupted ({signal_name(signum)})", file=sys.stderr)
        return 128 + signum
    except (FmuError, OSError, CompileError) as exc:
        print(f"{prefix} error: {_one_line(exc)}", file=sys.stderr)
        return 1
    except Exception as exc:  # a bug: still one line; the traceback on request
        if os.environ.get("IMPEDANCE_COSIM_DEBUG"):
            raise
        print(f"{prefix} internal error: {type(exc).__name__}: {_one_line(exc)} (set"
              " IMPEDANCE_COSIM_DEBUG=1 for the traceback)", file=sys.stderr)  # fmt: skip
        return 1
    finally:  # remove what read_ssp extracted, on every exit path
        if getattr(args, "system", None) is not None:
            args.system.close()


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


if __name__ == "__main__":
    entry()
