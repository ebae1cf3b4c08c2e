"""The impedance law, eq. (10): the joint torque that makes the end effector behave as the
target impedance (stiffness G, damping B) around the virtual trajectory, using the observed
velocity instead of a measured one."""

from __future__ import annotations

import math

from impedance_cosim.fmi.model import ModelError
from impedance_cosim.physics.arm import Arm
from impedance_cosim.physics.linalg3 import Vec3, matTvec, matvec, solve

TWO_PI = 2.0 * math.pi
SINGULAR_TOL = 1e-6  # |det J| below SINGULAR_TOL * a1 * a2 (i.e. |sin q2| < 1e-6) is singular


class SingularPoseError(ModelError):
    """The impedance law is undefined at this pose: J is singular (eq. 10 needs J^-1)."""


def wrap_angle(a: float) -> float:
    """a wrapped to (-pi, pi], so an orientation error never takes the long way round."""
    w = math.remainder(a, TWO_PI)
    return w + TWO_PI if w <= -math.pi else w


def impedance_law(
    arm: Arm,
    q: Vec3,
    yhat: Vec3,
    f_au: Vec3,
    xv: Vec3,
    xv_dot: Vec3,
    xv_ddot: Vec3,
    G: Vec3,
    B: Vec3,
) -> tuple[Vec3, Vec3, Vec3]:
    """Joint torque of eq. (10), with the tracking error e = x - x_v and the observed Cartesian
    velocity J yhat it used (outputs of the controller). Raises SingularPoseError when J is
    singular."""
    det = arm.jacobian_det(q)
    p = arm.params
    if not abs(det) >= SINGULAR_TOL * p.a1 * p.a2:
        raise SingularPoseError(
            f"the Jacobian is singular at q = ({q[0]:.6g}, {q[1]:.6g}, {q[2]:.6g}) rad"
            f" (det J = a1 a2 sin q2 = {det:.3g}): the impedance law needs J^-1"
        )
    terms = arm.terms  # the generated terms, called directly (this runs every sample)
    j = terms.jacobian(q)
    # Joint-space form of eq. (10), using J^T J^-T = I:
    # J^T (H_x xv_dd + C_x(q, yhat) xv_d) = H qdd_v + C(q, yhat) qd_v, J^T F_x xv_d = F qd_v,
    # J^T g_x = g, with C_x evaluated at the observed velocity (ERRATA).
    qd_v = solve(j, xv_dot)  # (3b)
    jdot_qd = matvec(terms.jacobian_dot(q, yhat), qd_v)
    qdd_v = solve(j, (xv_ddot[0] - jdot_qd[0], xv_ddot[1] - jdot_qd[1], xv_ddot[2] - jdot_qd[2]))
    pose = terms.kinematics(q)
    e = (pose[0] - xv[0], pose[1] - xv[1], wrap_angle(pose[2] - xv[2]))  # e = x - x_v
    xd_hat = matvec(j, yhat)  # observed Cartesian velocity J yhat
    # Cartesian terms that act through J^T: F_au - B (J yhat - xv_d) - G e
    f_c = (
        f_au[0] - B[0] * (xd_hat[0] - xv_dot[0]) - G[0] * e[0],
        f_au[1] - B[1] * (xd_hat[1] - xv_dot[1]) - G[1] * e[1],
        f_au[2] - B[2] * (xd_hat[2] - xv_dot[2]) - G[2] * e[2],
    )
    jtf = matTvec(j, f_c)
    hq = matvec(terms.inertia(q), qdd_v)
    cq = matvec(terms.coriolis(q, yhat), qd_v)
    fq = arm.friction(qd_v)
    g = terms.gravity(q)
    tau = (
        hq[0] + cq[0] + fq[0] + g[0] + jtf[0],
        hq[1] + cq[1] + fq[1] + g[1] + jtf[1],
        hq[2] + cq[2] + fq[2] + g[2] + jtf[2],
    )
    return tau, e, xd_hat


def gravity_hold_terms(arm: Arm, q: Vec3, yhat: Vec3, xv: Vec3) -> tuple[Vec3, Vec3, Vec3]:
    """What the controller outputs where eq. (10) is undefined (a singular J, only ever at
    initialization): gravity compensation tau = g(q) alone, with the tracking error and J yhat,
    which are defined at every pose (same order of operations as impedance_law)."""
    terms = arm.terms
    j = terms.jacobian(q)
    pose = terms.kinematics(q)
    e = (pose[0] - xv[0], pose[1] - xv[1], wrap_angle(pose[2] - xv[2]))
    return terms.gravity(q), e, matvec(j, yhat)
