"""Test hosts for the native plant's partial derivatives (tests/test_partials.py,
tests/test_output_derivatives.py): FMI 2.0 and 3.0 Model Exchange instances with the same small
interface (set states and torques, read derivatives and outputs, event update, directional
derivatives), and random states of the arm, free and in contact with the wall."""

from __future__ import annotations

import ctypes

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Model, FMU2Slave
from fmpy.fmi3 import FMU3Model, FMU3Slave

from impedance_cosim.physics.arm import Arm

STATES = ("q1_true", "q2_true", "q3_true", "qd1", "qd2", "qd3")
INPUTS = ("tau1", "tau2", "tau3")
KNOWNS = STATES + INPUTS
WALL_X, WALL_K = 0.65, 1e4  # the plant's default wall
ARM = Arm()  # the plant's default arm (Python, independent of the C under test)


def _open(path, cls, **kw):
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    guid = md.guid if md.fmiVersion == "2.0" else md.instantiationToken
    fmu = cls(guid=guid, unzipDirectory=extract(str(path)),
              modelIdentifier=md.coSimulation.modelIdentifier, instanceName="p", **kw)  # fmt: skip
    return md, vr, fmu


class _Host:
    """What both hosts share: torques in, values out, by name."""

    fmi3: bool
    vr: dict[str, int]
    fmu: object

    def set_inputs(self, tau) -> None:
        refs = [self.vr[n] for n in INPUTS]
        (self.fmu.setFloat64 if self.fmi3 else self.fmu.setReal)(refs, list(tau))

    def get(self, names) -> np.ndarray:
        refs = [self.vr[n] for n in names]
        return np.array((self.fmu.getFloat64 if self.fmi3 else self.fmu.getReal)(refs))


class MeHost(_Host):
    """A Model Exchange plant, FMI 2.0 or 3.0 (after initialization, in continuous-time mode)."""

    def __init__(self, path, fmi3: bool, **params: float) -> None:
        self.fmi3 = fmi3
        self.md, self.vr, self.fmu = _open(path, FMU3Model if fmi3 else FMU2Model)
        self.outputs = [v.name for v in self.md.modelVariables if v.causality == "output"]
        self.ders = [f"der({s})" for s in STATES]
        f = self.fmu
        if fmi3:
            f.instantiate()
            f.enterInitializationMode(startTime=0.0)
            for k, v in params.items():
                f.setFloat64([self.vr[k]], [v])
            f.exitInitializationMode()
        else:
            f.instantiate()
            f.setupExperiment(startTime=0.0)
            f.enterInitializationMode()
            for k, v in params.items():
                f.setReal([self.vr[k]], [v])
            f.exitInitializationMode()
        self.event_update(entered=True)  # initialization ends in event mode

    def _array(self, function: str, values=None, n: int = 6) -> np.ndarray:
        buf = (ctypes.c_double * n)(*(values if values is not None else []))
        getattr(self.fmu, function)(buf, n)
        return np.array(buf)

    def set_states(self, x) -> None:
        self._array("setContinuousStates", list(x))

    def derivatives(self) -> np.ndarray:
        name = "getContinuousStateDerivatives" if self.fmi3 else "getDerivatives"
        return self._array(name)

    def unknowns(self) -> np.ndarray:
        """The outputs, then the state derivatives (the order of unknown_names())."""
        return np.concatenate([self.get(self.outputs), self.derivatives()])

    def unknown_names(self) -> list[str]:
        return [*self.outputs, *self.ders]

    def event_update(self, entered: bool = False) -> None:
        """An event iteration at the current state: the contact mode switches where the current
        mode's switching function is positive."""
        f = self.fmu
        if not entered:
            f.enterEventMode()
        update = f.updateDiscreteStates if self.fmi3 else f.newDiscreteStates
        while update()[0]:  # discreteStatesNeedUpdate / newDiscreteStatesNeeded
            pass
        f.enterContinuousTimeMode()

    def jacobian(self, unknowns: list[str], knowns: list[str]) -> np.ndarray:
        """d unknowns / d knowns, one directional derivative per known (unit seeds)."""
        u = [self.vr[n] for n in unknowns]
        cols = [self.dd(u, [self.vr[k]], [1.0]) for k in knowns]
        return np.array(cols).T

    def dd(self, u, k, seed) -> list[float]:
        return self.fmu.getDirectionalDerivative(u, k, seed)


class CsHost(_Host):
    """A co-simulation plant, FMI 2.0 or 3.0, initialized with params, in step mode."""

    def __init__(self, path, fmi3: bool, **params: float) -> None:
        self.fmi3 = fmi3
        self.messages: list[str] = []
        self.md, self.vr, self.fmu = _open(path, FMU3Slave if fmi3 else FMU2Slave)
        f = self.fmu
        if fmi3:
            f.instantiate(loggingOn=True, logMessage=self._log3)
            f.enterInitializationMode(startTime=0.0)
        else:
            from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

            self._cb = fmi2CallbackFunctions()
            self._cb.logger = fmi2CallbackLoggerTYPE(self._log2)
            f.instantiate(callbacks=self._cb, loggingOn=True)
            f.setupExperiment(startTime=0.0)
            f.enterInitializationMode()
        for k, v in params.items():
            (f.setFloat64 if fmi3 else f.setReal)([self.vr[k]], [v])
        f.exitInitializationMode()
        self.t = 0.0

    def _log2(self, _env, _name, _status, _category, message) -> None:
        self.messages.append(message.decode())

    def _log3(self, _env, _status, _category, message) -> None:
        self.messages.append(message.decode())

    def step(self, h: float) -> None:
        self.fmu.doStep(self.t, h)
        self.t += h

    def output_derivatives(self, names, orders) -> np.ndarray:
        refs = [self.vr[n] for n in names]
        f = self.fmu
        get = f.getOutputDerivatives if self.fmi3 else f.getRealOutputDerivatives
        return np.array(get(refs, list(orders)))


def random_state(rng: np.random.Generator, contact: bool, wall_d: float = 0.0) -> np.ndarray:
    """A random elbow-up state of the arm; with contact, the tool 0.1-10 mm inside the wall and
    the wall law (WALL_K, wall_d) pushing; else the tool at least 1 mm outside."""
    while True:
        q = rng.uniform([-1.2, -2.6, -1.5], [1.2, -0.3, 1.5])
        qd = rng.uniform(-2.0, 2.0, 3)
        pen = ARM.kinematics(tuple(q))[0] - WALL_X
        xd = float(np.array(ARM.jacobian(tuple(q)))[0] @ qd)
        if contact and 1e-4 < pen < 1e-2 and WALL_K * pen + wall_d * xd > 0.0:
            return np.concatenate([q, qd])
        if not contact and pen < -1e-3:
            return np.concatenate([q, qd])


def penetration(x: np.ndarray) -> float:
    """x(q) - wall_x of a state, from the Python arm."""
    return ARM.kinematics(tuple(x[:3]))[0] - WALL_X
