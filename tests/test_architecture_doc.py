"""docs/architecture.md's module table against the tree: every module it names exists in the
package of its row, and every module of the tree is named in its package's row."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PAGE = REPO / "docs" / "architecture.md"
PACKAGES = ("impedance_cosim", "plant_model", "controller_model", "bridge_model")


def table() -> dict[str, set[str]]:
    """The module table: package path -> the modules its row names (in backticks, outside the
    parenthesised notes)."""
    text = PAGE.read_text()
    rows = text[text.index("## The modules") :].splitlines()
    out = {}
    for row in rows:
        m = re.match(r"\| `([\w/]+)` \| (.*) \|$", row)
        if m:
            names = re.sub(r"\([^)]*\)", "", m.group(2))
            out[m.group(1)] = set(re.findall(r"`(\w+)`", names))
    return out


def tree() -> dict[str, set[str]]:
    """package path -> its modules (without __init__)."""
    out: dict[str, set[str]] = {}
    for top in PACKAGES:
        for path in (REPO / top).rglob("*.py"):
            if "__pycache__" in path.parts or path.stem == "__init__":
                continue
            out.setdefault(path.parent.relative_to(REPO).as_posix(), set()).add(path.stem)
    return out


def test_every_module_named_exists_and_every_module_is_named():
    named, actual = table(), tree()
    assert set(named) == set(actual), set(named) ^ set(actual)
    for package, modules in actual.items():
        assert named[package] == modules, (
            package,
            {"not in the tree": named[package] - modules, "not named": modules - named[package]},
        )
