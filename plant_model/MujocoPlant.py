"""pythonfmu slave script of the MuJoCo plant FMU: a thin shell over
plant_model.mujoco_plant.MujocoPlantModel."""

from pythonfmu import Fmi2Slave

from impedance_cosim.fmi.fmi2_slave import ModelSlave, hold_slave_module
from plant_model.mujoco_plant import MujocoPlantModel

hold_slave_module(__name__)


class MujocoPlant(ModelSlave, Fmi2Slave):
    """PumaPlant's interface, simulated by MuJoCo from the MJCF it carries (see
    MujocoPlantModel)."""

    model_class = MujocoPlantModel
