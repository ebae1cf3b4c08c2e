"""The virtual trajectory x_v(t) of section 5: an ellipse truncated by (and pushed into) the
wall; the impedance law tracks it."""

from __future__ import annotations

import math

from controller_model.parameters import TrajectoryParams
from impedance_cosim.physics.linalg3 import Vec3

TWO_PI = 2.0 * math.pi


def virtual_trajectory(p: TrajectoryParams, t: float) -> tuple[Vec3, Vec3, Vec3]:
    """Virtual pose x_v(t), velocity and acceleration: the ellipse, with x switched to
    wall_x + wall_depth (zero x-velocity and x-acceleration) wherever the ellipse's x >= wall_x."""
    w = TWO_PI * p.traj_f
    theta = w * t - 0.5 * math.pi
    s, c = math.sin(theta), math.cos(theta)
    x = p.traj_cx + p.traj_ax * s
    y = p.traj_cy + p.traj_ay * c
    yd = -p.traj_ay * w * s
    ydd = -p.traj_ay * w * w * c
    if x >= p.wall_x:  # in contact: the target lies wall_depth inside the wall
        return (p.wall_x + p.wall_depth, y, p.traj_phi), (0.0, yd, 0.0), (0.0, ydd, 0.0)
    xd = p.traj_ax * w * c
    xdd = -p.traj_ax * w * w * s
    return (x, y, p.traj_phi), (xd, yd, 0.0), (xdd, ydd, 0.0)
