"""The arm model against independent derivations: rigid-body inertia from the links' centre-of-mass
Jacobians, Christoffel symbols from finite differences of H, the Lagrangian's Coriolis torque,
the potential energy's gradient and finite differences of the kinematics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from impedance_cosim.physics.arm import Arm, ArmParams, UnreachablePoseError

ARM = Arm()
RNG = np.random.default_rng(42)
STATES = [
    (tuple(RNG.uniform(-math.pi, math.pi, 3)), tuple(RNG.uniform(-2, 2, 3))) for _ in range(20)
]
EPS = 1e-6


def H(q):
    return np.array(ARM.inertia(tuple(q)))


def dH(q, i):
    """Central finite difference of H along q_i."""
    e = np.zeros(3)
    e[i] = EPS
    return (H(np.add(q, e)) - H(np.subtract(q, e))) / (2 * EPS)


def com_positions(q):
    """Planar positions of the links' centres of mass, from the link geometry alone."""
    p = ARM.params
    q1, q12, q123 = q[0], q[0] + q[1], q[0] + q[1] + q[2]
    u = lambda a: np.array([math.cos(a), math.sin(a)])  # noqa: E731
    v = lambda a: np.array([-math.sin(a), math.cos(a)])  # noqa: E731
    c1 = p.rx1 * u(q1) + p.ry1 * v(q1)
    c2 = p.a1 * u(q1) + p.rx2 * u(q12)
    c3 = p.a1 * u(q1) + p.a2 * u(q12) + p.rx3 * u(q123)
    return [c1, c2, c3]


def test_inertia_symmetric_positive_definite():
    for q, _ in STATES:
        h = H(q)
        assert np.allclose(h, h.T, atol=0, rtol=0)
        assert np.linalg.eigvalsh(h).min() > 0.1


def test_inertia_equals_rigid_body_sum():
    """H = sum_i m_i Jv_i^T Jv_i + Iu_i Jw_i^T Jw_i + diag(Im), Jv by finite differences."""
    p = ARM.params
    masses, link_inertia = (p.m1, p.m2, p.m3), (p.Iu1, p.Iu2, p.Iu3)
    for q, _ in STATES:
        total = np.diag([p.Im1, p.Im2, p.Im3]).astype(float)
        for i in range(3):
            jv = np.zeros((2, 3))
            for j in range(3):
                e = np.zeros(3)
                e[j] = EPS
                jv[:, j] = (
                    com_positions(np.add(q, e))[i] - com_positions(np.subtract(q, e))[i]
                ) / (2 * EPS)
            jw = np.array([[1.0 if j <= i else 0.0 for j in range(3)]])
            total += masses[i] * jv.T @ jv + link_inertia[i] * jw.T @ jw
        assert np.allclose(H(q), total, atol=1e-8)


def christoffel_C(q, qd):
    """C_kj = sum_i c_ijk qd_i, c_ijk = (dH_kj/dq_i + dH_ki/dq_j - dH_ij/dq_k) / 2."""
    d = [dH(q, i) for i in range(3)]
    c = np.zeros((3, 3))
    for k in range(3):
        for j in range(3):
            c[k, j] = sum(0.5 * (d[i][k, j] + d[j][k, i] - d[k][i, j]) * qd[i] for i in range(3))
    return c


def test_coriolis_matches_christoffel_symbols():
    for q, qd in STATES:
        assert np.allclose(np.array(ARM.coriolis(q, qd)), christoffel_C(q, qd), atol=1e-7)


def test_printed_c11_would_fail_this_check():
    """The paper's printed C11 (qd1 in place of qd2, see ERRATA) differs from the Christoffel form:
    the check above is able to catch it."""
    p = ARM.params
    q, qd = STATES[0]
    s2, s3, s23 = math.sin(q[1]), math.sin(q[2]), math.sin(q[1] + q[2])
    printed = -p.m2 * p.a1 * p.rx2 * qd[0] * s2 - p.m3 * (
        p.a1 * p.a2 * qd[1] * s2 + p.a1 * p.rx3 * (qd[0] + qd[1]) * s23 + p.a2 * p.rx3 * qd[2] * s3
    )
    assert abs(printed - christoffel_C(q, qd)[0, 0]) > 1e-2


def test_hdot_minus_2c_is_skew_symmetric():
    for q, qd in STATES:
        hdot = sum(dH(q, i) * qd[i] for i in range(3))
        n = hdot - 2 * np.array(ARM.coriolis(q, qd))
        assert np.allclose(n + n.T, 0, atol=1e-7)


