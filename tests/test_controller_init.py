"""The controller initializes with any finite inputs (issue 22), in every edition: the model,
the Python FMUs (FMI 2.0, FMI 3.0) and the native ones (FMI 2.0 and 3.0 co-simulation and Model
Exchange, the clocked FMI 3.0 one). Where eq. (10) is undefined (J singular: q2 = 0, e.g. the
all-zero inputs a loop-cutting host gives) sample 0 is gravity compensation only, tau = g(q),
with a logged warning; a step that samples at a singular pose is refused, naming the step time
and the pose. Elsewhere sample 0 is the law, as before."""

from __future__ import annotations

import math
import random
import shutil

import pytest
from fmpy import simulate_fmu

from controller_model.impedance_law import SingularPoseError
from controller_model.model import INPUTS, ControllerModel
from impedance_cosim.cosim.fmus.fmi2 import FmuError
from impedance_cosim.cosim.fmus.fmi3 import open_fmu
from impedance_cosim.physics.arm import Arm

TS = 1 / 400
ZERO = (0.0,) * 9
CONTROLLER = "ImpedanceController.fmu"
TORQUES = ("tau1", "tau2", "tau3")
needs_gcc = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")


def random_inputs(rng: random.Random, singular: bool) -> tuple:
    """Finite inputs: angles anywhere (q2 a multiple of pi when singular, else |sin q2| > 0.1),
    forces and velocities of any sign and size up to 1e3."""
    q = [rng.uniform(-10.0, 10.0) for _ in range(3)]
    if singular:
        q[1] = rng.choice((-2, -1, 0, 1, 2)) * math.pi
    while not singular and abs(math.sin(q[1])) < 0.1:
        q[1] = rng.uniform(-10.0, 10.0)
    return (*q, *(rng.uniform(-1e3, 1e3) for _ in range(6)))


def cases() -> list[tuple[str, tuple]]:
    rng = random.Random(22)
    return [
        ("zeros", ZERO),
        *((f"singular{i}", random_inputs(rng, True)) for i in range(3)),
        *((f"regular{i}", random_inputs(rng, False)) for i in range(3)),
    ]


def is_singular(inputs: tuple) -> bool:
    return abs(math.sin(inputs[1])) < 1e-6


# --- the model ------------------------------------------------------------------------------------


@pytest.mark.parametrize("source", ["observer", "difference", "measured"])
@pytest.mark.parametrize("name,inputs", cases())
def test_model_initializes_with_any_finite_inputs(name, inputs, source):
    m = ControllerModel({"velocity_source": source}, 0.0, inputs)
    out = m.outputs()
    q = inputs[:3]
    if is_singular(inputs):
        assert out[:3] == Arm().gravity(q)  # gravity compensation only
        assert len(m.init_warnings) == 1
        assert "singular" in m.init_warnings[0] and "gravity compensation" in m.init_warnings[0]
    else:
        assert m.init_warnings == ()
        assert out[:3] != Arm().gravity(q)  # the law (eq. 10), not the fallback
    assert all(math.isfinite(v) for v in out)


def test_a_singular_start_is_clipped_like_any_torque():
    m = ControllerModel({"limit_torque": True, "tau_max1": 10.0}, 0.0, ZERO)
    assert m.outputs()[:3] == (10.0, *Arm().gravity((0.0, 0.0, 0.0))[1:])


def test_a_step_that_samples_at_a_singular_pose_is_refused():
    m = ControllerModel({}, 0.0, ZERO)
    m.do_step(0.0, TS, ZERO)  # takes no sample (sample 0 was taken at initialization)
    before = m.get_state()
    with pytest.raises(SingularPoseError, match=r"singular at q = \(0, 0, 0\) rad"):
        m.do_step(TS, TS, ZERO)  # sample 1, at the stretched arm
    assert m.get_state() == before
    regular = ControllerModel({}, 0.0, ZERO)
    regular.do_step(0.0, TS, ZERO)
    regular.do_step(TS, TS, (0.1, 1.0, 0.2, *ZERO[3:]))  # a regular pose: the law applies
    assert regular.outputs()[:3] != Arm().gravity((0.1, 1.0, 0.2))


# --- every FMU edition ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def editions(fmu_dir, request) -> dict:
    """The controller's co-simulation editions: Python FMI 2.0 always, the others when a C
    compiler (native) or pythonfmu3 (Python FMI 3.0) is there."""
    found = {"python-fmi2": fmu_dir / CONTROLLER}
    if shutil.which("gcc"):
        native = request.getfixturevalue("native_dir")
        fmi3 = request.getfixturevalue("fmi3_dir")
        found["native-fmi2"] = native / CONTROLLER
        found["native-fmi3"] = fmi3 / CONTROLLER
        found["native-fmi3-clocked"] = fmi3 / "ImpedanceControllerClocked.fmu"
        if (fmi3 / "python" / CONTROLLER).is_file():
            found["python-fmi3"] = fmi3 / "python" / CONTROLLER
    return found


EDITIONS = ["python-fmi2", "python-fmi3", "native-fmi2", "native-fmi3", "native-fmi3-clocked"]


@pytest.mark.parametrize("edition", EDITIONS)
def test_every_edition_initializes_with_any_finite_inputs(editions, edition):
    if edition not in editions:
        pytest.skip(f"{edition} not built here")
    for name, inputs in cases():
        fmu = open_fmu(editions[edition], f"init-{name}")
        fmu.setup(0.0)
        fmu.enter_initialization()
        fmu.set(dict(zip(INPUTS, inputs, strict=True)))
        fmu.exit_initialization()  # raised FmuError at a singular pose before issue 22
        model = ControllerModel({}, 0.0, inputs)
        assert tuple(fmu.get(TORQUES)) == model.outputs()[:3], name  # bit for bit
        warnings = [m for s, _, m in fmu.messages if s == "Warning"]
        if is_singular(inputs):
            assert any("gravity compensation only" in w for w in warnings), (name, warnings)
        else:
            assert warnings == [], name
        fmu.step(0.0, TS)  # no sample at t = 0: the first step's inputs are not used
        if is_singular(inputs):
            with pytest.raises(FmuError, match=r"t=0\.0025.*the Jacobian is singular at q = "):
                fmu.step(TS, TS)  # sample 1 at the same singular pose
        else:
            fmu.step(TS, TS)
        fmu.free()


@needs_gcc
@pytest.mark.parametrize("which", ["native-fmi2", "native-fmi3"])
def test_model_exchange_initializes_at_the_stretched_arm(editions, which):
    """Under Model Exchange (fmpy's solver, inputs at their given values): initialization at
    q = 0 succeeds with tau = g(0); the run stops before sample 1 (at Ts)."""
    result = simulate_fmu(
        str(editions[which]),
        fmi_type="ModelExchange",
        start_values=dict.fromkeys(INPUTS, 0.0),
        stop_time=TS / 2,
        output_interval=TS / 4,
        output=list(TORQUES),
    )
    assert tuple(result[0][list(TORQUES)].tolist()) == Arm().gravity((0.0, 0.0, 0.0))
