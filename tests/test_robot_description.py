"""The robot description (physics/description.py) and its files (packaging/robot_files.py): the
bodies alone rebuild arm.py's H, g, kinematics and J (a planar chain computed here, from the
links' centre-of-mass Jacobians), and MuJoCo loading the MJCF gives arm.py's terms to 1e-10 at
random states, and so does Pinocchio loading the URDF (packaging/robot_check.py)."""

from __future__ import annotations

import math
import subprocess
import sys
import xml.etree.ElementTree as ET
from dataclasses import replace

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from impedance_cosim.packaging import robot_check
from impedance_cosim.packaging.robot_files import (
    MJCF_NAME,
    URDF_NAME,
    mjcf,
    start_poses,
    write_robot_files,
)
from impedance_cosim.physics.arm import Arm, ArmParams
from impedance_cosim.physics.description import TOOL_RADIUS, describe
from impedance_cosim.physics.wall import WallParams

TOL = 1e-10
STATES = robot_check.random_states(50, seed=7)


def chain(desc, q):
    """World positions of the joints, the centres of mass and the tool point, and the links'
    absolute angles, by composing the links' planar frames (relative angles)."""
    angle, origin = 0.0, np.zeros(2)
    joints, coms = [], []
    for link, qi in zip(desc.links, q, strict=True):
        rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
        origin = origin + rot @ np.array(link.origin)
        angle += qi
        rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
        joints.append(origin)
        coms.append(origin + rot @ np.array(link.com))
    tool = origin + rot @ np.array(desc.tool)
    return joints, coms, tool, angle


def point_jacobian(joints, point, upto):
    """d(point)/dq of a point on link `upto` (0-based): z x (point - joint j), joints j <= upto."""
    jac = np.zeros((2, 3))
    for j in range(upto + 1):
        r = point - joints[j]
        jac[:, j] = (-r[1], r[0])
    return jac


def rebuilt(desc, q):
    """H, g, pose and J of the description's bodies alone."""
    joints, coms, tool, phi = chain(desc, q)
    h = np.diag([link.armature for link in desc.links])
    grav = np.zeros(3)
    for i, link in enumerate(desc.links):
        jv = point_jacobian(joints, coms[i], i)
        jw = np.array([[1.0 if j <= i else 0.0 for j in range(3)]])
        h = h + link.mass * jv.T @ jv + link.inertia * jw.T @ jw
        grav -= link.mass * jv.T @ np.array(desc.gravity[:2])  # dV/dq, V = -m g_vec . c
    jac = np.vstack([point_jacobian(joints, tool, 2), np.ones((1, 3))])
    return h, grav, np.array([tool[0], tool[1], phi]), jac


@pytest.mark.parametrize("params", [ArmParams(), replace(ArmParams(), ry1=0.02, m3=2.5, g=3.7)])
def test_bodies_rebuild_our_model(params):
    desc, arm = describe(params), Arm(params)
    for q, _, _ in STATES:
        h, grav, pose, jac = rebuilt(desc, q)
        qt = tuple(q)
        assert np.abs(h - np.array(arm.inertia(qt))).max() < TOL
        assert np.abs(grav - np.array(arm.gravity(qt))).max() < TOL
        assert np.abs(pose - np.array(arm.kinematics(qt))).max() < TOL
        assert np.abs(jac - np.array(arm.jacobian(qt))).max() < TOL


def test_description_carries_every_parameter():
    """Each parameter lands where the module docstring says (a changed one changes the body)."""
    p, w = ArmParams(), WallParams()
    desc = describe(p, w)
    l1, l2, l3 = desc.links
    assert (l1.mass, l1.com, l1.inertia, l1.armature, l1.damping) == (
        p.m1, (p.rx1, p.ry1), p.Iu1, p.Im1, p.f1)  # fmt: skip
    assert (l2.origin, l2.com, l2.armature, l3.origin, l3.com) == (
        (p.a1, 0.0), (p.rx2, 0.0), p.Im2, (p.a2, 0.0), (p.rx3, 0.0))  # fmt: skip
    assert desc.tool == (p.a3, 0.0) and desc.gravity == (0.0, -p.g, 0.0)
    assert desc.wall_x == w.wall_x


