"""MujocoPlant: PumaPlant's interface with the arm, the wall and the wrist sensor simulated by
MuJoCo (issue 25): a third-party simulator to swap in for our plant.

MuJoCo steps the MJCF the FMU carries (puma3_mujoco.xml, written by packaging/mujoco_mjcf.py
from the plant's default parameters into the generated module carried_files.py, as
PinocchioPlant's URDF): its RK4 integrator, n = ceil(h / timestep) equal steps per
communication step h (0.25 ms: 10 per 400 Hz step), the joint torques as generalized forces
(qfrc_applied), the motor inertias as armature, viscous friction as joint damping. The FMU's
arm and wall parameters set the numbers in MuJoCo's compiled model (as an MJCF written with
them would: tests/test_mujoco_plant.py), then mj_setConst. Only the start pose (our inverse
kinematics) and the encoder model (noise, quantization) are PumaPlant's.

The wall is MuJoCo contact: the pair (tool sphere, wall box), frictionless, whose signed
distance is wall_x - x (docs/robotics.md). Its soft-contact parameters are chosen so that the
contact force is k pen + d pen_rate, PumaPlant's wall law (contact_solref has the derivation).
The wrist force/torque outputs are MuJoCo's force and torque sensors at the site `wrist`
(wrist_wrench). Integrator parameters of PumaPlant that MuJoCo has no use for (rtol, atol,
euler_substeps, max_rhs_evaluations) are not parameters here; `timestep` is.

Needs MuJoCo (`pip install mujoco==4.0.0`, the `robotics` extra) and numpy in the Python that
runs the FMU; without it the instantiation fails with one line saying so.
"""

from __future__ import annotations

import math
from typing import Any

from impedance_cosim.fmi.model import FmuModel, ModelError, check_step
from impedance_cosim.fmi.variables import Variable
from impedance_cosim.physics.description import RobotDescription, describe
from impedance_cosim.physics.wall import WallParams
from plant_model.carried import carried_file
from plant_model.model import INPUTS, PlantModel

MJCF_FILE = "puma3_mujoco.xml"
NEEDS = "the Python package mujoco (MuJoCo 4.0: pip install mujoco==4.0.0) in the Python running it"
MAX_SUBSTEPS = 1_000_000  # MuJoCo steps in one communication step (a bound on a request's work)
NOT_HERE = ("euler_substeps", "rtol", "atol", "max_rhs_evaluations")  # PumaPlant's integrator's
TIMESTEP = Variable("timestep", "parameter", 2.5e-4, "Longest MuJoCo (RK4) step: each"
                    " communication step is divided into ceil(h / timestep) equal steps", "s",
                    min=1e-7, max=0.1)  # fmt: skip


def carried_mjcf() -> str:
    """The MJCF the FMU carries (ModelError outside a built FMU: only the build writes it)."""
    return carried_file(MJCF_FILE)


def contact_solref(
    wall: WallParams, approx_inverse_mass: float, impedance: float
) -> tuple[float, float]:
    """MuJoCo's solref (direct form, both negative) that makes the contact force k pen + d rate.

    MuJoCo's force on one frictionless contact row is f = (a_ref - a0) / (A + R): a0 the
    acceleration of the contact distance without the contact, A = J M^-1 J^T, R = (1 - i) / i * Ā
    the regularization, from the impedance i (solimp dmin = dmax = i: constant) and MuJoCo's
    approximation Ā of A (body_invweight0 of the hand; the wall is static; computed once at
    qpos0). The direct solref (-s, -b) gives K = s / i^2, B = b / i, so the reference
    acceleration is a_ref = K i pen + B rate = (s pen + b rate) / i. With a1 = a0 + A f the
    normal acceleration the contact leaves (positive: separating), f (A + R) = a_ref - a1 + A f
    gives f (1 - i) Ā = s pen + b rate - i a1, so s = (1 - i) k Ā and b = (1 - i) d Ā make
        f = k pen + d rate - i a1 / ((1 - i) Ā):
    our law exactly but for the last term, i = 1e-4 (MuJoCo's smallest impedance) times the
    acceleration times a mass 1/Ā (15 kg here); zero in a static contact."""
    scale = (1.0 - impedance) * approx_inverse_mass
    return (-wall.wall_k * scale, -wall.wall_d * scale)


