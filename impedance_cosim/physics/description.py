"""The arm as a tree of rigid bodies, for robot description files (URDF, MJCF; packaging/
robot_files.py): derived once from ArmParams and WallParams, so every file says what arm.py says.

Frames (the paper's, section 5): the world's x-y plane is the vertical plane of motion, gravity
acts along -y, every joint turns about +z. Link i's frame has its origin on joint i and its x axis
along the link (joint angle q_i, relative to the previous link): joint 1 sits at the world origin,
joint 2 at (a1, 0) in link 1's frame, joint 3 at (a2, 0) in link 2's, the tool point at (a3, 0) in
link 3's (phi = q1 + q2 + q3). Each link's centre of mass is (rx_i, ry_i) in its own frame (ry2 =
ry3 = 0) and its inertia about the centre of mass, about z, is the paper's first triple I_u (the
ERRATA's reading: H11 holds I_u1 + m1 (rx1^2 + ry1^2)). The second triple, the motor inertias I_m,
adds to H_ii only: that is a rotor inertia reflected to the joint (MJCF `armature`). The viscous
friction F qd is joint damping. tests/test_robot_description.py rebuilds H, g, the kinematics and J
from these bodies alone and compares them with arm.py.

The out-of-plane inertias (about the links' x and y axes) are not in the paper and do not act on a
motion in the plane (every angular velocity is along z): they are set to I_u too, which makes each
inertia tensor a valid one (triangle inequality) for MuJoCo and Pinocchio.
"""

from __future__ import annotations

from dataclasses import dataclass

from impedance_cosim.physics.arm import ArmParams
from impedance_cosim.physics.wall import WallParams

Vec2 = tuple[float, float]

# The wall's box (half extents along x, y, z; not in the paper, which has a plane): thick enough
# for a contact solver, taller than the arm's reach (a1 + a2 + a3 = 1.015 m), deep across the plane.
WALL_HALF = (0.05, 1.2, 0.3)
# The tool point's contact sphere: the wall's contact face sits this far beyond wall_x, so the
# sphere's signed distance to it is exactly wall_x - x (contact starts when the point reaches x_w).
TOOL_RADIUS = 0.005


@dataclass(frozen=True)
class Link:
    """One moving link of the chain and the revolute joint (about +z) that carries it."""

    name: str
    parent: str  # the parent link's name; "world" for link 1
    joint: str  # the joint's name (q1, q2, q3: the paper's joint angles)
    origin: Vec2  # the joint's position in the parent's frame (z = 0)
    mass: float  # m_i
    com: Vec2  # centre of mass in the link's own frame (rx_i, ry_i)
    inertia: float  # I_u,i: about the centre of mass, about z (also used about x and y)
    armature: float  # I_m,i: rotor inertia reflected to the joint, on H_ii only
    damping: float  # f_i: viscous friction torque per joint velocity
    length: float  # to the next joint or, for link 3, to the tool point (for the pictures)


@dataclass(frozen=True)
class RobotDescription:
    """The arm, its tool point and the wall, in the frames of the module docstring."""

    name: str
    links: tuple[Link, Link, Link]
    tool: Vec2  # the tool point in link 3's frame (a3, 0)
    gravity: tuple[float, float, float]  # (0, -g, 0) in the world
    wall_x: float  # the wall's surface (it fills x >= wall_x), normal -x towards the arm
    wall_k: float  # its stiffness (N/m) and damping (N s/m): for a contact model's tuning
    wall_d: float


def describe(arm: ArmParams | None = None, wall: WallParams | None = None) -> RobotDescription:
    """The rigid-body description of the arm with these parameters (default: section 5's)."""
    p = arm if arm is not None else ArmParams()
    w = wall if wall is not None else WallParams()
    p.validate()
    w.validate()
    links = (
        Link("link1", "world", "q1", (0.0, 0.0), p.m1, (p.rx1, p.ry1), p.Iu1, p.Im1, p.f1, p.a1),
        Link("link2", "link1", "q2", (p.a1, 0.0), p.m2, (p.rx2, 0.0), p.Iu2, p.Im2, p.f2, p.a2),
        Link("link3", "link2", "q3", (p.a2, 0.0), p.m3, (p.rx3, 0.0), p.Iu3, p.Im3, p.f3, p.a3),
    )
    return RobotDescription(
        name="puma3",
        links=links,
        tool=(p.a3, 0.0),
        gravity=(0.0, -p.g, 0.0),
        wall_x=w.wall_x,
        wall_k=w.wall_k,
        wall_d=w.wall_d,
    )
