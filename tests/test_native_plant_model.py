"""The native plant model (native/plant/model.c, native/src/ode.c, native/src/pyrandom.c) against
plant_model.model.PlantModel, without the FMI layer: compiled with a small shim into a shared
library and driven through ctypes, step by step with the same inputs. The outputs, the time,
the integrator's step-size guess and the contact mode must be equal bit for bit."""

from __future__ import annotations

import ctypes
import math
import random
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import DT, contact_torques

from impedance_cosim.cosim.master.plain_loop import run_models
from impedance_cosim.fmi.model import ModelError
from plant_model.model import PlantModel

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

REPO = Path(__file__).resolve().parent.parent
SOURCES = ["native/plant/model.c", "native/plant/model_me.c", "native/src/wall.c",
           "native/src/fail.c", "native/src/ode.c", "native/src/pyrandom.c", "native/src/pyrepr.c",
           "native/src/arm_terms.c", "native/src/arm_partials.c"]  # fmt: skip
CFLAGS = ["-std=c99", "-O2", "-fPIC", "-ffp-contract=off", "-Wall", "-Wextra", "-Werror"]
MSG_MAX = 512

# The model's own state for ctypes; the rest of the shim is tests/c_host/model_shim.c.
SHIM = r"""
#include "glue.h"

/* t, h, in_contact, q[3], qd[3], q_meas[3] */
void state_get(const Data *d, double out[12])
{
    const ModelState *m = &d->m;
    out[0] = m->t;
    out[1] = m->h;
    out[2] = m->in_contact;
    for (int i = 0; i < 3; i++) {
        out[3 + i] = m->q[i];
        out[6 + i] = m->qd[i];
        out[9 + i] = m->q_meas[i];
    }
}
"""

NAMES = [v.name for v in PlantModel.variables()]
VR = {n: i for i, n in enumerate(NAMES)}
OUTPUTS = [v.name for v in PlantModel.variables() if v.causality == "output"]
OUT_VRS = [VR[n] for n in OUTPUTS]


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    tmp = tmp_path_factory.mktemp("native_plant")
    shim = tmp / "shim.c"
    shim.write_text(SHIM)
    so = tmp / "plant_test.so"
    cmd = ["gcc", *CFLAGS, "-shared", f"-I{REPO / 'native/src'}", f"-I{REPO / 'native/plant'}",
           *(str(REPO / s) for s in SOURCES), str(shim),
           str(REPO / "tests/c_host/model_shim.c"), "-lm", "-o", str(so)]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    lib = ctypes.CDLL(str(so))
    lib.data_size.restype = ctypes.c_size_t
    lib.state_size.restype = ctypes.c_size_t
    lib.data_r.restype = ctypes.POINTER(ctypes.c_double)
    lib.data_i.restype = ctypes.POINTER(ctypes.c_int)
    lib.data_init.argtypes = [ctypes.c_void_p, ctypes.c_double]
    lib.data_r.argtypes = lib.data_i.argtypes = [ctypes.c_void_p]
    lib.data_set_string.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_char_p]
    lib.model_initialize.argtypes = [ctypes.c_void_p, ctypes.c_char_p]
    lib.data_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_char_p]
    lib.state_get.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_double)]
    lib.pyrandom_seed.argtypes = [ctypes.c_void_p, ctypes.c_int64]
    lib.pyrandom_random.argtypes = [ctypes.c_void_p]
    lib.pyrandom_random.restype = ctypes.c_double
    lib.pyrandom_gauss.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double]
    lib.pyrandom_gauss.restype = ctypes.c_double
    lib.py_float_repr.argtypes = [ctypes.c_double, ctypes.c_char_p, ctypes.c_size_t]
    return lib


class NativePlant:
    """One native model instance in a ctypes buffer, with the glue's conventions."""

    def __init__(self, lib: ctypes.CDLL, parameters: dict | None = None, start_time=0.0):
        self.lib = lib
        self.buf = ctypes.create_string_buffer(lib.data_size())
        self.msg = ctypes.create_string_buffer(MSG_MAX)
        lib.data_init(self.buf, start_time)
        self.r, self.i = lib.data_r(self.buf), lib.data_i(self.buf)
        for name, value in (parameters or {}).items():
            if isinstance(value, float):
                self.r[VR[name]] = value
            elif isinstance(value, str):
                lib.data_set_string(self.buf, VR[name], value.encode())
            else:
                self.i[VR[name]] = int(value)

    def initialize(self) -> None:
        if self.lib.model_initialize(self.buf, self.msg):
            raise ModelError(self.msg.value.decode())

    def do_step(self, t: float, h: float, tau) -> None:
        for k, v in enumerate(tau):
            self.r[VR[f"tau{k + 1}"]] = v
        if self.lib.data_step(self.buf, t, h, self.msg):
            raise ModelError(self.msg.value.decode())

    def outputs(self) -> list[float]:
        return [self.r[vr] for vr in OUT_VRS]

    def state(self) -> list[float]:
        out = (ctypes.c_double * 12)()
        self.lib.state_get(self.buf, out)
        return list(out)


