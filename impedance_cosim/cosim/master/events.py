"""Event-exact stepping (issue 23): the master's fixed communication grid, with each FMI 3.0
Co-Simulation FMU that has event mode (the plant, at its wall contact) stepped up to its events.

What event-exact means here: the controller samples at 400 Hz, so its sampling instants, and the
communication points, stay on the fixed grid t_i = t_0 + i h. Inside a communication step the
plant returns early at each contact switch (earlyReturnAllowed, eventModeUsed); the master
handles the event there (fmi3EnterEventMode, fmi3UpdateDiscreteStates until nothing is left,
fmi3EnterStepMode), records its exact time, and completes the step to t_i+1 on the same,
sample-and-hold, inputs (the controller's torques are constant between its samples). The
recorded rows stay at the grid points; the event times are in EventExactMaster.events.

An FMU with event mode and an input clock (the controller's sample clock, issue 37) is
instantiated so too; its ticks are its events. The master cuts each communication step at the
next tick the FMU announced (nextEventTime), so every component reaches the tick; the FMU signals
eventHandlingNeeded there and takes the tick when the step from it starts, in Event Mode
(fmi3SetClock, fmi3UpdateDiscreteStates) on the inputs the algorithm gives it there: under
Gauss-Seidel and Jacobi alike the other components' outputs at the tick (under Jacobi their
inputs over the step from the tick are its outputs before the tick: the delay of one step
stays). A row at a tick holds the outputs before the tick, as in the fixed-step run; the tick at
the stop time is taken after the last row. At a step of one sample period the rows equal the
fixed-step run's bit for bit.
"""

from __future__ import annotations

import ctypes
import dataclasses
import math
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
    """True for an FMI 3.0 Co-Simulation FMU that offers event mode (hasEventMode="true")."""
    cs = getattr(description, "coSimulation", None)
    version = str(getattr(description, "fmiVersion", ""))
    return version.startswith("3") and cs is not None and bool(cs.hasEventMode)


def input_clock(description: Any) -> int | None:
    """The value reference of the FMU's input Clock (the controller's sample clock), or None."""
    clocks = [v for v in description.modelVariables
              if v.type == "Clock" and v.causality == "input"]  # fmt: skip
    return clocks[0].valueReference if clocks else None


class EventInstance(FmuInstance3):
    """An FMI 3.0 Co-Simulation FMU instantiated with eventModeUsed and earlyReturnAllowed:
    step(t, h) reaches t + h through the FMU's events, each handled in Event Mode."""

    def _call(self, method: str, *args: Any, **kwargs: Any) -> Any:
        if method == "instantiate":
            kwargs.update(eventModeUsed=True, earlyReturnAllowed=True)
            self.events: list[float] = []
        return super()._call(method, *args, **kwargs)

    def _event_iteration(self) -> float:
        """In Event Mode: fmi3UpdateDiscreteStates until no update is needed, then Step Mode;
        the next time event the FMU announced (inf: none)."""
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
        return when.value if flags[4].value else math.inf  # nextEventTimeDefined

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


class ClockedEventInstance(EventInstance):
    """An FMI 3.0 Co-Simulation FMU with event mode and an input clock (the controller), with
    eventModeUsed and earlyReturnAllowed. A tick signalled at the end of step(t, h) is pending
    until take_tick(), on the inputs set for it; next_tick is the tick after the last one taken.
    ticks: the times of the ticks taken."""

    def _call(self, method: str, *args: Any, **kwargs: Any) -> Any:
        if method == "instantiate":
            self.clock = input_clock(self.description)
            self.ticks: list[float] = []
            self.pending: float | None = None
            self.next_tick = math.inf
            self._event_mode = False
        return super()._call(method, *args, **kwargs)

    def exit_initialization(self) -> None:
        """Event Mode after initialization, the clock active: tick 0 pending."""
        FmuInstance3.exit_initialization(self)
        self.pending, self._event_mode = self.start_time, True

    def take_tick(self) -> None:
        """The pending tick in Event Mode: the clock activated, the sample taken on the inputs
        set (fmi3UpdateDiscreteStates), Step Mode again; next_tick from nextEventTime."""
        if not self._event_mode:
            self._call("enterEventMode")
        self._call("setClock", [self.clock], [True])
        self.next_tick = self._event_iteration()
        self.ticks.append(self.pending)
        self.pending, self._event_mode = None, False

    def step(self, t: float, h: float) -> None:
        """fmi3DoStep from t to t + h; a tick inside it (an early return) is an error: the
        master cuts its steps at next_tick. A tick at the end is pending."""
        if self.pending is not None:
            raise FmuError(f"{self.name}: the tick at t={self.pending} was not taken")
        status = self._do_step(self.slave.component, t, h, True, *self._step_refs)
        event, terminate, early, last = self._step_out
        if status > 1:
            raise self._fail(f"doStep at t={t} returned {STATUS[status]}", status)
        if terminate.value or early.value:
            raise FmuError(f"{self.name}: the step from t={t} to {t + h} ended at "
                           f"t={last.value} (terminate: {terminate.value}, the next tick "
                           f"announced: {self.next_tick})")  # fmt: skip
        if event.value:
            self.pending = last.value


