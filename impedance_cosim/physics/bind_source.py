"""The Python source of arm_terms.py: the arm's terms as closures bound to parameter values.

Build-time only (called by derivation.py, not bundled in the FMUs). Input: each term as printed
statements (temporary = expression) and result expressions, exactly as the C file prints them.
Output: one `bind(p)` whose closures evaluate those same expressions, except that every
subexpression of parameters alone is computed once, in bind. Python evaluates `a + b + c` as
`(a + b) + c`, so a hoisted subtree is the very same sequence of floating-point operations:
the results stay bit-identical with the per-call evaluation and with the native arm_terms.c
(tests/test_arm.py checks it on random states). forward_dynamics is H^-1 (tau - C qd - F qd - g)
fused into one function, with the operations of linalg3.matvec and linalg3.solve in their order.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass

FRICTION = ("f1", "f2", "f3")


@dataclass
class Term:
    """One generated function: its arguments, temporaries (name, expression) and results."""

    name: str
    doc: str
    args: list[str]
    temps: list[tuple[str, str]]
    results: list[str]
    shape: tuple[int, int]


class _Hoister(ast.NodeTransformer):
    """Replace every maximal parameter-only subtree of an expression by a bound name."""

    def __init__(self, constants: set[str], bound: list[tuple[str, str]]) -> None:
        self.constants = constants  # names known in bind's scope
        self.bound = bound  # (name, source) assigned in bind, in order

    def is_constant(self, node: ast.AST) -> bool:
        if isinstance(node, ast.Name):
            return node.id in self.constants
        if isinstance(node, ast.Constant):
            return True
        if isinstance(node, (ast.BinOp, ast.UnaryOp, ast.Call)):
            return all(self.is_constant(c) for c in ast.iter_child_nodes(node) if _is_value(c))
        return False

    def bind(self, node: ast.expr) -> ast.expr:
        """The name holding node's value, computed once in bind."""
        source = ast.unparse(node)
        for name, known in self.bound:
            if known == source:
                return ast.Name(name, ast.Load())
        name = f"k{len(self.bound)}"
        self.bound.append((name, source))
        self.constants.add(name)
        return ast.Name(name, ast.Load())

    def generic_visit(self, node: ast.AST) -> ast.AST:
        if isinstance(node, ast.expr) and not isinstance(node, (ast.Name, ast.Constant)):
            if self.is_constant(node):
                return self.bind(node)
        return super().generic_visit(node)


def _is_value(node: ast.AST) -> bool:
    return isinstance(node, ast.expr) and not (
        isinstance(node, ast.Name) and node.id in ("cos", "sin")
    )


def hoist(
    statements: list[tuple[str, str]], results: list[str], hoister: _Hoister
) -> tuple[list[tuple[str, str]], list[str]]:
    """Statements and results with parameter-only parts moved into the hoister's bound list; a
    temporary that is wholly parameter-only becomes a bound name itself (renamed)."""
    renames: dict[str, str] = {}

    def rewrite(source: str) -> ast.expr:
        tree = ast.parse(source, mode="eval").body
        tree = _Rename(renames).visit(tree)
        if isinstance(tree, ast.Name) and tree.id in hoister.constants:
            return tree
        return hoister.visit(tree)

    kept = []
    for name, source in statements:
        tree = rewrite(source)
        if isinstance(tree, ast.Name) and tree.id in hoister.constants:
            renames[name] = tree.id
        else:
            kept.append((name, ast.unparse(tree)))
    return kept, [ast.unparse(rewrite(r)) for r in results]


