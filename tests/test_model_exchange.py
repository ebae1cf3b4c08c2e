"""FMI 2.0 Model Exchange of the native FMUs (native/src/fmi2_me.c, instance_me.c). The plant: the
modelDescription, agreement with the co-simulation interface (default experiment and the paper
scenario's torques replayed open loop under fmpy's CVode), the contact event indicator, and the ME
rules (ideal sensors, call order). The controller: time events at its sample instants, the same
torques as under co-simulation."""

from __future__ import annotations

import ctypes
import math
import shutil
import subprocess
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Model,
    FMU2Slave,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy.simulation import Input
from fmpy.validation import validate_fmu

from impedance_cosim.cosim.engines.replay import cs_crossing_times, held_input, me_replay
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.results.result import read_csv
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.cosim.system.paper import CONNECTIONS
from plant_model.model import PlantModel

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

PLANT, CONTROLLER = "PumaPlant.fmu", "ImpedanceController.fmu"
STATES = ("q1_true", "q2_true", "q3_true", "qd1", "qd2", "qd3")
DT = 1 / 400
WALL_X, WALL_K = 0.65, 1e4  # the plant's defaults (the paper scenario sets the same)


class MEPlant:
    """A Model Exchange instance of the native plant, with its log kept."""

    def __init__(self, native_dir, name: str = PLANT) -> None:
        path = native_dir / name
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.messages: list[str] = []
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.fmu = FMU2Model(
            guid=self.md.guid,
            unzipDirectory=extract(str(path)),
            modelIdentifier=self.md.coSimulation.modelIdentifier,
            instanceName="me",
        )
        self.fmu.instantiate(callbacks=self._callbacks)

    def _log(self, _env, _instance, _status, _category, message) -> None:
        self.messages.append(message.decode())

    def initialize(self, **params: float) -> None:
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for name, value in params.items():
            self.fmu.setReal([self.vr[name]], [value])
        self.fmu.exitInitializationMode()

    def array(self, function: str, n: int) -> np.ndarray:
        out = (ctypes.c_double * n)()
        getattr(self.fmu, function)(self.fmu.component, out, n)
        return np.array(out)

    def states(self) -> np.ndarray:
        return self.array("fmi2GetContinuousStates", 6)

    def derivatives(self) -> np.ndarray:
        return self.array("fmi2GetDerivatives", 6)

    def indicator(self) -> float:
        return float(self.array("fmi2GetEventIndicators", 1)[0])


def _penetration(q) -> float:
    """x(q) - wall_x from the Python arm model (independent of the C code under test)."""
    plant = PlantModel({}, 0.0)
    return plant.arm.kinematics(q)[0] - WALL_X


# --- the model description -------------------------------------------------------------------


def test_native_plant_declares_model_exchange(native_dir, fmu_dir):
    path = native_dir / PLANT
    assert validate_fmu(str(path)) == []
    md = read_model_description(str(path))
    assert md.modelExchange is not None and md.coSimulation is not None
    assert md.modelExchange.modelIdentifier == md.coSimulation.modelIdentifier
    assert md.numberOfEventIndicators == 1
    # the states, in state-vector order, and their der() variables
    assert [d.variable.derivative.name for d in md.derivatives] == list(STATES)
    assert [d.variable.name for d in md.derivatives] == [f"der({s})" for s in STATES]
    units = {d.variable.derivative.name: d.variable.unit for d in md.derivatives}
    assert units == {**dict.fromkeys(STATES[:3], "rad/s"), **dict.fromkeys(STATES[3:], "rad/s2")}
    initial = {u.variable.name for u in md.initialUnknowns}
    assert {f"der({s})" for s in STATES} | set(STATES) <= initial
    # outputs depend on the states only (no direct feedthrough from the torques); which states
    # exactly is checked against the directional derivatives in tests/test_partials.py
    state_vars = {v for v in md.modelVariables if v.name in STATES}
    assert all(set(u.dependencies) <= state_vars for u in md.outputs)
    assert any(set(u.dependencies) == state_vars for u in md.outputs)
    with zipfile.ZipFile(path) as z:
        assert "sources/instance_me.c" in z.namelist()
    # the Python FMUs (pythonfmu: co-simulation only) do not claim ME
    for other in (fmu_dir / name for name in (PLANT, CONTROLLER, "BridgePlant.fmu")):
        with zipfile.ZipFile(other) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
        assert root.find("ModelExchange") is None and root.get("numberOfEventIndicators") == "0"


