"""The native controller model (native/controller/model.c) against the Python ControllerModel.

model.c is compiled with the FMU's flags into a test library, with a small shim (fail(), Data
setup and accessors) standing in for native/src/instance.c, and driven through ctypes with the
same parameters and inputs as controller_model.model.ControllerModel: the outputs must be equal
bit for bit after initialization and after every step, and the errors must carry the same
messages."""

from __future__ import annotations

import ctypes
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from controller_model.model import INPUT_START, ControllerModel
from controller_model.parameters import VELOCITY_SOURCE
from impedance_cosim.cosim.master.plain_loop import run_models
from impedance_cosim.fmi.model import ModelError

ROOT = Path(__file__).resolve().parents[1]
CFLAGS = ["-std=c99", "-O2", "-fPIC", "-ffp-contract=off", "-Wall", "-Wextra"]
TS = 1 / 400

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")

VARIABLES = ControllerModel.variables()
VR = {v.name: k for k, v in enumerate(VARIABLES)}
INPUTS = [v.name for v in VARIABLES if v.causality == "input"]
OUTPUTS = [v.name for v in VARIABLES if v.causality == "output"]

SHIM = r"""
#include "glue.h"

/* t, start_time, yhat, q_prev, tau_prev, f_prev (14 values); k_next, held_input_samples */
void state_reals(const Data *d, double out[14])
{
    out[0] = d->m.t;
    out[1] = d->m.start_time;
    for (int k = 0; k < 3; k++) {
        out[2 + k] = d->m.yhat[k];
        out[5 + k] = d->m.q_prev[k];
        out[8 + k] = d->m.tau_prev[k];
        out[11 + k] = d->m.f_prev[k];
    }
}
long long state_k_next(const Data *d) { return (long long)d->m.k_next; }
long long state_held(const Data *d) { return (long long)d->m.held_input_samples; }
"""  # the model's own state for ctypes; the rest of the shim is tests/c_host/model_shim.c


def _compile(src: list[Path], out: Path, werror: bool) -> None:
    inc = ["-I", str(ROOT / "native" / "src"), "-I", str(ROOT / "native" / "controller")]
    cmd = ["gcc", *CFLAGS, *(["-Werror"] if werror else []), *inc, "-c", *map(str, src)]
    subprocess.run([*cmd, "-o", str(out)], check=True, capture_output=True, text=True)


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    """model.c (warning-free) + arm_terms.c + pyrepr.c + the shim, as a shared library."""
    tmp = tmp_path_factory.mktemp("native_controller")
    shim = tmp / "shim.c"
    shim.write_text(SHIM)
    names = ("model.o", "arm_terms.o", "shim.o", "pyrepr.o", "model_shim.o", "fail.o")
    objs = [tmp / n for n in names]
    try:
        _compile([ROOT / "native" / "controller" / "model.c"], objs[0], werror=True)
        _compile([ROOT / "native" / "src" / "arm_terms.c"], objs[1], werror=False)
        _compile([shim], objs[2], werror=True)
        _compile([ROOT / "native" / "src" / "pyrepr.c"], objs[3], werror=True)
        _compile([ROOT / "tests" / "c_host" / "model_shim.c"], objs[4], werror=True)
        _compile([ROOT / "native" / "src" / "fail.c"], objs[5], werror=True)
    except subprocess.CalledProcessError as exc:
        pytest.fail(f"compilation failed:\n{exc.stderr}")
    so = tmp / "controller_test.so"
    subprocess.run(["gcc", "-shared", *map(str, objs), "-lm", "-o", str(so)], check=True)
    lib = ctypes.CDLL(str(so))
    p, d = ctypes.c_void_p, ctypes.c_double
    for name, res, args in [
        ("data_size", ctypes.c_size_t, []),
        ("state_size", ctypes.c_size_t, []),
        ("n_vars", ctypes.c_int, []),
        ("var_name", ctypes.c_char_p, [ctypes.c_int]),
        ("var_start", d, [ctypes.c_int]),
        ("data_init", None, [p, d]),
        ("data_r", ctypes.POINTER(d), [p]),
        ("data_i", ctypes.POINTER(ctypes.c_int), [p]),
        ("data_set_string", None, [p, ctypes.c_int, ctypes.c_char_p]),
        ("data_initialize", ctypes.c_int, [p, ctypes.c_char_p]),
        ("data_step", ctypes.c_int, [p, d, d, ctypes.c_char_p]),
        ("state_reals", None, [p, ctypes.POINTER(d)]),
        ("state_k_next", ctypes.c_longlong, [p]),
        ("state_held", ctypes.c_longlong, [p]),
    ]:
        f = getattr(lib, name)
        f.restype, f.argtypes = res, args
    return lib


