"""The built FMUs as a co-simulation tool sees them: standard compliance, fmpy's CLI, FMU state,
error reporting. (The closed loop over FMI is in test_master.py.)"""

from __future__ import annotations

import csv
import math
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from fmpy.validation import validate_fmu
from fmpy_cli import fmpy_cli
from fmu_steps import output_names, rows_after

from impedance_cosim.cosim.fmus.fmi2 import FmuError, FmuInstance
from impedance_cosim.packaging.regression import REFERENCES, compare, read_csv

DT = 1 / 400
PLANT, CONTROLLER = "PumaPlant.fmu", "ImpedanceController.fmu"
REFERENCES_BY_NAME = {p.name.replace("_ref.csv", ".fmu"): p for p in REFERENCES}


def started(path, name="x", **params) -> FmuInstance:
    """An instance through initialization, with parameters set."""
    fmu = FmuInstance(path, name)
    fmu.setup(0.0)
    fmu.set(params)
    fmu.enter_initialization()
    fmu.exit_initialization()
    return fmu


@pytest.mark.parametrize("name", [PLANT, CONTROLLER])
def test_fmu_is_valid_and_documented(fmu_dir, name):
    path = fmu_dir / name
    assert validate_fmu(str(path)) == []
    with zipfile.ZipFile(path) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    exp = root.find("DefaultExperiment").attrib
    assert (float(exp["startTime"]), float(exp["stopTime"]), float(exp["stepSize"])) == (
        0.0,
        20.0,
        0.0025,
    )
    assert root.find("CoSimulation").get("canGetAndSetFMUstate") == "true"
    units = {u.get("name") for u in root.iter("Unit")}
    for sv in root.iter("ScalarVariable"):
        assert sv.get("description"), sv.get("name")
        real = sv.find("Real")
        if real is not None and sv.get("name") not in ("rtol", "atol"):
            assert real.get("unit") in units, sv.get("name")


@pytest.mark.parametrize("name", [PLANT, CONTROLLER])
@pytest.mark.slow
def test_fmpy_simulate_from_a_shell(fmu_dir, tmp_path, name):
    """`fmpy simulate` runs each FMU's default experiment on its own."""
    out = tmp_path / "out.csv"
    cmd = ["simulate", str(fmu_dir / name), "--output-interval", "0.0025"]
    fmpy_cli([*cmd, "--output-file", str(out)], check=True, timeout=300)
    with open(out) as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 8001 and float(rows[-1]["time"]) == 20.0
    assert all(math.isfinite(float(v)) for row in rows for v in row.values())
    result = {k: np.array([float(r[k]) for r in rows[::40]]) for k in rows[0]}
    ref = read_csv(REFERENCES_BY_NAME[name])
    assert compare(result, ref, rtol=1e-9) == []
    if name == PLANT:  # unpowered, the arm falls and ends hanging down, nearly at rest
        assert float(rows[-1]["y"]) < -0.8
        assert abs(float(rows[-1]["q1"]) + math.pi / 2) < 0.1
        assert abs(float(rows[-1]["qd1"])) < 1e-3


@pytest.mark.parametrize(
    "name,inputs",
    [(PLANT, {"tau1": 30.0, "tau2": 20.0, "tau3": 1.0}), (CONTROLLER, {"q2": -2.7, "fx": 3.0})],
)
def test_state_restore_is_bit_identical(fmu_dir, name, inputs):
    """Step, save, step, restore, step again: identical outputs; the same through serialization
    into a second instance."""
    fmu = started(fmu_dir / name, q_noise=1e-4) if name == PLANT else started(fmu_dir / name)
    outputs = output_names(fmu)
    fmu.set(inputs)
    for i in range(40):
        fmu.step(i * DT, DT)
    state = fmu.get_state()
    blob = fmu.serialize_state(state)

    first = rows_after(fmu, outputs)
    fmu.set_state(state)
    assert rows_after(fmu, outputs) == first
    other = started(fmu_dir / name, "y", q_noise=1e-4) if name == PLANT else started(fmu_dir / name)
    other.set_state(other.deserialize_state(blob))
    fmu, fmu_saved = other, fmu
    assert rows_after(fmu, outputs) == first
    fmu_saved.free_state(state)
    for f in (fmu_saved, other):
        f.terminate()
        f.free()


