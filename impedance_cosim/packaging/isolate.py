"""Module names of their own for the code a Python FMU bundles.

pythonfmu puts an FMU's resources folder on the process's shared sys.path and imports the slave
module by name, so Python's module cache decides which code runs: in a process that already
imported `impedance_cosim` or `plant_model` (our master, a sweep worker, a notebook) every one of
our Python FMUs silently ran that process's copy, not its own; two builds of PumaPlant (a
modified plant swapped in, an older release) silently ran the first one loaded. Here the staged
packages and the slave script get a suffix made of a hash of the bundled sources
(`plant_model` -> `plant_model_<tag>`), and every import of them is rewritten: identical code
shares a name (harmless), different code never does.
"""

from __future__ import annotations

import ast
import hashlib
import shutil
from pathlib import Path

# Top-level packages of ours that a Python FMU may bundle.
ROOTS = ("impedance_cosim", "plant_model", "controller_model", "bridge_model")


class IsolationError(ValueError):
    """Bundled code imports one of our packages in a way the rewrite cannot follow (the build
    command reports it as one error line, exit status 2)."""


def content_tag(stage: Path, script_source: str) -> str:
    """12 hex digits of the SHA-256 of the slave script and every staged .py file (path, bytes)."""
    digest = hashlib.sha256(script_source.encode())
    for f in sorted(stage.rglob("*.py")):
        digest.update(f.relative_to(stage).as_posix().encode() + b"\0" + f.read_bytes())
    return digest.hexdigest()[:12]


def isolate(stage: Path, script: Path, tag: str) -> Path:
    """Rename stage/<root> to stage/<root>_<tag>, rewrite the imports of every staged module and
    of the slave script, and write the script as stage/<stem>_<tag>.py; returns that path."""
    renames = {root: f"{root}_{tag}" for root in ROOTS if (stage / root).is_dir()}
    for root, new in renames.items():
        shutil.move(stage / root, stage / new)
    for f in sorted(stage.rglob("*.py")):
        f.write_text(rewrite_imports(f.read_text(), renames, f.name))
    target = stage / f"{script.stem}_{tag}.py"
    target.write_text(rewrite_imports(script.read_text(), renames, script.name))
    return target


def rewrite_imports(source: str, renames: dict[str, str], where: str = "<source>") -> str:
    """source with every `from root... import ...` of a renamed root pointing at its new name.
    Raises IsolationError for `import root...` (the name would be needed in the code too) and
    if, after the rewrite, any import of an old root remains."""
    tree = ast.parse(source)
    edits = []  # (start line, start col, end line, end col, text)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            new = _renamed(node.module, renames)
            if new != node.module:
                text = ast.unparse(ast.ImportFrom(new, node.names, 0))
                edits.append((node.lineno, node.col_offset, node.end_lineno, node.end_col_offset,
                              text))  # fmt: skip
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if _renamed(alias.name, renames) != alias.name:
                    raise IsolationError(
                        f"{where}:{node.lineno}: `import {alias.name}` cannot be renamed for the"
                        " FMU; use `from ... import ...`"
                    )
    lines = source.splitlines(keepends=True)
    for l0, c0, l1, c1, text in sorted(edits, reverse=True):
        head, tail = lines[l0 - 1][:c0], lines[l1 - 1][c1:]
        lines[l0 - 1 : l1] = [head + text + tail]
    result = "".join(lines)
    for node in ast.walk(ast.parse(result)):  # nothing of the old names is imported any more
        module = getattr(node, "module", None) if isinstance(node, ast.ImportFrom) else None
        if module and node.level == 0 and _renamed(module, renames) != module:
            raise IsolationError(f"{where}:{node.lineno}: `from {module}` was not rewritten")
    return result


def _renamed(module: str, renames: dict[str, str]) -> str:
    root, dot, rest = module.partition(".")
    return renames[root] + dot + rest if root in renames else module
