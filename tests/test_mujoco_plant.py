"""MujocoPlant (plant_model/mujoco_plant.py): PumaPlant's interface simulated by MuJoCo from the
MJCF it carries. Its numbers follow the parameters as an MJCF written with them would; free
motion agrees with PumaPlant to the integrators' accuracy; the contact force and the wrist
sensor are the wall law; the paper's scenario swaps in (what every swapped-in plant must do
alike is in test_swapped_plants.py)."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
import zipfile
from dataclasses import replace

import mujoco
import numpy as np
import pytest
from plant_motion import free_motion

from impedance_cosim.cosim.results.result import read_csv
from impedance_cosim.fmi.model import ModelError
from impedance_cosim.packaging.mujoco_mjcf import MUJOCO_MJCF_NAME, mujoco_mjcf
from impedance_cosim.physics.arm import Arm, ArmParams
from impedance_cosim.physics.description import describe
from plant_model import mujoco_plant
from plant_model.model import PlantModel
from plant_model.mujoco_plant import NOT_HERE, MujocoPlantModel, mujoco_arm

CHANGED = replace(ArmParams(), a1=0.45, a3=0.16, m2=6.0, m3=2.5, rx2=0.08, ry1=0.01, Iu2=0.25,
                  Im3=0.2, f2=5.0, g=9.7)  # fmt: skip
CLI = [sys.executable, "-m", "impedance_cosim.cli"]
RUN = ["--no-figures", "--no-report", "--no-progress"]


@pytest.fixture
def bundled(monkeypatch):
    """The model run in this process, with the MJCF the FMU carries."""
    monkeypatch.setattr(mujoco_plant, "carried_mjcf", mujoco_mjcf)


def test_interface_is_pumaplants():
    """Inputs and outputs exactly PumaPlant's; its parameters less the integrator's, plus
    timestep."""
    ours = {v.name: v for v in PlantModel.variables()}
    theirs = {v.name: v for v in MujocoPlantModel.variables()}
    assert set(ours) - set(theirs) == set(NOT_HERE)
    assert set(theirs) - set(ours) == {"timestep"}
    for name, v in theirs.items():
        if name != "timestep":
            assert v == ours[name], name


def test_parameters_set_what_an_mjcf_with_them_says(bundled):
    """mujoco_arm(default MJCF, changed numbers) is what MuJoCo compiles from an MJCF written
    with the changed numbers: model fields, H(q) and the forward dynamics at random states."""
    desc = describe(CHANGED)
    ours, d1 = mujoco_arm(mujoco, mujoco_mjcf(), desc)
    theirs = mujoco.MjModel.from_xml_string(mujoco_mjcf(CHANGED))
    d2 = mujoco.MjData(theirs)
    theirs.pair_solref[0] = ours.pair_solref[0]  # the plant's own setting (wall_k, A)
    for field in ("body_pos", "body_mass", "body_ipos", "body_inertia", "body_invweight0",
                  "dof_armature", "dof_damping", "site_pos"):  # fmt: skip
        assert np.abs(getattr(ours, field) - getattr(theirs, field)).max() < 1e-12, field
    contact = [ours.geom(name).id for name in ("tool_tip", "wall")]  # (the capsules: pictures)
    assert np.abs(ours.geom_pos[contact] - theirs.geom_pos[contact]).max() < 1e-12
    assert list(ours.opt.gravity) == [0.0, -9.7, 0.0]
    rng = np.random.default_rng(5)
    h1, h2 = np.zeros((3, 3)), np.zeros((3, 3))
    for _ in range(20):
        for d in (d1, d2):
            d.qpos[:] = rng.uniform(-np.pi, np.pi, 3) if d is d1 else d1.qpos
            d.qvel[:] = rng.uniform(-3, 3, 3) if d is d1 else d1.qvel
            d.qfrc_applied[:] = rng.uniform(-50, 50, 3) if d is d1 else d1.qfrc_applied
        for m, d, h in ((ours, d1, h1), (theirs, d2, h2)):
            mujoco.mj_forward(m, d)
            mujoco.mj_fullM(m, d, h)
        assert np.abs(h1 - h2).max() < 1e-12 and np.abs(d1.qacc - d2.qacc).max() < 1e-10
        assert np.abs(h1 - np.array(Arm(CHANGED).inertia(tuple(d1.qpos)))).max() < 1e-10


@pytest.mark.parametrize("params", [{}, {f: getattr(CHANGED, f) for f in ("a1", "a3", "m3", "g")}])
def test_free_motion_agrees_with_pumaplant(bundled, params):
    """1 s of free fall from the start pose: every output within 1e-9 of PumaPlant's (MuJoCo's
    RK4 at 0.25 ms against our Dormand-Prince at rtol 1e-9), also with changed parameters."""
    ours = free_motion(PlantModel(params), 400)
    theirs = free_motion(MujocoPlantModel(params), 400)
    assert np.abs(ours[-1, 6:9] - ours[0, 6:9]).max() > 0.1  # it moved
    assert np.abs(ours - theirs).max() < 1e-9


def test_the_integrator_is_mujocos(bundled):
    """A 25 ms timestep (one RK4 step per communication step) is visibly less accurate."""
    ours = free_motion(PlantModel({}), 400)
    coarse = free_motion(MujocoPlantModel({"timestep": 0.0025}), 400)
    assert np.abs(ours - coarse).max() > 1e-9


@pytest.mark.parametrize("pose", [(0.651, 0.0, 0.0), (0.652, 0.12, 0.6)])
@pytest.mark.parametrize("wall_d", [0.0, 50.0])
def test_contact_force_and_wrist_sensor_are_the_wall_law(bundled, pose, wall_d):
    """Pressed into the wall (held there, moving at 0.05 m/s into it): MuJoCo's contact force
    and the wrist sensor's fx are k pen + d rate to 1e-3, fy and n (frictionless, at the tool
    point) zero, also with the wrist turned (phi = 0.6: the site frame rotated)."""
    model = MujocoPlantModel({"wall_d": wall_d})
    m, d = model.mj, model.mj_data
    q = Arm().inverse_kinematics(pose, True)
    jac = np.array(Arm().jacobian(q))
    qd = np.linalg.solve(jac, [0.05, 0.0, 0.0])
    model.q, model.qd = q, tuple(qd)
    d.qpos[:], d.qvel[:] = q, qd
    mujoco.mj_forward(m, d)
    names = [v.name for v in MujocoPlantModel.variables() if v.causality == "output"]
    out = dict(zip(names, model.outputs(), strict=True))
    law = 1e4 * (pose[0] - 0.65) + wall_d * 0.05
    assert out["penetration"] == pytest.approx(pose[0] - 0.65, abs=1e-12)
    assert out["contact_force"] == pytest.approx(law, rel=1e-3)
    # exactly contact_solref's formula: the law less i a1 / ((1 - i) A), a1 MuJoCo's normal
    # acceleration of the contact (J qacc), i the impedance, A the hand's body_invweight0
    a1 = float(d.efc_J.reshape(d.nefc, m.nv)[0] @ d.qacc)
    i, inverse_mass = m.pair_solimp[0][0], m.body_invweight0[m.body("hand").id, 0]
    assert abs(a1) > 0.1  # the term is there
    predicted = law - i * a1 / ((1 - i) * inverse_mass)
    assert out["contact_force"] == pytest.approx(predicted, rel=1e-9, abs=1e-12)
    assert out["fx"] == pytest.approx(out["contact_force"], rel=1e-9)
    assert abs(out["fy"]) < 1e-9 and abs(out["n"]) < 1e-9


def test_a_step_mujoco_cannot_take_is_refused_and_undone(bundled, tmp_path, monkeypatch):
    """A torque MuJoCo's integrator cannot follow (it would reset the state silently) is a
    ModelError naming MuJoCo's warning with its text; the plant stays where it was; MuJoCo's own
    handler (which writes MUJOCO_LOG.TXT into the working folder) is bypassed and left as it
    was; a step needing more than MAX_SUBSTEPS MuJoCo steps is refused before any work."""
    monkeypatch.chdir(tmp_path)
    model = MujocoPlantModel({})
    model.do_step(0.0, 0.0025, (1.0, 1.0, 1.0))
    before, state = model.outputs(), model.get_state()
    with pytest.raises(
        ModelError, match=r"MuJoCo step from t=0.0025 failed: mjWARN_BADQACC .*huge value in QACC"
    ):
        model.do_step(0.0025, 0.0025, (1e10, 1e10, 1e10))
    assert model.outputs() == before and model.get_state() == state
    assert list(tmp_path.iterdir()) == [] and mujoco.get_mju_user_warning() is None
    with pytest.raises(ModelError, match="needs 4000000000 MuJoCo steps"):
        model.do_step(0.0025, 1e6, (0.0, 0.0, 0.0))


def test_outside_an_fmu_the_missing_mjcf_is_named():
    """Only the build writes carried_files.py: the model run from the checkout says so."""
    with pytest.raises(ModelError, match=r"puma3_mujoco.xml is missing \(the FMU carries it"):
        MujocoPlantModel({})


def test_a_bad_timestep_is_named(bundled):
    with pytest.raises(ModelError, match="parameter timestep must be from"):
        MujocoPlantModel({"timestep": 0.0})


def test_the_fmu_carries_the_mjcf_and_declares_mujoco(fmu_dir):
    """The carried MJCF is mujoco_mjcf() of the default parameters; documentation/
    externalDependencies.txt names mujoco; needsExecutionTool stays false (the model is in the
    FMU, MuJoCo is a library it needs)."""
    with zipfile.ZipFile(fmu_dir / "MujocoPlant.fmu") as z:
        name = next(n for n in z.namelist() if n.endswith("/carried_files.py"))
        files = ast.literal_eval(z.read(name).decode().split("FILES = ", 1)[1])
        needs = z.read("documentation/externalDependencies.txt").decode()
        md = z.read("modelDescription.xml").decode()
    assert files == {MUJOCO_MJCF_NAME: mujoco_mjcf()}
    assert "pip install mujoco==4.0.0" in needs
    assert 'needsExecutionTool="false"' in md


@pytest.mark.slow
def test_swap_runs_the_paper_scenario(fmu_dir, ssp_path, tmp_path):
    """`swap --replace plant=MujocoPlant.fmu` runs the 20 s paper scenario (observer): the
    same free motion as PumaPlant before the contact (1e-7 rad), the same contact phases and
    impact peak within 0.1 N; run.json and the report name the replacement."""
    runs = {}
    for name, extra in (
        ("ours", []),
        ("mujoco", ["--replace", f"plant={fmu_dir}/MujocoPlant.fmu"]),
    ):
        command = "swap" if extra else "run"
        argv = [*CLI, command, "--ssp", str(ssp_path), "--scenario", "observer", *extra,
                "--out", str(tmp_path / name), "--no-figures", "--no-progress"]  # fmt: skip
        done = subprocess.run(argv, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
        runs[name] = read_csv(tmp_path / name / "observer.csv")
    ours, theirs = runs["ours"], runs["mujoco"]
    free = ours["time"] < 3.8
    q = [f"plant.q{i}_true" for i in (1, 2, 3)]
    assert max(np.abs(ours[k][free] - theirs[k][free]).max() for k in q) < 1e-7
    assert 50 < theirs["plant.contact_force"].max() < 200
    assert abs(theirs["plant.contact_force"].max() - ours["plant.contact_force"].max()) < 0.1
    s1, s2 = (json.loads((tmp_path / n / "observer_summary.json").read_text()) for n in runs)
    assert s1["contact_phases_s"] == s2["contact_phases_s"]
    record = json.loads((tmp_path / "mujoco" / "run.json").read_text())
    assert record["runs"][0]["fmus"]["plant"]["model"] == "MujocoPlant"
    assert record["runs"][0]["fmus"]["plant"]["in_system_archive"] is False
    assert "MujocoPlant" in (tmp_path / "mujoco" / "report.html").read_text()