def python_state(m: PlantModel) -> list[float]:
    return [m.t, m.h, float(m.in_contact), *m.q, *m.qd, *m.q_meas]


def bits(a) -> np.ndarray:
    """Bit patterns, so that equality also tells -0.0 from 0.0."""
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64)).view(np.uint64)


def assert_same(native, python, what: str) -> None:
    native, python = np.asarray(native, dtype=float), np.asarray(python, dtype=float)
    if np.array_equal(bits(native), bits(python)):
        return
    diff = np.abs(native - python)
    rel = diff / np.maximum(np.abs(python), 1e-300)
    where = tuple(int(k) for k in np.unravel_index(np.argmax(diff), diff.shape))
    first = tuple(int(k) for k in np.argwhere(bits(native) != bits(python))[0])
    pytest.fail(
        f"{what}: native != python; first at {first}, max abs diff {diff.max():.3g} at {where},"
        f" max rel diff {rel.max():.3g}"
    )


def run_both(lib, torques, parameters: dict | None = None):
    """Step the Python and the native plant with the same torques; return both histories
    (outputs and states, initial row included)."""
    py = PlantModel(parameters or {}, 0.0, None)
    nat = NativePlant(lib, parameters)
    nat.initialize()
    outs = [[nat.outputs(), list(py.outputs())]]
    states = [[nat.state(), python_state(py)]]
    for i, tau in enumerate(torques):
        tau = tuple(float(v) for v in tau)
        py.do_step(i * DT, DT, tau)
        nat.do_step(i * DT, DT, tau)
        outs.append([nat.outputs(), list(py.outputs())])
        states.append([nat.state(), python_state(py)])
    outs, states = np.array(outs), np.array(states)
    return outs[:, 0], outs[:, 1], states[:, 0], states[:, 1]


def check_run(lib, torques, parameters=None):
    nat_out, py_out, nat_state, py_state = run_both(lib, torques, parameters)
    assert_same(nat_state, py_state, "state (t, h, in_contact, q, qd, q_meas)")
    assert_same(nat_out, py_out, "outputs")
    return nat_out, py_out, nat_state


@pytest.fixture(scope="module")
def paper_run():
    return run_models(stop_time=20.0)


@pytest.fixture(scope="module")
def paper_torques(paper_run):
    n = len(paper_run["time"]) - 1
    taus = [paper_run[f"controller.tau{k}"] for k in (1, 2, 3)]
    return [(taus[0][i + 1], taus[1][i + 1], taus[2][i + 1]) for i in range(n)]


def test_model_state_is_plain_and_sized(lib):
    assert lib.state_size() == 2608
    assert lib.data_size() > lib.state_size()


@pytest.mark.slow
def test_default_experiment_zero_torque(lib):
    nat_out, _, _ = check_run(lib, [(0.0, 0.0, 0.0)] * 8000)
    assert np.all(np.isfinite(nat_out))


def test_paper_scenario_torques(lib, paper_run, paper_torques):
    nat_out, _, states = check_run(lib, paper_torques)
    for k, name in enumerate(OUTPUTS):  # the closed loop's recorded plant signals, too
        assert_same(nat_out[:, k], paper_run[f"plant.{name}"], name)
    assert states[:, 2].max() == 1.0  # the arm reaches the wall


def test_contact_switching(lib):
    nat_out, _, states = check_run(lib, contact_torques(6.0))
    switches = np.count_nonzero(np.diff(states[:, 2]))
    assert switches >= 3, switches
    assert nat_out[:, OUTPUTS.index("contact_force")].max() > 10.0


@pytest.mark.parametrize("seed", [7, -7, 0, 2**31 - 1])
def test_noise_and_quantization(lib, paper_torques, seed):
    params = {"q_noise": 1e-4, "q_quant": 1e-5, "noise_seed": seed}
    nat_out, _, _ = check_run(lib, paper_torques[:2000], params)
    q_meas, q_true = nat_out[:, 0], nat_out[:, OUTPUTS.index("q1_true")]
    assert 0.0 < np.abs(q_meas - q_true).max() < 1e-3