def mujoco_arm(mujoco: Any, mjcf: str, desc: RobotDescription) -> tuple[Any, Any]:
    """MuJoCo's model of the MJCF with desc's numbers (joint placements, masses, centres of mass,
    inertias, armature, damping, gravity, tool point, wall position, the contact's solref) and
    its data."""
    model = mujoco.MjModel.from_xml_string(mjcf)
    names = [model.joint(j).name for j in range(model.njnt)]
    if names != [link.joint for link in desc.links]:
        raise ValueError(f"joints {names}, expected {[link.joint for link in desc.links]}")
    for j, link in enumerate(desc.links):
        b = model.body(link.name).id
        model.body_pos[b] = (*link.origin, 0.0)
        model.body_mass[b] = link.mass
        model.body_ipos[b] = (*link.com, 0.0)
        model.body_inertia[b] = (link.inertia,) * 3
        model.dof_armature[j] = link.armature
        model.dof_damping[j] = link.damping
    model.site_pos[model.site("tool").id] = (*desc.tool, 0.0)
    model.geom_pos[model.geom("tool_tip").id] = (*desc.tool, 0.0)
    model.body_pos[model.body("wall").id] = (desc.wall_x, 0.0, 0.0)
    model.opt.gravity[:] = desc.gravity
    data = mujoco.MjData(model)
    mujoco.mj_setConst(model, data)  # body_invweight0 (and the rest) for these numbers
    wall = WallParams(desc.wall_x, desc.wall_k, desc.wall_d)
    dmin, dmax = (float(v) for v in model.pair_solimp[0][:2])
    if dmin != dmax:
        raise ValueError(f"the contact pair's impedance must be constant (solimp {dmin}, {dmax})")
    hand = float(model.body_invweight0[model.body("hand").id, 0])
    model.pair_solref[0] = contact_solref(wall, hand, dmax)
    if desc.wall_k == 0.0 and desc.wall_d == 0.0:  # no wall force at all: no contact
        model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    return model, data


