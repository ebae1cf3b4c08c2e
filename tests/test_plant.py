"""The plant model (arm + wall + sensors + integrator), without the FMI layer."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import DT, benchmark_module, contact_torques, output_dict

from impedance_cosim.fmi.model import ModelError
from impedance_cosim.physics.wall import WallParams, wall_force
from plant_model.model import PlantModel

reference_states = benchmark_module("plant_reference").reference_states  # scipy's DOP853
NO_FRICTION = {"f1": 0.0, "f2": 0.0, "f3": 0.0}


def states(plant: PlantModel) -> tuple:
    return (*plant.q, *plant.qd)


def run(torques, parameters=None, step=DT) -> np.ndarray:
    """Plant states at every 1/400 s sample, stepping the plant at `step` (torque held)."""
    plant = PlantModel(parameters or {}, 0.0, None)
    sub = round(DT / step)
    out = [states(plant)]
    k = 0
    for tau in torques:
        for _ in range(sub):
            plant.do_step(k * step, step, tau)
            k += 1
        out.append(states(plant))
    return np.array(out)


def test_starts_at_rest_at_the_paper_pose():
    plant = PlantModel({}, 0.0, None)
    out = output_dict(plant)
    assert (out["x"], out["y"], out["phi"]) == pytest.approx((0.3, 0.0, 0.0), abs=1e-12)
    assert plant.qd == (0.0, 0.0, 0.0)
    assert plant.q[1] < 0  # elbow up by default
    assert PlantModel({"elbow_up": False}, 0.0, None).q[1] > 0


def test_energy_conserved_without_friction_torque_or_wall():
    """10 s of free swinging at the default step: relative energy drift < 1e-6."""
    plant = PlantModel({**NO_FRICTION, "wall_k": 0.0}, 0.0, None)
    e0, drift, t_max = plant.energy(), 0.0, 0.0
    for i in range(round(10 / DT)):
        plant.do_step(i * DT, DT, (0.0, 0.0, 0.0))
        drift = max(drift, abs(plant.energy() - e0))
        t_max = max(t_max, plant.arm.kinetic_energy(plant.q, plant.qd))
    assert t_max > 10.0  # the arm really swings
    assert drift / t_max < 1e-6


def test_friction_only_dissipates():
    """With friction and no torque, total energy never increases (dE/dt = -qd^T F qd)."""
    plant = PlantModel({}, 0.0, None)
    energy = [plant.energy()]
    for i in range(round(3 / DT)):
        plant.do_step(i * DT, DT, (0.0, 0.0, 0.0))
        energy.append(plant.energy())
    assert np.all(np.diff(energy) <= 1e-9)
    assert energy[-1] < energy[0] - 1.0


def test_wall_force_law():
    wall = WallParams()
    assert wall_force(wall, 0.6499, 1.0) == 0.0
    assert wall_force(wall, 0.65, 1.0) == 0.0
    assert wall_force(wall, 0.652, 0.0) == pytest.approx(1e4 * 0.002)
    damped = WallParams(wall_d=100.0)
    assert wall_force(damped, 0.652, 0.1) == pytest.approx(1e4 * 0.002 + 100.0 * 0.1)
    assert wall_force(damped, 0.652, -1.0) == 0.0  # never pulls


@pytest.mark.slow
def test_contact_run_matches_tight_reference():
    """Contact closing and opening inside steps: the plant (rtol 1e-9) agrees with scipy DOP853
    (rtol 1e-10) and independent event handling to 1e-7 over 3 s."""
    torques = contact_torques(3.0)
    ours = run(torques)
    ref = reference_states({}, torques, DT)
    assert np.abs(ours - ref).max() < 1e-7
    plant = PlantModel({}, 0.0, None)
    forces = []
    for i, tau in enumerate(torques):
        plant.do_step(i * DT, DT, tau)
        forces.append(output_dict(plant)["contact_force"])
    assert max(forces) > 50.0 and forces[-1] == 0.0  # the wall was pushed, then left


@pytest.mark.parametrize("step", [DT / 10, DT / 3])
def test_result_independent_of_communication_step(step):
    torques = contact_torques(3.0)
    assert np.abs(run(torques, step=step) - run(torques)).max() < 1e-8


def test_coarse_communication_step():
    """One 0.1 s step (contact switches inside it) equals forty 1/400 s steps with that torque."""
    tau = (20.0, 30.0, 1.0)
    fine, coarse = PlantModel({}, 0.0, None), PlantModel({}, 0.0, None)
    for i in range(40):
        fine.do_step(i * DT, DT, tau)
    coarse.do_step(0.0, 0.1, tau)
    assert np.abs(np.subtract(states(fine), states(coarse))).max() < 1e-8


def test_sensor_noise_and_quantization_are_reproducible():
    params = {"q_noise": 1e-3, "q_quant": 1e-4, "noise_seed": 7}
    a, b = PlantModel(params, 0.0, None), PlantModel(params, 0.0, None)
    c = PlantModel({**params, "noise_seed": 8}, 0.0, None)
    for i in range(10):
        for m in (a, b, c):
            m.do_step(i * DT, DT, (0.0, 0.0, 0.0))
    qa, qb, qc = (output_dict(m) for m in (a, b, c))
    assert [qa[f"q{i}"] for i in (1, 2, 3)] == [qb[f"q{i}"] for i in (1, 2, 3)]
    assert qa["q1"] != qc["q1"]
    assert all(abs(qa[f"q{i}"] / 1e-4 - round(qa[f"q{i}"] / 1e-4)) < 1e-6 for i in (1, 2, 3))
    assert 0 < abs(qa["q1"] - qa["q1_true"]) < 5e-3
    assert qa["q1_true"] == qc["q1_true"]  # noise never touches the physics


def test_state_round_trip_is_bit_identical():
    params = {"q_noise": 1e-3}
    plant = PlantModel(params, 0.0, None)
    for i in range(50):
        plant.do_step(i * DT, DT, (5.0, 5.0, 0.5))
    saved = json.loads(json.dumps(plant.get_state()))
    first = []
    for i in range(50, 60):
        plant.do_step(i * DT, DT, (5.0, 5.0, 0.5))
        first.append(plant.outputs())
    other = PlantModel(params, 0.0, None)
    other.set_state(saved)
    for i, expected in zip(range(50, 60), first, strict=True):
        other.do_step(i * DT, DT, (5.0, 5.0, 0.5))
        assert other.outputs() == expected


@pytest.mark.parametrize(
    "params,message",
    [
        ({"m2": -1.0}, "m2 must be >= 0"),
        ({"wall_k": -5.0}, "wall_k must be >= 0"),
        ({"x0": 1.5}, "unreachable"),
        ({"rtol": 0.0}, "rtol"),
        ({"q_noise": -1e-3}, "q_noise must be >= 0"),
        ({"wall_x": math.nan}, "wall_x must be finite"),
    ],
)
def test_bad_parameters_are_named(params, message):
    with pytest.raises(ModelError, match=message):
        PlantModel(params, 0.0, None)


def test_bad_inputs_are_named():
    plant = PlantModel({}, 0.0, None)
    with pytest.raises(ModelError, match="tau2 is not finite"):
        plant.do_step(0.0, DT, (0.0, math.nan, 0.0))
    with pytest.raises(ModelError, match="tau3 is not finite"):
        plant.do_step(0.0, DT, (0.0, 0.0, math.inf))
    with pytest.raises(ModelError, match="step must be > 0"):
        plant.do_step(0.0, 0.0, (0.0, 0.0, 0.0))
    with pytest.raises(ModelError, match="plant is at t=0"):
        plant.do_step(1.0, DT, (0.0, 0.0, 0.0))
    plant.do_step(0.0, DT, (0.0, 0.0, 0.0))  # still usable after refusing


def test_diverging_input_fails_cleanly():
    plant = PlantModel({}, 0.0, None)
    with pytest.raises(ModelError, match="integration failed"):
        plant.do_step(0.0, 1.0, (1e300, -1e300, 1e300))
    assert plant.t == 0.0 and plant.qd == (0.0, 0.0, 0.0)  # state kept at the step's start


def test_huge_finite_parameters_are_a_model_error_not_an_overflow():
    """Fuzz finding (fuzz/corpus/robot_session/finding-init-overflow): an INIT whose rx2 is
    7.4e181 made the arm's terms overflow, and the robot answered INTERNAL instead of REFUSED."""
    params = {v.name: v.start for v in PlantModel.variables() if v.causality == "parameter"}
    with pytest.raises(ModelError, match="out of range"):
        PlantModel({**params, "rx2": 7.4e181}, 0.0)
