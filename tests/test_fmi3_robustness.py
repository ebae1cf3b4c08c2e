"""Robustness of the FMI 3.0 native FMUs, as test_native.py checks the FMI 2.0 ones: calls in the
wrong order, non-finite and out-of-range values, malformed calls (nValues, NULL, unknown or
read-only variables, wrong types), FMU states from outside, interfaces the FMU does not offer; a
C host with no Python in the process (its result equals our master's) and valgrind on it."""

from __future__ import annotations

import ctypes
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from c_hosts import build_host, links_and_record
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Model, FMU3ScheduledExecution, FMU3Slave

from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.packaging.build_fmi3 import CLOCKED_NAME

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

DT = 1 / 400
PLANT, CONTROLLER, CLOCKED = "PumaPlant.fmu", "ImpedanceController.fmu", f"{CLOCKED_NAME}.fmu"
HOST = Path(__file__).parent / "c_host" / "host3.c"
FREE_IN_UPDATE = Path(__file__).parent / "c_host" / "free_in_update.c"
ERROR = 3  # fmi3Error


class Fmu3:
    """A raw FMI 3.0 instance (fmpy's bindings) with its log kept and statuses returned."""

    def __init__(self, path: Path, cls=FMU3Slave, **instantiate) -> None:
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.log: list[str] = []
        interface = self.md.coSimulation or self.md.scheduledExecution
        self.fmu = cls(
            guid=self.md.guid,
            unzipDirectory=extract(str(path)),
            modelIdentifier=interface.modelIdentifier,
            instanceName="r",
        )
        self.fmu.instantiate(logMessage=self._log, **instantiate)
        self.c = self.fmu.component

    def _log(self, _env, _status, _category, message) -> None:
        self.log.append(message.decode())

    def raw(self, function: str, *args) -> int:
        return self.fmu._functions[function](self.c, *args)

    def set64(self, names_values: dict, n_values: int | None = None) -> int:
        n = len(names_values)
        vrs = (ctypes.c_uint32 * n)(*(self.vr[k] for k in names_values))
        vals = (ctypes.c_double * n)(*names_values.values())
        return self.raw("fmi3SetFloat64", vrs, n, vals, n if n_values is None else n_values)

    def get64(self, names: list[str], n_values: int | None = None) -> tuple[int, list[float]]:
        n = len(names)
        vrs = (ctypes.c_uint32 * n)(*(self.vr[k] for k in names))
        vals = (ctypes.c_double * n)()
        status = self.raw("fmi3GetFloat64", vrs, n, vals, n if n_values is None else n_values)
        return status, list(vals)

    def init(self) -> None:
        self.fmu.enterInitializationMode(startTime=0.0)
        self.fmu.exitInitializationMode()

    def step(self, t: float, h: float = DT) -> int:
        flags = [ctypes.c_bool() for _ in range(3)]
        last = ctypes.c_double()
        return self.raw("fmi3DoStep", t, h, True, *(ctypes.byref(f) for f in flags),
                        ctypes.byref(last))  # fmt: skip

    def close(self) -> None:
        self.fmu.freeInstance()


def test_calls_in_the_wrong_order_are_errors(fmi3_dir):
    p = Fmu3(fmi3_dir / PLANT)
    assert p.step(0.0) == ERROR
    assert "fmi3DoStep called in Instantiated" in p.log[-1]
    assert p.get64(["x"])[0] == ERROR  # nothing to read before initialization mode
    p.fmu.enterInitializationMode(startTime=0.0)
    assert p.raw("fmi3EnterInitializationMode", False, 0.0, 0.0, False, 0.0) == ERROR
    assert "fmi3EnterInitializationMode called in Initialization Mode" in p.log[-1]
    p.fmu.exitInitializationMode()
    assert p.raw("fmi3EnterEventMode") == ERROR  # co-simulation without event mode
    assert p.raw("fmi3EnterStepMode") == ERROR
    assert p.set64({"m1": 2.0}) == ERROR and "cannot be set after initialization" in p.log[-1]
    assert p.step(0.0) == 0
    p.fmu.terminate()
    assert p.step(DT) == ERROR
    p.close()


