"""The FMI 3.0 array edition (fmus/fmi3/arrays/, issue 37): the joint angles `q`, torques `tau`
and wrist force/torque `ft` as Float64 arrays of fixed size 3 (native/src/fmi3_arrays.c,
impedance_cosim/fmi/fmi3_arrays.py). A host on fmpy's FMU3Slave runs the closed loop of the array
plant and array controller and of the scalar edition: the same torques and angles bit for bit.
PaperScenario-fmi3-arrays-ssp2.ssp wires them with SSP 2.0 array connectors; our master moves the
arrays and records the same rows as with PaperScenario-fmi3-ssp2.ssp."""

from __future__ import annotations

import ctypes
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.archive import SspError
from impedance_cosim.cosim.ssp.read import read_ssp

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

DT = 1 / 400
ERROR = 3  # fmi3Error
FMUS = ("PumaPlant.fmu", "ImpedanceController.fmu")
# what the loop moves, per edition: plant outputs -> controller inputs, torques back
SCALAR = {"sensors": ["q1", "q2", "q3", "fx", "fy", "n"], "q": ["q1", "q2", "q3"],
          "tau": ["tau1", "tau2", "tau3"]}  # fmt: skip
ARRAY = {"sensors": ["q", "ft"], "q": ["q"], "tau": ["tau"]}


class Fmu3:
    """An FMI 3.0 Co-Simulation instance under fmpy, its log kept."""

    def __init__(self, path) -> None:
        self.md = read_model_description(str(path))
        self.var = {v.name: v for v in self.md.modelVariables}
        self.log: list[str] = []
        self.fmu = FMU3Slave(guid=self.md.guid, unzipDirectory=extract(str(path)),
                             modelIdentifier=self.md.coSimulation.modelIdentifier)  # fmt: skip
        self.fmu.instantiate(logMessage=lambda _e, _s, _c, m: self.log.append(m.decode()))

    def vrs(self, names: list[str]) -> list[int]:
        return [self.var[n].valueReference for n in names]

    def raw(self, function: str, vrs: list[int], values, n_values: int) -> int:
        array = (ctypes.c_uint32 * len(vrs))(*vrs)
        return self.fmu._functions[function](self.fmu.component, array, len(vrs), values, n_values)