def test_coriolis_torque_equals_lagrangian():
    """C qd = Hdot qd - d/dq (qd^T H qd / 2), from Lagrange's equations."""
    for q, qd in STATES:
        qd = np.array(qd)
        hdot = sum(dH(q, i) * qd[i] for i in range(3))
        grad_t = np.array([0.5 * qd @ dH(q, i) @ qd for i in range(3)])
        assert np.allclose(np.array(ARM.coriolis(q, tuple(qd))) @ qd, hdot @ qd - grad_t, atol=1e-7)


def test_gravity_is_gradient_of_potential_energy():
    for q, _ in STATES:
        grad = []
        for i in range(3):
            e = np.zeros(3)
            e[i] = EPS
            vp = ARM.potential_energy(tuple(np.add(q, e)))
            vm = ARM.potential_energy(tuple(np.subtract(q, e)))
            grad.append((vp - vm) / (2 * EPS))
        assert np.allclose(ARM.gravity(q), grad, atol=1e-6)


def test_gravity_pulls_along_minus_y():
    """Arm stretched along +x: each joint carries the moment of the weight outboard of it
    (link 3's centre of mass sits behind joint 3, rx3 < 0); arm pointing up: only ry1 acts."""
    p = ARM.params
    g1, g2, g3 = ARM.gravity((0.0, 0.0, 0.0))
    assert g3 == pytest.approx(p.g * p.m3 * p.rx3)
    assert g2 == pytest.approx(p.g * (p.m2 * p.rx2 + p.m3 * (p.a2 + p.rx3)))
    assert g1 == pytest.approx(g2 + p.g * (p.m1 * p.rx1 + (p.m2 + p.m3) * p.a1))
    assert ARM.gravity((math.pi / 2, 0.0, 0.0))[0] == pytest.approx(-p.g * p.m1 * p.ry1, abs=1e-9)


def test_jacobian_matches_finite_differences():
    for q, _ in STATES:
        jac = np.zeros((3, 3))
        for j in range(3):
            e = np.zeros(3)
            e[j] = EPS
            jac[:, j] = (
                np.array(ARM.kinematics(tuple(np.add(q, e))))
                - np.array(ARM.kinematics(tuple(np.subtract(q, e))))
            ) / (2 * EPS)
        assert np.allclose(np.array(ARM.jacobian(q)), jac, atol=1e-8)


def test_jacobian_dot_matches_finite_differences():
    for q, qd in STATES:
        dt = 1e-6
        jp = np.array(ARM.jacobian(tuple(np.add(q, np.multiply(qd, dt)))))
        jm = np.array(ARM.jacobian(tuple(np.subtract(q, np.multiply(qd, dt)))))
        assert np.allclose(np.array(ARM.jacobian_dot(q, qd)), (jp - jm) / (2 * dt), atol=1e-7)


def test_jacobian_determinant():
    for q, _ in STATES:
        assert np.linalg.det(np.array(ARM.jacobian(q))) == pytest.approx(
            ARM.jacobian_det(q), abs=1e-12
        )


@pytest.mark.parametrize("elbow_up", [True, False])
def test_inverse_kinematics_round_trip(elbow_up):
    for pose in [(0.3, 0.0, 0.0), (0.65, 0.2, 0.0), (0.5, -0.5, 0.3), (0.1, 0.6, -1.0)]:
        q = ARM.inverse_kinematics(pose, elbow_up)
        assert np.allclose(ARM.kinematics(q), pose, atol=1e-12)
        assert (q[1] <= 0) == elbow_up


def test_unreachable_pose_is_refused():
    with pytest.raises(UnreachablePoseError, match="unreachable"):
        ARM.inverse_kinematics((2.0, 0.0, 0.0))


@pytest.mark.parametrize(
    "name,value", [("m2", -1.0), ("Iu1", -0.1), ("f3", -2.0), ("a1", 0.0), ("g", math.nan)]
)
def test_bad_parameters_are_named(name, value):
    with pytest.raises(ValueError, match=name):
        Arm(ArmParams(**{name: value}))


def test_forward_dynamics_inverts_equation_1():
    """H qdd + C qd + F qd + g = tau for the qdd forward_dynamics returns."""
    for q, qd in STATES:
        tau = tuple(RNG.uniform(-50, 50, 3))
        qdd = np.array(ARM.forward_dynamics(q, qd, tau))
        lhs = H(q) @ qdd + np.array(ARM.coriolis(q, qd)) @ qd + ARM.friction(qd) + ARM.gravity(q)
        assert np.allclose(lhs, tau, atol=1e-9)