@pytest.mark.parametrize(
    "name,params,message",
    [
        (PLANT, {"m2": -1.0}, "parameter m2 must be >= 0"),
        (PLANT, {"wall_k": -1.0}, "parameter wall_k must be >= 0"),
        (PLANT, {"x0": 1.5}, "unreachable"),
        (CONTROLLER, {"K2": 0.0}, "parameter K2 must be > 0"),
        (CONTROLLER, {"sample_period": -0.001}, "sample_period must be > 0"),
        (CONTROLLER, {"velocity_source": 7}, "velocity_source must be one of"),
    ],
)
def test_bad_parameters_give_a_clear_fmi_error(fmu_dir, capfd, name, params, message):
    fmu = FmuInstance(fmu_dir / name, "bad")
    fmu.setup(0.0)
    fmu.set(params)
    fmu.enter_initialization()
    with pytest.raises(FmuError, match=message):
        fmu.exit_initialization()
    assert any(message in m for m in fmu.errors())  # through the FMU logger
    assert message in capfd.readouterr().err  # and visible in a shell with logging off


@pytest.mark.parametrize(
    "name,inputs,message",
    [
        (PLANT, {"tau2": math.nan}, "input tau2 is not finite"),
        (PLANT, {"tau1": math.inf}, "input tau1 is not finite"),
        (CONTROLLER, {"q1": math.nan}, "input q1 is not finite"),
        (CONTROLLER, {"fx": -math.inf}, "input fx is not finite"),
    ],
)
def test_non_finite_inputs_are_refused(fmu_dir, name, inputs, message):
    fmu = started(fmu_dir / name)
    fmu.step(0.0, DT)
    fmu.set(inputs)
    with pytest.raises(FmuError, match=f"Discard.*{message}"):
        fmu.step(DT, DT)


def test_wrong_call_order_is_refused(fmu_dir):
    fmu = FmuInstance(fmu_dir / PLANT, "early")
    fmu.setup(0.0)
    with pytest.raises(FmuError, match="before initialization"):
        fmu.step(0.0, DT)
    fmu.enter_initialization()
    fmu.exit_initialization()
    with pytest.raises(FmuError, match="cannot be set after initialization"):
        fmu.set({"m1": 2.0})


def test_two_instances_in_one_process(fmu_dir):
    """pythonfmu 0.7.0 crashed on a second instance in one process (see fmi.fmi2_slave)."""
    a = started(fmu_dir / PLANT, "a")
    b = started(fmu_dir / PLANT, "b", x0=0.4)
    a.free()
    c = started(fmu_dir / PLANT, "c")
    assert b.get(["x"]) == [pytest.approx(0.4)] and c.get(["x"]) == [pytest.approx(0.3)]
    for f in (b, c):
        f.free()


if __name__ == "__main__":
    sys.exit(pytest.main([__file__]))


def test_process_survives_an_initialization_error(ssp_path):
    """After fmi2Fatal the instance is left alone (pythonfmu 0.7 releases Python objects twice if
    it is freed, and the process crashed at a later garbage collection: segfault before the fix)."""
    script = f"""
import gc
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp
system = read_ssp(r"{ssp_path}")
for k in range(3):
    bad = Master(system, RunOptions(overrides={{"plant.x0": 5.0}}, stop_time=0.1)).run()
    assert "unreachable" in bad.error, bad.error
    assert Master(system, RunOptions(stop_time=0.1)).run().ok
    gc.collect()
print("survived")
from impedance_cosim.cosim.fmus.fmi2 import exit_process
exit_process(0)  # the libraries left loaded after fmi2Fatal: see exit_process
"""
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0 and "survived" in done.stdout, done.stderr[-1000:]