class Native:
    """One native controller instance (its Data in a ctypes buffer)."""

    def __init__(self, lib: ctypes.CDLL, parameters: dict, start_time: float, inputs) -> None:
        self.lib = lib
        self.buf = ctypes.create_string_buffer(lib.data_size())
        self.msg = ctypes.create_string_buffer(512)
        lib.data_init(self.buf, start_time)
        n = lib.n_vars()
        self.r = np.ctypeslib.as_array(lib.data_r(self.buf), shape=(n,))
        self.i = np.ctypeslib.as_array(lib.data_i(self.buf), shape=(n,))
        for name, value in parameters.items():
            if name == "velocity_source" and isinstance(value, str):  # as the Python model
                self.i[VR[name]] = VELOCITY_SOURCE.value(value)
            elif isinstance(value, str):
                lib.data_set_string(self.buf, VR[name], value.encode())
            elif isinstance(value, (bool, int)):  # Boolean and Integer parameters
                self.i[VR[name]] = int(value)
            else:
                self.r[VR[name]] = value
        self.set_inputs(inputs)
        if lib.data_initialize(self.buf, self.msg):
            raise ModelError(self.msg.value.decode())

    def set_inputs(self, inputs) -> None:
        self.r[VR["q1"] : VR["q1"] + len(INPUTS)] = inputs

    def do_step(self, t: float, h: float, inputs) -> None:
        self.set_inputs(inputs)
        if self.lib.data_step(self.buf, t, h, self.msg):
            raise ModelError(self.msg.value.decode())

    def outputs(self) -> np.ndarray:
        return self.r[VR["tau1"] : VR["tau1"] + len(OUTPUTS)].copy()

    def state(self) -> dict:
        reals = (ctypes.c_double * 14)()
        self.lib.state_reals(self.buf, reals)
        v = list(reals)
        return {
            "t": v[0],
            "start_time": v[1],
            "k_next": self.lib.state_k_next(self.buf),
            "held_input_samples": self.lib.state_held(self.buf),
            "yhat": v[2:5],
            "q_prev": v[5:8],
            "tau_prev": v[8:11],
            "f_prev": v[11:14],
        }


@pytest.fixture(scope="module")
def plant_rows() -> np.ndarray:
    """The controller's inputs at t_i = i / 400 in the paper scenario (20 s): row i holds the
    plant's q1..3, fx, fy, n, qd1..3."""
    r = run_models(stop_time=20.0)
    cols = ["q1", "q2", "q3", "fx", "fy", "n", "qd1", "qd2", "qd3"]
    return np.column_stack([r[f"plant.{c}"] for c in cols])


def run_both(lib, parameters: dict, rows: np.ndarray, h: float, n: int, per_row: float, t0=0.0):
    """Build both models at t0 from row 0, take n steps of h (step j at t0 + j h with row
    int(j * per_row), held between rows); return both output histories (n + 1, 24) and both
    models."""
    u0 = tuple(float(v) for v in rows[0])
    py = ControllerModel(parameters, t0, u0)
    nat = Native(lib, parameters, t0, u0)
    out_py = np.empty((n + 1, len(OUTPUTS)))
    out_nat = np.empty_like(out_py)
    out_py[0], out_nat[0] = py.outputs(), nat.outputs()
    for j in range(n):
        u = tuple(float(v) for v in rows[int(j * per_row)])
        t = t0 + j * h
        py.do_step(t, h, u)
        nat.do_step(t, h, u)
        out_py[j + 1], out_nat[j + 1] = py.outputs(), nat.outputs()
    return out_py, out_nat, py, nat