def test_bad_values_are_refused_and_messages_name_them(fmi3_dir):
    p = Fmu3(fmi3_dir / PLANT)
    p.fmu.enterInitializationMode(startTime=0.0)
    assert p.set64({"m2": -1.0}) == ERROR and "m2 must be >= 0" in p.log[-1]
    assert p.set64({"tau1": float("nan")}) == ERROR and "tau1 is not finite" in p.log[-1]
    assert p.set64({"time": 1.0}) == ERROR and "independent variable" in p.log[-1]
    assert p.set64({"tau1": 1.0}, n_values=2) == ERROR and "every variable is a scalar" in p.log[-1]
    vals = (ctypes.c_int32 * 1)()
    vrs = (ctypes.c_uint32 * 1)(p.vr["tau1"])
    assert p.raw("fmi3GetInt32", vrs, 1, vals, 1) == ERROR
    assert "is not of type Int32" in p.log[-1] and "fmi2" not in p.log[-1]
    vrs = (ctypes.c_uint32 * 1)(10_000)
    assert p.raw("fmi3GetFloat64", vrs, 1, (ctypes.c_double * 1)(), 1) == ERROR
    assert "10000" in p.log[-1]
    assert p.raw("fmi3GetFloat64", None, 1, None, 1) == ERROR and "NULL" in p.log[-1]
    p.fmu.exitInitializationMode()
    status, (t, q1) = p.get64(["time", "q1"])
    assert status == 0 and t == 0.0 and np.isfinite(q1)
    assert p.step(0.0) == 0 and p.get64(["time"])[1] == [DT]
    assert p.step(DT, float("inf")) == 2  # fmi3Discard: the step is refused, state unchanged
    assert p.get64(["time"])[1] == [DT]
    p.close()


def test_state_round_trip_and_hostile_states(fmi3_dir):
    p = Fmu3(fmi3_dir / PLANT)
    p.init()
    p.set64({"tau1": 30.0})
    for i in range(4):
        assert p.step(i * DT) == 0
    state = p.fmu.getFMUState()
    data = p.fmu.serializeFMUState(state)
    before = p.get64(["q1_true", "qd1", "time"])[1]
    for i in range(4, 8):
        p.step(i * DT)
    assert p.get64(["q1_true"])[1] != before[:1]
    restored = p.fmu.deserializeFMUState(data)
    p.fmu.setFMUState(restored)
    assert p.get64(["q1_true", "qd1", "time"])[1] == before
    out = ctypes.c_void_p()
    for bad in (data[:-1], b"\0" * len(data), data[:8] + b"\xff" * (len(data) - 8)):
        buf = (ctypes.c_uint8 * len(bad)).from_buffer_copy(bad)
        assert p.raw("fmi3DeserializeFMUState", buf, len(bad), ctypes.byref(out)) == ERROR
    c = Fmu3(fmi3_dir / CONTROLLER)
    c.init()
    foreign = c.fmu.serializeFMUState(c.fmu.getFMUState())
    buf = (ctypes.c_uint8 * len(foreign)).from_buffer_copy(foreign)
    assert p.raw("fmi3DeserializeFMUState", buf, len(foreign), ctypes.byref(out)) == ERROR
    assert "serialized state" in p.log[-1]
    for fmu in (p, c):
        fmu.close()


def test_interfaces_not_offered_are_refused(fmi3_dir):
    with pytest.raises(Exception, match="instantiate"):
        Fmu3(fmi3_dir / PLANT, cls=FMU3ScheduledExecution)  # the plant has no clock
    c = Fmu3(fmi3_dir / CLOCKED, cls=FMU3ScheduledExecution)
    clock = c.vr["sample_clock"]
    assert c.raw("fmi3ActivateModelPartition", clock, 0.0) == ERROR  # before initialization
    c.init()
    assert c.raw("fmi3ActivateModelPartition", clock + 1, 0.0) == ERROR
    assert c.raw("fmi3ActivateModelPartition", clock, float("nan")) == ERROR
    assert c.raw("fmi3ActivateModelPartition", clock, 0.0) == 0
    assert c.raw("fmi3ActivateModelPartition", clock, -DT) == ERROR  # time going back
    assert c.step(0.0) == ERROR and "called in Clock Activation Mode" in c.log[-1]
    c.close()
    me = Fmu3(fmi3_dir / PLANT, cls=FMU3Model)
    me.init()
    assert me.step(0.0) == ERROR
    n = ctypes.c_size_t()
    assert me.raw("fmi3GetNumberOfContinuousStates", ctypes.byref(n)) == 0 and n.value == 6
    assert me.raw("fmi3GetNumberOfEventIndicators", ctypes.byref(n)) == 0 and n.value == 1
    status, (z,) = me.get64(["event_indicator1"])
    z_api = (ctypes.c_double * 1)()
    assert status == 0 and me.raw("fmi3GetEventIndicators", z_api, 1) == 0 and z == z_api[0]
    me.close()


# --- a C host, and valgrind ----------------------------------------------------------------


def _host(tmp_path: Path) -> Path:
    return build_host(HOST, tmp_path / "host3")