# --- the equations ---------------------------------------------------------------------------


def test_derivatives_are_the_plant_equations(native_dir):
    """fmi2GetDerivatives against the Python plant's right-hand side (its own copy of eq. 1),
    free and in contact, at states and torques set by the host. The contact indicator is then
    -wall_k |x(q) - wall_x| (the switching function of the mode the event update chose)."""
    me = MEPlant(native_dir)
    me.initialize()
    me.fmu.enterContinuousTimeMode()
    plant = PlantModel({}, 0.0)
    rng = np.random.default_rng(3)
    for trial in range(6):
        q = plant.arm.inverse_kinematics((0.56 + 0.03 * trial, 0.1, 0.2), True)
        x = np.array([*q, *rng.normal(0.0, 0.5, 3)])
        tau = rng.normal(0.0, 20.0, 3)
        me.fmu.setTime(0.1 * trial)
        me.fmu.setContinuousStates((ctypes.c_double * 6)(*x), 6)
        me.fmu.setReal([me.vr[f"tau{i}"] for i in (1, 2, 3)], list(tau))
        me.fmu.enterEventMode()  # the contact mode follows the state at an event
        me.fmu.newDiscreteStates()
        me.fmu.enterContinuousTimeMode()
        mode = _penetration(q) > 0.0
        assert me.indicator() == pytest.approx(-WALL_K * abs(_penetration(q)), rel=1e-9)
        expected = plant._rhs(tuple(tau), mode)(tuple(x))
        np.testing.assert_allclose(me.derivatives(), expected, rtol=1e-12, atol=1e-12)
        ders = me.fmu.getReal([me.vr[f"der({s})"] for s in STATES])
        np.testing.assert_array_equal(ders, me.derivatives())
        np.testing.assert_array_equal(me.fmu.getReal([me.vr[s] for s in STATES]), x)
        assert me.states().tolist() == x.tolist()
    me.fmu.terminate()
    me.fmu.freeInstance()


def test_fmu_state_under_model_exchange(native_dir):
    """fmi2GetFMUstate/SetFMUstate restore the states, the contact mode and the mode phase."""
    me = MEPlant(native_dir)
    me.initialize()
    me.fmu.enterContinuousTimeMode()
    plant = PlantModel({}, 0.0)
    q = plant.arm.inverse_kinematics((0.651, 0.1, 0.2), True)  # 1 mm into the wall
    x = (ctypes.c_double * 6)(*q, -0.1, 0.2, 0.0)
    me.fmu.setContinuousStates(x, 6)
    saved = me.fmu.getFMUstate()
    free = me.derivatives()  # still the free mode: the host has not seen the event yet
    assert me.indicator() > 0.0
    me.fmu.enterEventMode()
    me.fmu.newDiscreteStates()  # contact: the wall force acts from here on
    me.fmu.enterContinuousTimeMode()
    in_contact = me.derivatives()
    assert me.indicator() < 0.0 and not np.allclose(in_contact, free)
    me.fmu.setContinuousStates((ctypes.c_double * 6)(*q, 0.0, 0.0, 0.0), 6)
    me.fmu.setFMUstate(saved)
    assert me.states().tolist() == list(x)
    assert me.derivatives().tolist() == free.tolist()
    me.fmu.setContinuousStates(x, 6)  # allowed: the restored phase is continuous-time mode
    me.fmu.freeFMUstate(saved)
    me.fmu.terminate()
    me.fmu.freeInstance()


def test_sensor_effects_are_refused_under_model_exchange(native_dir):
    for name in ("q_noise", "q_quant"):
        me = MEPlant(native_dir)
        with pytest.raises(FMICallException):
            me.initialize(**{name: 1e-4})
        assert "under Model Exchange the encoders are ideal" in me.messages[-1]
        assert name in me.messages[-1]
        me.fmu.freeInstance()


