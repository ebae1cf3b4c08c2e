"""The FMI 3.0 plant's contact switch as the standard's Co-Simulation features
(native/src/fmi3_cosim.c): the intermediate update callback at each switch, the early return it
may request, and event mode in Co-Simulation; each run against the plain plant, bit for bit."""

from __future__ import annotations

import ctypes
import shutil
import xml.etree.ElementTree as ET
import zipfile

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

DT = 1 / 400
WALL = 0.65
DISCARD, ERROR = 2, 3  # fmi3Discard, fmi3Error
STATE = ["q1_true", "q2_true", "q3_true", "qd1", "qd2", "qd3", "contact_force", "x", "q1"]


@pytest.fixture(scope="module")
def torques() -> list[tuple]:
    from conftest import contact_torques

    return contact_torques(6.0)  # two contacts: each closes and opens


class Plant:
    """The FMI 3 plant under fmpy's FMU3Slave, its log kept; raw() returns the status."""

    def __init__(self, fmi3_dir, name: str = "PumaPlant", required: tuple = (), **instantiate):
        path = fmi3_dir / f"{name}.fmu"
        md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        if required:
            instantiate["requiredIntermediateVariables"] = [self.vr[n] for n in required]
        self.log: list[str] = []
        self.fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(path)),
                             modelIdentifier=name, instanceName="e")  # fmt: skip
        self.fmu.instantiate(logMessage=lambda _e, _s, _c, m: self.log.append(m.decode()),
                             **instantiate)  # fmt: skip

    def raw(self, function: str, *args) -> int:
        return self.fmu._functions[function](self.fmu.component, *args)

    def get(self, names: list[str]) -> list[float]:
        return self.fmu.getFloat64([self.vr[n] for n in names])

    def set_torques(self, tau) -> None:
        self.fmu.setFloat64([self.vr[f"tau{i}"] for i in (1, 2, 3)], list(tau))

    def update_discrete_states(self) -> tuple[int, list[bool]]:
        flags = [ctypes.c_bool() for _ in range(5)]
        when = ctypes.c_double()
        s = self.raw("fmi3UpdateDiscreteStates", *(ctypes.byref(f) for f in flags),
                     ctypes.byref(when))  # fmt: skip
        return s, [f.value for f in flags]


def _plain_run(fmi3_dir, torques) -> list[float]:
    plain = Plant(fmi3_dir)
    plain.fmu.enterInitializationMode(startTime=0.0)
    plain.fmu.exitInitializationMode()
    for i, tau in enumerate(torques):
        plain.set_torques(tau)
        assert plain.fmu.doStep(i * DT, DT)[2] is False
    return plain.get(STATE)


def test_the_plant_declares_the_features(fmi3_dir):
    """The plant's intermediate update and event mode are at its contact; the controller's at
    its clock's ticks (tests/test_fmi3_clock_cs.py, test_fmi3_clock_update.py)."""
    for name, offered in (("PumaPlant", "true"), ("ImpedanceController", "true")):
        md = read_model_description(str(fmi3_dir / f"{name}.fmu"))
        cs = md.coSimulation
        assert str(cs.hasEventMode).lower() == "true", name
        assert str(cs.providesIntermediateUpdate).lower() == offered, name
        assert str(cs.canReturnEarlyAfterIntermediateUpdate).lower() == offered, name
        with zipfile.ZipFile(fmi3_dir / f"{name}.fmu") as z:  # fmpy does not read the attribute
            root = ET.fromstring(z.read("modelDescription.xml"))
        flags = {v.get("intermediateUpdate", "false") for v in root.find("ModelVariables")
                 if v.get("causality") == "output"}  # fmt: skip
        assert flags == {offered}, name
    log: list[str] = []
    md = read_model_description(str(fmi3_dir / "PumaPlant.fmu"))
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(fmi3_dir / "PumaPlant.fmu")),
                    modelIdentifier="PumaPlant", instanceName="r")  # fmt: skip
    tau1 = next(v.valueReference for v in md.modelVariables if v.name == "tau1")
    with pytest.raises(Exception, match="instantiate"):  # an input is no intermediate variable
        fmu.instantiate(requiredIntermediateVariables=[tau1],
                        logMessage=lambda _e, _s, _c, m: log.append(m.decode()))  # fmt: skip
    assert "not an output" in log[-1]


