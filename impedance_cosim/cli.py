"""Command-line interface: `impedance-cosim <subcommand>`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _cmd_build(args: argparse.Namespace) -> int:
    from impedance_cosim.build import build_all

    for path in build_all(Path(args.out), args.only or None):
        print(f"built {path}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the impedance-cosim command."""
    parser = argparse.ArgumentParser(
        prog="impedance-cosim",
        description="Impedance control without velocity measurements, as FMI co-simulation.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("build", help="build the FMUs into fmus/")
    p.add_argument(
        "--out",
        default=str(Path(__file__).resolve().parent.parent / "fmus"),
        help="output folder (default: the repository's fmus/)",
    )
    p.add_argument(
        "--only",
        action="append",
        choices=["plant", "controller"],
        help="build only this FMU (repeatable)",
    )
    p.set_defaults(func=_cmd_build)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, FileNotFoundError) as exc:
        print(f"impedance-cosim {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
