"""Output derivatives in co-simulation (fmi2GetRealOutputDerivatives, fmi3GetOutputDerivatives,
maxOutputDerivativeOrder=1) of the native plant: against finite differences of the outputs over
time along a run into a damped wall and out, FMI 2.0 and 3.0; orders other than 1, the quantized
encoder and a controller (none provided) refused with one log line."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from partials_hosts import CsHost

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

H = 1e-5  # s, the finite differences' time step
ACCURATE = {"rtol": 1e-12, "atol": 1e-14, "wall_d": 20.0, "x0": 0.62}


def _outputs(path) -> list[str]:
    md = read_model_description(str(path))
    return [v.name for v in md.modelVariables if v.causality == "output"]


@pytest.mark.parametrize("fmi3", [False, True], ids=["fmi2", "fmi3"])
def test_output_derivatives_match_the_outputs_over_time(native_dir, fmi3_dir, fmi3):
    """At 120 communication points (free, pressing on the wall, leaving it), the first
    derivative of every output equals the second-order one-sided difference of the outputs over
    two steps of 1e-5 s with the torques held. The wrist force's derivative includes the damping
    term wall_d * xdd: leaving it out fails here."""
    path = (fmi3_dir if fmi3 else native_dir) / "PumaPlant.fmu"
    names = _outputs(path)
    cs = CsHost(path, fmi3, **ACCURATE)
    rng = np.random.default_rng(5)
    checked = {"free": 0, "contact": 0}
    for i in range(360):
        push = 40.0 if i < 270 else -40.0  # into the wall, then away
        tau = np.array([push, 0.4 * push, 0.0]) + rng.uniform(-5.0, 5.0, 3)
        cs.set_inputs(tau)
        cs.step(1 / 400)
        if i % 3:
            continue
        d = cs.output_derivatives(names, [1] * len(names))
        y0 = cs.get(names)
        cs.step(H)
        y1 = cs.get(names)
        cs.step(H)
        y2 = cs.get(names)
        forces = [y[names.index("contact_force")] for y in (y0, y1, y2)]
        if len({f > 0.0 for f in forces}) > 1:
            continue  # the contact switched inside the difference: no derivative there
        fd = (-3.0 * y0 + 4.0 * y1 - y2) / (2.0 * H)
        err = np.abs(d - fd) / (1.0 + np.abs(d))
        assert err.max() < 1e-4, (names[int(np.argmax(err))], d, fd)
        checked["contact" if forces[0] > 0.0 else "free"] += 1
        if forces[0] > 0.0:
            assert abs(d[names.index("fx")]) > 1.0  # the force moves while pressing
    assert checked["free"] > 20 and checked["contact"] > 20, checked


@pytest.mark.parametrize("fmi3", [False, True], ids=["fmi2", "fmi3"])
def test_orders_beyond_one_and_noisy_encoders_are_refused(native_dir, fmi3_dir, fmi3):
    folder = fmi3_dir if fmi3 else native_dir
    cs = CsHost(folder / "PumaPlant.fmu", fmi3)
    cs.step(1 / 400)
    for order in (2, 0):
        with pytest.raises(FMICallException):
            cs.output_derivatives(["x"], [order])
        assert any(f"order {order} of x refused" in m and "maxOutputDerivativeOrder" in m
                   for m in cs.messages), cs.messages  # fmt: skip
    assert cs.output_derivatives(["q1", "fy"], [1, 1])[1] == 0.0
    noisy = CsHost(folder / "PumaPlant.fmu", fmi3, q_quant=1e-4)
    noisy.step(1 / 400)
    with pytest.raises(FMICallException):
        noisy.output_derivatives(["q1"], [1])
    assert any("q1 has no time derivative" in m for m in noisy.messages)
    ctrl = CsHost(folder / "ImpedanceController.fmu", fmi3)
    with pytest.raises(FMICallException):
        ctrl.output_derivatives(["tau1"], [1])
    assert any("output derivatives are not provided" in m for m in ctrl.messages)
