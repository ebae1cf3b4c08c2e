"""The architecture (docs/architecture.md) as a test: each layer imports only the layers below it,
and no modules import each other in a cycle. Every import counts, also those inside functions."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("impedance_cosim", "plant_model", "controller_model", "bridge_model")

# bottom to top; a module belongs to the first layer whose prefix matches its name
LAYERS = [
    ("util", ["impedance_cosim.util", "impedance_cosim.version"]),
    ("physics", ["impedance_cosim.physics"]),
    ("fmi", ["impedance_cosim.fmi"]),
    ("models", ["plant_model", "controller_model", "bridge_model"]),
    ("cosim", ["impedance_cosim.cosim"]),
    ("packaging", ["impedance_cosim.packaging"]),
    ("apps", ["impedance_cosim.apps"]),
    # the root package is the API's facade (its __getattr__ imports api): a lower layer that
    # imports it (`from impedance_cosim import __version__`) imports upward, around a cycle
    (
        "interfaces",
        [
            "impedance_cosim",
            "impedance_cosim.api",
            "impedance_cosim.cli",
            "impedance_cosim.__main__",
        ],
    ),  # fmt: skip
]
ROOT = "impedance_cosim"


def layer_of(module: str) -> int:
    """Index of the layer of a module (the longest matching prefix wins)."""
    best, rank = -1, -1
    for i, (_, prefixes) in enumerate(LAYERS):
        for p in prefixes:
            exact = p == "impedance_cosim"  # the root package itself, not everything below it
            if module == p if exact else module == p or module.startswith(p + "."):
                if len(p) > best:
                    best, rank = len(p), i
    if rank < 0:
        raise AssertionError(f"{module} is in no layer: add it to LAYERS and docs/architecture.md")
    return rank


def modules() -> dict[str, Path]:
    out = {}
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob("*.py")):
            parts = path.relative_to(REPO).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = path
    return out


def imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The project modules a module imports (`from a import b` counts b when b is a module)."""
    is_package = path.name == "__init__.py"
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against this module's package
                base = name.split(".")
                base = base if is_package else base[:-1]
                base = base[: len(base) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            names = [f"{module}.{a.name}" for a in node.names]
            # `from pkg import submodule` runs pkg's __init__ but uses none of its names: it
            # counts pkg only when a name imported is not a module of ours (an attribute of pkg)
            uses_package = any(n not in known for n in names)
            targets = ([module] if uses_package else []) + names
        else:
            continue
        for t in targets:
            while t and t not in known:
                t = t.rpartition(".")[0]
            if t and t != name:
                found.add(t)
    return found


MODULES = modules()
GRAPH = {n: imports(n, p, set(MODULES)) for n, p in MODULES.items()}


def test_every_module_has_a_layer():
    for name in MODULES:
        layer_of(name)


def upward(name: str, deps: set[str]) -> list[str]:
    """The imports of module name that go to a higher layer ("dep (layer)"); a module's own
    parent packages do not count, but for the root package (the API's facade)."""
    own = layer_of(name)
    return sorted(
        f"{dep} ({LAYERS[layer_of(dep)][0]})"
        for dep in deps
        if layer_of(dep) > own and not (dep != ROOT and (name + ".").startswith(dep + "."))
    )


@pytest.mark.parametrize("name", sorted(MODULES))
def test_imports_go_downward(name):
    """A module imports only from its own layer or below."""
    found = upward(name, GRAPH[name])
    assert not found, f"{name} ({LAYERS[layer_of(name)][0]}) imports upward: {', '.join(found)}"


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components larger than one module: the import cycles."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def cycle_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """The import graph less a package's imports of its own submodules (but the root's)."""
    return {
        n: {d for d in deps if n == ROOT or not d.startswith(n + ".")} for n, deps in graph.items()
    }


def test_no_import_cycles():
    """No modules import each other, directly or around a loop (a package's __init__ importing
    its own submodules is not a cycle, but for the root package: its facade imports api, so a
    module of any layer that imports the root closes a loop through every layer)."""
    found = cycles(cycle_graph(GRAPH))
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_the_checks_can_fail(tmp_path):
    """The checker sees imports (also inside functions), upward ones, and cycles."""
    source = tmp_path / "x.py"
    source.write_text("def f():\n    from impedance_cosim.cosim.master.master import Master\n"
                      "import plant_model.model\n")  # fmt: skip
    known = {"impedance_cosim.cosim.master.master", "plant_model.model", "plant_model"}
    found = imports("impedance_cosim.physics.arm", source, known)
    assert found == {"impedance_cosim.cosim.master.master", "plant_model.model"}
    assert layer_of("impedance_cosim.physics.arm") < layer_of("impedance_cosim.cosim.master.master")
    assert layer_of("impedance_cosim.util.atomic") == layer_of("impedance_cosim.version") == 0
    assert layer_of("impedance_cosim") == layer_of("impedance_cosim.cli") == len(LAYERS) - 1
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_a_lower_layer_importing_the_root_package_is_caught(tmp_path):
    """`from impedance_cosim import __version__` (or `import impedance_cosim`) in a lower layer is
    an upward import and closes a cycle through the facade; `from impedance_cosim import fmi`
    (a submodule) and the leaf `impedance_cosim.version` are not the root."""
    known = set(MODULES)
    for line in ("from impedance_cosim import __version__\n", "import impedance_cosim\n"):
        source = tmp_path / "x.py"
        source.write_text(line)
        deps = imports("impedance_cosim.fmi.variables", source, known)
        assert ROOT in deps, line
        assert upward("impedance_cosim.fmi.variables", deps) == [f"{ROOT} (interfaces)"], line
        graph = {**GRAPH, "impedance_cosim.fmi.variables": deps}
        found = [
            c
            for c in cycles(cycle_graph(graph))
            if ROOT in c and "impedance_cosim.fmi.variables" in c
        ]
        assert found, line  # root -> api -> ... -> fmi.variables -> root
    source.write_text("from impedance_cosim import fmi\nfrom impedance_cosim.version import "
                      "__version__\n")  # fmt: skip
    deps = imports("impedance_cosim.cosim.system.paper", source, known)
    assert ROOT not in deps and "impedance_cosim.version" in deps
    assert upward("impedance_cosim.cosim.system.paper", deps) == []