@pytest.mark.parametrize("request_return", [False, True])
def test_intermediate_update_at_each_switch_and_the_early_return_it_requests(
    fmi3_dir, torques, request_return
):
    """The callback comes at each contact switch with the wrist on the wall and the outputs
    readable; nothing but getters is allowed inside it. Requested, the early return ends the step
    at the switch; completing the step from there ends where the plain plant ends, bit for bit."""
    calls: list[tuple] = []
    plant: Plant

    def update(_env, t, set_requested, get_allowed, finished, can_return, requested, when):
        x, now = plant.get(["x", "time"])
        refused = plant.raw("fmi3DoStep", t, DT, True, *([None] * 4))
        calls.append((t, x - WALL, now, set_requested, get_allowed, finished, can_return,
                      refused, plant.log[-1]))  # fmt: skip
        requested[0] = request_return
        when[0] = t

    plant = Plant(fmi3_dir, required=("x", "contact_force"), earlyReturnAllowed=True,
                  intermediateUpdate=update)  # fmt: skip
    plant.fmu.enterInitializationMode(startTime=0.0)
    plant.fmu.exitInitializationMode()
    returns = []
    for i, tau in enumerate(torques):
        t = i * DT
        plant.set_torques(tau)
        event, _, early, reached = plant.fmu.doStep(t, DT)
        assert event is False
        if early:
            returns.append(reached)
            assert plant.fmu.doStep(reached, t + DT - reached)[2:] == (False, t + DT)
    assert len(calls) == 4
    for t, gap, now, set_requested, get_allowed, finished, can_return, refused, line in calls:
        assert abs(gap) < 1e-9 and now == t
        assert (set_requested, get_allowed, finished, can_return) == (False, True, True, True)
        assert refused == ERROR and "inside the intermediate update callback" in line
    assert returns == ([c[0] for c in calls] if request_return else [])
    assert plant.get(STATE) == _plain_run(fmi3_dir, torques)


def test_without_early_return_allowed_the_callback_cannot_end_the_step(fmi3_dir, torques):
    flags: list[bool] = []

    def update(_env, t, _set, _get, _finished, can_return, requested, _when):
        flags.append(can_return)
        requested[0] = True  # not allowed: the plant goes on

    plant = Plant(fmi3_dir, earlyReturnAllowed=False, intermediateUpdate=update)
    plant.fmu.enterInitializationMode(startTime=0.0)
    plant.fmu.exitInitializationMode()
    for i, tau in enumerate(torques):
        plant.set_torques(tau)
        assert plant.fmu.doStep(i * DT, DT)[2:] == (False, i * DT + DT)
    assert flags == [False] * 4
    assert plant.get(STATE) == _plain_run(fmi3_dir, torques)


