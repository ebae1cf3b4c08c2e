"""pythonfmu slave script of the controller FMU: a thin shell over
controller_model.model.ControllerModel."""

from pythonfmu import Fmi2Slave

from controller_model.model import ControllerModel
from impedance_cosim.fmi.fmi2_slave import ModelSlave, hold_slave_module

hold_slave_module(__name__)


class ImpedanceController(ModelSlave, Fmi2Slave):
    """Velocity observer + impedance controller, sampled and held (see ControllerModel)."""

    model_class = ControllerModel
