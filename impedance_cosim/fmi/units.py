"""The units the models use: SI base-unit exponents, the physical quantity of each (FMI
TypeDefinitions) and the unit a tool should show a value in (FMI DisplayUnit); the
<UnitDefinitions> element written from them (FMI 2.0 and 3.0). Standard library only: bundled
in the Python FMUs."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

# Base-unit exponents (kg, m, s, rad) of every unit the models use.
UNITS: dict[str, dict[str, int]] = {
    "1": {},
    "m": {"m": 1},
    "rad": {"rad": 1},
    "s": {"s": 1},
    "kg": {"kg": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N/m": {"kg": 1, "s": -2},
    "N.s/m": {"kg": 1, "s": -1},
    "N.m/rad": {"kg": 1, "m": 2, "s": -2, "rad": -1},
    "N.m.s/rad": {"kg": 1, "m": 2, "s": -1, "rad": -1},
    "kg.m2": {"kg": 1, "m": 2},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "rad/s": {"rad": 1, "s": -1},
    "rad/s2": {"rad": 1, "s": -2},
    "1/s": {"s": -1},
    "Hz": {"s": -1},
}

# The physical quantity of each unit (FMI TypeDefinitions: one SimpleType per unit) and the unit
# a tool should show a value in (FMI DisplayUnit: display = factor * value + offset).
QUANTITIES: dict[str, str] = {
    "1": "Dimensionless",
    "m": "Length",
    "rad": "Angle",
    "s": "Time",
    "kg": "Mass",
    "N": "Force",
    "N.m": "Torque",
    "N/m": "TranslationalStiffness",
    "N.s/m": "TranslationalDamping",
    "N.m/rad": "RotationalStiffness",
    "N.m.s/rad": "RotationalDamping",
    "kg.m2": "MomentOfInertia",
    "m/s": "Velocity",
    "m/s2": "Acceleration",
    "rad/s": "AngularVelocity",
    "rad/s2": "AngularAcceleration",
    "1/s": "Rate",
    "Hz": "Frequency",
}
DEG = 180.0 / math.pi
DISPLAY_UNITS: dict[str, tuple[str, float, float]] = {
    "rad": ("deg", DEG, 0.0),
    "rad/s": ("deg/s", DEG, 0.0),
    "rad/s2": ("deg/s2", DEG, 0.0),
    "N.m/rad": ("N.m/deg", 1.0 / DEG, 0.0),
    "N.m.s/rad": ("N.m.s/deg", 1.0 / DEG, 0.0),
}


def add_unit_definitions(root: ET.Element, used: list[str]) -> None:
    """<UnitDefinitions> of the named units (SI base-unit exponents, display units), the same
    element in FMI 2.0 and 3.0; a unit missing from UNITS is a ValueError."""
    unknown = [u for u in used if u not in UNITS]
    if unknown:
        raise ValueError(f"units {unknown} are not defined in UNITS")
    units = ET.SubElement(root, "UnitDefinitions")
    for u in used:
        unit = ET.SubElement(units, "Unit", {"name": u})
        ET.SubElement(unit, "BaseUnit", {k: str(e) for k, e in UNITS[u].items()})
        if u in DISPLAY_UNITS:
            name, factor, offset = DISPLAY_UNITS[u]
            display = {"name": name, "factor": repr(factor), "offset": repr(offset)}
            ET.SubElement(unit, "DisplayUnit", display)
