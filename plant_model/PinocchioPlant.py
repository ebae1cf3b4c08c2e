"""pythonfmu slave script of the Pinocchio plant FMU: a thin shell over
plant_model.urdf_plant.PinocchioPlantModel."""

from pythonfmu import Fmi2Slave

from impedance_cosim.fmi.fmi2_slave import ModelSlave, hold_slave_module
from plant_model.urdf_plant import PinocchioPlantModel

hold_slave_module(__name__)


class PinocchioPlant(ModelSlave, Fmi2Slave):
    """PumaPlant's interface, the arm's dynamics from Pinocchio and the URDF (see
    PinocchioPlantModel)."""

    model_class = PinocchioPlantModel
