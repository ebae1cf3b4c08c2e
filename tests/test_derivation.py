"""Generated sources are the committed output of their generators (one source of truth)."""

from __future__ import annotations

import math

import pytest

from impedance_cosim.packaging import cgen


@pytest.mark.slow
def test_arm_terms_are_up_to_date():
    """impedance_cosim/physics/arm_terms.py and native/src/arm_terms.{c,h} regenerate byte for
    byte from the symbolic derivation (python -m impedance_cosim.physics.derivation)."""
    pytest.importorskip("sympy")
    from impedance_cosim.physics.derivation import generate

    for path, content in generate().items():
        assert path.read_text() == content, f"{path.name} is stale"


def test_native_configs_are_up_to_date():
    """native/<model>/config.h regenerate from the variable tables the Python FMUs use
    (python -m impedance_cosim.packaging.cgen)."""
    for path, content in cgen.generate().items():
        assert path.read_text() == content, f"{path} is stale"


def _bind(source: str):
    namespace: dict = {}
    exec(compile(source, "<arm_terms>", "exec"), namespace)
    return namespace["bind"]


@pytest.mark.slow
def test_optimized_terms_are_bit_identical_to_per_call_evaluation():
    """The shipped arm_terms.py hoists parameter-only subexpressions into bind() and computes
    repeated values once (bind_source.hoist, reuse). Every term must equal, bit for bit, the
    printed expressions evaluated per call (optimize=False), for random states and parameters."""
    pytest.importorskip("sympy")
    import dataclasses
    import random

    from impedance_cosim.physics.arm import ArmParams
    from impedance_cosim.physics.derivation import derive, python_source

    # (test_arm_terms_are_up_to_date checks the committed arm_terms.py is the optimized source)
    optimized, plain = python_source(derive()), python_source(derive(), optimize=False)
    assert optimized != plain  # it does optimize
    fast_bind, plain_bind = _bind(optimized), _bind(plain)
    rng = random.Random(7)
    for trial in range(200):
        p = ArmParams()
        if trial:  # other parameter values too, so no constant can hide in the source
            p = dataclasses.replace(p, **{
                f.name: getattr(p, f.name) * rng.uniform(0.5, 2.0) for f in dataclasses.fields(p)
            })  # fmt: skip
        fast, ref = fast_bind(p), plain_bind(p)
        q = tuple(rng.uniform(-4.0, 4.0) for _ in range(3))
        qd = tuple(rng.uniform(-10.0, 10.0) for _ in range(3))
        tau = tuple(rng.uniform(-100.0, 100.0) for _ in range(3))
        calls = {
            "kinematics": (q,), "jacobian": (q,), "jacobian_dot": (q, qd), "inertia": (q,),
            "coriolis": (q, qd), "gravity": (q,), "potential_energy": (q,),
            "forward_dynamics": (*q, *qd, *tau),
        }  # fmt: skip
        for name, args in calls.items():
            got, want = getattr(fast, name)(*args), getattr(ref, name)(*args)
            assert repr(got) == repr(want), f"{name} differs at trial {trial}: {got} != {want}"


def test_fused_forward_dynamics_is_the_sum_of_its_parts():
    """forward_dynamics = linalg3.solve(H, tau - matvec(C, qd) - F qd - g), operation for
    operation (the order the native arm.h uses): bit for bit on random states."""
    import random

    from impedance_cosim.physics.arm import Arm
    from impedance_cosim.physics.linalg3 import matvec, solve

    arm = Arm()
    t, p = arm.terms, arm.params
    rng = random.Random(3)
    for _ in range(2000):
        q = tuple(rng.uniform(-4.0, 4.0) for _ in range(3))
        qd = tuple(rng.uniform(-10.0, 10.0) for _ in range(3))
        tau = tuple(rng.uniform(-100.0, 100.0) for _ in range(3))
        cqd, grav, f = matvec(t.coriolis(q, qd), qd), t.gravity(q), (p.f1, p.f2, p.f3)
        rhs = tuple(tau[i] - cqd[i] - f[i] * qd[i] - grav[i] for i in range(3))
        assert repr(t.forward_dynamics(*q, *qd, *tau)) == repr(solve(t.inertia(q), rhs))


def test_the_generators_on_one_small_term():
    """The C printer and the bit-preserving rewrites (hoist, reuse) on a two-value term: what
    the two tests above check on the whole arm (its derivation takes half a minute: slow tier)."""
    sp = pytest.importorskip("sympy")
    from sympy.printing.c import ccode

    from impedance_cosim.physics import bind_source, derivation

    q1, a1, m1 = sp.symbols("q1 a1 m1")
    expr = sp.Matrix([[a1 * m1 * sp.cos(q1) + a1 * m1], [a1 * m1 * sp.sin(q1)]])
    decl, body = derivation.c_function(ccode, "demo", ["q"], expr, "a demo")
    assert decl[1] == "void arm_demo(const ArmParams *p, const double q[3], double *out);"
    # parameters and angles read in place, the printed order of operations kept
    assert "    const double x0 = p->a1*p->m1;" in body and "    (void)qd;" not in body
    assert "    out[0] = x0*(cos(q[0]) + 1);" in body
    assert any(line.startswith("    out[1] = ") for line in body)
    hoister = bind_source._Hoister({"a1", "m1"}, [])
    temps = [("x0", "a1 * m1"), ("x1", "x0 * cos(q1)")]
    results = ["x1 + x0", "sin(q1) * (m1 * a1)"]
    temps, results = bind_source.reuse(*bind_source.hoist(temps, results, hoister))
    # parameter-only parts bound once (a1 * m1 and m1 * a1 apart: not the same rounding order
    # in general), the copy x0 dropped; the values unchanged, bit for bit
    assert hoister.bound == [("k0", "a1 * m1"), ("k1", "m1 * a1")]
    assert temps == [("x1", "k0 * cos(q1)")] and results == ["x1 + k0", "sin(q1) * k1"]
    scope = {"a1": 0.1 + 0.2, "m1": 1 / 3, "q1": 0.7, "cos": math.cos, "sin": math.sin}
    for name, source in hoister.bound + temps:
        scope[name] = eval(source, scope)
    printed = ["a1 * m1 * cos(q1) + a1 * m1", "sin(q1) * (m1 * a1)"]
    assert [eval(r, scope) for r in results] == [eval(e, scope) for e in printed]
