"""The FMI 3.0 variant of the glue layer (slave.py) for pythonfmu3: the same ModelSlave mixin on
pythonfmu3's variable types (Float64, Int32, Boolean, String) and enums, plus the `independent`
time variable FMI 3.0 requires, registered after the table (value reference = table size, as in
the native FMI 3.0 FMUs). A slave script lists it first among the bases:

    class PumaPlant3(ModelSlave3, Fmi3Slave):
        model_class = PlantModel
"""

from __future__ import annotations

from typing import Any

from pythonfmu3 import Boolean, Float64, Fmi3Causality, Fmi3Variability, Int32, String
from pythonfmu3.enums import Fmi3Status

from impedance_cosim.fmi.slave import ModelSlave


class ModelSlave3(ModelSlave):
    """Mixin for pythonfmu3.Fmi3Slave (list it first among the bases)."""

    _var_types = {"Real": Float64, "Integer": Int32, "Boolean": Boolean, "String": String}
    _causality = Fmi3Causality
    _variability = Fmi3Variability
    _error_status = Fmi3Status.error

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self._time = 0.0
        self.register_variable(
            Float64(
                "time",
                causality=Fmi3Causality.independent,
                variability=Fmi3Variability.continuous,
                description="Simulation time",
                getter=lambda: self._time,
            )
        )

    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None) -> None:
        super().setup_experiment(start_time, stop_time, tolerance)
        self._time = float(start_time)

    def do_step(self, current_time: float, step_size: float) -> bool:
        ok = super().do_step(current_time, step_size)
        self._time = current_time + step_size if ok else current_time
        return ok

    def _get_fmu_state(self) -> dict[str, Any]:
        return {**super()._get_fmu_state(), "time": self._time}

    def _set_fmu_state(self, state: dict[str, Any]) -> None:
        super()._set_fmu_state(state)
        self._time = state["time"]
