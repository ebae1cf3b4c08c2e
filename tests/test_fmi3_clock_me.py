"""The FMI 3.0 controller's clocked Model Exchange (native/src/fmi3_events.c, fmi3_glue.c): its
sample clock's ticks are time events (nextEventTime); in Event Mode at a tick the clock is
active, the importer activates it with fmi3SetClock (FMI 3.0, 2.3: Event Mode, time-based
clocks), fmi3UpdateDiscreteStates takes the sample and deactivates it. A host on fmpy's FMU3Model
runs the FMI 3.0 plant and the controller, both in Model Exchange: it integrates the plant's
continuous states with the explicit Euler substeps of the co-simulation plant's `euler_substeps`
(native/plant/model.c, euler_steps: the contact mode switches after a substep whose switching
function, the event indicator, turned positive), so the torques can equal the FMI 2.0
Gauss-Seidel run of that plant bit for bit."""

from __future__ import annotations

import shutil
from ctypes import POINTER, c_double

import numpy as np
import pytest
from fmi3_loop import ClosedLoop, Fmu
from fmpy import read_model_description
from fmpy.fmi3 import FMU3Model

from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

DT = 1 / 400
SUBSTEPS = 10  # the plant's Euler substeps per sample period
SECONDS = 4.5  # past the wall contact at 3.85 s


class Plant(Fmu):
    """The plant in Model Exchange, integrated by explicit Euler steps (as ode_euler_step)."""

    def __init__(self, fmi3_dir):
        super().__init__(fmi3_dir, "PumaPlant", FMU3Model)
        self.x, self.dx, self.z = np.zeros(6), np.zeros(6), np.zeros(1)
        self.switch_times: list[float] = []

    def array(self, a: np.ndarray):
        return a.ctypes.data_as(POINTER(c_double))

    def event_iteration(self) -> None:
        while self.fmu.updateDiscreteStates()[0]:
            pass

    def euler_step(self, t: float, dt: float) -> None:
        """y + dt f(y); the contact switches after the step where its indicator turned positive."""
        self.fmu.getContinuousStates(self.array(self.x), 6)
        self.fmu.getContinuousStateDerivatives(self.array(self.dx), 6)
        self.x = self.x + dt * self.dx
        self.fmu.setTime(t + dt)
        self.fmu.setContinuousStates(self.array(self.x), 6)
        self.fmu.getEventIndicators(self.array(self.z), 1)
        self.fmu.completedIntegratorStep()
        if self.z[0] > 0.0:
            self.switch_times.append(t + dt)
            self.fmu.enterEventMode()
            self.event_iteration()
            self.fmu.enterContinuousTimeMode()


class Loop(ClosedLoop):
    """The closed loop in Model Exchange: at each tick (the controller's nextEventTime) the
    controller's Event Mode (fmi3SetClock where set_clock), then the plant's Euler substeps to
    the next tick on the torques of the sample."""

    def __init__(self, fmu_dir, fmi3_dir, set_clock: bool = True):
        self.set_clock = set_clock
        super().__init__(fmu_dir, Plant(fmi3_dir),
                         Fmu(fmi3_dir, "ImpedanceController", FMU3Model))  # fmt: skip
        self.clock = self.ctrl.vr["sample_clock"]
        self.plant.event_iteration()
        self.plant.fmu.enterContinuousTimeMode()

    def tick(self, t: float) -> float:
        """The controller's Event Mode at the tick t: the clock active, the sample; the next."""
        assert self.ctrl.fmu.getClock([self.clock]) == [True]
        if self.set_clock:
            self.ctrl.fmu.setClock([self.clock], [True])
        self.inputs()
        need, stop, _, _, defined, next_tick = self.ctrl.fmu.updateDiscreteStates()
        assert (need, stop, defined) == (False, False, True)
        assert self.ctrl.fmu.getClock([self.clock]) == [False]  # deactivated by the update
        self.samples.append((t, self.torques()))
        self.ctrl.fmu.enterContinuousTimeMode()
        return next_tick

    def run(self, seconds: float = SECONDS) -> None:
        t, next_tick = 0.0, self.tick(0.0)  # Event Mode after initialization: tick 0
        dt = DT / SUBSTEPS  # as the co-simulation plant's step of DT
        while next_tick <= seconds:
            assert self.ctrl.fmu.getClock([self.clock]) == [False]  # Continuous-Time Mode
            for _ in range(SUBSTEPS):
                self.plant.euler_step(t, dt)
                t += dt
            t = next_tick
            self.ctrl.fmu.setTime(t)
            self.ctrl.fmu.enterEventMode()
            next_tick = self.tick(t)


@pytest.fixture(scope="module")
def fmi2_euler_run(fmu_dir, native_dir):
    """The FMI 2.0 native archive under our master, its plant on the same Euler substeps:
    Gauss-Seidel, 1/400 s, 4.5 s."""
    system = read_ssp(fmu_dir / "PaperScenario-native.ssp")
    options = RunOptions(parameter_set="observer", stop_time=SECONDS,
                         overrides={"plant.euler_substeps": SUBSTEPS})  # fmt: skip
    run = Master(system, options).run()
    assert run.ok, run.error
    return np.column_stack([run[f"controller.tau{i}"] for i in (1, 2, 3)])