def _closed_loop(folder, parameters: dict, edition: dict) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Seidel at 1/400 s for 2 s (controller first, on the plant's outputs): the
    controller's torques and the plant's measured angles after each step."""
    plant, ctrl = Fmu3(folder / FMUS[0]), Fmu3(folder / FMUS[1])
    for fmu, key in ((plant, "plant"), (ctrl, "controller")):
        fmu.fmu.enterInitializationMode(startTime=0.0)
        for name, value in parameters[key].items():
            getattr(fmu.fmu, f"set{fmu.var[name].type}")(fmu.vrs([name]), [value])
        fmu.fmu.exitInitializationMode()
    sensors, tau = edition["sensors"], edition["tau"]
    qd, qd_meas = ["qd1", "qd2", "qd3"], ["qd_meas1", "qd_meas2", "qd_meas3"]
    torques, angles = [], []
    for i in range(800):
        ctrl.fmu.setFloat64(ctrl.vrs(sensors), plant.fmu.getFloat64(plant.vrs(sensors), 6))
        ctrl.fmu.setFloat64(ctrl.vrs(qd_meas), plant.fmu.getFloat64(plant.vrs(qd)))
        ctrl.fmu.doStep(i * DT, DT)
        torques.append(ctrl.fmu.getFloat64(ctrl.vrs(tau), 3))
        plant.fmu.setFloat64(plant.vrs(tau), torques[-1])
        plant.fmu.doStep(i * DT, DT)
        angles.append(plant.fmu.getFloat64(plant.vrs(edition["q"]), 3))
    for fmu in (plant, ctrl):
        fmu.fmu.terminate()
        fmu.fmu.freeInstance()
    return np.array(torques), np.array(angles)


def test_the_array_edition_gives_the_scalar_torques_and_angles_bit_for_bit(fmu_dir, fmi3_dir):
    parameters = Master(read_ssp(fmu_dir / "PaperScenario-fmi3.ssp"),
                        RunOptions(parameter_set="observer")).parameters  # fmt: skip
    tau_s, q_s = _closed_loop(fmi3_dir, parameters, SCALAR)
    tau_a, q_a = _closed_loop(fmi3_dir / "arrays", parameters, ARRAY)
    assert np.array_equal(tau_a, tau_s) and np.array_equal(q_a, q_s)
    assert np.abs(tau_s).max() > 1.0  # the loop does something


@pytest.mark.parametrize("name", FMUS)
def test_array_variables_are_declared_with_a_fixed_dimension_and_valid(fmi3_dir, name):
    path = fmi3_dir / "arrays" / name
    assert validate_fmu(str(path)) == []
    assert validate_fmu(str(fmi3_dir / name)) == []
    with zipfile.ZipFile(path) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    arrays = {v.get("name"): v for v in root.iter("Float64") if v.find("Dimension") is not None}
    assert set(arrays) == {"q", "ft", "tau"}
    for v in arrays.values():
        assert [d.attrib for d in v.findall("Dimension")] == [{"start": "3"}]
    names = {v.get("name") for v in root.find("ModelVariables")}
    assert not names & {"q1", "q2", "q3", "fx", "fy", "n", "tau1", "tau2", "tau3"}
    assert "providesDirectionalDerivatives" not in root.find("CoSimulation").attrib
    if name == "PumaPlant.fmu":
        assert arrays["tau"].get("start") == "0.0 0.0 0.0"


def test_wrong_n_values_element_references_and_null_arrays_are_refused(fmi3_dir):
    p = Fmu3(fmi3_dir / "arrays" / FMUS[0])
    p.fmu.enterInitializationMode(startTime=0.0)
    p.fmu.exitInitializationMode()
    out = (ctypes.c_double * 8)()
    q, ft, tau = p.vrs(["q"])[0], p.vrs(["ft"])[0], p.vrs(["tau"])[0]
    for vrs, n in (([q], 1), ([q], 4), ([q, ft], 3), ([q, p.vrs(["x"])[0]], 3)):
        assert p.raw("fmi3GetFloat64", vrs, out, n) == ERROR
        assert f"{n} values for {len(vrs)} value references" in p.log[-1]
    assert p.raw("fmi3SetFloat64", [tau], (ctypes.c_double * 2)(1.0, 2.0), 2) == ERROR
    assert "2 values for 1 value references whose variables hold 3 values" in p.log[-1]
    assert p.raw("fmi3GetFloat64", [q + 1], out, 1) == ERROR
    assert f"value reference {q + 1} is an element of the array variable {q}" in p.log[-1]
    assert p.fmu._functions["fmi3GetFloat64"](p.fmu.component, None, 1, None, 3) == ERROR
    assert "NULL array" in p.log[-1]
    # well-formed calls: the time, the angles and the force/torque in one; the torques
    assert p.raw("fmi3GetFloat64", [p.vrs(["time"])[0], q, ft], out, 7) == 0
    assert out[0] == 0.0 and np.all(np.isfinite(out[:7]))
    assert p.raw("fmi3SetFloat64", [tau], (ctypes.c_double * 3)(1.0, 2.0, 3.0), 3) == 0
    assert p.raw("fmi3SetFloat64", [tau], (ctypes.c_double * 3)(1.0, float("nan"), 0.0), 3) == 3
    assert "tau2 is not finite" in p.log[-1]  # the scalar checks, naming the element
    p.fmu.freeInstance()


@pytest.mark.parametrize("name", FMUS)
def test_the_editions_share_their_sources_the_array_one_adds_the_mapping(fmi3_dir, name):
    with zipfile.ZipFile(fmi3_dir / name) as s, zipfile.ZipFile(fmi3_dir / "arrays" / name) as a:
        scalar, array = set(s.namelist()), set(a.namelist())
        assert array - scalar == {"sources/fmi3_arrays.c", "sources/fmi3_arrays.h"}
        for member in scalar & array:
            if member.startswith("sources/") and not member.endswith(
                ("guid.h", "fmi3_config.h", "Description.xml")
            ):
                assert s.read(member) == a.read(member), member
        config = a.read("sources/fmi3_config.h").decode()
        assert config.startswith(s.read("sources/fmi3_config.h").decode())
        assert "#define FMI3_ARRAYS {{" in config
        built = a.read("sources/buildDescription.xml").decode()
        assert "fmi3_arrays.c" in built and "fmi3_values.c" in built


# the array archive's signals that the scalar archive records under the elements' names
ELEMENT_NAMES = {
    **{f"controller.tau[{k}]": f"controller.tau{k}" for k in (1, 2, 3)},
    **{f"plant.q[{k}]": f"plant.q{k}" for k in (1, 2, 3)},
    **{f"plant.ft[{k}]": f"plant.{n}" for k, n in ((1, "fx"), (2, "fy"), (3, "n"))},
}


@pytest.mark.parametrize(
    ("parameter_set", "algorithm"),
    [("observer", "gauss-seidel"), ("measured", "gauss-seidel"), ("difference", "jacobi")],
)
def test_the_array_archive_gives_the_rows_of_the_ssp2_archive_bit_for_bit(
    fmi3_dir, parameter_set, algorithm
):
    runs = []
    for name in ("PaperScenario-fmi3-arrays-ssp2.ssp", "PaperScenario-fmi3-ssp2.ssp"):
        options = RunOptions(parameter_set=parameter_set, algorithm=algorithm, stop_time=2.0)
        runs.append(Master(read_ssp(fmi3_dir.parent / name), options).run())
    arrays, scalars = runs
    assert [ELEMENT_NAMES.get(n, n) for n in arrays.names] == scalars.names
    assert np.array_equal(arrays.data, scalars.data) and len(arrays.data) > 100
    assert arrays.info["loop"] == "python"  # the compiled loop moves scalars only


def test_the_array_archive_validates_and_wires_array_connectors(fmi3_dir):
    from impedance_cosim.packaging.build_ssp2 import validation_problems

    archive = fmi3_dir.parent / "PaperScenario-fmi3-arrays-ssp2.ssp"
    assert validation_problems(archive) == []
    system = read_ssp(archive)
    sizes = {(c.name, k.name): k.size for c in system.components for k in c.connectors.values()}
    assert {key for key, size in sizes.items() if size == 3} == {
        (c, n) for c in ("plant", "controller") for n in ("q", "ft", "tau")
    }
    assert ("plant", "q", "controller", "q") in system.connections
    assert ("controller", "tau", "plant", "tau") in system.connections


def test_an_array_connected_to_another_size_is_refused(fmi3_dir, tmp_path):
    archive = fmi3_dir.parent / "PaperScenario-fmi3-arrays-ssp2.ssp"
    broken = tmp_path / "broken.ssp"
    with zipfile.ZipFile(archive) as zin, zipfile.ZipFile(broken, "w") as zout:
        for name in zin.namelist():
            data = zin.read(name)
            if name.endswith(".ssd"):  # the controller's q (its second array connector q)
                head, tail = data.split(b'name="q" kind="input"', 1)
                tail = tail.replace(b'size="3"', b'size="2"', 1)
                data = head + b'name="q" kind="input"' + tail
            zout.writestr(name, data)
    with pytest.raises(SspError, match=r"connection plant.q -> controller.q: 3 elements -> 2"):
        read_ssp(broken)


def test_run_on_the_array_archive_writes_the_rows_of_the_ssp2_archive(fmi3_dir, tmp_path):
    csv = {}
    for name in ("PaperScenario-fmi3-arrays-ssp2.ssp", "PaperScenario-fmi3-ssp2.ssp"):
        out = tmp_path / name
        args = ["run", "--stop", "2", "--ssp", str(fmi3_dir.parent / name), "--no-report",
                "--out", str(out)]  # fmt: skip
        done = subprocess.run([sys.executable, "-m", "impedance_cosim.cli", *args],
                              capture_output=True, text=True, timeout=300)  # fmt: skip
        assert done.returncode == 0, done.stderr
        csv[name] = {p.name: p.read_text().split("\n", 1) for p in out.glob("*.csv")}
    arrays, scalars = csv.values()
    assert sorted(arrays) == sorted(scalars) and len(arrays) == 4  # the runs of the Fig. 4 pair
    for name, (header, rows) in arrays.items():
        assert rows == scalars[name][1], name
        assert [ELEMENT_NAMES.get(n, n) for n in header.split(",")] == scalars[name][0].split(",")
