"""The Python FMUs as FMI 3.0 (pythonfmu3, fmi/fmi3_slave.py, build_fmi3.build_python_fmu3):
valid, the native FMI 3.0 FMUs' variables, our master's 20 s paper run equal to the FMI 2.0
Python FMUs' bit for bit, FMU state save/restore, and bad parameters reported."""

from __future__ import annotations

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from impedance_cosim.cosim.fmus.fmi2 import FmuError
from impedance_cosim.cosim.fmus.fmi3 import FmuInstance3
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp

pytest.importorskip("pythonfmu3")

DT = 1 / 400
NAMES = ("PumaPlant.fmu", "ImpedanceController.fmu")


@pytest.fixture(scope="module")
def python3_dir(fmi3_dir):
    return fmi3_dir / "python"


@pytest.mark.parametrize("name", NAMES)
def test_python_fmi3_fmu_is_valid_with_the_native_variables(python3_dir, fmi3_dir, name):
    path = python3_dir / name
    assert validate_fmu(str(path)) == []
    md = read_model_description(str(path))
    assert md.fmiVersion == "3.0" and md.coSimulation.canGetAndSetFMUstate
    native = {v.name: v for v in read_model_description(str(fmi3_dir / name)).modelVariables}
    time = next(v for v in md.modelVariables if v.name == "time")
    assert time.causality == "independent"
    assert time.valueReference == len(md.modelVariables) - 1  # after the table (no der() here)
    for v in md.modelVariables:
        if v is time:
            continue
        w = native[v.name]
        assert (v.valueReference, v.type, v.causality, v.unit, str(v.start)) == (
            w.valueReference, w.type, w.causality, w.unit, str(w.start))  # fmt: skip


@pytest.mark.slow
def test_master_runs_python_fmi3_equal_to_python_fmi2(fmu_dir, python3_dir):
    fmi2 = Master(
        read_ssp(fmu_dir / "PaperScenario.ssp"), RunOptions(parameter_set="observer")
    ).run()
    files = {"plant": python3_dir / NAMES[0], "controller": python3_dir / NAMES[1]}
    fmi3 = Master(
        read_ssp(fmu_dir / "PaperScenario-fmi3.ssp"),
        RunOptions(parameter_set="observer", fmu_files=files),
    ).run()
    assert fmi2.ok and fmi3.ok, (fmi2.error, fmi3.error)
    assert fmi3.names == fmi2.names and np.array_equal(fmi3.data, fmi2.data)
    assert fmi3.data.shape[0] == 8001 and fmi3["plant.contact_force"].max() > 1.0


def test_python_fmi3_state_and_errors(python3_dir):
    fmu = FmuInstance3(python3_dir / NAMES[0], "p")
    fmu.setup(0.0)
    fmu.enter_initialization()
    fmu.exit_initialization()
    fmu.set({"tau1": 30.0})
    for i in range(4):
        fmu.step(i * DT, DT)
    state = fmu.get_state()
    data = fmu.serialize_state(state)
    before = fmu.get(["q1_true", "qd1", "time"])
    for i in range(4, 8):
        fmu.step(i * DT, DT)
    assert fmu.get(["q1_true"]) != before[:1]
    fmu.set_state(fmu.deserialize_state(data))
    assert fmu.get(["q1_true", "qd1", "time"]) == before
    fmu.free()
    bad = FmuInstance3(python3_dir / NAMES[0], "bad")
    bad.setup(0.0)
    bad.set({"m2": -1.0})
    with pytest.raises(FmuError, match="m2"):
        bad.enter_initialization()
        bad.exit_initialization()
    bad.free()
