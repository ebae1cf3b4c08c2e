"""The command line answers `--version`, `--help` and a mistyped command without loading numpy,
fmpy or dask (only the chosen command's module loads); every command's help line in the top-level
list is the one its own parser registers; every option says what it does and its default."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from impedance_cosim.cli import COMMANDS, build_parser

HEAVY = ("numpy", "fmpy", "dask", "matplotlib", "scipy")


@pytest.mark.parametrize("argv", [["--version"], ["--help"], ["nosuch"], []])
def test_the_top_level_loads_nothing_heavy(argv: list[str]) -> None:
    probe = (
        "import sys\nfrom impedance_cosim.cli import main\n"
        f"try:\n    main({argv!r})\nexcept SystemExit:\n    pass\n"
        f"print([m for m in {HEAVY!r} if m in sys.modules], file=sys.stderr)\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                          timeout=120, check=False)  # fmt: skip
    assert done.stderr.strip().splitlines()[-1] == "[]", done.stderr


def _subcommands(parser: argparse.ArgumentParser) -> argparse._SubParsersAction:
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))


def test_the_help_lines_are_the_commands_own() -> None:
    sub = _subcommands(build_parser("*"))
    assert {c.dest: c.help for c in sub._choices_actions} == {
        n: h for n, (h, _) in COMMANDS.items()
    }
    assert set(sub.choices) == set(COMMANDS)


def test_every_option_says_what_it_does_and_its_default() -> None:
    for name, parser in _subcommands(build_parser("*")).choices.items():
        for action in parser._actions:
            if action.dest == "help":
                continue
            where = f"{name} {'/'.join(action.option_strings) or action.dest}"
            assert action.help, f"{where} has no help"
            flag = isinstance(action, argparse._StoreTrueAction | argparse._StoreFalseAction)
            if action.default not in (None, False, [], argparse.SUPPRESS) and not flag:
                assert "default" in action.help, f"{where}: help does not say its default"


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_each_command_parses_with_only_its_own_module(command: str) -> None:
    parser = build_parser(command)
    assert _subcommands(parser).choices[command]._actions[1:], command  # more than --help


@pytest.mark.parametrize("argv", [["--version"], ["--help"]])
def test_the_console_script_loads_nothing_heavy(argv: list[str]) -> None:
    """entry() (what `impedance-cosim` runs) too: its safe exit must not pull fmpy in."""
    probe = (
        "import atexit, sys\nfrom impedance_cosim.cli import entry\n"
        f"atexit.register(lambda: print([m for m in {HEAVY!r} if m in sys.modules],"
        " file=sys.stderr))\n"
        f"sys.argv = ['impedance-cosim', *{argv!r}]\nentry()\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                          timeout=120, check=False)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip().splitlines()[-1] == "[]", done.stderr
