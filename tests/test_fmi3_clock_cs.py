"""The FMI 3.0 controller's Co-Simulation with clock information (native/src/fmi3_cosim.c,
native/controller/model_me.c): with eventModeUsed its sample clock's ticks are events. A host on
fmpy's FMU3Slave runs the closed loop with the FMI 3.0 plant (plain Co-Simulation): fmi3DoStep of
the controller returns early at each tick inside the step and signals eventHandlingNeeded there
(or at the step's end on a tick); in Event Mode the clock is active, the host sets the plant's
outputs, fmi3UpdateDiscreteStates takes the sample and tells the next tick."""

from __future__ import annotations

import shutil
from itertools import cycle

import numpy as np
import pytest
from fmi3_loop import ClosedLoop, Fmu
from fmpy import read_model_description

from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

DT = 1 / 400
ERROR = 3  # fmi3Error
VARIABLE = [0.0007, 0.0031, 0.0012, 0.0025, 0.004, 0.0001]  # s, repeated


def _steps(h, seconds: float) -> list[tuple[float, float]]:
    """The communication steps (t, size) of size h (or the VARIABLE sequence) up to seconds;
    fixed steps start at i * h, as our master's."""
    if h != "variable":
        return [(i * h, h) for i in range(round(seconds / h))]
    steps, t = [], 0.0
    for size in cycle(VARIABLE):
        if t >= seconds - 1e-12:
            return steps
        steps.append((t, size))
        t += size


class Loop(ClosedLoop):
    """The closed loop: the FMI 3.0 plant and the controller (instantiated as given) in
    Co-Simulation; the torques the plant got in each of its steps, and the samples taken in
    Event Mode."""

    def __init__(self, fmu_dir, fmi3_dir, **controller):
        self.event_mode = controller.get("eventModeUsed", False)
        super().__init__(fmu_dir, Fmu(fmi3_dir, "PumaPlant"),
                         Fmu(fmi3_dir, "ImpedanceController", **controller))  # fmt: skip
        self.applied: list[list[float]] = []

    def event(self, t: float) -> float:
        """Event Mode at t: the clock is active (fmi3GetClock, an answer the standard asks only
        of output clocks; fmi3SetClock activates it), the sample taken; the next tick."""
        clock = self.ctrl.vr["sample_clock"]
        assert self.ctrl.fmu.getClock([clock]) == [True]
        self.ctrl.fmu.setClock([clock], [True])  # the standard's activation of an input clock
        self.inputs()
        need, stop, _, _, defined, next_tick = self.ctrl.fmu.updateDiscreteStates()
        assert (need, stop, defined) == (False, False, True)
        self.samples.append((t, self.torques()))
        self.ctrl.fmu.enterStepMode()
        assert self.ctrl.fmu.getClock([clock]) == [False]
        return next_tick

    def step(self, t: float, h: float) -> None:
        """One communication step (controller first, Gauss-Seidel), cut at its events."""
        t_end = t + h
        while True:
            self.inputs()
            event, stop, early, reached = self.ctrl.fmu.doStep(t, h)
            assert not stop and (reached == t_end) != early and (event or not early)
            self.applied.append(self.torques())
            self.plant.fmu.doStep(t, reached - t if early else h)
            if not event:
                return
            self.ctrl.fmu.enterEventMode()
            assert self.event(reached) == pytest.approx(reached + DT, abs=1e-9 * DT)
            if not early:
                return
            t, h = reached, t_end - reached

    def run(self, steps: list[tuple[float, float]]) -> None:
        if self.event_mode:
            self.event(0.0)  # Event Mode after initialization: tick 0 (sampled in it)
        for t, h in steps:
            self.step(t, h)


@pytest.fixture(scope="module")
def fmi2_run(fmu_dir, native_dir):
    """The FMI 2.0 native archive under our master: Gauss-Seidel, 1/400 s, 2 s."""
    system = read_ssp(fmu_dir / "PaperScenario-native.ssp")
    run = Master(system, RunOptions(parameter_set="observer", stop_time=2.0)).run()
    assert run.ok, run.error
    return np.column_stack([run[f"controller.tau{i}"] for i in (1, 2, 3)])


def _event_run(fmu_dir, fmi3_dir, h, seconds=2.0, early=True) -> Loop:
    loop = Loop(fmu_dir, fmi3_dir, eventModeUsed=True, earlyReturnAllowed=early)
    loop.run(_steps(h, seconds))
    return loop


def test_the_controller_declares_event_mode_and_its_clock(fmi3_dir):
    md = read_model_description(str(fmi3_dir / "ImpedanceController.fmu"))
    cs = md.coSimulation
    assert str(cs.hasEventMode).lower() == str(cs.mightReturnEarlyFromDoStep).lower() == "true"
    assert str(cs.providesIntermediateUpdate).lower() == "true"  # test_fmi3_clock_update.py
    (clock,) = [v for v in md.modelVariables if v.type == "Clock"]
    assert (clock.name, clock.causality, clock.intervalVariability) == (
        "sample_clock", "input", "fixed")  # fmt: skip
    assert not [v for v in md.modelVariables if v.clocks]  # the same FMU serves hosts without


def test_event_mode_at_1_400_gives_the_fmi2_torques_bit_for_bit(fmu_dir, fmi3_dir, fmi2_run):
    """Every step ends on a tick: eventHandlingNeeded at its end, 801 samples in 2 s at
    k/400 s, the torques those of the FMI 2.0 Gauss-Seidel run."""
    loop = _event_run(fmu_dir, fmi3_dir, DT)
    times = [t for t, _ in loop.samples]
    assert len(times) == 801
    assert np.max(np.abs(np.array(times) - np.arange(801) * DT)) <= 1e-9 * DT
    # the FMI 2.0 output at k/400 s (k >= 1) is sample k - 1
    assert np.array_equal(np.array([tau for _, tau in loop.samples[:800]]), fmi2_run[1:])