@pytest.fixture(scope="module")
def robot_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("robot")


@pytest.fixture(scope="module")
def written(robot_dir):
    return write_robot_files(robot_dir)


def test_mjcf_loads_in_mujoco(written, robot_dir):
    model = mujoco.MjModel.from_xml_path(str(robot_dir / MJCF_NAME))
    assert (model.nq, model.nv, model.nu) == (3, 3, 0)
    assert [model.joint(i).name for i in range(3)] == ["q1", "q2", "q3"]
    assert list(model.dof_armature) == [4.71, 0.830, 0.179]
    assert list(model.dof_damping) == [27.4, 4.54, 5.0]
    assert list(model.opt.gravity) == [0.0, -9.81, 0.0]


def test_mujoco_gives_our_terms(written, robot_dir):
    worst = robot_check.mujoco_differences(robot_dir / MJCF_NAME, poses=200)
    assert set(worst) == {*robot_check.TERMS, "out_of_plane"}
    assert max(worst.values()) < TOL, worst


def test_the_check_sees_a_wrong_file(tmp_path):
    """The comparison can fail: an MJCF with a heavier link 3 against the default arm."""
    heavy = replace(ArmParams(), m3=1.1)
    write_robot_files(tmp_path, heavy)
    worst = robot_check.mujoco_differences(tmp_path / MJCF_NAME, poses=5)
    assert worst["H"] > 1e-3 and worst["g"] > 1e-2
    assert worst["fk"] < TOL  # the kinematics do not depend on the mass
    assert max(robot_check.mujoco_differences(tmp_path / MJCF_NAME, heavy, 5).values()) < TOL


def test_keyframes_start_the_plant_at_its_pose(written, robot_dir):
    """The MJCF's keyframes are the plant's initial pose (0.3, 0, 0) in both elbow solutions."""
    model = mujoco.MjModel.from_xml_path(str(robot_dir / MJCF_NAME))
    data = mujoco.MjData(model)
    tool = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "tool")
    for name, q in start_poses().items():
        mujoco.mj_resetDataKeyframe(model, data, model.key(name).id)
        mujoco.mj_forward(model, data)
        assert np.allclose(data.qpos, q, rtol=0, atol=0)
        assert np.abs(data.site_xpos[tool] - (0.3, 0.0, 0.0)).max() < 1e-12
        assert (data.qpos[1] < 0) == (name == "elbow_up")


def test_wall_contact_starts_at_wall_x(written, robot_dir):
    """The tool's contact sphere touches the wall's face exactly when the tool point reaches
    wall_x: MuJoCo's signed contact distance is wall_x - x."""
    model = mujoco.MjModel.from_xml_path(str(robot_dir / MJCF_NAME))
    data = mujoco.MjData(model)
    arm = Arm()
    for depth in (-0.003, 0.00196, 0.004):  # outside, the paper's target depth, deeper
        q = arm.inverse_kinematics((0.65 + depth, 0.1, 0.0))
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        tip = [c for c in data.contact[: data.ncon]
               if "tool_tip" in (model.geom(c.geom1).name, model.geom(c.geom2).name)]  # fmt: skip
        if depth < 0.0:  # short of the wall (by less than the sphere's radius): no contact
            assert tip == [] and -depth < TOOL_RADIUS
            continue
        assert len(tip) == 1 and abs(tip[0].dist - (-depth)) < 1e-12


def test_mjcf_refuses_a_massless_link():
    with pytest.raises(ValueError, match="link3: mass 0.0"):
        mjcf(describe(replace(ArmParams(), m3=0.0)))


def test_numbers_are_written_exactly(written, robot_dir):
    """Every number reads back as the same double (repr), e.g. an awkward inertia."""
    odd = replace(ArmParams(), Iu2=0.1 + 0.2)
    root = ET.fromstring(mjcf(describe(odd)))
    inertial = root.find(".//body[@name='link2']/inertial")
    assert [float(v) for v in inertial.get("diaginertia").split()] == [0.1 + 0.2] * 3


