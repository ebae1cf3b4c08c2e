"""The FMI 3.0 array edition (fmus/fmi3/arrays/): the joint vectors as fixed-size Float64 arrays.

Written from the scalar edition's modelDescription.xml (fmi3_description.py), which stays as it
is: each array replaces its scalar elements (consecutive variables of the table) by one Float64
variable with `<Dimension start="N"/>`, whose value reference is its first element's, whose start
values are the elements' in order, and whose dependencies are the union of theirs. The C side
(native/src/fmi3_values.c with fmi3_arrays.c) maps the array's value reference to the same slots
(FMI3_ARRAYS, appended to fmi3_config.h).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass


@dataclass(frozen=True)
class Fmi3Array:
    """A fixed-size Float64 array variable made of consecutive scalar variables of the table."""

    name: str
    elements: tuple[str, ...]
    description: str


_Q = Fmi3Array("q", ("q1", "q2", "q3"), "Joint angles, measured (encoder)")
_FT = Fmi3Array(
    "ft", ("fx", "fy", "n"), "Wrist F/T sensor: force on the environment x, y (N), moment (N.m)"
)
_TAU = Fmi3Array("tau", ("tau1", "tau2", "tau3"), "Joint torques")
# the array variables of each model's array edition (FMUS keys)
ARRAYS3 = {"plant": (_TAU, _Q, _FT), "controller": (_Q, _FT, _TAU)}
# what the array edition does not declare: its partial derivatives are the scalar edition's
NOT_IN_ARRAY_EDITION = ("providesDirectionalDerivatives", "maxOutputDerivativeOrder")


def array_slots(xml: bytes, arrays: tuple[Fmi3Array, ...]) -> list[tuple[int, int]]:
    """(value reference, size) of each array in the scalar edition's description xml, checked:
    its elements must be Float64 variables with consecutive value references."""
    vr_of = {
        v.get("name"): (v.tag, int(v.get("valueReference")))
        for v in ET.fromstring(xml).find("ModelVariables")
    }
    slots = []
    for a in arrays:
        found = [vr_of.get(e) for e in a.elements]
        first = found[0][1] if found[0] else None
        if any(f is None or f[0] != "Float64" for f in found) or [f[1] for f in found] != list(
            range(first, first + len(found))
        ):
            raise ValueError(f"array {a.name}: {a.elements} are not consecutive Float64 variables")
        slots.append((first, len(a.elements)))
    return slots


def c_arrays3(xml: bytes, arrays: tuple[Fmi3Array, ...]) -> str:
    """The lines the array edition appends to fmi3_config.h: FMI3_ARRAYS, {value reference,
    size} of each array (native/src/fmi3_arrays.c)."""
    items = ", ".join(f"{{{vr}u, {n}u}}" for vr, n in array_slots(xml, arrays))
    head = "/* the array variables: {value reference, size} */\n"
    return head + f"#define FMI3_ARRAYS {{{items}}}\n"


def array_description3(xml: bytes, arrays: tuple[Fmi3Array, ...]) -> bytes:
    """The array edition's modelDescription.xml from the scalar edition's (xml)."""
    slots = array_slots(xml, arrays)
    root = ET.fromstring(xml)
    head = {}  # value reference of every element -> its array's
    for vr, n in slots:
        head.update({vr + k: vr for k in range(n)})
    for interface in ("ModelExchange", "CoSimulation"):
        for element in root.findall(interface):
            for name in NOT_IN_ARRAY_EDITION:
                element.attrib.pop(name, None)
    mv = root.find("ModelVariables")
    for a, (vr, n) in zip(arrays, slots, strict=True):
        members = [v for v in mv if int(v.get("valueReference")) in range(vr, vr + n)]
        _array_variable(members[0], members, a)
        for v in members[1:]:
            mv.remove(v)
    _array_structure(root.find("ModelStructure"), head)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _array_variable(first: ET.Element, members: list[ET.Element], a: Fmi3Array) -> None:
    """Turn the first element's variable into the array: its name, description, the elements'
    start values in order, one unit only if they share it, a Dimension of fixed size."""
    starts = [v.get("start") for v in members]
    first.set("name", a.name)
    first.set("description", a.description)
    if starts[0] is not None:
        first.set("start", " ".join(starts))
    for unit_attr in ("declaredType", "unit", "displayUnit"):
        if len({v.get(unit_attr) for v in members}) > 1:
            first.attrib.pop(unit_attr, None)
    ET.SubElement(first, "Dimension", {"start": str(len(members))})


def _array_structure(ms: ET.Element, head: dict[int, int]) -> None:
    """ModelStructure over the arrays: one entry per array (the union of its elements'
    dependencies, a dependency kind `dependent` where they differ), every dependency on an
    element turned into one on its array."""
    merged: dict[tuple[str, int], ET.Element] = {}
    for entry in list(ms):
        vr = int(entry.get("valueReference"))
        key = (entry.tag, head.get(vr, vr))
        deps = _dependencies(entry, head)
        if key in merged:
            ms.remove(entry)
            _merge(merged[key], deps)
        else:
            merged[key] = entry
            entry.set("valueReference", str(key[1]))
            _write(entry, deps)


def _dependencies(entry: ET.Element, head: dict[int, int]) -> dict[int, str | None] | None:
    """An entry's dependencies as {value reference: kind}, elements mapped to their arrays
    (None: no dependencies attribute, i.e. depends on every known)."""
    if entry.get("dependencies") is None:
        return None
    vrs = [int(d) for d in entry.get("dependencies").split()]
    kinds = entry.get("dependenciesKind", "").split() or [None] * len(vrs)
    deps: dict[int, str | None] = {}
    for vr, kind in zip(vrs, kinds, strict=True):
        vr = head.get(vr, vr)
        deps[vr] = kind if deps.get(vr, kind) == kind else "dependent"
    return deps


def _merge(entry: ET.Element, deps: dict[int, str | None] | None) -> None:
    """Add deps to an entry's dependencies (written back)."""
    current = _dependencies(entry, {})
    if current is None or deps is None:
        _write(entry, None)
        return
    for vr, kind in deps.items():
        current[vr] = kind if current.get(vr, kind) == kind else "dependent"
    _write(entry, current)


def _write(entry: ET.Element, deps: dict[int, str | None] | None) -> None:
    """Set an entry's dependencies and dependenciesKind attributes from deps."""
    entry.attrib.pop("dependencies", None)
    entry.attrib.pop("dependenciesKind", None)
    if deps is None:
        return
    entry.set("dependencies", " ".join(str(vr) for vr in deps))
    if deps and all(kind is not None for kind in deps.values()):
        entry.set("dependenciesKind", " ".join(deps.values()))