def assert_same(out_py: np.ndarray, out_nat: np.ndarray, py, nat) -> None:
    """Outputs equal bit for bit at every step, and the final states equal."""
    if not np.array_equal(out_py, out_nat):
        diff = np.abs(out_py - out_nat)
        rel = diff / np.maximum(np.abs(out_py), 1e-300)
        step, col = np.unravel_index(np.argmax(rel), rel.shape)
        pytest.fail(
            f"native != Python: max abs diff {diff.max():.3g}, max rel diff {rel.max():.3g}"
            f" ({OUTPUTS[col]} after step {step}); first differing step"
            f" {np.argmax(np.any(diff != 0.0, axis=1))}"
        )
    s_py, s_nat = py.get_state(), nat.state()
    for key, value in s_nat.items():
        assert value == s_py[key], key


def test_table_matches_python(lib) -> None:
    """config.h's table is the Python table (names, order, start values)."""
    assert lib.n_vars() == len(VARIABLES)
    for k, v in enumerate(VARIABLES):
        assert lib.var_name(k).decode() == v.name
        if isinstance(v.start, float) and not isinstance(v.start, bool):
            assert lib.var_start(k) == v.start, v.name
    assert OUTPUTS == [VARIABLES[VR["tau1"] + k].name for k in range(len(OUTPUTS))]


@pytest.mark.parametrize("source", ["observer", "difference", "measured"])
def test_paper_scenario(lib, plant_rows: np.ndarray, source: str) -> None:
    """20 s of the paper's closed loop, master step = sample period, each velocity source."""
    n = len(plant_rows) - 1
    out_py, out_nat, py, nat = run_both(lib, {"velocity_source": source}, plant_rows, TS, n, 1)
    assert_same(out_py, out_nat, py, nat)
    assert py.k_next == n and py.held_input_samples == 0


@pytest.mark.parametrize("method", ["implicit", "exponential"])
@pytest.mark.parametrize("K", [50.0, 2000.0])
def test_observer_discretizations(lib, plant_rows: np.ndarray, method: str, K: float) -> None:
    """The other observer updates, bit for bit, with the paper's gain and with K Ts = 5 (far
    beyond explicit Euler's K Ts < 2): the estimate stays bounded and near the true velocity."""
    parameters = {"observer_discretization": method, "K1": K, "K2": K, "K3": K}
    n = len(plant_rows) - 1
    out_py, out_nat, py, nat = run_both(lib, parameters, plant_rows, TS, n, 1)
    assert_same(out_py, out_nat, py, nat)
    qd_obs = out_py[1:, OUTPUTS.index("qd_obs1")]
    assert np.abs(qd_obs - plant_rows[:-1, 6]).max() < 0.2  # the truth at the same sample


@pytest.mark.slow
def test_finer_master_step(lib, plant_rows: np.ndarray) -> None:
    """h = Ts / 10: a sample every tenth step, inputs held between the plant's rows."""
    n = (len(plant_rows) - 1) * 10
    out_py, out_nat, py, nat = run_both(lib, {}, plant_rows, TS / 10, n, 0.1)
    assert_same(out_py, out_nat, py, nat)
    assert py.held_input_samples == 0


def test_coarser_master_step(lib, plant_rows: np.ndarray) -> None:
    """h = 4 Ts: samples inside the step reuse the inputs given at its start."""
    n = (len(plant_rows) - 1) // 4
    out_py, out_nat, py, nat = run_both(lib, {}, plant_rows, 4 * TS, n, 4)
    assert_same(out_py, out_nat, py, nat)
    assert py.held_input_samples == 3 * n


def test_start_time_and_odd_step(lib, plant_rows: np.ndarray) -> None:
    """A non-zero start time and a master step that is not a multiple of the sample period."""
    h = 0.0037
    n = 1000
    out_py, out_nat, py, nat = run_both(
        lib, {"velocity_source": "difference"}, plant_rows, h, n, h / TS, t0=1.25
    )
    assert_same(out_py, out_nat, py, nat)


def test_limit_torque(lib, plant_rows: np.ndarray) -> None:
    """Small torque limits: the clipped torque is output and fed to the observer."""
    parameters = {"limit_torque": True, "tau_max1": 5.0, "tau_max2": 2.0, "tau_max3": 0.5}
    n = len(plant_rows) - 1
    out_py, out_nat, py, nat = run_both(lib, parameters, plant_rows, TS, n, 1)
    assert_same(out_py, out_nat, py, nat)
    tau = out_nat[:, :3]
    assert np.any(tau[:, 0] == 5.0) and np.any(tau[:, 0] == -5.0)
    assert np.any(np.abs(tau[:, 1]) == 2.0) and np.any(np.abs(tau[:, 2]) == 0.5)