def test_event_mode_in_co_simulation_at_each_switch(fmi3_dir, torques):
    """eventModeUsed: Event Mode after initialization, eventHandlingNeeded at each switch (the
    wrist on the wall), the event iteration changes nothing; calls in the wrong mode are errors
    with a log line. The run ends where the plain plant ends, bit for bit."""
    plant = Plant(fmi3_dir, eventModeUsed=True, earlyReturnAllowed=True)
    assert plant.raw("fmi3EnterStepMode") == ERROR  # before initialization
    plant.fmu.enterInitializationMode(startTime=0.0)
    plant.fmu.exitInitializationMode()
    assert plant.update_discrete_states() == (0, [False] * 5)  # Event Mode after initialization
    flags = [ctypes.c_bool() for _ in range(3)]
    last = ctypes.c_double()
    step = (0.0, DT, True, *(ctypes.byref(f) for f in flags), ctypes.byref(last))
    assert plant.raw("fmi3DoStep", *step) == ERROR and "called in Event Mode" in plant.log[-1]
    assert plant.raw("fmi3EnterEventMode") == ERROR and "called in Event Mode" in plant.log[-1]
    plant.fmu.enterStepMode()
    assert plant.raw("fmi3EnterStepMode") == ERROR and "called in Step Mode" in plant.log[-1]
    assert plant.update_discrete_states()[0] == ERROR and "called in Step Mode" in plant.log[-1]
    events = []
    for i, tau in enumerate(torques):
        t = i * DT
        plant.set_torques(tau)
        event, terminate, early, reached = plant.fmu.doStep(t, DT)
        assert terminate is False and event == early
        if event:
            assert t < reached < t + DT
            events.append(plant.get(["x"])[0] - WALL)
            plant.fmu.enterEventMode()
            assert plant.update_discrete_states() == (0, [False] * 5)
            plant.fmu.enterStepMode()
            assert plant.fmu.doStep(reached, t + DT - reached)[:3] == (False, False, False)
    assert len(events) == 4 and all(abs(gap) < 1e-9 for gap in events)
    assert plant.get(STATE) == _plain_run(fmi3_dir, torques)


def test_event_mode_without_early_return_steps_as_today(fmi3_dir, torques):
    """eventModeUsed without earlyReturnAllowed: the plant may not stop inside the step, so it
    switches inside it as without event mode and never asks for event handling."""
    plant = Plant(fmi3_dir, eventModeUsed=True, earlyReturnAllowed=False)
    plant.fmu.enterInitializationMode(startTime=0.0)
    plant.fmu.exitInitializationMode()
    plant.fmu.enterStepMode()
    for i, tau in enumerate(torques):
        plant.set_torques(tau)
        assert plant.fmu.doStep(i * DT, DT) == (False, False, False, i * DT + DT)
    assert plant.get(STATE) == _plain_run(fmi3_dir, torques)


@pytest.mark.parametrize(
    "max_rhs, refusal",
    [(None, "more than 200000 evaluations of the dynamics"), (10**8, "more than 1000 switches")],
)
def test_the_work_bound_holds_for_the_whole_step_across_the_callbacks(fmi3_dir, max_rhs, refusal):
    """Issue 34: with the callback, fmi3DoStep restarted the model step at each contact switch,
    each with a fresh budget of max_rhs_evaluations and switches: doStep(0, 1e6) with torques into
    the wall made 130,000 callbacks and ran on. One budget for the whole call now: refused
    (fmi3Discard, undone whole) after at most 1000 switches. Past 3000 callbacks, the callback
    ends the step (a hang guard for the old behaviour, which would fail the test)."""
    from conftest import contact_torques

    calls: list[float] = []

    def update(_env, t, _set, _get, _finished, _can_return, requested, _when):
        calls.append(t)
        requested[0] = len(calls) > 3000

    plant = Plant(fmi3_dir, earlyReturnAllowed=True, intermediateUpdate=update)
    if max_rhs is not None:
        plant.fmu.setInt32([plant.vr["max_rhs_evaluations"]], [max_rhs])
    plant.fmu.enterInitializationMode(startTime=0.0)
    plant.fmu.exitInitializationMode()
    start = plant.get(STATE)
    plant.set_torques(contact_torques(DT)[0])  # into the wall, and held there
    flags = [ctypes.c_bool() for _ in range(3)]
    last = ctypes.c_double(-1.0)
    status = plant.raw("fmi3DoStep", 0.0, 1e6, True, *(ctypes.byref(f) for f in flags),
                       ctypes.byref(last))  # fmt: skip
    assert status == DISCARD and refusal in plant.log[-1], (len(calls), plant.log[-1:])
    assert 0 < len(calls) <= 1000 and last.value == 0.0
    assert plant.get(STATE) == start
