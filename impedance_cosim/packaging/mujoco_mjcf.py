"""The MJCF the MuJoCo plant FMU carries (plant_model/mujoco_plant.py): robot_files' MJCF of the
arm, plus what a simulation of the paper's scenario needs and a description file does not say:

- the wrist force/torque sensor: a massless body `hand` fixed to link 3 at the wrist (joint 3)
  carries the sites `wrist` and `tool` and the contact sphere; MuJoCo's `force` and `torque`
  sensors at site `wrist` then read what link 3 exerts on the hand, which (the hand having no
  mass) is exactly what the hand exerts on the environment: PumaPlant's fx, fy, n once rotated
  into the world and taken about the tool point (mujoco_plant.wrist_wrench);
- the wall as one explicit contact pair (tool_tip, wall), frictionless (condim 1), with a
  constant impedance (solimp dmin = dmax = 1e-4, MuJoCo's smallest) and a direct-stiffness solref
  that the plant sets from wall_k and wall_d when it loads the file (the derivation is in
  mujoco_plant.contact_solref); the geoms themselves collide with nothing else;
- the integrator: RK4 (4th order, like the smooth dynamics want; MuJoCo's implicit integrators
  are 1st order) with a 0.25 ms step, a tenth of the 400 Hz communication step.

Standard library only (xml.etree): the build writes it without MuJoCo.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from impedance_cosim.packaging.robot_files import mjcf, start_poses
from impedance_cosim.physics.arm import ArmParams
from impedance_cosim.physics.description import describe
from impedance_cosim.physics.wall import WallParams

MUJOCO_MJCF_NAME = "puma3_mujoco.xml"
TIMESTEP = 2.5e-4  # s: 10 RK4 steps per 400 Hz communication step
IMPEDANCE = 1e-4  # solimp dmin = dmax: MuJoCo clamps the impedance to [1e-4, 0.9999]
PLACEHOLDER_SOLREF = "-1 0"  # replaced at load: (-wall_k * A, -wall_d * A), see mujoco_plant


def mujoco_mjcf(arm: ArmParams | None = None, wall: WallParams | None = None) -> str:
    """The MJCF text of the MuJoCo plant (see module docstring), from robot_files.mjcf."""
    desc = describe(arm, wall)
    keys = {k: tuple(v) for k, v in start_poses(arm).items()}
    root = ET.fromstring(mjcf(desc, keys))
    option = root.find("option")
    option.set("timestep", repr(TIMESTEP))
    option.set("integrator", "RK4")
    link3 = root.find(".//body[@name='link3']")
    hand = ET.SubElement(link3, "body", name="hand", pos="0 0 0")  # no inertial: massless
    for tag, name in (("site", "wrist"), ("site", "tool"), ("geom", "tool_tip")):
        element = link3.find(f"{tag}[@name='{name}']")
        link3.remove(element)
        hand.append(element)
    for name in ("tool_tip", "wall"):
        geom = root.find(f".//geom[@name='{name}']")
        geom.set("contype", "0")
        geom.set("conaffinity", "0")  # only the explicit pair below touches
    contact = ET.SubElement(root, "contact")
    imp = repr(IMPEDANCE)
    ET.SubElement(contact, "pair", name="tool_wall", geom1="tool_tip", geom2="wall", condim="1",
                  solref=PLACEHOLDER_SOLREF, solimp=f"{imp} {imp} 0.001 0.5 2")  # fmt: skip
    sensor = ET.SubElement(root, "sensor")
    ET.SubElement(sensor, "force", name="wrist_force", site="wrist")
    ET.SubElement(sensor, "torque", name="wrist_torque", site="wrist")
    keyframe = root.find("keyframe")
    if keyframe is not None:  # MJCF wants keyframes last but one: keep contact/sensor before
        root.remove(keyframe)
        root.append(keyframe)
    root.insert(1, ET.Comment(
        " The MuJoCo plant's model (impedance_cosim/packaging/mujoco_mjcf.py): robot_files' arm"
        " plus the wrist F/T sensor on the massless body hand, the wall as the contact pair"
        " tool_wall (its solref is set by plant_model/mujoco_plant.py from wall_k and wall_d),"
        " RK4 at 0.25 ms. "))  # fmt: skip
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n"