def test_urdf_loads_in_pinocchio(written, robot_dir):
    model = pin.buildModelFromUrdf(str(robot_dir / URDF_NAME))
    assert (model.nq, model.nv) == (6, 3)  # continuous joints: (cos q, sin q) each
    assert list(model.names)[1:] == ["q1", "q2", "q3"]
    assert list(model.damping) == [27.4, 4.54, 5.0]
    assert list(model.armature) == [0.0, 0.0, 0.0]  # URDF cannot carry the motor inertias
    for frame in ("tool", "wall", "link3"):
        assert model.existFrame(frame)


def test_pinocchio_gives_our_terms(written, robot_dir):
    worst = robot_check.pinocchio_differences(robot_dir / URDF_NAME, poses=200)
    assert set(worst) == {*robot_check.TERMS, "out_of_plane"}
    assert max(worst.values()) < TOL, worst


def test_the_urdf_check_sees_a_wrong_file(tmp_path):
    """A URDF with a longer tool: the kinematics and J differ, H and g (no tool mass) do not."""
    write_robot_files(tmp_path, replace(ArmParams(), a3=0.16))
    worst = robot_check.pinocchio_differences(tmp_path / URDF_NAME, poses=5)
    assert worst["fk"] > 1e-3 and worst["J"] > 1e-3
    assert worst["H"] < TOL and worst["g"] < TOL


def test_the_motor_inertias_matter(written, robot_dir):
    """Without model.armature set after loading, Pinocchio's H misses I_m on the diagonal."""
    model = robot_check.pinocchio_model(robot_dir / URDF_NAME)
    model.armature = np.zeros(3)
    q = STATES[0][0]
    h = pin.crba(model, model.createData(), robot_check.pinocchio_q(q))
    missing = np.diag(np.array(Arm().inertia(tuple(q))) - np.triu(h) - np.triu(h, 1).T)
    assert np.abs(missing - (4.71, 0.830, 0.179)).max() < TOL


CHILD = """
import resource, signal, sys
from pathlib import Path
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write beyond the limit fails with EFBIG
from impedance_cosim.packaging.robot_files import write_robot_files
resource.setrlimit(resource.RLIMIT_FSIZE, (1000, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
try:
    write_robot_files(Path(sys.argv[1]))
except OSError as exc:
    print(type(exc).__name__, exc)
    sys.exit(1)
"""


def test_no_room_leaves_no_partial_file(tmp_path):
    """A 1 kB file size limit (the MJCF is ~2 kB): one error naming the file, nothing under its
    name and no temporary file."""
    done = subprocess.run([sys.executable, "-c", CHILD, str(tmp_path)], capture_output=True,
                          text=True, timeout=120)  # fmt: skip
    assert done.returncode == 1, done.stderr
    assert done.stdout.startswith(f"ArchiveWriteError cannot write {MJCF_NAME} in {tmp_path}:")
    assert list(tmp_path.iterdir()) == []


def test_check_without_the_libraries_says_so():
    """robot_check without mujoco installed: one line naming the extra, exit 1, no traceback."""
    child = (
        "import sys; sys.modules['mujoco'] = None\n"
        "from impedance_cosim.packaging.robot_check import main\nsys.exit(main([]))"
    )
    done = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True,
                          timeout=120)  # fmt: skip
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and "impedance-cosim[robotics]" in done.stderr
    assert "Traceback" not in done.stderr


def test_plant_documentation_says_where_the_conventions_go():
    """The plant FMU's documentation page names the files and where I_u, I_m, F, gravity, the
    tool point, the wall and the elbow-up start go in them."""
    from impedance_cosim.packaging.model_docs import model_section

    page = model_section("PumaPlant", {})
    for text in (f"fmus/robot/{MJCF_NAME}", URDF_NAME, "<code>armature</code>",
                 "<code>model.armature</code>", "joint damping", "(0, −g, 0)",
                 "<code>tool</code>", "fixed body", "<code>elbow_up</code>"):  # fmt: skip
        assert text in page, text
