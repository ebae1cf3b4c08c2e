"""The 3-DOF planar PUMA-560 subset of the paper (section 5): kinematics and dynamics.

One model, used twice: by the plant (with the true parameters) and by the controller's internal
model (with the controller's own parameter values, so model mismatch can be studied).

Conventions: the arm moves in the vertical x-y plane, gravity acts along -y, joint angles are
relative (q2 is measured from link 1, q3 from link 2), the end-effector pose is
x = (x, y, phi) with phi = q1 + q2 + q3. Equation (1): H qdd + C qd + F qd + g = tau - J^T F_ext.
The printed model has typos (see shared/paper/ERRATA.md): H22/H33 use I_m2/I_m3, the first inertia
triple is the link inertias I_u, and C11 is taken from the Christoffel symbols. The terms are
generated from a symbolic Lagrangian derivation (impedance_cosim/physics/derivation.py);
tests/test_arm.py checks every term independently (Christoffel symbols from finite differences of H,
the gradient of the potential energy, finite differences of the kinematics, a rigid-body inertia
built from the links' centre-of-mass Jacobians).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

from impedance_cosim.physics import arm_terms as terms
from impedance_cosim.physics.linalg3 import Mat3, Vec3, matvec


def _p(
    default: Any,
    unit: str,
    description: str,
    minimum: float | None = None,
    maximum: float | None = None,
    **extra: Any,
) -> Any:
    """A parameter field with the metadata the FMU variable tables are generated from (extra:
    tunable=True for a parameter that may change during a run, enumeration=<Enumeration>)."""
    return field(
        default=default,
        metadata={
            "unit": unit,
            "description": description,
            "min": minimum,
            "max": maximum,
            **extra,
        },  # fmt: skip
    )


@dataclass(frozen=True)
class ArmParams:
    """Kinematic and dynamic parameters (paper section 5, corrected per ERRATA.md)."""

    a1: float = _p(0.432, "m", "Link 1 length (shoulder to elbow)", 0.0)
    a2: float = _p(0.433, "m", "Link 2 length (elbow to wrist)", 0.0)
    a3: float = _p(0.15, "m", "Tool length (wrist to end-effector point)", 0.0)
    m1: float = _p(17.4, "kg", "Link 1 mass", 0.0)
    m2: float = _p(5.62, "kg", "Link 2 mass", 0.0)
    m3: float = _p(1.00, "kg", "Link 3 mass (wrist, force sensor, end effector)", 0.0)
    rx1: float = _p(0.068, "m", "Link 1 centre of mass, along the link")
    ry1: float = _p(0.006, "m", "Link 1 centre of mass, across the link")
    rx2: float = _p(0.070, "m", "Link 2 centre of mass, along the link")
    rx3: float = _p(-0.010, "m", "Link 3 centre of mass, along the link")
    Iu1: float = _p(0.539, "kg.m2", "Link 1 inertia about its centre of mass", 0.0)
    Iu2: float = _p(0.212, "kg.m2", "Link 2 inertia about its centre of mass", 0.0)
    Iu3: float = _p(0.006, "kg.m2", "Link 3 inertia about its centre of mass", 0.0)
    Im1: float = _p(4.71, "kg.m2", "Motor 1 rotor inertia reflected to joint 1", 0.0)
    Im2: float = _p(0.830, "kg.m2", "Motor 2 rotor inertia reflected to joint 2", 0.0)
    Im3: float = _p(0.179, "kg.m2", "Motor 3 rotor inertia reflected to joint 3", 0.0)
    f1: float = _p(27.4, "N.m.s/rad", "Joint 1 viscous friction (incl. back-emf)", 0.0)
    f2: float = _p(4.54, "N.m.s/rad", "Joint 2 viscous friction (incl. back-emf)", 0.0)
    f3: float = _p(5.0, "N.m.s/rad", "Joint 3 viscous friction (incl. back-emf)", 0.0)
    g: float = _p(9.81, "m/s2", "Gravitational acceleration, acting along -y")

    def validate(self) -> None:
        """Raise ValueError naming the first parameter that is non-finite or below its minimum."""
        check_fields(self)
        if self.a1 <= 0.0 or self.a2 <= 0.0:
            raise ValueError(f"link lengths a1, a2 must be > 0 (got a1={self.a1}, a2={self.a2})")


def check_fields(obj: object) -> None:
    """Raise ValueError if a number field of a parameter dataclass is non-finite or outside its
    min/max."""
    for f in fields(obj):  # type: ignore[arg-type]
        value = getattr(obj, f.name)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            continue
        if not math.isfinite(value):
            raise ValueError(f"parameter {f.name} must be finite (got {value})")
        minimum = f.metadata.get("min")
        if minimum is not None and value < minimum:
            raise ValueError(f"parameter {f.name} must be >= {minimum} (got {value})")
        maximum = f.metadata.get("max")
        if maximum is not None and value > maximum:
            raise ValueError(f"parameter {f.name} must be <= {maximum} (got {value})")


class UnreachablePoseError(ValueError):
    """The requested end-effector pose is outside the arm's workspace."""


