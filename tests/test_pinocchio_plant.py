"""PinocchioPlant (plant_model/urdf_plant.py): PumaPlant's interface with the arm's dynamics from
Pinocchio and the URDF. Its numbers follow the parameters as a URDF written with them would; free
motion and the paper's closed loop (a swap) agree with PumaPlant to rounding (what every
swapped-in plant must do alike is in test_swapped_plants.py)."""

from __future__ import annotations

import ast
import subprocess
import sys
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from plant_motion import free_motion

from impedance_cosim.cosim.results.result import read_csv
from impedance_cosim.fmi.model import ModelError
from impedance_cosim.packaging import robot_check
from impedance_cosim.packaging.robot_files import URDF_NAME, write_robot_files
from impedance_cosim.physics.arm import ArmParams
from impedance_cosim.physics.description import describe
from plant_model import urdf_plant
from plant_model.model import PlantModel
from plant_model.urdf_plant import PinocchioPlantModel, pinocchio_arm

CHANGED = replace(ArmParams(), a1=0.45, a3=0.16, m2=6.0, m3=2.5, rx2=0.08, ry1=0.01, Iu2=0.25,
                  Im3=0.2, f2=5.0, g=9.7)  # fmt: skip
CLI = [sys.executable, "-m", "impedance_cosim.cli"]


@pytest.fixture(scope="module")
def default_urdf(tmp_path_factory) -> Path:
    """The URDF the FMU carries: written from the default parameters."""
    folder = tmp_path_factory.mktemp("urdf")
    write_robot_files(folder)
    return folder / URDF_NAME


@pytest.fixture
def bundled(default_urdf, monkeypatch):
    """The model run in this process, with the URDF the FMU carries."""
    monkeypatch.setattr(urdf_plant, "carried_urdf", default_urdf.read_text)


def test_parameters_set_what_a_urdf_with_them_says(default_urdf, tmp_path):
    """pinocchio_arm(default URDF, changed numbers) computes what Pinocchio computes from a URDF
    written with the changed numbers (and both what arm.py computes with them)."""
    write_robot_files(tmp_path, CHANGED)
    from_file = robot_check.pinocchio_model(tmp_path / URDF_NAME, CHANGED)
    ours = pinocchio_arm(pin, default_urdf.read_text(), describe(CHANGED))
    assert list(ours.damping) == [CHANGED.f1, CHANGED.f2, CHANGED.f3]
    d1, d2 = from_file.createData(), ours.createData()
    for q, qd, tau in robot_check.random_states(30, seed=3):
        a = robot_check.pinocchio_terms(from_file, d1, q, qd, tau)
        b = robot_check.pinocchio_terms(ours, d2, q, qd, tau)
        for name in robot_check.TERMS:
            assert np.abs(a[name] - b[name]).max() < 1e-12, name
    assert max(robot_check.largest_differences(
        lambda q, qd, tau: robot_check.pinocchio_terms(ours, d2, q, qd, tau), CHANGED, 30, 3
    ).values()) < 1e-10  # fmt: skip


@pytest.mark.parametrize("params", [{}, {f: getattr(CHANGED, f) for f in ("a1", "a3", "m3", "g")}])
def test_free_motion_agrees_with_pumaplant(bundled, params):
    """1 s of free fall from the start pose: every output within 1e-9 of PumaPlant's (the same
    integrator on dynamics equal to rounding), also with changed parameters."""
    ours = free_motion(PlantModel(params), 400)
    theirs = free_motion(PinocchioPlantModel(params), 400)
    assert np.abs(ours[-1, 6:9] - ours[0, 6:9]).max() > 0.1  # it moved
    assert np.abs(ours - theirs).max() < 1e-9


def test_same_variables_as_pumaplant():
    assert PinocchioPlantModel.variables() == PlantModel.variables()


def test_outside_an_fmu_the_missing_urdf_is_named():
    """Only the build writes carried_files.py: the model run from the checkout says so."""
    with pytest.raises(ModelError, match=r"puma3.urdf is missing \(the FMU carries it"):
        PinocchioPlantModel({})


def test_the_fmu_carries_the_plants_urdf(fmu_dir, default_urdf):
    """The carried URDF is the one `build` writes from the plant's parameters."""
    with zipfile.ZipFile(fmu_dir / "PinocchioPlant.fmu") as z:
        name = next(n for n in z.namelist() if n.endswith("/carried_files.py"))
        source = z.read(name).decode()
    files = ast.literal_eval(source.split("FILES = ", 1)[1])
    assert files == {URDF_NAME: default_urdf.read_text()}


@pytest.mark.slow
def test_swap_runs_the_paper_scenario_as_pumaplant(fmu_dir, ssp_path, tmp_path):
    """`swap --replace plant=PinocchioPlant.fmu` runs the closed loop through the first impact
    (4.5 s): every column within 1e-9 of the run with PumaPlant."""
    runs = {}
    for name, extra in (
        ("ours", []),
        ("pin", ["--replace", f"plant={fmu_dir}/PinocchioPlant.fmu"]),
    ):
        command = "swap" if extra else "run"
        argv = [*CLI, command, "--ssp", str(ssp_path), "--stop", "4.5", *extra, "--out",
                str(tmp_path / name), "--no-figures", "--no-report", "--no-progress"]  # fmt: skip
        done = subprocess.run(argv, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
        runs[name] = read_csv(tmp_path / name / "observer.csv")
    ours, theirs = runs["ours"], runs["pin"]
    assert ours.keys() == theirs.keys()
    assert ours["plant.contact_force"].max() > 50.0  # the impact is in it
    worst = max(np.abs(ours[k] - theirs[k]).max() for k in ours)
    assert worst < 1e-9, worst


def test_the_dynamics_are_pinocchios(bundled):
    """The plant integrates Pinocchio's model: without its motor inertias it falls differently."""
    model = PinocchioPlantModel({})
    model.robot.armature = np.zeros(3)
    ours = free_motion(PlantModel({}), 100)
    assert np.abs(free_motion(model, 100) - ours).max() > 1e-3
