"""The FMI 3.0 variant of the glue layer (fmi2_slave.py) for pythonfmu3: the same ModelSlave mixin
on pythonfmu3's variable types (Float64, Int32, Boolean, String) and enums, plus the `independent`
time variable FMI 3.0 requires, registered after the table (value reference = table size, as in
the native FMI 3.0 FMUs). A slave script lists it first among the bases:

    class PumaPlant3(ModelSlave3, Fmi3Slave):
        model_class = PlantModel
"""

from __future__ import annotations

from typing import Any

from pythonfmu3 import Boolean, Float64, Fmi3Causality, Fmi3Variability, Int32, String
from pythonfmu3.enums import Fmi3Status

from impedance_cosim.fmi.fmi2_slave import ModelSlave


class ModelSlave3(ModelSlave):
    """Mixin for pythonfmu3.Fmi3Slave (list it first among the bases)."""

    _var_types = {"Real": Float64, "Integer": Int32, "Boolean": Boolean, "String": String}
    _causality = Fmi3Causality
    _variability = Fmi3Variability
    _error_status = Fmi3Status.error
    _warning_status = Fmi3Status.warning

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.register_variable(
            Float64(
                "time",
                causality=Fmi3Causality.independent,
                variability=Fmi3Variability.continuous,
                description="Simulation time",
                getter=self._time,
            )
        )

    def _time(self) -> float:
        """The model's time (where its last step ended), else the start time: part of the state
        the model already saves, so FMU states need nothing more."""
        return float(getattr(self.model, "t", self._start_time))