@pytest.mark.parametrize("h", [1 / 1000, 1 / 150, "variable"])
def test_every_sample_at_its_tick_for_any_step(fmu_dir, fmi3_dir, fmi2_run, h):
    """Ticks inside a step end it early, exactly at k/400 s; ticks on a communication point
    within 1e-9 sample periods of it (its arithmetic). Every tick once. The plant's steps are
    cut differently, so the torques follow the 1/400 run within 1e-9 of their range, not bit
    for bit."""
    loop = _event_run(fmu_dir, fmi3_dir, h)
    times = np.array([t for t, _ in loop.samples])
    k = np.round(times / DT)
    assert np.array_equal(k, np.arange(len(times))) and len(times) >= 801
    assert np.max(np.abs(times - k * DT)) <= 1e-9 * DT
    taus = np.array([tau for _, tau in loop.samples[:800]])
    err = np.max(np.abs(taus - fmi2_run[1:])) / np.max(np.abs(fmi2_run))
    assert err <= 1e-9  # measured over 2 s: 4.8e-12 (1/1000), 1.5e-11 (1/150, variable)


@pytest.mark.parametrize("h", [DT, 1 / 1000, 1 / 150, "variable"])
def test_without_event_mode_or_early_return_the_controller_samples_as_today(fmu_dir, fmi3_dir, h):
    """eventModeUsed=false: sampled inside fmi3DoStep as before. eventModeUsed without
    earlyReturnAllowed: ticks inside a step are sampled inside it (on the inputs at its start,
    as without event mode), a tick on its end in Event Mode; the plant gets the same torques in
    every step, bit for bit (at 1/400 s with early return too: no tick falls inside a step)."""
    steps = _steps(h, 1.0)
    modes = ({}, {"eventModeUsed": True}, {"eventModeUsed": True, "earlyReturnAllowed": True})
    runs = [Loop(fmu_dir, fmi3_dir, **kw) for kw in modes]
    for loop in runs[: 3 if h == DT else 2]:
        loop.run(steps)
        assert not loop.ctrl.log or "error" not in " ".join(loop.ctrl.log).lower()
    assert runs[1].applied == runs[0].applied and len(runs[0].applied) == len(steps)
    if h == DT:
        assert runs[2].applied == runs[0].applied
    state = [v.name for v in runs[0].plant.md.modelVariables if v.causality == "output"]
    vrs = [runs[0].plant.vr[n] for n in state]
    assert runs[1].plant.fmu.getFloat64(vrs) == runs[0].plant.fmu.getFloat64(vrs)


def test_wrong_mode_calls_are_refused(fmu_dir, fmi3_dir):
    loop = Loop(fmu_dir, fmi3_dir, eventModeUsed=True, earlyReturnAllowed=True)
    ctrl, clock = loop.ctrl, loop.ctrl.vr["sample_clock"]

    def raw(function: str, *args) -> int:
        return ctrl.fmu._functions[function](ctrl.fmu.component, *args)

    assert raw("fmi3EnterEventMode") == ERROR and "called in Event Mode" in ctrl.log[-1]
    assert raw("fmi3DoStep", 0.0, DT, True, *[None] * 4) == ERROR
    assert "called in Event Mode" in ctrl.log[-1]
    loop.event(0.0)
    assert raw("fmi3UpdateDiscreteStates", *[None] * 6) == ERROR
    assert "called in Step Mode" in ctrl.log[-1]
    with pytest.raises(Exception, match="fmi3SetClock"):  # a tick set outside Event Mode
        ctrl.fmu.setClock([clock], [True])
    assert "sample_period" in ctrl.log[-1]
    assert ctrl.fmu.doStep(0.0, DT)[0] is True  # the tick at its end: the host ignores it
    with pytest.raises(Exception, match="fmi3DoStep"):
        ctrl.fmu.doStep(DT, DT)
    assert "was not taken" in ctrl.log[-1]
    plain = Fmu(fmi3_dir, "ImpedanceController")
    plain.fmu.enterInitializationMode(startTime=0.0)
    plain.fmu.exitInitializationMode()
    with pytest.raises(Exception, match="fmi3EnterEventMode"):
        plain.fmu.enterEventMode()
    assert "eventModeUsed=false" in plain.log[-1]


def test_the_fmu_state_round_trip_in_event_mode(fmu_dir, fmi3_dir):
    """FMU states got in Step Mode between ticks and set back: the run repeats bit for bit."""
    loop = Loop(fmu_dir, fmi3_dir, eventModeUsed=True, earlyReturnAllowed=True)
    first_steps = _steps(1 / 150, 0.1)
    loop.run(first_steps)
    states = [fmu.fmu.getFMUState() for fmu in (loop.plant, loop.ctrl)]
    t0 = sum(first_steps[-1])
    steps = [(t0 + t, h) for t, h in _steps("variable", 0.08)]
    n = len(loop.samples)
    for t, h in steps:
        loop.step(t, h)
    first = loop.samples[n:]
    for fmu, state in zip((loop.plant, loop.ctrl), states):
        fmu.fmu.setFMUState(state)
    for t, h in steps:
        loop.step(t, h)
    assert loop.samples[n + len(first) :] == first and len(first) > 10