def test_noise_in_contact(lib):
    params = {"q_noise": 1e-3, "q_quant": 0.0, "noise_seed": 123456, "wall_d": 50.0}
    check_run(lib, contact_torques(3.0), params)


def test_other_parameters(lib):
    params = {"x0": 0.5, "y0": 0.2, "phi0": 0.3, "elbow_up": False, "wall_x": 0.55,
              "wall_d": 200.0, "rtol": 1e-6, "atol": 1e-8, "m3": 2.5, "g": 0.0}  # fmt: skip
    check_run(lib, contact_torques(3.0, params), params)


@pytest.mark.parametrize("n", [1, 3])
def test_euler_substeps(lib, paper_torques, n):
    """euler_substeps = n (explicit Euler steps per communication step, the Fig. 4 reproduction
    aid): bit for bit, it reaches the wall, and it is not the adaptive result (open loop: the
    paper's torques drive the Euler plant elsewhere, so no closeness check)."""
    nat_out, py_out, states = check_run(lib, paper_torques[:2400], {"euler_substeps": n})
    assert states[:, 2].max() == 1.0
    dopri = run_both(lib, paper_torques[:2400])[0]
    assert not np.array_equal(bits(nat_out), bits(dopri))


def test_one_euler_substep_is_one_explicit_step(lib):
    """One step of h from rest: q unchanged, qd = h * qdd(q, 0, tau) (explicit Euler)."""
    py = PlantModel({"euler_substeps": 1}, 0.0, None)
    q0 = py.q
    tau = (5.0, -3.0, 1.0)
    qdd = py.arm.forward_dynamics(q0, (0.0, 0.0, 0.0), tau)
    py.do_step(0.0, DT, tau)
    assert py.q == q0
    assert py.qd == tuple(DT * a for a in qdd)


@pytest.mark.parametrize(
    ("n", "message"), [(-1, "must be >= 0"), (10**6 + 1, "must be <= 1000000")]
)
def test_bad_euler_substeps_refused(lib, n, message):
    with pytest.raises(ModelError, match=f"parameter euler_substeps {message}"):
        PlantModel({"euler_substeps": n}, 0.0, None)
    if n > 0:  # (the FMI glue refuses values below the minimum before the model sees them)
        nat = NativePlant(lib, {"euler_substeps": n})
        with pytest.raises(ModelError, match=f"parameter euler_substeps {message}"):
            nat.initialize()


def test_start_time_and_uneven_steps(lib):
    rng = random.Random(5)
    params = {"wall_x": 0.6, "q_noise": 1e-5, "noise_seed": 11}
    py, nat = PlantModel(params, 100.0, None), NativePlant(lib, params, 100.0)
    nat.initialize()
    t, tau = 100.0, (0.0, 0.0, 0.0)
    for i in range(600):
        if i % 50 == 0:
            tau = tuple(rng.uniform(-40.0, 40.0) for _ in range(3))
        h = rng.choice([DT, 1e-3, 0.01, rng.uniform(1e-5, 0.05)])
        py.do_step(t, h, tau)
        nat.do_step(t, h, tau)
        assert_same(nat.state() + nat.outputs(), python_state(py) + list(py.outputs()), f"step {i}")
        t += h


def test_fmu_state_is_the_model_state(lib, paper_torques):
    """Copying Data (what fmi2GetFMUstate does) and restoring it replays the same numbers."""
    nat = NativePlant(lib, {"q_noise": 1e-4, "noise_seed": 3})
    nat.initialize()
    for i in range(800):
        nat.do_step(i * DT, DT, paper_torques[i])
    saved = nat.buf.raw
    first = []
    for i in range(800, 1200):
        nat.do_step(i * DT, DT, paper_torques[i])
        first.append(nat.outputs())
    ctypes.memmove(nat.buf, saved, len(saved))
    again = []
    for i in range(800, 1200):
        nat.do_step(i * DT, DT, paper_torques[i])
        again.append(nat.outputs())
    assert_same(again, first, "after restoring the state")


def test_random_generator_is_cpythons(lib):
    buf = ctypes.create_string_buffer(4096)  # a PyRandom (2512 bytes)
    for seed in [0, 1, 7, -7, 2**31 - 1, -(2**31), 2**32 + 5, -(2**63)]:
        lib.pyrandom_seed(buf, seed)
        rng = random.Random(seed)
        native = [lib.pyrandom_random(buf) for _ in range(700)]
        native += [lib.pyrandom_gauss(buf, 0.5, 2.0) for _ in range(701)]
        python = [rng.random() for _ in range(700)] + [rng.gauss(0.5, 2.0) for _ in range(701)]
        assert_same(native, python, f"seed {seed}")


