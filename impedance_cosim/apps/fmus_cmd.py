"""`impedance-cosim fmus`: the FMUs and system archives this installation runs (an installed
wheel's packaged ones, or a clone's fmus/), listed with their sizes or copied where the user
wants them (e.g. for Simulink or Dymola): `--copy-to DIR`, which never overwrites a differing
file unless `--force`."""

from __future__ import annotations

import argparse
from pathlib import Path

from impedance_cosim.apps.options import FMUS_DIR, CliError
from impedance_cosim.packaging.wheel_fmus import archive_files, copy_files

HELP = "list the packaged FMUs and system archives, or copy them (--copy-to DIR)"


def add_parser(sub) -> None:
    """The `fmus` subcommand."""
    p = sub.add_parser("fmus", help=HELP, description=HELP + f"; they are in {FMUS_DIR}")
    p.add_argument("--copy-to", metavar="DIR", help="copy them into DIR (made if missing)")
    p.add_argument("--force", action="store_true",
                   help="with --copy-to: overwrite files in DIR that differ")  # fmt: skip
    p.set_defaults(func=cmd_fmus)


def available() -> list[str]:
    """The FMUs and archives in FMUS_DIR (relative paths); CliError when there are none."""
    names = archive_files(FMUS_DIR) if FMUS_DIR.is_dir() else []
    if not names:
        raise CliError(f"no FMUs in {FMUS_DIR}: build them with `impedance-cosim build`")
    return names


def cmd_fmus(args: argparse.Namespace) -> int:
    if args.force and not args.copy_to:
        raise CliError("--force goes with --copy-to DIR")
    names = available()
    if args.copy_to is None:
        for name in names:
            print(f"{(FMUS_DIR / name).stat().st_size:>12,d}  {name}")
        print(f"{len(names)} files in {FMUS_DIR}")
        return 0
    return copy_to(Path(args.copy_to), names, args.force)


def copy_to(dest: Path, names: list[str], force: bool) -> int:
    """Copy names from FMUS_DIR into dest: files already there with the same bytes are left,
    differing ones refused (nothing copied) unless force."""
    if dest.exists() and not dest.is_dir():
        raise CliError(f"--copy-to {dest} is not a folder")
    blocked = [n for n in names if (dest / n).exists() and not (dest / n).is_file()]
    if blocked:
        raise CliError(f"--copy-to {dest}: {blocked[0]} is there and is not a file")
    same = [n for n in names if (dest / n).is_file() and _same(FMUS_DIR / n, dest / n)]
    differ = [n for n in names if (dest / n).is_file() and n not in same]
    if differ and not force:
        more = ", ..." if len(differ) > 1 else ""
        raise CliError(f"--copy-to {dest}: {len(differ)} file(s) there differ ({differ[0]}{more}):"
                       " not overwritten without --force")  # fmt: skip
    todo = [n for n in names if n not in same]
    try:
        copy_files(FMUS_DIR, dest, todo)
    except OSError as exc:
        raise CliError(f"--copy-to {dest}: {exc.strerror or exc}: {exc.filename}") from None
    for name in todo:
        print(f"copied {dest / name}{' (overwritten)' if name in differ else ''}")
    if same:
        print(f"{len(same)} file(s) already in {dest} with the same bytes, left as they are")
    print(f"{len(todo)} file(s) copied from {FMUS_DIR} into {dest}")
    return 0


def _same(a: Path, b: Path) -> bool:
    """True when the two files hold the same bytes."""
    if a.stat().st_size != b.stat().st_size:
        return False
    return a.read_bytes() == b.read_bytes()
