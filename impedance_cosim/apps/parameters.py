"""`run --list-parameters`: every name `--set` accepts in a system archive, with its type, unit,
the value the chosen scenario gives it (or the FMU's start value) and the FMU's description, so a
user need not open the model descriptions to find a name."""

from __future__ import annotations

import re

from impedance_cosim.cosim.fmus.files import model_description
from impedance_cosim.cosim.master.master import MasterError
from impedance_cosim.cosim.ssp.read import SystemDescription


def parameter_lines(system: SystemDescription, scenario: str | None) -> list[str]:
    """One line per settable parameter of every component (and per K1..K3-style group, which
    `--set controller.K=80` sets at once), the values as the scenario binds them."""
    sets = system.parameter_sets
    name = next(iter(sets), "") if scenario is None else scenario
    if name not in sets and sets:
        raise MasterError(f"no parameter set {name!r} in the SSD (have {list(sets)})")
    bound = {p.name: p.value for p in sets.get(name, [])}
    rows: list[tuple[str, str, str, str]] = []
    for comp in system.components:
        params = [v for v in model_description(comp.fmu).modelVariables
                  if v.causality == "parameter"]  # fmt: skip
        groups: dict[str, list[str]] = {}
        for v in params:
            full = f"{comp.name}.{v.name}"
            value = bound.get(full)
            shown = f"{value} (scenario)" if value is not None else f"{v.start} (FMU start)"
            rows.append((full, f"{v.type} [{v.unit or '-'}]", shown, v.description or ""))
            if m := re.fullmatch(r"(.+?)_?[123]", v.name):
                groups.setdefault(m.group(1), []).append(v.name)
        for stem, members in groups.items():
            if len(members) > 1 and not any(v.name == stem for v in params):
                rows.append((f"{comp.name}.{stem}", "shorthand", "", f"sets {', '.join(members)}"))
    width = max((len(r[0]) for r in rows), default=0)
    kind = max((len(r[1]) for r in rows), default=0)
    head = f"parameters of scenario {name!r} (set one with --set component.variable=value):"
    return [head] + [f"  {a:<{width}}  {b:<{kind}}  {c}  {d}".rstrip() for a, b, c, d in rows]
