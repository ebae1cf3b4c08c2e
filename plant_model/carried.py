"""The robot description files a Python plant FMU carries (MujocoPlant's MJCF, PinocchioPlant's
URDF): the build writes them into the FMU as the module carried_files (packaging/build.py); a
checkout has none."""

from __future__ import annotations

from impedance_cosim.fmi.model import ModelError

try:  # imported with the plant's module (a later import could not find a build's deleted stage)
    from plant_model.carried_files import FILES  # generated into the FMU by the build
except ImportError:  # the checkout: only the build writes it
    FILES: dict[str, str] = {}


def carried_file(name: str) -> str:
    """The text of the carried file `name` (ModelError outside a built FMU)."""
    if name not in FILES:
        raise ModelError(f"{name} is missing (the FMU carries it: rebuild the FMU)")
    return FILES[name]
