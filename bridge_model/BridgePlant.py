"""pythonfmu slave script of the bridge plant FMU: a thin shell over bridge_model.model.BridgeModel.

Status: every failed step returns fmi2Discard with the cause logged (fmi2Error status) and printed
to stderr, like every model here: a refused step (bad input, the robot's ERROR reply) and a broken
link (timeout, robot gone, reply out of sequence, session lost). After a broken link every later
step is refused too. (An exception out of do_step would make pythonfmu 0.7 return fmi2Fatal and
leave the Python interpreter in a state that crashes the next FMU call: never raise there.)
"""

from pythonfmu import Fmi2Slave

from bridge_model.model import BridgeModel
from impedance_cosim.fmi.fmi2_slave import ModelSlave, hold_slave_module

hold_slave_module(__name__)


class BridgePlant(ModelSlave, Fmi2Slave):
    """PumaPlant's interface, answered by an external robot process (see BridgeModel)."""

    model_class = BridgeModel
    _built_with = None

    def _build(self) -> None:
        """Initialization sets the inputs again on every pass; only new parameters need a new
        INIT exchange (the plant's outputs do not depend on its inputs)."""
        params = {n: self._values[n] for n in self._params}
        if self.model is not None and params == self._built_with:
            self._dirty = False
            return
        super()._build()
        self._built_with = params
