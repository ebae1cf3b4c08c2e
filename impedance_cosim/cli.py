"""Command-line interface: `impedance-cosim <subcommand>`. Only parses and dispatches: each
command lives in impedance_cosim.apps (run, sweep, stability, hil) or packaging (dist)."""

from __future__ import annotations

import argparse
import os
import signal
import sys

from impedance_cosim.util.interrupt import signal_name, sigterm_raises

# The commands (numpy, fmpy, dask: up to a second to import) load inside main(), so that a
# Ctrl-C while they load is caught by entry() like any other interrupt, and only the one asked
# for loads at all (COMMANDS).


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage block), exit status 2."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


# Each command: its one-line help and where its parser is defined ("module:function"). Only the
# chosen command's module is imported (sweep and stability load numpy, fmpy and dask: up to a
# second), so `--version`, `--help` and a mistyped command answer at once; the others get a
# parser with their help line only. tests/test_cli_help.py checks these lines against the
# parsers' own.
COMMANDS = {
    "build": ("build the FMUs and the system archive into fmus/", "impedance_cosim.cli:add_build"),
    "dist": ("build everything and zip the distribution bundle",
             "impedance_cosim.packaging.dist:add_parser"),
    "run": ("run a scenario of the system: CSV, summary, figures", "impedance_cosim.cli:add_run"),
    "sweep": ("parameter sweep on dask: metrics table (CSV) and maps (PNG)",
              "impedance_cosim.apps.sweep.command:add_parser"),
    "stability": ("stability study: bisected boundaries, linearised loop, Fig. 4 conditions,"
                  " observer discretizations (docs/stability.md)",
                  "impedance_cosim.apps.stability.command:add_parser"),
    "swap": ("run the system with a component replaced by another FMU (checked first)",
             "impedance_cosim.apps.hil:add_parsers"),
    "fmus": ("list the packaged FMUs and system archives, or copy them (--copy-to DIR)",
             "impedance_cosim.apps.fmus_cmd:add_parser"),
    "robot": ("the stand-in for the robot hardware: the plant model behind the bridge protocol",
              "impedance_cosim.apps.hil:add_parsers"),
}  # fmt: skip


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line's parser, in full for `command` (every command when it is "*"), with
    only the help line for the others (see COMMANDS)."""
    from importlib import import_module

    from impedance_cosim.version import __version__

    parser = _Parser(
        prog="impedance-cosim",
        description="Impedance control without velocity measurements, as FMI co-simulation.",
        epilog="`impedance-cosim <command> --help` lists that command's options.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    wanted = {COMMANDS[c][1] for c in COMMANDS if command in (c, "*")}
    for where in wanted:
        module, function = where.split(":")
        getattr(import_module(module), function)(sub)
    for name, (help_text, where) in COMMANDS.items():
        if where not in wanted:
            sub.add_parser(name, help=help_text)
    return parser


def add_build(sub) -> None:
    """The `build` subcommand."""
    from impedance_cosim.apps import build_cmd
    from impedance_cosim.apps.options import REPO

    p = sub.add_parser("build", help=COMMANDS["build"][0])
    p.add_argument("--out", default=str(REPO / "fmus"),
                   help="output folder (default: the repository's fmus/)")  # fmt: skip
    p.add_argument("--only", action="append",
                   choices=["plant", "controller", "bridge", "pinocchio", "mujoco", "closedloop"],
                   help="build only this FMU (repeatable; skips the .ssp; closedloop: the"
                   " closed-loop FMUs)")  # fmt: skip
    p.set_defaults(func=build_cmd.cmd_build)


def add_run(sub) -> None:
    """The `run` subcommand."""
    from impedance_cosim.apps import run as run_cmd
    from impedance_cosim.apps.options import add_run_options

    p = sub.add_parser("run", help=COMMANDS["run"][0], epilog=RUN_EXIT_STATUS)
    add_run_options(p)
    p.add_argument(
        "--list-parameters",
        action="store_true",
        help="list the names --set accepts, with the scenario's values, and exit",
    )
    p.add_argument(
        "--event-exact",
        action="store_true",
        help="step each FMI 3.0 FMU with event mode to its events inside the communication"
        " steps, handled in Event Mode: the plant's contact switches, the controller's clock"
        " ticks (each step cut at the tick, sampled on the plant's outputs there); the rows stay"
        " on the communication grid",
    )
    p.set_defaults(func=run_cmd.cmd_run)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the impedance-cosim command."""
    argv = sys.argv[1:] if argv is None else list(argv)
    # The top level takes no option with a value: the first word is the command.
    command = next((a for a in argv if not a.startswith("-")), None)
    args = build_parser(command if command in COMMANDS else None).parse_args(argv)
    args.command_line = ["impedance-cosim", *argv]
    with sigterm_raises():
        return _dispatch(args)


def entry() -> None:
    """The console script: main(), then leave the process safely (see cosim.leave.exit_process). A
    Ctrl-C before a command has taken over its signals (while the modules load, the arguments
    are read) is one line and exit status 130 too, never a traceback (no FMU is loaded then:
    the commands catch their own interrupts)."""
    try:
        from impedance_cosim.cosim.leave import exit_process

        status = main()
    except KeyboardInterrupt:
        print("impedance-cosim: interrupted (SIGINT) while starting", file=sys.stderr)
        raise SystemExit(128 + signal.SIGINT) from None
    exit_process(status)


RUN_EXIT_STATUS = (
    "exit status: 0 every run ok; 3 a run diverged (a result: its rows, summary and Fig. 4 are"
    " written); 1 a run failed; 2 bad input; 130/143 interrupted by SIGINT/SIGTERM"
)


def _dispatch(args: argparse.Namespace) -> int:
    """Run a subcommand; every failure becomes one line on stderr and an exit status:
    2 bad input, 1 a failed run or other error, 128 + signal number when interrupted; a command
    may return 3 itself: a run diverged, which is a result (cosim.results.result.exit_status)."""
    from impedance_cosim.apps.options import CliError
    from impedance_cosim.cosim.fmus.fmi2 import FmuError
    from impedance_cosim.cosim.master.master import MasterError
    from impedance_cosim.cosim.ssp.read import SspError
    from impedance_cosim.packaging.toolchains import CompileError
    from impedance_cosim.util.atomic import FolderBusyError
    from impedance_cosim.util.interrupt import RunInterrupted

    prefix = f"impedance-cosim {args.command}:"
    try:
        try:
            return args.func(args)
        except Exception as exc:  # raised while an interruption unwound: it is the interruption
            interruption = _interruption_behind(exc)
            if interruption is None:
                raise
            raise interruption from None
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


def _interruption_behind(exc: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C or SIGTERM during whose handling exc was raised, if any (e.g. a closed pipe's
    EBADF from subprocess's clean-up when the signal landed while it started a compiler)."""
    seen: set[int] = set()
    context = exc.__context__
    while context is not None and id(context) not in seen:
        if isinstance(context, KeyboardInterrupt):
            return context
        seen.add(id(context))
        context = context.__context__
    return None


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


if __name__ == "__main__":
    entry()
