#!/usr/bin/env python3
"""Fuzz target: the command line's option parsing and the checks made before anything runs.
The bytes split on NUL are argv (decoded as Python decodes a real argv: UTF-8, surrogateescape),
parsed by cli.build_parser("*") and then checked by each command's own validators, never run:
run and swap (--set, the real-time options, --output-interval against --step and --stop),
sweep (_check_options: --grid, --random, --workers, --out ...), stability (_check), robot
(_robot_options, without its token file). May come out: SystemExit 2 (argparse's one line),
SystemExit 0 only for --help or --version, CliError, and what the CLI also prints as one line
with exit status 2: a ValueError (SweepError, StabilityError, ...; not UnicodeDecodeError) with
a one-line message, FileNotFoundError (stability's missing archive)."""

from __future__ import annotations

import argparse
import contextlib
import io
import sys

import _common  # noqa: F401 - sys.path

from impedance_cosim import cli
from impedance_cosim.apps import hil, options
from impedance_cosim.apps.stability import command as stability_command
from impedance_cosim.apps.sweep import command as sweep_command
from impedance_cosim.cosim.master.realtime import realtime_setting

PARSER = cli.build_parser("*")
hil._session_key = lambda token_file: b"k" * 32  # the real one creates --token-file
NO_ARCHIVE = "/nonexistent/impcosim-fuzz.ssp"  # stability's default archive would be built


def _check(args: argparse.Namespace) -> None:
    """The validation of args.command that happens before any build, read or run."""
    if args.command in ("run", "swap"):
        options.parse_overrides(args.set or [])
        realtime_setting(args)
        step = args.step or 1 / 400
        steps = round((args.stop or 20.0) / step) if (args.stop or 20.0) / step < 1e15 else None
        options.output_every(args.output_interval, step, steps)
        options.check_out(args.out)
    elif args.command == "sweep":
        sweep_command._check_options(args)
    elif args.command == "stability":
        args.ssp = args.ssp or NO_ARCHIVE
        stability_command._check(args)
    elif args.command == "robot":
        hil._robot_options(args)


def _help(argv: list[str]) -> bool:
    return any(a.startswith("-h") or "--help".startswith(a) and len(a) > 2 or
               "--version".startswith(a) and len(a) > 2 for a in argv)  # fmt: skip


def entry(data: bytes) -> None:
    argv = [a.decode("utf-8", "surrogateescape") for a in data.split(b"\0")[:40]]
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        try:
            _check(PARSER.parse_args(argv))
        except SystemExit as exc:
            assert exc.code == 2 or (exc.code == 0 and _help(argv)), repr(exc)
        except options.CliError as exc:
            assert str(exc), repr(exc)
        except UnicodeDecodeError:
            raise
        except (ValueError, FileNotFoundError) as exc:
            assert str(exc) and "\n" not in str(exc), repr(exc)


def seeds() -> dict[str, bytes]:
    """Valid command lines of each command (and a few refused ones)."""
    lines = {
        "run": ["run", "--stop", "2", "--step", "0.0025", "--output-interval", "0.01",
                "--set", "controller.K=80", "--out", "/tmp/x"],
        "run-rt": ["run", "--realtime", "--rt-fifo", "10", "--rt-spin", "0.001"],
        "swap": ["swap", "--replace", "plant=fmus/native/PumaPlant.fmu", "--set", "plant.a=1"],
        "sweep": ["sweep", "--grid", "controller.K=10,50", "--grid", "plant.wall_k=lin:1:2:3",
                  "--workers", "2", "--plot", "overshoot", "--out", "/tmp/x"],
        "sweep-random": ["sweep", "--random", "5", "--grid", "controller.B=range:0:10"],
        "stability": ["stability", "--parts", "linear", "--stop", "2"],
        "robot": ["robot", "--tick", "0.001", "--port", "0", "--fault", "drop:3"],
        "build": ["build", "--only", "plant", "--out", "/tmp/x"],
        "bad": ["run", "--stop", "nan", "--output-interval", "1e308", "--step", "1e-300"],
    }  # fmt: skip
    return {k: "\0".join(v).encode() for k, v in lines.items()}


if __name__ == "__main__":
    _common.main(entry)
    sys.exit(0)
