"""Plain-float 3-vector and 3x3-matrix helpers.

The FMUs step at 400 Hz with several right-hand-side evaluations per step; numpy costs ~10 us per
operation on 3-element arrays, so the hot path works on tuples of floats instead.
A matrix is a tuple of three row tuples.
"""

from __future__ import annotations

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]


def matvec(m: Mat3, v: Vec3) -> Vec3:
    """m @ v."""
    (a, b, c), (d, e, f), (g, h, i) = m
    x, y, z = v
    return (a * x + b * y + c * z, d * x + e * y + f * z, g * x + h * y + i * z)


def matTvec(m: Mat3, v: Vec3) -> Vec3:
    """m.T @ v (used for J^T F)."""
    (a, b, c), (d, e, f), (g, h, i) = m
    x, y, z = v
    return (a * x + d * y + g * z, b * x + e * y + h * z, c * x + f * y + i * z)


def det(m: Mat3) -> float:
    """Determinant of m."""
    (a, b, c), (d, e, f), (g, h, i) = m
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


def solve(m: Mat3, v: Vec3) -> Vec3:
    """Solve m x = v by Cramer's rule; raises ZeroDivisionError when m is exactly singular."""
    (a, b, c), (d, e, f), (g, h, i) = m
    x, y, z = v
    c00 = e * i - f * h
    c01 = f * g - d * i
    c02 = d * h - e * g
    inv_det = 1.0 / (a * c00 + b * c01 + c * c02)
    return (
        (c00 * x + (c * h - b * i) * y + (b * f - c * e) * z) * inv_det,
        (c01 * x + (a * i - c * g) * y + (c * d - a * f) * z) * inv_det,
        (c02 * x + (b * g - a * h) * y + (a * e - b * d) * z) * inv_det,
    )


def add(u: Vec3, v: Vec3) -> Vec3:
    """u + v."""
    return (u[0] + v[0], u[1] + v[1], u[2] + v[2])


def sub(u: Vec3, v: Vec3) -> Vec3:
    """u - v."""
    return (u[0] - v[0], u[1] - v[1], u[2] - v[2])


def scale(s: float, v: Vec3) -> Vec3:
    """s * v."""
    return (s * v[0], s * v[1], s * v[2])
