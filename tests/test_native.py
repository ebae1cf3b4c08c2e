"""The native (C99) FMUs: standard compliance, agreement with the Python FMUs, a C host with no
Python in the process, FMI API robustness, rebuilding from sources/, and no leaks (valgrind)."""

from __future__ import annotations

import ctypes
import math
import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from c_hosts import build_host, links_and_record
from fmpy import extract, read_model_description
from fmpy.validation import validate_fmu
from fmu_steps import output_names, rows_after

from impedance_cosim.cosim.fmus.fmi2 import FmuError, FmuInstance
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.results.result import read_csv
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.packaging.regression import REFERENCES, compare

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

DT = 1 / 400
PLANT, CONTROLLER = "PumaPlant.fmu", "ImpedanceController.fmu"
HOST = Path(__file__).parent / "c_host" / "host.c"


@pytest.mark.parametrize("name", [PLANT, CONTROLLER])
def test_native_fmu_is_valid_with_sources(native_dir, fmu_dir, name):
    path = native_dir / name
    assert validate_fmu(str(path)) == []
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
    assert f"binaries/linux64/{name[:-4]}.so" in names
    assert "sources/buildDescription.xml" in names and "sources/instance.c" in names
    native, python = (read_model_description(str(p)) for p in (path, fmu_dir / name))
    assert [
        (v.name, v.valueReference, v.causality, v.variability, v.type, v.unit, v.start)
        for v in native.modelVariables
        if v.derivative is None  # Model Exchange's der() variables: native only
    ] == [
        (v.name, v.valueReference, v.causality, v.variability, v.type, v.unit, v.start)
        for v in python.modelVariables
    ]


@pytest.mark.parametrize("name", [PLANT, CONTROLLER])
@pytest.mark.slow
def test_fmpy_simulate_native(native_dir, tmp_path, name):
    out = tmp_path / "out.csv"
    cmd = ["fmpy", "simulate", str(native_dir / name), "--output-interval", "0.0025"]
    subprocess.run([*cmd, "--output-file", str(out)], check=True, timeout=120)
    result = read_csv(out)
    ref_path = next(p for p in REFERENCES if p.name == name.replace(".fmu", "_ref.csv"))
    every_40th = {k: v[::40] for k, v in result.items()}
    assert compare(every_40th, read_csv(ref_path), rtol=1e-9) == []


@pytest.fixture(scope="module")
def both_runs(ssp_path, native_dir, fmu_dir):
    python = Master(read_ssp(ssp_path)).run()
    native = Master(read_ssp(fmu_dir / "PaperScenario-native.ssp")).run()
    assert python.ok and native.ok, (python.error, native.error)
    return python, native


def test_native_equals_python_over_the_paper_scenario(both_runs):
    """Every recorded signal within 1e-9 (relative to its range) over the 20 s scenario."""
    python, native = both_runs
    assert python.names == native.names
    scale = np.abs(python.data).max(axis=0) + 1e-300
    worst = (np.abs(native.data - python.data) / scale).max()
    assert worst <= 1e-9, worst


def test_swapping_flavours_is_a_change_of_file(ssp_path, native_dir):
    system = read_ssp(ssp_path)
    mixed = Master(system, RunOptions(fmu_files={"plant": native_dir / PLANT}, stop_time=1.0)).run()
    pure = Master(system, RunOptions(stop_time=1.0)).run()
    assert mixed.ok and np.allclose(mixed.data, pure.data, rtol=1e-12, atol=1e-12)


def _host(tmp_path: Path) -> Path:
    return build_host(HOST, tmp_path / "host")


def _host_args(native_dir: Path, steps: int, out: Path) -> list[str]:
    """Arguments for the C host: controller (A) and plant (B), the system's connections, the
    signals to record (plant x, y, contact force; controller torques)."""
    args = []
    mds = {}
    for name, fmu in (("controller", CONTROLLER), ("plant", PLANT)):
        md = read_model_description(str(native_dir / fmu))
        unzip = Path(extract(str(native_dir / fmu)))
        mds[name] = {v.name: v.valueReference for v in md.modelVariables}
        lib = unzip / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
        args += [str(lib), md.guid, (unzip / "resources").as_uri()]
    return [*args, str(steps), repr(DT), str(out), *links_and_record(mds)]


def test_c_host_runs_the_closed_loop_without_python(native_dir, tmp_path, both_runs):
    """The native FMUs load and run in a plain C program; the result equals our master's."""
    exe = _host(tmp_path)
    out = tmp_path / "host.csv"
    subprocess.run([str(exe), *_host_args(native_dir, 8000, out)], check=True, timeout=120)
    rows = np.loadtxt(out, delimiter=",")
    _, native = both_runs
    names = ["time", "plant.x", "plant.y", "plant.contact_force",
             *(f"controller.tau{i}" for i in (1, 2, 3))]  # fmt: skip
    expected = np.column_stack([native[n] for n in names])
    assert rows.shape == expected.shape
    assert np.array_equal(rows, expected)
    assert (
        "libpython" not in subprocess.run(["ldd", str(exe)], capture_output=True, text=True).stdout
    )


@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind not installed")
@pytest.mark.slow
def test_no_leaks_under_valgrind(native_dir, tmp_path):
    exe = _host(tmp_path)
    cmd = ["valgrind", "--leak-check=full", "--errors-for-leak-kinds=all", "--error-exitcode=3",
           str(exe), *_host_args(native_dir, 8000, tmp_path / "v.csv")]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "All heap blocks were freed" in done.stderr


