"""RunOptions: how the master runs a system, built once by the API or a command and given to
Master. Its values are checked when it is made (MasterError, one line); `for_system` fills what
is left open from the SSD (algorithm, step, stop time) and checks the run's time grid."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from impedance_cosim.cosim.master.realtime import RealtimeOptions
from impedance_cosim.cosim.master.setup import ALGORITHMS, MasterError, step_count
from impedance_cosim.cosim.ssp.read import SystemDescription

LOOPS = ("auto", "c", "python")


@dataclass(frozen=True)
class RunOptions:
    """The options of one run (None: the SSD's value); see the master module's docstring."""

    parameter_set: str | None = None
    """The SSD's parameter set (scenario) to start from; None: its first."""
    overrides: Mapping[str, Any] | None = None
    """Parameter values over the set's, "component.variable" -> value ("controller.K": K1..K3)."""
    overrides_origin: str = "in overrides"
    """Where the overrides came from, for the message naming a bad one ("given with --set")."""
    algorithm: str | None = None
    """"gauss-seidel" or "jacobi"; None: the SSD's, else Gauss-Seidel."""
    step_size: float | None = None
    """The communication step h in s; None: the SSD's."""
    stop_time: float | None = None
    """The stop time in s (the start time is the SSD's); None: the SSD's."""
    divergence_limit: float = 1e6
    """A recorded value beyond it (in magnitude) stops the run as diverged."""
    fmu_files: Mapping[str, Path] | None = None
    """FMU files in place of the SSD's, by component name."""
    loop: str = "auto"
    """"c" (the compiled loop), "python", or "auto": the C loop where it can run the system."""
    realtime: bool | RealtimeOptions = False
    """Pace the steps at wall-clock time (RealtimeOptions: also lock memory, SCHED_FIFO, ...)."""
    step_times: Callable[[int], tuple[float, float]] | None = None
    """Another engine's time grid: step i -> (its start time, its length); Python loop only."""
    zero_start_inputs: bool = False
    """Another engine's start: the first step's connected inputs are 0.0 (Jacobi, Python loop)."""
    extrapolation: str = "none"
    """Jacobi inputs: "none" (held) or "linear" (y + h dy/dt where the source gives dy/dt)."""

    def __post_init__(self) -> None:
        """MasterError unless the values go together (those left None are checked later)."""
        if self.algorithm is not None and self.algorithm not in ALGORITHMS:
            raise MasterError(f"algorithm must be one of {ALGORITHMS} (got {self.algorithm!r})")
        if self.loop not in LOOPS:
            raise MasterError(f"loop must be auto, c or python (got {self.loop!r})")
        other_engine = self.step_times or self.zero_start_inputs
        if other_engine and (self.loop == "c" or self.realtime):
            raise MasterError("step_times and zero_start_inputs need the Python loop")
        if self.zero_start_inputs and self.algorithm not in (None, "jacobi"):
            raise MasterError("zero_start_inputs needs the Jacobi algorithm")
        if self.extrapolation != "none" and self.zero_start_inputs:
            raise MasterError(f"extrapolation {self.extrapolation!r} needs the initialized outputs"
                              " as first inputs (not zero_start_inputs)")  # fmt: skip

    def for_system(self, system: SystemDescription) -> RunOptions:
        """These options with the SSD's values where None and the loop another engine's grid
        needs; MasterError when the stop time is not a whole number of steps (or absurd)."""
        algorithm = self.algorithm or system.algorithm or "gauss-seidel"
        step_size = self.step_size if self.step_size is not None else system.step_size
        stop_time = self.stop_time if self.stop_time is not None else system.stop_time
        resolved = dataclasses.replace(
            self,
            algorithm=algorithm,
            step_size=step_size,
            stop_time=stop_time,
            loop="python" if self.step_times or self.zero_start_inputs else self.loop,
        )
        step_count(system.start_time, stop_time, step_size)
        return resolved