def test_model_exchange_call_rules(native_dir):
    me = MEPlant(native_dir)
    with pytest.raises(FMICallException):
        me.fmu.setTime(0.0)  # before initialization
    assert "fmi2SetTime cannot be called in instantiated" in me.messages[-1]
    me.initialize()
    with pytest.raises(FMICallException):  # event mode after initialization
        me.fmu.setContinuousStates((ctypes.c_double * 6)(), 6)
    me.fmu.enterContinuousTimeMode()
    with pytest.raises(FMICallException):
        me.fmu.setContinuousStates((ctypes.c_double * 5)(), 5)
    assert "5 states given, this FMU has 6" in me.messages[-1]
    bad = (ctypes.c_double * 6)(0.0, 0.0, math.nan, 0.0, 0.0, 0.0)
    with pytest.raises(FMICallException):
        me.fmu.setContinuousStates(bad, 6)
    assert "state 3 is not finite" in me.messages[-1]
    with pytest.raises(FMICallException):
        me.fmu.setReal([me.vr["der(qd1)"]], [1.0])
    assert "computed by the model" in me.messages[-1]
    do_step = me.fmu.dll.fmi2DoStep
    do_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
    assert do_step(me.fmu.component, 0.0, DT, 1) == 3  # fmi2Error: not a co-simulation instance
    me.fmu.terminate()
    me.fmu.freeInstance()
    # and a co-simulation instance refuses the ME functions
    md = read_model_description(str(native_dir / PLANT))
    cs = FMU2Slave(
        guid=md.guid,
        unzipDirectory=extract(str(native_dir / PLANT)),
        modelIdentifier="PumaPlant",
        instanceName="cs",
    )
    cs.instantiate()
    cs.setupExperiment(startTime=0.0)
    cs.enterInitializationMode()
    cs.exitInitializationMode()
    set_time = cs.dll.fmi2SetTime
    set_time.argtypes = [ctypes.c_void_p, ctypes.c_double]
    assert set_time(cs.component, 0.0) == 3  # fmi2Error
    cs.terminate()
    cs.freeInstance()


# --- agreement with co-simulation ------------------------------------------------------------


@pytest.mark.slow
def test_default_experiment_agrees_with_co_simulation(native_dir, tmp_path):
    """fmpy simulate, CVode at the DefaultExperiment's tolerance (1e-9), against CS."""
    out = tmp_path / "me.csv"
    cmd = ["fmpy", "simulate", str(native_dir / PLANT), "--interface-type", "ModelExchange"]
    subprocess.run([*cmd, "--output-interval", str(DT), "--output-file", str(out)], check=True)
    me_cli = read_csv(out)
    me = simulate_fmu(str(native_dir / PLANT), fmi_type="ModelExchange", output_interval=DT)
    cs = simulate_fmu(str(native_dir / PLANT), fmi_type="CoSimulation", output_interval=DT)
    assert len(me) == len(cs) == len(me_cli["time"]) == 8001
    for name in ("q1_true", "q2_true", "q3_true"):
        assert np.abs(me[name] - cs[name]).max() < 1e-6
        assert np.abs(me_cli[name] - cs[name]).max() < 1e-6
        assert np.array_equal(me[name], me["q" + name[1]])  # ideal encoders under ME
    assert np.abs(cs["q1_true"][-1] - cs["q1_true"][0]) > 1.0  # the arm did fall


@pytest.fixture(scope="module")
def paper_torques(native_dir):
    """The controller's torques over the paper scenario (our master, native system) and the
    CS plant's joint angles there."""
    run = Master(read_ssp(native_dir.parent / "PaperScenario-native.ssp")).run()
    assert run.ok, run.error
    t = run["time"]
    assert np.allclose(np.diff(t), DT)
    # the torque applied over [t_i, t_i+1] is recorded in the row at t_i+1
    tau = np.column_stack([run[f"controller.tau{i}"][1:] for i in (1, 2, 3)])
    q_cs = np.column_stack([run[f"plant.q{i}_true"] for i in (1, 2, 3)])
    return t, tau, q_cs


def test_held_input_gives_the_new_torque_from_each_step_on(native_dir, paper_torques):
    """fmpy's Input, as its CVode root function and its event handling call it, sees tau[i]
    everywhere in [t_i, t_i+1) (the master's sample-and-hold), to the rounding of fmpy's linear
    interpolation between equal values."""
    t, tau, _ = paper_torques
    signal = held_input(t[:41], tau[:40], ("tau1", "tau2", "tau3"))
    table = np.stack([signal[n] for n in ("tau1", "tau2", "tau3")])
    for i in range(40):
        for time in (t[i], t[i] + 0.3 * DT, t[i + 1] - 1e-9):
            for after_event in (False, True):
                value, _ = Input.interpolate(time, signal["time"], table, False, after_event)
                np.testing.assert_allclose(value, tau[i], rtol=1e-15)  # fmpy interpolates
    # one input event per torque change, each at t_i as fmpy's isclose sees it
    events = Input.findEvents(signal, read_model_description(str(native_dir / PLANT)))
    assert len(events) == 40 and events[-1] == math.inf
    assert all(math.isclose(e, ti) and e < ti for e, ti in zip(events[:-1], t[1:40]))


