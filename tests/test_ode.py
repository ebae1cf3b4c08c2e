"""The plant's integrator (impedance_cosim.physics.ode): the unrolled Dormand-Prince step equals
the tableau applied component by component, bit for bit, and integrates to its tolerance."""

from __future__ import annotations

import math
import random

import pytest

from impedance_cosim.physics import ode


def reference_step(f, y, h, k1):
    """The Dormand-Prince step written as loops over the components (the tableau's definition)."""
    n = range(len(y))
    k2 = f(tuple(y[i] + h * ode._A2 * k1[i] for i in n))
    a, b = ode._A3
    k3 = f(tuple(y[i] + h * (a * k1[i] + b * k2[i]) for i in n))
    a, b, c = ode._A4
    k4 = f(tuple(y[i] + h * (a * k1[i] + b * k2[i] + c * k3[i]) for i in n))
    a, b, c, d = ode._A5
    k5 = f(tuple(y[i] + h * (a * k1[i] + b * k2[i] + c * k3[i] + d * k4[i]) for i in n))
    a, b, c, d, e = ode._A6
    k6 = f(tuple(y[i] + h * (a * k1[i] + b * k2[i] + c * k3[i] + d * k4[i] + e * k5[i]) for i in n))
    b1, b3, b4, b5, b6 = ode._B
    y_new = tuple(
        y[i] + h * (b1 * k1[i] + b3 * k3[i] + b4 * k4[i] + b5 * k5[i] + b6 * k6[i]) for i in n
    )
    k7 = f(y_new)
    e1, e3, e4, e5, e6, e7 = ode._E
    err = tuple(
        h * (e1 * k1[i] + e3 * k3[i] + e4 * k4[i] + e5 * k5[i] + e6 * k6[i] + e7 * k7[i]) for i in n
    )
    return y_new, err, k7


def nonlinear(y):
    """A coupled nonlinear right-hand side of any dimension."""
    n = len(y)
    return tuple(math.sin(y[(i + 1) % n]) - 0.3 * y[i] * y[i - 1] + 0.1 * i for i in range(n))


@pytest.mark.parametrize("n", [1, 2, 3, 6, 9])
def test_unrolled_step_equals_the_tableau_bit_for_bit(n):
    rng = random.Random(n)
    for _ in range(300):
        y = tuple(rng.uniform(-3.0, 3.0) for _ in range(n))
        h = 10 ** rng.uniform(-6.0, -1.0)
        k1 = nonlinear(y)
        assert repr(ode.dopri5_step(nonlinear, y, h, k1)) == repr(
            reference_step(nonlinear, y, h, k1)
        )


def test_integrates_the_harmonic_oscillator_to_its_tolerance():
    """y'' = -y from (1, 0) over 10 s: cos and -sin, within a few times the tolerance."""
    t, y, _, hit = ode.integrate(lambda y: (y[1], -y[0]), 0.0, (1.0, 0.0), 10.0, 1e-3, 1e-10, 1e-12)
    assert t == 10.0 and not hit
    assert abs(y[0] - math.cos(10.0)) < 1e-8 and abs(y[1] + math.sin(10.0)) < 1e-8
