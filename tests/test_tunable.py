"""Tunable parameters: the controller's gains, force setpoint and trajectory change during a run.

FMI 2.0 lets a master set a parameter of variability "tunable" between communication points
(co-simulation, state stepComplete); our controller reads it from its next sample on. Both
flavours (Python and native) are driven through fmi2SetReal by fmpy, and must agree bit for bit.
"""

from __future__ import annotations

import pytest
from fmpy import read_model_description

from controller_model.model import INPUT_START
from impedance_cosim.cosim.fmus.fmi2 import FmuError, FmuInstance

TS = 1 / 400
CHANGE_AT = 40  # the set happens after this many steps


def open_controller(path) -> FmuInstance:
    """A controller through initialization, its angle inputs at the start pose (held)."""
    fmu = FmuInstance(path, "controller")
    fmu.setup(0.0)
    fmu.enter_initialization()
    fmu.set({f"q{i}": INPUT_START[i - 1] for i in (1, 2, 3)})
    fmu.exit_initialization()
    return fmu


def torques(path, change: dict | None = None, steps: int = 80) -> list[float]:
    """tau2 after each step (G1 acts along x: at the start pose, y = 0, through joint 2), the
    inputs held at the start pose; `change` set through fmi2SetReal after CHANGE_AT steps."""
    fmu = open_controller(path)
    try:
        out = []
        for k in range(steps):
            if k == CHANGE_AT and change:
                fmu.set(change)
            fmu.step(k * TS, TS)
            out.append(fmu.get(["tau2"])[0])
        return out
    finally:
        fmu.free()


@pytest.fixture(scope="module", params=["python", "native"])
def controller(request, fmu_dir, native_dir):
    return (native_dir if request.param == "native" else fmu_dir) / "ImpedanceController.fmu"


def test_gains_force_setpoint_and_trajectory_are_tunable(controller):
    variability = {
        v.name: v.variability for v in read_model_description(str(controller)).modelVariables
    }
    tunable = {"K1", "G1", "G3", "B2", "wall_depth", "wall_x", "traj_f", "traj_cx"}
    assert all(variability[n] == "tunable" for n in tunable)
    fixed = {"sample_period", "a1", "m2", "velocity_source", "tau_max1", "limit_torque"}
    assert all(variability[n] == "fixed" for n in fixed)


def test_changing_G_mid_run_changes_the_torque_from_the_next_sample_on(controller):
    base = torques(controller)
    changed = torques(controller, {"G1": 3000.0})
    assert changed[:CHANGE_AT] == base[:CHANGE_AT]  # samples before the set: untouched
    assert abs(changed[CHANGE_AT] - base[CHANGE_AT]) > 1e-6  # the first sample after the set
    assert all(abs(c - b) > 1e-9 for c, b in zip(changed[CHANGE_AT:], base[CHANGE_AT:]))


def test_python_and_native_agree_bit_for_bit_with_a_change(fmu_dir, native_dir):
    change = {"G1": 3000.0, "B1": 10.0, "wall_depth": 0.004}
    python = torques(fmu_dir / "ImpedanceController.fmu", change)
    native = torques(native_dir / "ImpedanceController.fmu", change)
    assert python == native


@pytest.mark.parametrize(
    "change,message",
    [
        ({"sample_period": 0.001}, "parameter sample_period is fixed"),
        ({"G1": 0.0}, r"parameter G1 must be > 0 \(got 0.0\)"),
    ],
)
def test_a_fixed_parameter_or_a_bad_value_is_refused_in_step_mode(controller, change, message):
    """The native FMU returns fmi2Error, keeps the old value and goes on; the Python FMU returns
    fmi2Fatal (pythonfmu 0.7 turns every exception of a setter into fmi2Fatal), after which the
    standard allows no further call."""
    fmu = open_controller(controller)
    try:
        fmu.step(0.0, TS)
        with pytest.raises(FmuError, match=message) as refused:
            fmu.set(change)
        if "native" not in str(controller):
            assert "(fatal)" in str(refused.value)
            return
        assert "(error)" in str(refused.value)
        assert fmu.get(["G1", "sample_period"]) == [1000.0, TS]  # the refused value not taken
        fmu.set({"G1": 2000.0})  # and the instance goes on
        fmu.step(TS, TS)
    finally:
        fmu.free()