def reuse(
    statements: list[tuple[str, str]], results: list[str]
) -> tuple[list[tuple[str, str]], list[str]]:
    """Drop copies (a temporary that is a name or a number is replaced by it) and compute each
    value once: a subexpression equal to an earlier temporary's expression, up to the order of
    the two operands of + or * (commutative, exactly, in IEEE arithmetic), becomes that name.
    E.g. the Cramer cofactors of the symmetric H: three of them equal three others."""
    renames: dict[str, ast.expr] = {}
    known: dict[tuple, str] = {}

    def rewrite(source: str) -> ast.expr:
        tree = _Substitute(renames).visit(ast.parse(source, mode="eval").body)
        return _Reuse(known).visit(tree)

    kept = []
    for name, source in statements:
        tree = rewrite(source)
        if isinstance(tree, (ast.Name, ast.Constant)):
            renames[name] = tree
            continue
        known.setdefault(_key(tree), name)
        kept.append((name, ast.unparse(tree)))
    return kept, [ast.unparse(rewrite(r)) for r in results]


def _key(node: ast.AST) -> tuple:
    """A value's structure, with the operands of + and * in a canonical order."""
    if isinstance(node, ast.Name):
        return ("name", node.id)
    if isinstance(node, ast.Constant):
        return ("const", repr(node.value))
    if isinstance(node, ast.BinOp):
        op, left, right = type(node.op).__name__, _key(node.left), _key(node.right)
        if op in ("Add", "Mult") and right < left:
            left, right = right, left
        return (op, left, right)
    if isinstance(node, ast.UnaryOp):
        return (type(node.op).__name__, _key(node.operand))
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and not node.keywords:
        return ("call", node.func.id, *map(_key, node.args))
    return ("source", ast.unparse(node))


class _Reuse(ast.NodeTransformer):
    def __init__(self, known: dict[tuple, str]) -> None:
        self.known = known

    def generic_visit(self, node: ast.AST) -> ast.AST:
        if isinstance(node, ast.expr) and not isinstance(node, (ast.Name, ast.Constant)):
            name = self.known.get(_key(node))
            if name is not None:
                return ast.Name(name, ast.Load())
        return super().generic_visit(node)


class _Substitute(ast.NodeTransformer):
    def __init__(self, renames: dict[str, ast.expr]) -> None:
        self.renames = renames

    def visit_Name(self, node: ast.Name) -> ast.expr:
        return self.renames.get(node.id, node)


class _Rename(ast.NodeTransformer):
    def __init__(self, renames: dict[str, str]) -> None:
        self.renames = renames

    def visit_Name(self, node: ast.Name) -> ast.Name:
        return ast.Name(self.renames.get(node.id, node.id), ast.Load())


def _fused_forward_dynamics(terms: dict[str, Term]) -> Term:
    """H^-1 (tau - C qd - F qd - g) in one body: coriolis, gravity and inertia with prefixed
    temporaries, then Arm.forward_dynamics' matvec, right-hand side and Cramer solve."""
    temps: list[tuple[str, str]] = []
    values = {}
    for key, prefix in (("coriolis", "c"), ("gravity", "g"), ("inertia", "h")):
        term = terms[key]
        renames = {name: f"{prefix}_{name}" for name, _ in term.temps}

        def renamed(source: str, renames: dict[str, str] = renames) -> str:
            return ast.unparse(_Rename(renames).visit(ast.parse(source, mode="eval").body))

        temps += [(renames[name], renamed(source)) for name, source in term.temps]
        values[key] = [renamed(r) for r in term.results]
    c, g, h = values["coriolis"], values["gravity"], values["inertia"]
    qd = ("qd1", "qd2", "qd3")
    temps += [(f"C{i}", c[i]) for i in range(9)]
    temps += [(f"H{i}", h[i]) for i in range(9)]
    for r in range(3):  # linalg3.matvec(C, qd), then Arm.forward_dynamics' right-hand side
        cqd = f"C{3 * r} * qd1 + C{3 * r + 1} * qd2 + C{3 * r + 2} * qd3"
        temps.append((f"cqd{r}", cqd))
        temps.append((f"r{r}", f"tau{r + 1} - cqd{r} - {FRICTION[r]} * {qd[r]} - ({g[r]})"))
    # linalg3.solve(H, r): a b c / d e f / g h i = H0 .. H8
    temps += [
        ("c00", "H4 * H8 - H5 * H7"),
        ("c01", "H5 * H6 - H3 * H8"),
        ("c02", "H3 * H7 - H4 * H6"),
        ("inv_det", "1.0 / (H0 * c00 + H1 * c01 + H2 * c02)"),
    ]
    results = [
        "(c00 * r0 + (H2 * H7 - H1 * H8) * r1 + (H1 * H5 - H2 * H4) * r2) * inv_det",
        "(c01 * r0 + (H0 * H8 - H2 * H6) * r1 + (H2 * H3 - H0 * H5) * r2) * inv_det",
        "(c02 * r0 + (H1 * H6 - H0 * H7) * r1 + (H0 * H4 - H1 * H3) * r2) * inv_det",
    ]
    doc = (
        "qdd = H^-1 (tau - C qd - F qd - g), eq. (5), on plain floats; tau is the net joint"
        " torque. Raises ZeroDivisionError when H is exactly singular."
    )
    args = ["q1", "q2", "q3", "qd1", "qd2", "qd3", "tau1", "tau2", "tau3"]
    return Term("forward_dynamics", doc, args, temps, results, (3, 1))