class _Opener:
    """The master's instance source (its `instances` hook): EventInstance for each FMU with event
    mode (ClockedEventInstance with an input clock), the usual instance otherwise; each freed
    after the run."""

    def __init__(self) -> None:
        self.opened: dict[str, FmuInstance] = {}

    def take(self, path: Path, name: str, opener: Any = open_fmu) -> FmuInstance:
        from impedance_cosim.cosim.fmus.files import model_description

        md = model_description(Path(path).resolve())
        if not has_event_mode(md):
            fmu = opener(path, name)
        else:
            clocked = input_clock(md) is not None
            fmu = (ClockedEventInstance if clocked else EventInstance)(path, name)
        self.opened[name] = fmu
        return fmu

    def give(self, fmu: FmuInstance, clean: bool) -> None:
        fmu.free()


class EventExactMaster(Master):
    """Master (same arguments, Python loop) stepping the FMUs with event mode event-exactly;
    after run(), events (and the result's info["events"]) maps each such component to its
    event times, ticks (info["ticks"]) each one with an input clock to its ticks."""

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
        self.ticks: dict[str, list[float]] = {}

    def run(self, *args: Any, **kwargs: Any) -> RunResult:
        """Master.run, then the event times of each component with event mode (its ticks for
        one with an input clock: EventExactMaster.ticks, the result's info["ticks"])."""
        self.instances.opened.clear()
        result = super().run(*args, **kwargs)
        opened = self.instances.opened.items()
        self.ticks = {n: list(f.ticks) for n, f in opened if isinstance(f, ClockedEventInstance)}
        self.events = {n: list(f.events) for n, f in opened if isinstance(f, EventInstance)
                       and n not in self.ticks}  # fmt: skip
        result.info["events"] = self.events
        if self.ticks:
            result.info["ticks"] = self.ticks
        return result

    def _take_ticks(self, ordered: list, h: float, zero: bool = False) -> None:
        """Each clocked FMU's pending tick, on the inputs the algorithm gives it for a step of h
        (Master._inputs: the other components' outputs now)."""
        for s in ordered:
            if isinstance(s.fmu, ClockedEventInstance) and s.fmu.pending is not None:
                s.write(self._inputs(s, ordered, h, zero))
                s.fmu.take_tick()

    def _step_all(self, ordered: list, t: float, h: float, zero: bool = False) -> None:
        """Master._step_all from t to t + h, cut at the clocked FMUs' ticks inside: at each, the
        pending ticks taken first, then every component steps to the next tick or the end."""
        end = t + h
        while True:
            self._take_ticks(ordered, h, zero)
            ticks = [s.fmu.next_tick for s in ordered if isinstance(s.fmu, ClockedEventInstance)]
            cut = min(ticks, default=math.inf)
            if cut >= end - 1e-9 * min(h, cut - t):  # on the end (the FMU's own tolerance)
                return super()._step_all(ordered, t, h, zero)
            super()._step_all(ordered, t, cut - t, zero)
            t, h, zero = cut, end - cut, False

    def _python_steps(self, ordered, data, names, first: int, count: int):
        """Master._python_steps; after the last step, the ticks at the stop time (not in a row:
        each row holds the outputs before its tick)."""
        done, error = super()._python_steps(ordered, data, names, first, count)
        last = round((self.stop_time - self.start_time) / self.step_size)
        if error is None and first + done == last:
            try:
                self._take_ticks(ordered, 0.0)
            except FmuError as exc:
                return done, str(exc)
        return done, error