@pytest.mark.slow
def test_rebuild_from_sources_with_fmpy(native_dir, tmp_path):
    """Tools can rebuild the binary from sources/ (fmpy's compile support, CMake)."""
    pytest.importorskip("cmake")
    from fmpy.build import build_platform_binary

    unzip = tmp_path / "plant"
    with zipfile.ZipFile(native_dir / PLANT) as z:
        z.extractall(unzip)
    (unzip / "binaries" / "linux64" / "PumaPlant.so").unlink()
    (tmp_path / "build").mkdir()
    build_platform_binary(unzip, build_dir=tmp_path / "build")
    assert (unzip / "binaries" / "linux64" / "PumaPlant.so").is_file()
    result = fmpy.simulate_fmu(str(unzip), stop_time=1.0, output_interval=DT)
    assert result["y"][-1] < 0.0  # the unpowered arm falls


# --- FMI API robustness (through fmpy's ctypes bindings and FmuInstance) --------------------


def _instance(native_dir, name=PLANT, **params) -> FmuInstance:
    fmu = FmuInstance(native_dir / name, "r")
    fmu.setup(0.0)
    fmu.set(params)
    return fmu


def _status(fmu: FmuInstance, function: str, *args) -> int:
    return fmu.slave._functions[function](fmu.slave.component, *args)


def test_calls_in_the_wrong_order_are_errors(native_dir):
    fmu = _instance(native_dir)
    assert _status(fmu, "fmi2DoStep", 0.0, DT, 1) == 3  # before initialization
    assert "fmi2DoStep cannot be called in instantiated" in fmu.errors()[-1]
    fmu.enter_initialization()
    fmu.exit_initialization()
    fmu.step(0.0, DT)
    with pytest.raises(FmuError, match="cannot be set after initialization"):
        fmu.set({"m1": 2.0})
    fmu.terminate()
    with pytest.raises(FmuError, match="fmi2SetReal cannot be called in terminated"):
        fmu.set({"tau1": 1.0})
    assert _status(fmu, "fmi2DoStep", DT, DT, 1) == 3
    fmu.free()


@pytest.mark.parametrize(
    "values,message",
    [
        ({"tau2": math.nan}, "input tau2 is not finite"),
        ({"tau1": math.inf}, "input tau1 is not finite"),
        ({"m2": -1.0}, "parameter m2 must be >= 0"),
        ({"wall_k": math.nan}, "parameter wall_k must be finite"),
        ({"q_noise": -1e-3}, "parameter q_noise must be >= 0"),
    ],
)
def test_bad_values_are_refused_when_set(native_dir, values, message):
    fmu = _instance(native_dir)
    with pytest.raises(FmuError, match=message):
        fmu.set(values)
    fmu.free()


@pytest.mark.parametrize(
    "name,params,message",
    [
        (PLANT, {"x0": 1.5}, "unreachable"),
        (PLANT, {"a1": 0.0}, "link lengths a1, a2 must be > 0"),
        (CONTROLLER, {"K2": 0.0}, "parameter K2 must be > 0"),
        (CONTROLLER, {"velocity_source": 7}, "velocity_source must be one of"),
    ],
)
def test_bad_configurations_fail_initialization(native_dir, name, params, message):
    fmu = _instance(native_dir, name, **params)
    fmu.enter_initialization()
    with pytest.raises(FmuError, match=message):
        fmu.exit_initialization()
    fmu.free()


def test_unknown_value_references_and_types(native_dir):
    fmu = _instance(native_dir)
    fmu.enter_initialization()
    vr = (ctypes.c_uint * 1)(9999)
    value = (ctypes.c_double * 1)()
    assert _status(fmu, "fmi2GetReal", vr, 1, value) == 3
    assert "unknown value reference 9999" in fmu.errors()[-1]
    vr[0] = fmu.vr("elbow_up")
    assert _status(fmu, "fmi2GetReal", vr, 1, value) == 3
    assert "not of type Real" in fmu.errors()[-1]
    vr[0] = fmu.vr("x")
    assert _status(fmu, "fmi2SetReal", vr, 1, value) == 3
    assert "is an output" in fmu.errors()[-1]
    fmu.free()


def test_state_restore_and_serialization(native_dir):
    fmu = _instance(native_dir, q_noise=1e-4)
    fmu.enter_initialization()
    fmu.exit_initialization()
    fmu.set({"tau1": 30.0, "tau2": 20.0})
    for i in range(40):
        fmu.step(i * DT, DT)
    state = fmu.get_state()
    blob = fmu.serialize_state(state)
    outputs = output_names(fmu)

    first = rows_after(fmu, outputs)
    fmu.set_state(state)
    assert rows_after(fmu, outputs) == first
    fmu.set_state(fmu.deserialize_state(blob))
    assert rows_after(fmu, outputs) == first
    with pytest.raises(FmuError, match="serialized state"):
        fmu.deserialize_state(blob[:-8])
    fmu.free_state(state)
    fmu.free()


def test_instantiate_and_free_many_times(native_dir):
    for k in range(300):
        fmu = _instance(native_dir, PLANT, x0=0.3 + 1e-4 * (k % 10))
        fmu.enter_initialization()
        fmu.exit_initialization()
        fmu.step(0.0, DT)
        assert fmu.get(["x"])[0] == pytest.approx(0.3 + 1e-4 * (k % 10), abs=1e-4)
        fmu.free()


def test_wrong_guid_is_refused(native_dir):
    md = read_model_description(str(native_dir / PLANT))
    from fmpy.fmi2 import FMU2Slave

    slave = FMU2Slave(
        guid="{00000000-0000-0000-0000-000000000000}",
        unzipDirectory=extract(str(native_dir / PLANT)),
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName="g",
    )
    with pytest.raises(Exception, match="instantiate"):
        slave.instantiate()