class MujocoPlantModel(PlantModel):
    """PumaPlant's interface; the arm, the wall and the wrist sensor are MuJoCo's (see above)."""

    MODEL_NAME = "MujocoPlant"
    DESCRIPTION = (
        "PumaPlant (the paper's 3-DOF planar PUMA-560 subset against a stiff frictionless wall)"
        " simulated by MuJoCo from the MJCF it carries: RK4, the wall as MuJoCo contact tuned to"
        f" wall_k and wall_d, the wrist F/T sensor MuJoCo's: a third-party plant to swap in. Needs"
        f" {NEEDS}"
    )
    DEFAULT_EXPERIMENT = FmuModel.DEFAULT_EXPERIMENT  # no tolerance: MuJoCo's RK4 has a fixed step
    MODEL_EXCHANGE = None

    @classmethod
    def variables(cls) -> list[Variable]:
        table = [v for v in PlantModel.variables() if v.name not in NOT_HERE]
        at = next(i for i, v in enumerate(table) if v.name == "noise_seed") + 1
        return [*table[:at], TIMESTEP, *table[at:]]

    def __init__(self, parameters: dict[str, Any], start_time: float = 0.0, inputs=None) -> None:
        super().__init__(parameters, start_time, inputs)  # parameters, start pose, sensors
        try:
            import mujoco
            import numpy as np
        except ImportError as exc:
            raise ModelError(f"MujocoPlant needs {NEEDS} ({exc})") from None
        self.timestep = float(parameters.get("timestep", TIMESTEP.start))
        if not (TIMESTEP.min <= self.timestep <= TIMESTEP.max):
            raise ModelError(f"parameter timestep must be from {TIMESTEP.min:g} to"
                             f" {TIMESTEP.max:g} s (got {self.timestep!r})")  # fmt: skip
        mjcf = self.mjcf_text()
        try:
            self.mj, self.mj_data = mujoco_arm(mujoco, mjcf, describe(self.arm.params, self.wall))
        except (ValueError, RuntimeError) as exc:
            raise ModelError(f"{MJCF_FILE} cannot be loaded: {exc}") from None
        self._mujoco, self._np = mujoco, np
        m, d = self.mj, self.mj_data
        self._ids = (m.site("tool").id, m.site("wrist").id)
        self._state_kind = mujoco.mjtState.mjSTATE_INTEGRATION
        self._jacp, self._jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        d.qpos[:] = self.q
        d.qvel[:] = 0.0
        mujoco.mj_forward(m, d)

    def mjcf_text(self) -> str:
        """The MJCF this plant loads: the one its FMU carries (the robot process writes its own:
        apps/robot_plant.py)."""
        return carried_mjcf()

    # --- stepping -------------------------------------------------------------------------------

    def do_step(self, t: float, h: float, inputs: tuple) -> None:
        check_step(t, h, self.t, "plant", INPUTS, inputs)
        mujoco, m, d = self._mujoco, self.mj, self.mj_data
        n = max(1, math.ceil(h / self.timestep * (1.0 - 1e-12)))
        if n > MAX_SUBSTEPS:
            raise ModelError(f"a {h:g} s step needs {n} MuJoCo steps of at most {self.timestep:g}"
                             f" s, more than {MAX_SUBSTEPS}: take a smaller step")  # fmt: skip
        saved = self._mj_state()
        warnings = [int(w.number) for w in d.warning]
        m.opt.timestep = h / n
        d.qfrc_applied[:] = inputs
        # MuJoCo's own warning handler prints and appends to MUJOCO_LOG.TXT in the host's working
        # folder: while we step, its messages come here (and into our error), then it is restored
        previous, messages = mujoco.get_mju_user_warning(), []
        mujoco.set_mju_user_warning(messages.append)
        try:
            mujoco.mj_step(m, d, nstep=n)
            mujoco.mj_forward(m, d)  # sensors, contacts and kinematics at the new state
        finally:
            mujoco.set_mju_user_warning(previous)
        problem = self._step_problem(warnings)
        if problem and messages:
            problem += f" ({messages[0].strip()})"
        if problem:
            self._set_mj_state(saved)
            raise ModelError(f"MuJoCo step from t={t:g} failed: {problem}")
        q = (float(d.qpos[0]), float(d.qpos[1]), float(d.qpos[2]))
        try:
            q_meas = self._measure(q)
        except (OverflowError, ValueError) as exc:
            self._set_mj_state(saved)
            raise ModelError(f"joint angle measurement failed: {exc}") from None
        self.t, self.q = t + h, q
        self.qd = (float(d.qvel[0]), float(d.qvel[1]), float(d.qvel[2]))
        self.q_meas = q_meas

    def _step_problem(self, before: list[int]) -> str:
        """Why the step just taken is not a result ("" when it is): a MuJoCo warning (a bad
        acceleration makes MuJoCo reset the state silently) or a non-finite state."""
        d, np = self.mj_data, self._np
        for kind, (w, n) in enumerate(zip(d.warning, before)):
            if int(w.number) > n:
                name = self._mujoco.mjtWarning(kind).name
                return f"{name} (value {int(w.lastinfo)}): take a smaller timestep or torque"
        if not (np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()):
            return "the state is not finite"
        return ""

    # --- outputs --------------------------------------------------------------------------------

    def wrist_wrench(self) -> tuple[float, float, float]:
        """The wrist F/T sensor as PumaPlant's fx, fy, n: MuJoCo's force and torque sensors read
        what link 3 exerts on the massless hand, in the site's frame, the torque about the site;
        rotated into the world, that is the force on the environment, and its moment about the
        tool point is n = torque_z + ((p_wrist - p_tool) x f)_z."""
        d, (tool, wrist) = self.mj_data, self._ids
        rot = d.site_xmat[wrist].reshape(3, 3)
        f = rot @ d.sensordata[0:3]
        torque = rot @ d.sensordata[3:6]
        r = d.site_xpos[wrist] - d.site_xpos[tool]
        n = torque[2] + r[0] * f[1] - r[1] * f[0]
        return float(f[0]), float(f[1]), float(n)

    def contact_force(self) -> float:
        """MuJoCo's normal contact force on the wall (>= 0)."""
        mujoco, m, d = self._mujoco, self.mj, self.mj_data
        total, out = 0.0, self._np.zeros(6)
        for i in range(d.ncon):
            mujoco.mj_contactForce(m, d, i, out)
            total += float(out[0])
        return total

    def outputs(self) -> tuple:
        mujoco, m, d, (tool, _) = self._mujoco, self.mj, self.mj_data, self._ids
        q, qd = self.q, self.qd
        mujoco.mj_jacSite(m, d, self._jacp, self._jacr, tool)
        v, w = self._jacp @ d.qvel, self._jacr @ d.qvel
        x, y = float(d.site_xpos[tool][0]), float(d.site_xpos[tool][1])
        pose = (x, y, q[0] + q[1] + q[2])  # phi unwrapped, as PumaPlant's
        xdot = (float(v[0]), float(v[1]), float(w[2]))
        pen = max(0.0, x - self.wall.wall_x)
        return (*self.q_meas, *self.wrist_wrench(), *q, *qd, *pose, *xdot,
                self.contact_force(), pen)  # fmt: skip

    # --- state ----------------------------------------------------------------------------------

    def _mj_state(self) -> Any:
        size = self._mujoco.mj_stateSize(self.mj, self._state_kind)
        out = self._np.empty(size)
        self._mujoco.mj_getState(self.mj, self.mj_data, out, self._state_kind)
        return out

    def _set_mj_state(self, state) -> None:
        self._mujoco.mj_setState(self.mj, self.mj_data, self._np.asarray(state, dtype=float),
                                 self._state_kind)  # fmt: skip
        self._mujoco.mj_forward(self.mj, self.mj_data)

    def get_state(self) -> dict[str, Any]:
        state = super().get_state()
        state["mujoco"] = [float(x) for x in self._mj_state()]
        return state

    def set_state(self, state: dict[str, Any]) -> None:
        super().set_state(state)
        self._set_mj_state(state["mujoco"])
