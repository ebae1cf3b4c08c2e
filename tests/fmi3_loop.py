"""The closed loop of the FMI 3.0 plant and controller on fmpy, for the tests of the controller's
clock (tests/test_fmi3_clock_cs.py, test_fmi3_clock_me.py, test_fmi3_clock_update.py): the two
instances (Co-Simulation or Model Exchange), initialized with the observer scenario's
parameters and connected as the paper's system."""

from __future__ import annotations

from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave

from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.cosim.system.paper import CONNECTIONS


class Fmu:
    """An FMI 3.0 instance under fmpy (KIND: FMU3Slave or FMU3Model), its log kept."""

    def __init__(self, fmi3_dir, name: str, kind=FMU3Slave, **instantiate):
        path = str(fmi3_dir / f"{name}.fmu")
        md = read_model_description(path)
        self.md = md
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.log: list[str] = []
        self.fmu = kind(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=name,
                        instanceName=name)  # fmt: skip
        self.fmu.instantiate(logMessage=lambda _e, _s, _c, m: self.log.append(m.decode()),
                             **instantiate)  # fmt: skip

    def set_parameters(self, values: dict) -> None:
        by_name = {v.name: v for v in self.md.modelVariables}
        for name, value in values.items():
            getattr(self.fmu, f"set{by_name[name].type}")([by_name[name].valueReference], [value])


class ClosedLoop:
    """The plant and the controller (instantiated), through Initialization Mode with the
    observer scenario's parameters and the connections' values; the samples a test records."""

    def __init__(self, fmu_dir, plant: Fmu, ctrl: Fmu):
        params = Master(read_ssp(fmu_dir / "PaperScenario-fmi3.ssp"),
                        RunOptions(parameter_set="observer")).parameters  # fmt: skip
        self.plant, self.ctrl = plant, ctrl
        for fmu, name in ((self.plant, "plant"), (self.ctrl, "controller")):
            fmu.fmu.enterInitializationMode(startTime=0.0)
            fmu.set_parameters(params[name])
        p, c = self.plant.vr, self.ctrl.vr
        self.links = [(p[s], c[e]) for sc, s, _ec, e in CONNECTIONS if sc == "plant"]
        self.tau = [(c[s], p[e]) for sc, s, _ec, e in CONNECTIONS if sc == "controller"]
        self.inputs()
        self.torques()
        self.plant.fmu.exitInitializationMode()
        self.ctrl.fmu.exitInitializationMode()
        self.samples: list[tuple[float, list[float]]] = []

    def inputs(self) -> None:
        """The plant's outputs to the controller's inputs."""
        self.ctrl.fmu.setFloat64([c for _, c in self.links],
                                 self.plant.fmu.getFloat64([p for p, _ in self.links]))  # fmt: skip

    def torques(self) -> list[float]:
        """The controller's torques to the plant; they are returned."""
        tau = self.ctrl.fmu.getFloat64([c for c, _ in self.tau])
        self.plant.fmu.setFloat64([p for _, p in self.tau], tau)
        return tau