def test_other_parameters(lib, plant_rows: np.ndarray) -> None:
    """Model mismatch, other gains, a wrapped orientation error and a non-zero yhat0."""
    parameters = {
        "a1": 0.44, "m2": 6.0, "rx3": 0.02, "g": 9.8, "f1": 20.0, "traj_phi": 3.0,
        "traj_f": 0.23, "wall_x": 0.6, "K1": 80.0, "G2": 700.0, "B3": 30.0,
        "sample_period": 0.003, "yhat0_1": 0.1, "yhat0_2": -0.2, "yhat0_3": 0.3,
    }  # fmt: skip
    n = 2000
    out_py, out_nat, py, nat = run_both(lib, parameters, plant_rows, 0.003, n, 0.003 / TS)
    assert_same(out_py, out_nat, py, nat)
    assert np.any(out_nat[:, OUTPUTS.index("e_phi")] < -2.0)  # wrapped past -pi


def test_state_is_plain_data(lib, plant_rows: np.ndarray) -> None:
    """Copying the Data bytes is a complete FMU state: restoring them repeats the run exactly."""
    nat = Native(lib, {}, 0.0, tuple(plant_rows[0]))
    for j in range(500):
        nat.do_step(j * TS, TS, tuple(plant_rows[j]))
    saved = nat.buf.raw

    def run() -> np.ndarray:
        out = []
        for j in range(500, 600):
            nat.do_step(j * TS, TS, tuple(plant_rows[j]))
            out.append(nat.outputs())
        return np.array(out)

    first = run()
    ctypes.memmove(nat.buf, saved, len(saved))
    assert np.array_equal(run(), first)


def model_error(make) -> str:
    with pytest.raises(ModelError) as exc:
        make()
    return str(exc.value)


@pytest.mark.parametrize(
    "parameters",
    [
        {"K2": 0.0},
        {"G1": 0.0},
        {"B3": 0.0},
        {"sample_period": 0.0},
        {"tau_max1": 0.0},
        {"a1": 0.0},
        {"a2": 0.0, "K1": 0.0},
        {"velocity_source": 0},
        {"velocity_source": 4},
        {"velocity_source": -1},
        {"velocity_source": 2**31 - 1},
        {"observer_discretization": "rk4"},
        {"observer_discretization": "it's"},
        {"velocity_source": 0, "observer_discretization": "y"},
    ],
)
def test_bad_parameters(lib, parameters: dict) -> None:
    expected = model_error(lambda: ControllerModel(parameters, 0.0, INPUT_START))
    assert model_error(lambda: Native(lib, parameters, 0.0, INPUT_START)) == expected


def _inputs(**changes) -> tuple:
    u = dict(zip(INPUTS, INPUT_START))
    u.update(changes)
    return tuple(u[name] for name in INPUTS)


@pytest.mark.parametrize(
    ("parameters", "inputs"),
    [
        ({}, _inputs(q1=math.nan)),
        ({}, _inputs(fy=-math.inf)),
        ({"velocity_source": "measured"}, _inputs(qd_meas3=math.inf)),
    ],
)
def test_bad_inputs_at_initialization(lib, parameters: dict, inputs: tuple) -> None:
    expected = model_error(lambda: ControllerModel(parameters, 0.0, inputs))
    assert model_error(lambda: Native(lib, parameters, 0.0, inputs)) == expected


@pytest.mark.parametrize("inputs", [_inputs(q2=0.0), _inputs(q2=-math.pi), _inputs(q2=3e-7)])
def test_a_singular_start_initializes_as_the_python_model(lib, inputs: tuple) -> None:
    """Gravity compensation only at sample 0, the same bits and the same warning (the message
    a successful initialization leaves, which the glue logs)."""
    py = ControllerModel({}, 0.0, inputs)
    nat = Native(lib, {}, 0.0, inputs)
    assert np.array_equal(py.outputs(), nat.outputs())
    assert nat.msg.value.decode() == py.init_warnings[0]
    with pytest.raises(ModelError) as exc:
        py.do_step(0.0, TS, inputs) or py.do_step(TS, TS, inputs)
    nat.do_step(0.0, TS, inputs)
    assert model_error(lambda: nat.do_step(TS, TS, inputs)) == str(exc.value)