class Arm:
    """Kinematics and dynamics of the planar arm, on plain floats (see module docstring).

    The terms (kinematics, J, Jdot, H, C, g, V) are generated from one symbolic derivation
    (impedance_cosim/physics/derivation.py -> arm_terms.py, and arm_terms.c for the native FMUs)."""

    def __init__(self, params: ArmParams | None = None) -> None:
        p = params if params is not None else ArmParams()
        p.validate()
        self.params = p
        # The generated terms as closures over p (parameter-only parts computed once); hot loops
        # call self.terms.<term> directly, skipping the method call.
        self.terms = terms.bind(p)

    # --- kinematics, eq. (2) ---------------------------------------------------------------

    def kinematics(self, q: Vec3) -> Vec3:
        """End-effector pose x = kin(q) = (x, y, phi), eq. (2a)."""
        return self.terms.kinematics(q)

    def jacobian(self, q: Vec3) -> Mat3:
        """J(q), with xd = J qd, eq. (2b)."""
        return self.terms.jacobian(q)

    def jacobian_dot(self, q: Vec3, qd: Vec3) -> Mat3:
        """dJ/dt along the motion qd, for xdd = J qdd + Jdot qd, eq. (2c)."""
        return self.terms.jacobian_dot(q, qd)

    def jacobian_det(self, q: Vec3) -> float:
        """det J(q) = a1 a2 sin(q2): zero at the stretched and folded elbow singularities."""
        return self.params.a1 * self.params.a2 * math.sin(q[1])

    def inverse_kinematics(self, pose: Vec3, elbow_up: bool = True) -> Vec3:
        """q = invkin(x), eq. (3a); elbow_up picks the solution with the elbow above the
        shoulder-wrist line (q2 <= 0). Raises UnreachablePoseError outside the workspace."""
        p = self.params
        x, y, phi = pose
        if not all(math.isfinite(v) for v in pose):
            raise UnreachablePoseError(f"pose {pose} is not finite")
        wx = x - p.a3 * math.cos(phi)
        wy = y - p.a3 * math.sin(phi)
        c2 = (wx * wx + wy * wy - p.a1**2 - p.a2**2) / (2.0 * p.a1 * p.a2)
        if c2 > 1.0 or c2 < -1.0:
            r = math.hypot(wx, wy)
            raise UnreachablePoseError(
                f"pose (x={x}, y={y}, phi={phi}) is unreachable: the wrist is {r:.4f} m from the"
                f" shoulder, the arm reaches from {abs(p.a1 - p.a2):.4f} m to {p.a1 + p.a2:.4f} m"
            )
        s2 = -math.sqrt(1.0 - c2 * c2) if elbow_up else math.sqrt(1.0 - c2 * c2)
        q2 = math.atan2(s2, c2)
        q1 = math.atan2(wy, wx) - math.atan2(p.a2 * s2, p.a1 + p.a2 * c2)
        return (q1, q2, phi - q1 - q2)

    # --- dynamics, eq. (1) -----------------------------------------------------------------

    def inertia(self, q: Vec3) -> Mat3:
        """H(q) = I_r(q) + I_m: link inertia plus motor inertia on the diagonal."""
        return self.terms.inertia(q)

    def coriolis(self, q: Vec3, qd: Vec3) -> Mat3:
        """C(q, qd) in Christoffel form, so Hdot - 2C is skew-symmetric."""
        return self.terms.coriolis(q, qd)

    def gravity(self, q: Vec3) -> Vec3:
        """g(q): gradient of the potential energy, gravity along -y."""
        return self.terms.gravity(q)

    def friction(self, qd: Vec3) -> Vec3:
        """Viscous friction torque F qd, F = diag(f1, f2, f3)."""
        p = self.params
        return (p.f1 * qd[0], p.f2 * qd[1], p.f3 * qd[2])

    def forward_dynamics(self, q: Vec3, qd: Vec3, tau: Vec3) -> Vec3:
        """qdd = H^-1 (tau - C qd - F qd - g), eq. (5); tau is the net joint torque
        (motor torque minus J^T F_ext). Generated fused (C qd by linalg3.matvec, then the
        right-hand side, then linalg3.solve); the native arm.h does the same operations."""
        return self.terms.forward_dynamics(*q, *qd, *tau)

    # --- energy (for checks and analysis) ---------------------------------------------------

    def kinetic_energy(self, q: Vec3, qd: Vec3) -> float:
        """T = qd^T H qd / 2 (links and rotors)."""
        hq = matvec(self.inertia(q), qd)
        return 0.5 * (qd[0] * hq[0] + qd[1] * hq[1] + qd[2] * hq[2])

    def potential_energy(self, q: Vec3) -> float:
        """V = g * sum(m_i * y_ci): the height of each centre of mass, zero at the shoulder."""
        return self.terms.potential_energy(q)