def test_float_repr_is_pythons(lib):
    values = [0.0, -0.0, 1.0, -2.5, 0.1, 1 / 3, 1e-4, 1e-5, 123456789.0, 1e15, 1e16, 1.5e16,
              1e22, 5e-324, 1.7976931348623157e308, math.inf, -math.inf, math.nan, 0.0025,
              20.000000000000004, 2.0**-1074 * 3, 4e-14, 1 / 400 * 3]  # fmt: skip
    values += [struct.unpack("d", struct.pack("Q", b))[0] for b in range(1, 2**64, 2**57 + 12345)]
    buf = ctypes.create_string_buffer(64)
    for v in values:
        lib.py_float_repr(v, buf, 64)
        assert buf.value.decode() == repr(v)


# --- refusals: same conditions, same messages ----------------------------------------------------


def python_error(parameters, steps=()) -> str:
    try:
        m = PlantModel(parameters, 0.0, None)
        for t, h, tau in steps:
            m.do_step(t, h, tau)
    except (ModelError, ValueError, ArithmeticError) as exc:
        return str(exc)
    raise AssertionError("Python accepted")


def native_error(lib, parameters, steps=()) -> str:
    nat = NativePlant(lib, parameters)
    try:
        nat.initialize()
        for t, h, tau in steps:
            nat.do_step(t, h, tau)
    except ModelError as exc:
        return str(exc)
    raise AssertionError("native accepted")


@pytest.mark.parametrize(
    "parameters, steps",
    [
        ({"a1": 0.0}, ()),
        ({"a2": 0.0, "a1": 0.25}, ()),
        ({"x0": 1.5}, ()),
        ({"x0": 0.0, "y0": 0.0, "phi0": 0.0, "a1": 0.5, "a2": 0.2, "a3": 0.1}, ()),
        ({}, [(0.0, DT, (0.0, math.nan, 0.0))]),
        ({}, [(0.0, DT, (math.inf, 0.0, 0.0))]),
        ({}, [(0.0, DT, (1.0, 2.0, -math.inf))]),
        ({}, [(0.0, 0.0, (0.0, 0.0, 0.0))]),
        ({}, [(0.0, -DT, (0.0, 0.0, 0.0))]),
        ({}, [(0.0, math.nan, (0.0, 0.0, 0.0))]),
        ({}, [(0.0, DT, (0.0, 0.0, 0.0)), (0.5, DT, (0.0, 0.0, 0.0))]),
        ({"max_rhs_evaluations": 10**8}, [(0.0, DT, (1e12, 0.0, 0.0))]),  # contact chattering
        ({"max_rhs_evaluations": 50}, [(0.0, 1.0, (0.0, 0.0, 0.0))]),  # the work bound
        ({"max_rhs_evaluations": 50, "euler_substeps": 51}, [(0.0, DT, (0.0, 0.0, 0.0))]),
        ({}, [(0.0, DT, (1e30, 0.0, 0.0))]),  # step size underflow
        ({"q_quant": 1e-320}, ()),  # round() of an infinite ratio
        ({}, [(0.0, math.inf, (0.0, 0.0, 0.0))]),  # an infinite step
    ],
)
@pytest.mark.slow
def test_same_refusals(lib, parameters, steps):
    params = {k: (float(v) if isinstance(v, float) else v) for k, v in parameters.items()}
    steps = [(t, h, tuple(float(v) for v in tau)) for t, h, tau in steps]
    py_msg, nat_msg = python_error(params, steps), native_error(lib, params, steps)
    assert nat_msg == py_msg


def test_math_domain_error_ends_the_step(lib):
    """math.sin(inf) raises ValueError: both flavours refuse the step with the same message."""
    steps = [(0.0, DT, (1e300, 1e300, 0.0))]
    assert python_error({}, steps) == "plant integration failed: math domain error"
    assert native_error(lib, {}, steps) == "plant integration failed: math domain error"


def test_refused_step_leaves_the_state(lib):
    nat = NativePlant(lib, {"max_rhs_evaluations": 10**8})
    nat.initialize()
    nat.do_step(0.0, DT, (1.0, 2.0, 3.0))
    before = nat.buf.raw
    with pytest.raises(ModelError, match="contact chattering"):
        nat.do_step(DT, DT, (1e12, 0.0, 0.0))
    for k, v in enumerate((1.0, 2.0, 3.0)):  # the refused step's inputs are the only change
        nat.r[VR[f"tau{k + 1}"]] = v
    assert nat.buf.raw == before