def test_unused_measured_velocity_may_be_nan(lib) -> None:
    inputs = _inputs(qd_meas1=math.nan)
    py = ControllerModel({}, 0.0, inputs)
    nat = Native(lib, {}, 0.0, inputs)
    py.do_step(0.0, TS, inputs)
    nat.do_step(0.0, TS, inputs)
    assert np.array_equal(py.outputs(), nat.outputs())


@pytest.mark.parametrize(
    ("t", "h", "inputs"),
    [
        (0.0, 0.0, INPUT_START),
        (0.0, -0.0, INPUT_START),
        (0.0, -1.0, INPUT_START),
        (0.0, -1e-5, INPUT_START),
        (0.0, -1.5e-300, INPUT_START),
        (0.0, -123.456, INPUT_START),
        (0.0, -1e16, INPUT_START),
        (0.0, -1234567890123456.0, INPUT_START),
        (0.0, -0.0001, INPUT_START),
        (0.0, math.nan, INPUT_START),
        (0.0, -math.inf, INPUT_START),
        (0.0, 0.0, _inputs(q3=math.nan)),  # inputs are checked first
        (1.0, TS, INPUT_START),
        (1 / 3, TS, INPUT_START),
        (1e20, TS, INPUT_START),
        (-2.5e-9, TS, INPUT_START),
        (0.0, TS, _inputs(q2=0.0)),
        (0.0, TS, _inputs(n=math.nan)),
    ],
)
def test_bad_steps(lib, t: float, h: float, inputs: tuple) -> None:
    """The same message as Python's, and (as the glue does) nothing changed."""
    py = ControllerModel({}, 0.0, INPUT_START)
    nat = Native(lib, {}, 0.0, INPUT_START)
    py.do_step(0.0, TS, INPUT_START)
    nat.do_step(0.0, TS, INPUT_START)
    t = TS + t
    before = nat.buf.raw
    expected = model_error(lambda: py.do_step(t, h, inputs))
    got = model_error(lambda: nat.do_step(t, h, inputs))
    assert got == expected
    nat.set_inputs(INPUT_START)
    assert nat.buf.raw == before


def test_infinite_step_refused(lib) -> None:
    """Both flavours refuse an infinite communication step with the same message."""
    nat = Native(lib, {}, 0.0, INPUT_START)
    message = "communication step must be finite (got inf)"
    assert model_error(lambda: nat.do_step(0.0, math.inf, INPUT_START)) == message
    py = ControllerModel({}, 0.0, INPUT_START)
    assert model_error(lambda: py.do_step(0.0, math.inf, INPUT_START)) == message


@pytest.mark.parametrize(
    ("n_max", "h", "refused"),
    [(3, 3 * TS, False), (2, 3 * TS, True), (100_000, 1e6, True), (1, 1.5 * TS, True)],
)
def test_work_bound(lib, n_max: int, h: float, refused: bool) -> None:
    """max_samples_per_step: the same boundary and message in both flavours; a refused step
    changes nothing (it is refused before any sample is taken)."""
    params = {"max_samples_per_step": n_max}
    py = ControllerModel(params, 0.0, INPUT_START)
    nat = Native(lib, params, 0.0, INPUT_START)
    py.do_step(0.0, TS, INPUT_START)
    nat.do_step(0.0, TS, INPUT_START)
    before = nat.buf.raw
    if not refused:
        py.do_step(TS, h, INPUT_START)
        nat.do_step(TS, h, INPUT_START)
        assert np.array_equal(py.outputs(), nat.outputs()) and py.k_next == 1 + n_max
        return
    expected = model_error(lambda: py.do_step(TS, h, INPUT_START))
    assert f"would take more than {n_max} samples (parameter max_samples_per_step)" in expected
    assert model_error(lambda: nat.do_step(TS, h, INPUT_START)) == expected
    assert nat.buf.raw == before


def test_state_size(lib) -> None:
    assert lib.state_size() <= 256  # plain data, copied with every FMU state