@pytest.mark.slow
def test_paper_scenario_torques_reproduce_co_simulation(native_dir, paper_torques):
    """The ME plant under CVode, driven by the paper scenario's torques, against the CS plant:
    contact times within 1 ms, joint angles within 1e-5 rad over 20 s. The replay is open loop,
    where differences grow about a thousandfold from 10 s to 20 s, so CVode runs at rtol 1e-14.
    The event indicator is zero (to 1e-9 m of penetration) exactly at the contact events and
    negative everywhere else."""
    t, tau, q_cs = paper_torques
    result, log = me_replay(native_dir / PLANT, t, tau, relative_tolerance=1e-14)
    q_me = np.column_stack([result[f"q{i}_true"] for i in (1, 2, 3)])
    assert np.array_equal(result["time"], t)
    assert np.abs(q_me - q_cs).max() < 1e-5

    on_grid = np.isclose(log[:, 0] / DT, np.round(log[:, 0] / DT), rtol=0.0, atol=1e-6)
    events = log[~on_grid]  # state events: where CVode stopped off the 2.5 ms grid
    cs_times, q_cs_replay = cs_crossing_times(native_dir / PLANT, t, tau, WALL_X)
    assert np.abs(q_cs_replay - q_cs).max() < 1e-8  # the replayed CS plant is the master's
    assert len(cs_times) == 4  # two contacts: closing at ~3.85 s and ~13.85 s, opening after
    assert len(events) == len(cs_times)
    assert np.abs(events[:, 0] - cs_times).max() < 1e-3
    for row in events:
        pen = _penetration(row[2:5])
        assert abs(pen) < 1e-9
        assert abs(row[1]) <= WALL_K * 1e-9
    assert (log[on_grid, 1] < 0.0).all()  # between events, the indicator is negative


# --- the controller: time events at the sample instants --------------------------------------


def test_controller_model_exchange_has_time_events_only(native_dir):
    path = native_dir / CONTROLLER
    assert validate_fmu(str(path)) == []
    md = read_model_description(str(path))
    assert md.modelExchange is not None and md.coSimulation is not None
    assert md.numberOfEventIndicators == 0 and md.derivatives == []
    fmu = FMU2Model(
        guid=md.guid,
        unzipDirectory=extract(str(path)),
        modelIdentifier=md.modelExchange.modelIdentifier,
        instanceName="c",
    )
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    for k in range(1, 4):
        needed, terminate, _, changed, defined, next_time = fmu.newDiscreteStates()
        assert (needed, terminate, changed, defined) == (False, False, False, True)
        assert next_time == k * DT  # the next sample instant
        fmu.enterContinuousTimeMode()
        fmu.setTime(next_time)
        fmu.enterEventMode()
    fmu.terminate()
    fmu.freeInstance()


def test_controller_model_exchange_reproduces_co_simulation(native_dir):
    """The ME controller under fmpy, fed the plant outputs our master recorded (native paper
    scenario, the same parameter set), takes the same samples: torques bit-identical."""
    master = Master(read_ssp(native_dir.parent / "PaperScenario-native.ssp"))
    run = master.run()
    assert run.ok, run.error
    t = run["time"]
    pairs = [(f"plant.{src}", dst) for comp, src, _, dst in CONNECTIONS if comp == "plant"]
    signal = np.zeros(len(t), dtype=[("time", float)] + [(dst, float) for _, dst in pairs])
    signal["time"] = t
    for src, dst in pairs:
        signal[dst] = run[src]
    result = simulate_fmu(
        str(native_dir / CONTROLLER),
        fmi_type="ModelExchange",
        input=signal,
        start_values=master.parameters["controller"],
        output_interval=DT,
        record_events=False,
    )
    assert np.array_equal(result["time"], t)
    for i in (1, 2, 3):
        # the sample taken at t_k is the torque applied over [t_k, t_k+1]: the master's row k + 1
        assert np.array_equal(result[f"tau{i}"][:-1], run[f"controller.tau{i}"][1:])
    assert np.abs(result["tau1"]).max() > 1.0  # the controller did work