@pytest.fixture(scope="module")
def me_loop(fmu_dir, fmi3_dir) -> Loop:
    loop = Loop(fmu_dir, fmi3_dir)
    loop.run()
    return loop


def test_the_controller_declares_model_exchange_and_its_clock(fmi3_dir):
    md = read_model_description(str(fmi3_dir / "ImpedanceController.fmu"))
    assert md.modelExchange is not None
    (clock,) = [v for v in md.modelVariables if v.type == "Clock"]
    assert (clock.name, clock.causality, clock.intervalVariability) == (
        "sample_clock", "input", "fixed")  # fmt: skip


def test_clocked_model_exchange_gives_the_fmi2_torques_bit_for_bit(me_loop, fmi2_euler_run):
    """Every tick once, at exactly k/400 s (the FMU's nextEventTime); the torques those of the
    FMI 2.0 Gauss-Seidel run with the co-simulation plant on the same Euler substeps, through
    the wall contact (the plant's state event)."""
    times = np.array([t for t, _ in me_loop.samples])
    assert len(times) == 1801 and np.array_equal(times, np.arange(1801) * DT)
    assert len(me_loop.plant.switch_times) == 1 and 3.8 < me_loop.plant.switch_times[0] < 3.9
    assert not [m for m in me_loop.ctrl.log + me_loop.plant.log if "rror" in m]
    # the FMI 2.0 output at k/400 s (k >= 1) is sample k - 1
    taus = np.array([tau for _, tau in me_loop.samples[:1800]])
    assert np.array_equal(taus, fmi2_euler_run[1:])


def test_a_host_that_never_sets_the_clock_gets_the_same_torques(fmu_dir, fmi3_dir, me_loop):
    """The samples are taken at the time events whether or not the importer activates the
    clock: the Model Exchange host of before, bit for bit."""
    loop = Loop(fmu_dir, fmi3_dir, set_clock=False)
    loop.run()
    assert loop.samples == me_loop.samples


def test_the_clock_is_active_only_at_a_tick(fmu_dir, fmi3_dir):
    """Outside a tick (Continuous-Time Mode, an Event Mode between ticks, after the update)
    fmi3GetClock is false and fmi3SetClock refused; fmi3UpdateDiscreteStates there takes no
    sample and tells the next tick."""
    loop = Loop(fmu_dir, fmi3_dir)
    ctrl, clock = loop.ctrl, loop.clock
    assert loop.tick(0.0) == DT
    assert ctrl.fmu.getClock([clock]) == [False]
    with pytest.raises(Exception, match="fmi3SetClock"):  # Continuous-Time Mode
        ctrl.fmu.setClock([clock], [True])
    assert "in Event Mode at a tick" in ctrl.log[-1]
    ctrl.fmu.setTime(DT / 2)
    ctrl.fmu.enterEventMode()  # an event between ticks (the plant's contact, say)
    assert ctrl.fmu.getClock([clock]) == [False]
    with pytest.raises(Exception, match="fmi3SetClock"):
        ctrl.fmu.setClock([clock], [True])
    ctrl.fmu.setClock([clock], [False])  # inactive it is
    tau = ctrl.fmu.getFloat64([c for c, _ in loop.tau])
    assert ctrl.fmu.updateDiscreteStates()[4:] == (True, DT)
    assert ctrl.fmu.getFloat64([c for c, _ in loop.tau]) == tau  # no sample
    ctrl.fmu.enterContinuousTimeMode()
    ctrl.fmu.setTime(DT)
    ctrl.fmu.enterEventMode()
    assert loop.tick(DT) == 2 * DT and len(loop.samples) == 2


def test_the_fmu_state_keeps_the_clock(fmu_dir, fmi3_dir):
    """An FMU state got in Event Mode at a tick restores the clock active (the sample taken
    again equals the first); one got there after the update, inactive."""
    loop = Loop(fmu_dir, fmi3_dir)
    ctrl, clock = loop.ctrl, loop.clock
    loop.tick(0.0)
    ctrl.fmu.setTime(DT)
    ctrl.fmu.enterEventMode()
    at_tick = ctrl.fmu.getFMUState()
    ctrl.fmu.setClock([clock], [True])
    loop.inputs()
    ctrl.fmu.updateDiscreteStates()
    first = loop.torques()
    after = ctrl.fmu.getFMUState()
    ctrl.fmu.setFMUState(at_tick)
    assert ctrl.fmu.getClock([clock]) == [True]
    assert loop.tick(DT) == 2 * DT and loop.samples[-1] == (DT, first)
    ctrl.fmu.setFMUState(after)
    assert ctrl.fmu.getClock([clock]) == [False]
    with pytest.raises(Exception, match="fmi3SetClock"):
        ctrl.fmu.setClock([clock], [True])