def _host_args(fmi3_dir: Path, steps: int, out: Path) -> list[str]:
    args, vrs = [], {}
    for name, fmu in (("controller", CONTROLLER), ("plant", PLANT)):
        md = read_model_description(str(fmi3_dir / fmu))
        unzip = Path(extract(str(fmi3_dir / fmu)))
        vrs[name] = {v.name: v.valueReference for v in md.modelVariables}
        args += [str(unzip / "binaries" / "x86_64-linux" / f"{md.coSimulation.modelIdentifier}.so"),
                 md.guid]  # fmt: skip
    return [*args, str(steps), "1/400", str(out), *links_and_record(vrs)]


def test_c_host_runs_fmi3_closed_loop_as_our_master(fmu_dir, fmi3_dir, tmp_path):
    """4 s (through the first wall contact) in a plain C FMI 3.0 host, FMU states round-tripped
    through serialization half-way: the same numbers as our master's FMI 3.0 run."""
    out = tmp_path / "host.csv"
    steps = 1600
    subprocess.run([str(_host(tmp_path)), *_host_args(fmi3_dir, steps, out)], check=True,
                   timeout=120)  # fmt: skip
    rows = np.loadtxt(out, delimiter=",")
    run = Master(
        read_ssp(fmu_dir / "PaperScenario-fmi3.ssp"), RunOptions(stop_time=steps * DT)
    ).run()
    assert run.ok, run.error
    names = ["time", "plant.x", "plant.y", "plant.contact_force",
             *(f"controller.tau{i}" for i in (1, 2, 3))]  # fmt: skip
    assert np.array_equal(rows, np.column_stack([run[n] for n in names]))
    assert run["plant.contact_force"].max() > 1.0


@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind not installed")
@pytest.mark.slow
def test_fmi3_no_leaks_under_valgrind(fmi3_dir, tmp_path):
    cmd = ["valgrind", "--leak-check=full", "--errors-for-leak-kinds=all", "--error-exitcode=3",
           str(_host(tmp_path)), *_host_args(fmi3_dir, 1600, tmp_path / "v.csv")]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "All heap blocks were freed" in done.stderr
    assert "ERROR SUMMARY: 0 errors" in done.stderr


def _free_in_update(fmi3_dir: Path, tmp_path: Path) -> list[str]:
    """The C host of free_in_update.c, built, and its arguments for the FMI 3.0 plant."""
    exe = build_host(FREE_IN_UPDATE, tmp_path / "free_in_update", "-O0", "-g")
    md = read_model_description(str(fmi3_dir / PLANT))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    lib = Path(extract(str(fmi3_dir / PLANT))) / "binaries" / "x86_64-linux" / "PumaPlant.so"
    return [str(exe), str(lib), md.guid, str(vr["tau2"]), str(vr["x"])]


def _check_free_in_update(out: str) -> None:
    """Each fmi3FreeInstance in the callback refused with a message; the steps went on."""
    calls = int(out.split("callbacks=")[1].split()[0])
    assert calls >= 2, out  # the wrist closes and opens contact in the 2 s step
    assert "step=0 get=0 step_after=0" in out, out
    refusals = out.count("fmi3FreeInstance called in Intermediate Update Mode")
    assert refusals == calls, out


def test_free_instance_inside_the_intermediate_update_is_refused(fmi3_dir, tmp_path):
    """Issue 34: fmi3FreeInstance from inside the callback freed the instance, and fmi3DoStep
    then read the freed block. Refused now, the instance steps on and frees at the end."""
    done = subprocess.run(_free_in_update(fmi3_dir, tmp_path), capture_output=True, text=True,
                          timeout=120)  # fmt: skip
    assert done.returncode == 0, done.stderr
    _check_free_in_update(done.stdout)


@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind not installed")
@pytest.mark.slow
def test_free_instance_inside_the_intermediate_update_under_valgrind(fmi3_dir, tmp_path):
    """The same under valgrind: no invalid read (of the freed instance), nothing leaked."""
    cmd = ["valgrind", "--leak-check=full", "--errors-for-leak-kinds=definite",
           "--error-exitcode=3", *_free_in_update(fmi3_dir, tmp_path)]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Invalid read" not in done.stderr and "ERROR SUMMARY: 0 errors" in done.stderr
    _check_free_in_update(done.stdout)


def test_tunable_gains_change_after_initialization_fixed_parameters_do_not(fmi3_dir):
    """The controller's gains are tunable in its FMI 3.0 modelDescription too (issue 12's
    tables): set in step mode they are taken; a fixed parameter is refused with its name."""
    c = Fmu3(fmi3_dir / CONTROLLER)
    assert {v.name: v.variability for v in c.md.modelVariables}["K1"] == "tunable"
    c.init()
    assert c.step(0.0) == 0
    assert c.set64({"K1": 80.0}) == 0 and c.get64(["K1"])[1] == [80.0]
    assert c.set64({"sample_period": 0.001}) == ERROR and "sample_period is fixed" in c.log[-1]
    assert c.step(DT) == 0
    c.close()
