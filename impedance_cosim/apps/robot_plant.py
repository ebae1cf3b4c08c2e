"""Which plant the robot process runs (`impedance-cosim robot --plant`): ours (plant_model's
PlantModel, the default) or MuJoCo's (plant_model/mujoco_plant.py), the stand-in for hardware
becoming a third-party simulator behind the same bridge protocol.

The MuJoCo plant steps here exactly as inside fmus/MujocoPlant.fmu: the same model class, the
MJCF the FMU carries written by packaging/mujoco_mjcf.py (from the plant's default parameters;
the INIT parameters then set its numbers), the same do_step calls. So a lock-step run through
the bridge equals the run with MujocoPlant.fmu swapped in, bit for bit (tests/test_hil_mujoco.py).
"""

from __future__ import annotations

from plant_model.model import PlantModel
from plant_model.mujoco_plant import NEEDS, MujocoPlantModel

PLANTS = ("ours", "mujoco")


def plant_class(name: str) -> type:
    """The model class of a --plant choice; ValueError (one line: exit 2) for an unknown name
    or when MuJoCo cannot be imported."""
    if name == "ours":
        return PlantModel
    if name != "mujoco":
        raise ValueError(f"--plant must be one of {', '.join(PLANTS)} (got {name!r})")
    try:
        import mujoco  # noqa: F401
    except ImportError as exc:
        raise ValueError(f"--plant mujoco needs {NEEDS} ({exc})") from None
    return RobotMujocoPlant


class RobotMujocoPlant(MujocoPlantModel):
    """MujocoPlantModel with the MJCF written here instead of carried by an FMU."""

    def mjcf_text(self) -> str:
        from impedance_cosim.packaging.mujoco_mjcf import mujoco_mjcf

        return mujoco_mjcf()
