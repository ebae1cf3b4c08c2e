"""PinocchioPlant: PumaPlant with the arm's dynamics computed by Pinocchio from the URDF.

A second, independent plant to swap in (issue 25): the same variables as PumaPlant (inputs,
outputs, units, parameters), the same wall law, sensors and integrator (plant_model.model), but
the forward dynamics (Pinocchio's ABA), the tool point's position and Jacobian (its frame `tool`)
come from Pinocchio's model of the URDF that the FMU carries (puma3.urdf, written by
packaging/robot_files.py from the plant's default parameters; the build puts it beside this code
as the generated module carried_files.py: code, so Python's module cache can never pair this
module with another build's file). The FMU's arm parameters then set
the numbers through Pinocchio's model (joint placements, link inertias, the tool frame, rotor
inertias, damping, gravity): pinocchio_arm() gives the same model as a URDF written with them
(tests/test_pinocchio_plant.py). What URDF cannot say, the motor inertias and gravity along -y,
is set here too. Only the initial pose comes from our own inverse kinematics.

Needs Pinocchio (`pip install pin==4.1.0`, the `robotics` extra) and numpy in the Python that
runs the FMU; without it the instantiation fails with one line saying so.
"""

from __future__ import annotations

import math
from typing import Any

from impedance_cosim.fmi.model import ModelError
from impedance_cosim.physics.description import RobotDescription, describe
from impedance_cosim.physics.wall import contact_event, contact_force_law, wall_force
from plant_model.carried import carried_file
from plant_model.model import PlantModel

URDF_FILE = "puma3.urdf"
NEEDS = "the Python package pin (Pinocchio 4.1: pip install pin==4.1.0) in the Python running it"


def carried_urdf() -> str:
    """The URDF the FMU carries (ModelError outside a built FMU: only the build writes it)."""
    return carried_file(URDF_FILE)


def pinocchio_arm(pin: Any, urdf: str, desc: RobotDescription) -> Any:
    """Pinocchio's model of the URDF with desc's numbers: joint placements, link inertias about
    their centres of mass, the tool frame, rotor inertias (armature), damping, gravity along -y."""
    import numpy as np

    model = pin.buildModelFromXML(urdf)
    names = [link.joint for link in desc.links]
    if list(model.names)[1:] != names:
        raise ValueError(f"joints {list(model.names)[1:]}, expected {names}")
    for j, link in enumerate(desc.links, start=1):
        model.jointPlacements[j] = pin.SE3(np.eye(3), np.array([*link.origin, 0.0]))
        model.inertias[j] = pin.Inertia(link.mass, np.array([*link.com, 0.0]),
                                        np.eye(3) * link.inertia)  # fmt: skip
    tool = model.frames[model.getFrameId("tool")]
    tool.placement = pin.SE3(np.eye(3), np.array([*desc.tool, 0.0]))
    model.frames[model.getFrameId("tool")] = tool
    model.armature = np.array([link.armature for link in desc.links])
    model.damping = np.array([link.damping for link in desc.links])
    model.gravity = pin.Motion(np.array(desc.gravity), np.zeros(3))
    return model


class PinocchioPlantModel(PlantModel):
    """PumaPlant's interface; the arm's dynamics and kinematics from Pinocchio (see above)."""

    MODEL_NAME = "PinocchioPlant"
    DESCRIPTION = (
        "PumaPlant (the paper's 3-DOF planar PUMA-560 subset against a stiff frictionless wall)"
        " with the arm's forward dynamics and tool kinematics computed by Pinocchio from the"
        f" URDF it carries: a second, independent plant to swap in. Needs {NEEDS}"
    )

    def __init__(self, parameters: dict[str, Any], start_time: float = 0.0, inputs=None) -> None:
        super().__init__(parameters, start_time, inputs)  # parameters, start pose, sensors
        try:
            import numpy as np
            import pinocchio as pin
        except ImportError as exc:
            raise ModelError(f"PinocchioPlant needs {NEEDS} ({exc})") from None
        urdf = carried_urdf()
        try:
            self.robot = pinocchio_arm(pin, urdf, describe(self.arm.params, self.wall))
        except (ValueError, RuntimeError) as exc:
            raise ModelError(f"{URDF_FILE} cannot be loaded: {exc}") from None
        self._np, self._pin = np, pin
        self.pin_data = self.robot.createData()
        self.tool = self.robot.getFrameId("tool")
        x, xd = self._tool_x(self.q, self.qd)
        self.in_contact = contact_event(self.wall, x, xd, False) > 0.0

    # --- Pinocchio's kinematics and dynamics -----------------------------------------------------

    def _config(self, q) -> Any:
        """Pinocchio's configuration: a URDF continuous joint is (cos q, sin q)."""
        c1, c2, c3 = math.cos(q[0]), math.cos(q[1]), math.cos(q[2])
        s1, s2, s3 = math.sin(q[0]), math.sin(q[1]), math.sin(q[2])
        return self._np.array((c1, s1, c2, s2, c3, s3))

    def _tool(self, q) -> tuple[Any, Any]:
        """The tool frame's placement and its Jacobian (world-aligned: rows x, y, z, wx, wy, wz)."""
        pin, model, data = self._pin, self.robot, self.pin_data
        pin.computeJointJacobians(model, data, self._config(q))  # also the forward kinematics
        placement = pin.updateFramePlacement(model, data, self.tool)
        return placement, pin.getFrameJacobian(model, data, self.tool, pin.LOCAL_WORLD_ALIGNED)

    def _tool_x(self, q, qd) -> tuple[float, float]:
        """The tool point's x and x-velocity (all the wall needs)."""
        placement, jac = self._tool(q)
        return float(placement.translation[0]), float(jac[0] @ self._np.asarray(qd))

    def _rhs(self, tau, in_contact: bool, budget: list[int] | None = None):
        """y' = f(y), eq. (1) with qdd from Pinocchio's ABA: tau - F qd - J^T F_ext."""
        np, pin, model, data = self._np, self._pin, self.robot, self.pin_data
        wall, damping, tau = self.wall, self.robot.damping, np.asarray(tau, dtype=float)
        counter = budget if budget is not None else [math.inf]

        def f(y):
            self._count_evaluation(counter)
            qd = np.asarray(y[3:])
            net = tau - damping * qd
            if in_contact:
                placement, jac = self._tool(y[:3])
                fx = contact_force_law(wall, float(placement.translation[0]), float(jac[0] @ qd))
                net = net - fx * jac[0]
            qdd = pin.aba(model, data, self._config(y[:3]), qd, net)
            return (y[3], y[4], y[5], float(qdd[0]), float(qdd[1]), float(qdd[2]))

        return f

    def _event(self, in_contact: bool):
        wall = self.wall

        def g(y):
            x, xd = self._tool_x(y[:3], y[3:])
            return contact_event(wall, x, xd, in_contact)

        return g

    def outputs(self) -> tuple:
        q, qd = self.q, self.qd
        placement, jac = self._tool(q)
        # phi unwrapped, as PumaPlant's (the frame's rotation about z is this angle modulo 2 pi)
        pose = (
            float(placement.translation[0]),
            float(placement.translation[1]),
            q[0] + q[1] + q[2],
        )
        v = jac @ self._np.asarray(qd)
        xdot = (float(v[0]), float(v[1]), float(v[5]))
        fx = wall_force(self.wall, pose[0], xdot[0])
        pen = max(0.0, pose[0] - self.wall.wall_x)
        return (*self.q_meas, fx, 0.0, 0.0, *q, *qd, *pose, *xdot, fx, pen)
