"""Exact directional derivatives of the native plant (native/plant/model_me.c model_partials, from
the sympy derivation's arm_partials.c): against central finite differences of the FMU's own
derivatives and outputs at 400 random states, free and in contact, under FMI 2.0 and 3.0 Model
Exchange; in co-simulation the knowns are the torques (state derivatives against ME's, outputs
zero); the ModelStructure's dependencies and dependenciesKind against the numbers."""

from __future__ import annotations

import ctypes
import shutil
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from partials_hosts import INPUTS, KNOWNS, STATES, CsHost, MeHost, random_state

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

N_STATES = 200  # per contact mode and per standard: 400 states each
REL = 1e-6  # the finite differences' step, relative


def fd_jacobian(me: MeHost, x: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Central differences of (outputs, derivatives) in (states, torques) at (x, tau)."""
    z = np.concatenate([x, tau])
    cols = []
    for k in range(len(z)):
        h = REL * max(1.0, abs(z[k]))
        vals = []
        for sign in (1.0, -1.0):
            zz = z.copy()
            zz[k] += sign * h
            me.set_states(zz[:6])
            me.set_inputs(zz[6:])
            vals.append(me.unknowns())
        cols.append((vals[0] - vals[1]) / (2 * h))
    me.set_states(x)
    me.set_inputs(tau)
    return np.array(cols).T


WALL_D = 20.0  # N s/m: a damped wall, so that the contact force depends on the velocities too


def _check_states(me: MeHost, contact: bool, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    names = me.unknown_names()
    jacobians = []
    worst = 0.0
    for _ in range(N_STATES):
        x, tau = random_state(rng, contact, WALL_D), rng.uniform(-60.0, 60.0, 3)
        me.set_states(x)
        me.set_inputs(tau)
        me.event_update()  # enters (or leaves) the contact mode the state is in
        analytic = me.jacobian(names, list(KNOWNS))
        numeric = fd_jacobian(me, x, tau)
        scale = 1.0 + np.abs(analytic).max(axis=0, keepdims=True)
        err = np.abs(analytic - numeric) / scale
        worst = max(worst, err.max())
        assert err.max() < 1e-5, (names[np.argmax(err.max(axis=1))], err.max(), x)
        seed_vec = rng.normal(size=len(KNOWNS))  # a linear combination in one call
        combined = me.dd([me.vr[n] for n in names], [me.vr[k] for k in KNOWNS], list(seed_vec))
        np.testing.assert_allclose(combined, analytic @ seed_vec, rtol=1e-12, atol=1e-9)
        jacobians.append(analytic)
    print(f"{'contact' if contact else 'free'}: worst relative error {worst:.2e}")
    return jacobians


@pytest.mark.parametrize("fmi3", [False, True], ids=["fmi2", "fmi3"])
@pytest.mark.slow
def test_me_directional_derivatives_match_finite_differences(native_dir, fmi3_dir, fmi3):
    """400 states (200 free, 200 in contact), every output and state derivative against every
    state and torque, on a damped wall. In contact the wall's stiffness dominates: dropping its
    contribution to the Jacobian (or the contact force's dJ/dq term) fails here."""
    path = (fmi3_dir if fmi3 else native_dir) / "PumaPlant.fmu"
    me = MeHost(path, fmi3, wall_d=WALL_D)
    free = _check_states(me, contact=False, seed=1)
    touching = _check_states(me, contact=True, seed=2)
    # the wall is in the state derivatives' Jacobian only in contact
    qdd = [me.unknown_names().index(f"der({s})") for s in STATES[3:]]
    wall_k = 1e4
    assert max(np.abs(j[qdd, :3]).max() for j in touching) > wall_k / 100
    assert max(np.abs(j[qdd, :3]).max() for j in free) < wall_k / 100
    _check_structure(me, free + touching)


def _check_structure(me: MeHost, jacobians: list[np.ndarray]) -> None:
    """The declared dependencies are exactly the non-zero entries; "constant" ones constant."""
    md = me.md
    names = me.unknown_names()
    unknowns = md.outputs + md.derivatives
    stack = np.array(jacobians)
    nonzero = (np.abs(stack) > 0).any(axis=0)
    for u in unknowns:
        row = names.index(u.variable.name)
        declared = {d.name: kind for d, kind in zip(u.dependencies, u.dependenciesKind or [])}
        used = {KNOWNS[k] for k in range(len(KNOWNS)) if nonzero[row, k]}
        assert used == set(declared), (u.variable.name, used, declared)
        for name, kind in declared.items():
            column = stack[:, row, KNOWNS.index(name)]
            if kind == "constant":
                assert np.all(column == column[0]), (u.variable.name, name)
            else:
                assert kind == "dependent" and np.ptp(column) > 0, (u.variable.name, name, kind)


@pytest.mark.parametrize("fmi3", [False, True], ids=["fmi2", "fmi3"])
def test_cs_directional_derivatives_are_the_torques_partials(native_dir, fmi3_dir, fmi3):
    """Co-simulation, 400 communication points of a run driven into the wall and out: the
    knowns are the torques; the state derivatives' partials equal Model Exchange's at the same
    state and mode, the outputs' are zero (no direct feedthrough); a state as known is refused."""
    folder = fmi3_dir if fmi3 else native_dir
    cs = CsHost(folder / "PumaPlant.fmu", fmi3, x0=0.62)
    me = MeHost(folder / "PumaPlant.fmu", fmi3, x0=0.62)
    rng = np.random.default_rng(3)
    md = read_model_description(str(folder / "PumaPlant.fmu"))
    outputs = [cs.vr[v.name] for v in md.modelVariables if v.causality == "output"]
    ders = [cs.vr[f"der({s})"] for s in STATES[3:]]
    knowns = [cs.vr[n] for n in INPUTS]
    in_contact = 0
    for i in range(400):
        push = 40.0 if (i // 100) % 2 == 0 else -40.0  # into the wall and back, twice
        tau = np.array([push, 0.4 * push, 0.0]) + rng.uniform(-5.0, 5.0, 3)
        cs.set_inputs(tau)
        cs.step(1 / 400)
        x = cs.get(STATES)
        me.set_states(x)
        me.set_inputs(tau)
        me.event_update()
        in_contact += cs.get(["contact_force"])[0] > 0.0
        for k, ref in enumerate(knowns):
            seed = [1.0 if j == k else 0.0 for j in range(3)]
            got = cs.fmu.getDirectionalDerivative(ders + outputs, knowns, seed)
            want = me.dd(ders, [ref], [1.0])
            np.testing.assert_allclose(got[:3], want, rtol=1e-12, atol=1e-15)
            assert not any(got[3:])
    assert 20 < in_contact < 380, in_contact  # both modes visited
    with pytest.raises(FMICallException):
        cs.fmu.getDirectionalDerivative(ders, [cs.vr["q1_true"]], [1.0])
    assert any("in co-simulation the knowns are the inputs" in m for m in cs.messages)


def test_bad_requests_are_refused(native_dir, fmi3_dir):
    """Unknowns that are not outputs or derivatives, knowns that are not states or inputs, and a
    controller (no partials) are refused with a clear error, not answered."""
    cs = CsHost(native_dir / "PumaPlant.fmu", False)
    for unknowns, knowns in (([cs.vr["wall_k"]], [cs.vr["tau1"]]), ([cs.vr["x"]], [0])):
        with pytest.raises(FMICallException):
            cs.fmu.getDirectionalDerivative(unknowns, knowns, [1.0])
    assert any("is not an output or a state derivative" in m for m in cs.messages)
    assert any("known 0 (a1) is not an input" in m for m in cs.messages)
    f = cs.fmu  # raw calls: NULL arrays with counts, and more knowns than variables
    with pytest.raises(FMICallException):
        f.fmi2GetDirectionalDerivative(f.component, None, 1, None, 1, None, None)
    assert any("NULL array with a non-zero count" in m for m in cs.messages)
    refs = (ctypes.c_uint * 1)(cs.vr["x"])
    seed, out = (ctypes.c_double * 1)(1.0), (ctypes.c_double * 1)()
    with pytest.raises(FMICallException):
        f.fmi2GetDirectionalDerivative(f.component, refs, 1, refs, 10**9, seed, out)
    assert any("more than the" in m for m in cs.messages)
    ctrl = CsHost(native_dir / "ImpedanceController.fmu", False)
    with pytest.raises(FMICallException):
        ctrl.fmu.getDirectionalDerivative([ctrl.vr["tau1"]], [ctrl.vr["q1"]], [1.0])
    assert any("directional derivatives are not provided" in m for m in ctrl.messages)


@pytest.mark.parametrize("fmi3", [False, True], ids=["fmi2", "fmi3"])
def test_controller_declares_sampled_dependencies_and_no_partials(native_dir, fmi3_dir, fmi3):
    """The controller's outputs depend on every input, only at its samples ("discrete"); it
    claims neither directional nor output derivatives."""
    md = read_model_description(str((fmi3_dir if fmi3 else native_dir) / "ImpedanceController.fmu"))
    # the data inputs (the FMI 3.0 controller's sample_clock is an input too: its ticks are when
    # the outputs change, "discrete", not a value they are computed from)
    inputs = {v.name for v in md.modelVariables if v.causality == "input" and v.type != "Clock"}
    for u in md.outputs:
        assert {d.name for d in u.dependencies} == inputs
        assert set(u.dependenciesKind) == {"discrete"}
    flag = "providesDirectionalDerivatives" if fmi3 else "providesDirectionalDerivative"
    for name, provides in (("ImpedanceController.fmu", None), ("PumaPlant.fmu", "true")):
        with zipfile.ZipFile((fmi3_dir if fmi3 else native_dir) / name) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
        for kind in ("CoSimulation", "ModelExchange"):
            assert root.find(kind).get(flag) == provides, (name, kind)
        order = root.find("CoSimulation").get("maxOutputDerivativeOrder")
        assert order == ("1" if provides else None), name
