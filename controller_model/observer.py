"""The reduced-order velocity observer, eq. (9): the joint-velocity estimate yhat from the
measured joint angles, the applied torque and the measured wrist force, without velocity
measurements."""

from __future__ import annotations

import math

from impedance_cosim.physics.arm import Arm
from impedance_cosim.physics.linalg3 import Vec3, matTvec


def observer_update(
    arm: Arm,
    yhat_prev: Vec3,
    q_prev: Vec3,
    q_now: Vec3,
    tau_prev: Vec3,
    f_prev: Vec3,
    K: Vec3,
    dt: float,
    discretization: str = "euler",
) -> Vec3:
    """One step of the discrete velocity observer, eq. (9): yhat_i from yhat_i-1 and q_i-1, q_i.

    yhat_i = yhat_i-1 + K (q_i - q_i-1) - dt K yhat_i-1
             + dt H^-1(q_i-1) [tau_i-1 - C(q_i-1, yhat_i-1) yhat_i-1 - F yhat_i-1 - g(q_i-1)
                               - J^T(q_i-1) F_au,i-1]

    That is explicit Euler of yhat' = K (qdot - yhat) + acc, stable only for K dt < 2.
    discretization = implicit takes the -K yhat term at yhat_i:
    yhat_i = (yhat_i-1 + K (q_i - q_i-1) + dt acc) / (1 + dt K); exponential integrates it
    exactly with qdot = (q_i - q_i-1) / dt and acc held over the sample:
    yhat_i = a yhat_i-1 + (1 - a) ((q_i - q_i-1) / dt + acc / K), a = exp(-K dt).
    Both keep |yhat's own pole| < 1 for every K > 0, and equal eq. (9) to first order in K dt.
    """
    # The bracket is evaluated at the previous sample: explicit Euler of the integral in eq. (7)
    # over [t - dt, t]. tau_prev is the torque actually applied (held) over that interval (the
    # clipped one when limits are on), f_prev the wrist force measured at its start.
    terms = arm.terms  # the generated terms, called directly (this runs every sample)
    jtf = matTvec(terms.jacobian(q_prev), f_prev)
    net = (tau_prev[0] - jtf[0], tau_prev[1] - jtf[1], tau_prev[2] - jtf[2])
    # H^-1 [tau - C y - F y - g - J^T F], eq. (5)
    acc = terms.forward_dynamics(*q_prev, *yhat_prev, *net)
    if discretization != "euler":
        out = []
        for i in range(3):
            dq = q_now[i] - q_prev[i]
            if discretization == "implicit":
                out.append((yhat_prev[i] + K[i] * dq + dt * acc[i]) / (1.0 + dt * K[i]))
            else:
                a = math.exp(-K[i] * dt)
                out.append(a * yhat_prev[i] + (1.0 - a) * (dq / dt + acc[i] / K[i]))
        return (out[0], out[1], out[2])
    return (
        yhat_prev[0] + K[0] * (q_now[0] - q_prev[0]) + dt * acc[0] - dt * K[0] * yhat_prev[0],
        yhat_prev[1] + K[1] * (q_now[1] - q_prev[1]) + dt * acc[1] - dt * K[1] * yhat_prev[1],
        yhat_prev[2] + K[2] * (q_now[2] - q_prev[2]) + dt * acc[2] - dt * K[2] * yhat_prev[2],
    )
