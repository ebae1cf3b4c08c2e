"""Event-exact stepping (issue 23): the master's fixed communication grid, with each FMI 3.0
Co-Simulation FMU that has event mode (the plant, at its wall contact) stepped up to its events.

What event-exact means here: the controller samples at 400 Hz, so its sampling instants, and the
communication points, stay on the fixed grid t_i = t_0 + i h. Inside a communication step the
plant returns early at each contact switch (earlyReturnAllowed, eventModeUsed); the master
handles the event there (fmi3EnterEventMode, fmi3UpdateDiscreteStates until nothing is left,
fmi3EnterStepMode), records its exact time, and completes the step to t_i+1 on the same,
sample-and-hold, inputs (the controller's torques are constant between its samples). The
recorded rows stay at the grid points; the event times are in EventExactMaster.events.
"""

from __future__ import annotations

import ctypes
import dataclasses
from pathlib import Path
from typing import Any

from impedance_cosim.cosim.fmus.fmi2 import STATUS, FmuError, FmuInstance
from impedance_cosim.cosim.fmus.fmi3 import FmuInstance3, open_fmu
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.master.setup import MasterError
from impedance_cosim.cosim.results.result import RunResult
from impedance_cosim.cosim.ssp.read import SystemDescription

MAX_EVENTS_PER_STEP = 100  # a hang guard: contact chattering inside one communication step


def has_event_mode(description: Any) -> bool:
    """True for an FMI 3.0 Co-Simulation FMU that offers event mode (hasEventMode="true") for
    its own events. One with an input clock (the controller's sample clock) is stepped without
    event mode: its ticks would need the master to set its inputs at each tick, which it does
    not; it samples inside its steps then, as on the fixed grid."""
    cs = getattr(description, "coSimulation", None)
    version = str(getattr(description, "fmiVersion", ""))
    clocks = [v for v in getattr(description, "modelVariables", ()) if v.type == "Clock"]
    return version.startswith("3") and cs is not None and bool(cs.hasEventMode) and not clocks


class EventInstance(FmuInstance3):
    """An FMI 3.0 Co-Simulation FMU instantiated with eventModeUsed and earlyReturnAllowed:
    step(t, h) reaches t + h through the FMU's events, each handled in Event Mode."""

    def _call(self, method: str, *args: Any, **kwargs: Any) -> Any:
        if method == "instantiate":
            kwargs.update(eventModeUsed=True, earlyReturnAllowed=True)
            self.events: list[float] = []
        return super()._call(method, *args, **kwargs)

    def _event_iteration(self) -> None:
        """In Event Mode: fmi3UpdateDiscreteStates until no update is needed, then Step Mode."""
        flags = [ctypes.c_bool() for _ in range(5)]
        when = ctypes.c_double()
        update = self.slave._functions["fmi3UpdateDiscreteStates"]
        for _ in range(MAX_EVENTS_PER_STEP):
            status = update(self.slave.component, *(ctypes.byref(f) for f in flags),
                            ctypes.byref(when))  # fmt: skip
            if status > 1:
                raise self._fail("fmi3UpdateDiscreteStates failed", status)
            if flags[1].value:
                raise FmuError(f"{self.name}: the FMU asks to terminate the simulation")
            if not flags[0].value:
                break
        else:
            raise FmuError(f"{self.name}: discrete states still changing after "
                           f"{MAX_EVENTS_PER_STEP} updates")  # fmt: skip
        self._call("enterStepMode")

    def exit_initialization(self) -> None:
        """fmi3ExitInitializationMode leads to Event Mode (eventModeUsed): iterate, step mode."""
        super().exit_initialization()
        self._event_iteration()

    def step(self, t: float, h: float) -> None:
        """fmi3DoStep from t to t + h, stopping at each event (recorded in self.events)."""
        end, now = t + h, t
        event, terminate, early, last = self._step_out
        for _ in range(MAX_EVENTS_PER_STEP):
            status = self._do_step(self.slave.component, now, end - now, True, *self._step_refs)
            if status > 1:
                raise self._fail(f"doStep at t={now} returned {STATUS[status]}", status)
            if terminate.value:
                raise FmuError(f"{self.name}: the FMU asks to terminate at t={last.value}")
            if event.value:
                self.events.append(last.value)
                self._call("enterEventMode")
                self._event_iteration()
            if not early.value:
                return
            now = last.value
        raise FmuError(f"{self.name}: more than {MAX_EVENTS_PER_STEP} events in the step at t={t}")


class _Opener:
    """The master's instance source (its `instances` hook): EventInstance for each FMU with event
    mode, the usual instance otherwise; each freed after the run."""

    def __init__(self) -> None:
        self.opened: dict[str, FmuInstance] = {}

    def take(self, path: Path, name: str, opener: Any = open_fmu) -> FmuInstance:
        from impedance_cosim.cosim.fmus.files import model_description

        md = model_description(Path(path).resolve())
        fmu = EventInstance(path, name) if has_event_mode(md) else opener(path, name)
        self.opened[name] = fmu
        return fmu

    def give(self, fmu: FmuInstance, clean: bool) -> None:
        fmu.free()


class EventExactMaster(Master):
    """Master (same arguments, Python loop) stepping the FMUs with event mode event-exactly;
    after run(), events (and the result's info["events"]) maps each such component to its
    event times."""

    def __init__(self, system: SystemDescription, options: RunOptions | None = None) -> None:
        options = options or RunOptions()
        if options.loop not in ("auto", "python"):
            raise MasterError(f"event-exact stepping sets loop itself (got {options.loop!r})")
        super().__init__(system, dataclasses.replace(options, loop="python"), _Opener())
        if not any(has_event_mode(md) for md in self.descriptions.values()):
            raise MasterError("event-exact stepping needs an FMI 3.0 co-simulation FMU with event"
                              " mode (hasEventMode), and no component has one: use the FMI 3.0"
                              " archive (fmus/PaperScenario-fmi3.ssp)")  # fmt: skip
        self.events: dict[str, list[float]] = {}

    def run(self, *args: Any, **kwargs: Any) -> RunResult:
        """Master.run, then the event times of each component with event mode."""
        self.instances.opened.clear()
        result = super().run(*args, **kwargs)
        self.events = {n: list(f.events) for n, f in self.instances.opened.items()
                       if isinstance(f, EventInstance)}  # fmt: skip
        result.info["events"] = self.events
        return result
