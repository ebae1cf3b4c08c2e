"""pythonfmu slave script of the plant FMU: a thin shell over plant_model.model.PlantModel."""

from pythonfmu import Fmi2Slave

from impedance_cosim.fmi.fmi2_slave import ModelSlave, hold_slave_module
from plant_model.model import PlantModel

hold_slave_module(__name__)


class PumaPlant(ModelSlave, Fmi2Slave):
    """PUMA-560 subset arm against a stiff wall (see PlantModel)."""

    model_class = PlantModel
