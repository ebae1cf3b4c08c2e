"""The environment of the paper's scenario: a frictionless vertical wall at x = x_w."""

from __future__ import annotations

from dataclasses import dataclass

from impedance_cosim.physics.arm import _p, check_fields


@dataclass(frozen=True)
class WallParams:
    """A compliant, frictionless wall occupying x >= wall_x (section 5: 1e4 N/m at 0.65 m)."""

    wall_x: float = _p(0.65, "m", "Wall surface position along x (the wall fills x >= wall_x)")
    wall_k: float = _p(1.0e4, "N/m", "Wall contact stiffness", 0.0)
    wall_d: float = _p(0.0, "N.s/m", "Wall contact damping (0: purely elastic)", 0.0)

    def validate(self) -> None:
        """Raise ValueError naming a non-finite or negative parameter."""
        check_fields(self)


def wall_force(p: WallParams, x: float, xd: float) -> float:
    """Normal force the end effector exerts on the wall (>= 0): F_ext,x in eq. (1).

    k * pen + d * pen_rate while penetrated (pen = x - wall_x > 0), never pulling, zero outside.
    """
    pen = x - p.wall_x
    if pen <= 0.0:
        return 0.0
    force = p.wall_k * pen + p.wall_d * xd
    return force if force > 0.0 else 0.0


def contact_force_law(p: WallParams, x: float, xd: float) -> float:
    """The smooth force law used while the contact is closed. The integrator keeps it active
    until contact_event() says the contact opens, so within one Runge-Kutta step the
    right-hand side is smooth."""
    return p.wall_k * (x - p.wall_x) + p.wall_d * xd


def contact_event(p: WallParams, x: float, xd: float, in_contact: bool) -> float:
    """Switching function: turns positive when the contact mode must change.

    Closed contact opens when the compressive force k*pen + d*pen_rate drops to zero. Open
    contact closes when the surface is penetrated while that force would push (with damping, an
    end effector leaving faster than the wall relaxes stays free)."""
    force = contact_force_law(p, x, xd)
    if in_contact:
        return -force
    return min(p.wall_k * (x - p.wall_x), force)
