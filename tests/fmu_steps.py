"""Stepping an FMU instance (impedance_cosim.cosim.fmus.fmi2.FmuInstance) for the tests of saved
and restored FMU states."""

from __future__ import annotations

DT = 1 / 400


def output_names(fmu) -> list[str]:
    """The FMU's output variables, in its model description's order."""
    return [v.name for v in fmu.description.modelVariables if v.causality == "output"]


def rows_after(fmu, outputs: list[str], first: int = 40, stop: int = 60) -> list:
    """The outputs after each of the steps first..stop-1 of DT (the steps after a saved state)."""
    rows = []
    for i in range(first, stop):
        fmu.step(i * DT, DT)
        rows.append(fmu.get(outputs))
    return rows