def python_source(header: str, params: list[str], terms: list[Term], optimize: bool = True) -> str:
    """arm_terms.py: bind(p) with every term (and the fused forward dynamics) as a closure.
    optimize=False leaves out hoist() and reuse(): the printed expressions evaluated per call,
    the reference tests/test_derivation.py compares the optimized source with, bit for bit."""
    by_name = {t.name: t for t in terms}
    all_terms = [*terms, _fused_forward_dynamics(by_name)]
    hoister = _Hoister(set(params), [])
    bodies = []
    for term in all_terms:
        temps, results = term.temps, term.results
        if optimize:
            temps, results = reuse(*hoist(temps, results, hoister))
        bodies.append((term, temps, results))
    names = ", ".join(t.name for t in all_terms)
    lines = [
        f'"""{header}',
        "",
        "bind(p) returns the arm's terms for the parameter values p, as closures on plain floats",
        "(matrices are tuples of rows). Every subexpression of the parameters alone is computed",
        "once, in bind: the same floating-point operations as per call, so the results are",
        "bit-identical with the native arm_terms.c.",
        '"""',
        "",
        "# ruff: noqa",
        "from math import cos, sin",
        "from types import SimpleNamespace",
        "",
        "",
        "def bind(p):",
        f'    """SimpleNamespace of {names} for the parameters p."""',
    ]
    lines += [f"    {n} = p.{n}" for n in params]
    lines += [f"    {name} = {source}" for name, source in hoister.bound]
    for term, temps, results in bodies:
        lines += ["", f"    def {term.name}({', '.join(term.args)}):", f'        """{term.doc}"""']
        if "q" in term.args:
            lines.append("        q1, q2, q3 = q")
        if "qd" in term.args:
            lines.append("        qd1, qd2, qd3 = qd")
        lines += [f"        {name} = {source}" for name, source in temps]
        lines += _return(results, term.shape)
    lines += ["", f"    return SimpleNamespace({', '.join(f'{n}={n}' for n in names.split(', '))})"]
    return "\n".join(lines) + "\n"


def _return(values: list[str], shape: tuple[int, int]) -> list[str]:
    values = [f"{v}.0" if v.lstrip("-").isdigit() else v for v in values]  # floats, never ints
    if shape == (1, 1):
        return [f"        return {values[0]}"]
    if shape[1] == 1:
        return [f"        return ({', '.join(values)})"]
    rows = [f"({', '.join(values[3 * r : 3 * r + 3])})" for r in range(3)]
    return ["        return (", *[f"            {row}," for row in rows], "        )"]
