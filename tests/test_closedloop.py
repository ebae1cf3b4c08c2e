"""The paper's closed loop as one FMU (PaperClosedLoop-<scenario>.fmu, FMI 2.0 and 3.0): every
output equals our master's Gauss-Seidel run of the same scenario on the two native FMUs, row for
row over the paper's 20 s; the parameters reach the parts; it validates, runs under `fmpy
simulate` on its own, and (when IMPCOSIM_FMUCHECK names the binary) passes the FMU Compliance
Checker."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import benchmark_module
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from controller_model.model import ControllerModel
from impedance_cosim.cosim.fmus.fmi2 import FmuError
from impedance_cosim.cosim.fmus.fmi3 import open_fmu
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.cosim.system.paper import SCENARIOS
from impedance_cosim.packaging.build_all import build_all
from impedance_cosim.packaging.closedloop import fmu_name
from plant_model.model import PlantModel

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

H = 1 / 400
run_alone = benchmark_module(
    "closedloop_speed"
).run_alone  # the FMU stepped alone, rows of names at each t_i
FLOOR = 1e-9  # the bound; measured: 0.0 on every output (difference 0)
N_OUTPUTS = sum(
    v.causality == "output" for m in (PlantModel, ControllerModel) for v in m.variables()
)


@pytest.fixture(scope="module")
def closed_loops(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The closed-loop FMUs of every scenario, FMI 2.0 in native/, FMI 3.0 in fmi3/ (a folder of
    their own: other tests count the session's FMUs)."""
    out = tmp_path_factory.mktemp("closedloop")
    built = build_all(out, only=["closedloop"])  # as `impedance-cosim build --only closedloop`
    expected = [path_of(out, fmi, s) for fmi in (2, 3) for s in SCENARIOS]
    assert sorted(built) == sorted(expected)
    return out


def path_of(folder: Path, fmi: int, scenario: str) -> Path:
    return folder / ("native" if fmi == 2 else "fmi3") / f"{fmu_name(scenario)}.fmu"


def master_run(native_ssp: Path, scenario: str, stop: float, overrides=None):
    with read_ssp(native_ssp) as system:
        result = Master(
            system,
            RunOptions(
                parameter_set=scenario,
                algorithm="gauss-seidel",
                stop_time=stop,
                overrides=overrides,
            ),
        ).run()
    assert result.error is None, result.error
    return result


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_equals_the_masters_gauss_seidel_run(closed_loops, native_ssp, scenario, fmi):
    """20 s, every output of both parts, difference 0 (<= 1e-9) to the master's rows."""
    reference = master_run(native_ssp, scenario, 20.0)
    names = reference.names[1:]
    assert len(names) == N_OUTPUTS
    rows = run_alone(path_of(closed_loops, fmi, scenario), names, 20.0)
    assert rows.shape == reference.data[:, 1:].shape
    assert reference["plant.contact_force"].max() > 1.0  # the arm did meet the wall
    worst = np.abs(rows - reference.data[:, 1:]).max(axis=0)
    print(f"{scenario} FMI {fmi}: largest difference {worst.max():.3g} ({names[worst.argmax()]})")
    assert worst.max() <= FLOOR, names[worst.argmax()]


@pytest.mark.parametrize("fmi", [2, 3])
def test_parameters_reach_the_parts(closed_loops, native_ssp, fmi):
    """A parameter of each part set on the closed loop acts as on the part's own FMU."""
    overrides = {"controller.G1": 2000.0, "plant.wall_k": 2.0e4}
    reference = master_run(native_ssp, "observer", 4.5, overrides)
    default = master_run(native_ssp, "observer", 4.5)
    names = reference.names[1:]
    rows = run_alone(path_of(closed_loops, fmi, "observer"), names, 4.5, parameters=overrides)
    assert np.abs(reference.data[:, 1:] - default.data[:, 1:]).max() > 1e-3  # they do matter
    assert np.abs(rows - reference.data[:, 1:]).max() <= FLOOR


def test_a_long_communication_step_is_cut_at_the_samples(closed_loops, native_ssp):
    """A host step of 4 sample periods gives the rows of the 400 Hz loop at its points."""
    reference = master_run(native_ssp, "observer", 5.0)
    names = reference.names[1:]
    rows = run_alone(path_of(closed_loops, 2, "observer"), names, 5.0, h=4 * H)
    scale = np.abs(reference.data[::4, 1:]).max(axis=0) + 1e-300
    assert (np.abs(rows - reference.data[::4, 1:]) / scale).max() <= 1e-9


def test_tunable_between_steps_fixed_refused(closed_loops):
    """The parts' tunable parameters stay tunable; a fixed one is refused after initialization."""
    md = read_model_description(str(path_of(closed_loops, 2, "observer")))
    kinds = {v.name: v.variability for v in md.modelVariables}
    assert kinds["controller.G1"] == "tunable" and kinds["plant.wall_k"] == "fixed"
    assert md.variableNamingConvention == "structured"
    inst = open_fmu(path_of(closed_loops, 2, "observer"), "loop")
    try:
        inst.setup(0.0, 1.0)
        inst.enter_initialization()
        inst.exit_initialization()
        inst.step(0.0, H)
        inst.set({"controller.G1": 1500.0})
        with pytest.raises(FmuError, match="wall_k"):
            inst.set({"plant.wall_k": 1.0})
    finally:
        inst.free()


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.slow
def test_validates_and_runs_under_fmpy_simulate(closed_loops, fmi, tmp_path):
    fmu = path_of(closed_loops, fmi, "observer")
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    assert [i for i in md.modelVariables if i.causality == "input"] == []
    if fmi == 3:
        assert float(md.coSimulation.fixedInternalStepSize) == H
    out = tmp_path / "out.csv"
    done = subprocess.run(
        [str(Path(sys.executable).parent / "fmpy"), "simulate", str(fmu), "--stop-time", "2",
         "--output-interval", "0.0025", "--output-file", str(out)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert len(out.read_text().splitlines()) == 1 + 801


FMUCHECK = os.environ.get("IMPCOSIM_FMUCHECK")


@pytest.mark.skipif(not FMUCHECK, reason="IMPCOSIM_FMUCHECK does not name the checker binary")
@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_fmu_compliance_checker_reports_nothing(closed_loops, scenario, tmp_path):
    """modelica-tools/FMUComplianceChecker: 0 warnings and 0 errors (FMI 2.0)."""
    fmu = path_of(closed_loops, 2, scenario)
    done = subprocess.run(
        [FMUCHECK, "-h", "0.0025", "-s", "2", "-o", str(tmp_path / "out.csv"),
         "-t", str(tmp_path), str(fmu)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    report = done.stdout + done.stderr
    assert done.returncode == 0, report[-3000:]
    assert re.search(r"FMU reported:\s+0 warning\(s\) and error\(s\)", report), report[-3000:]
    assert re.search(r"Checker reported:\s+0 Warning\(s\)\s+0 Error\(s\)", report), report[-3000:]


@pytest.mark.parametrize("fmi", [2, 3])
def test_a_serialized_state_resumes_the_same_rows(closed_loops, fmi):
    """Both parts travel in the closed loop's FMU state: rows after restoring a serialized state
    (taken in contact, at 4 s) equal the uninterrupted run's; a flipped byte is refused."""
    names = ["plant.x", "plant.contact_force", "controller.tau1", "controller.xd_hat"]
    inst = open_fmu(path_of(closed_loops, fmi, "observer"), "loop")
    try:
        inst.setup(0.0, 5.0)
        inst.enter_initialization()
        inst.exit_initialization()
        read = inst.real_getter(names)
        for i in range(1600):
            inst.step(i * H, H)
        state = inst.get_state()
        data = inst.serialize_state(state)
        inst.free_state(state)
        first = []
        for i in range(1600, 1800):
            inst.step(i * H, H)
            first.append(read())
        restored = inst.deserialize_state(data)
        inst.set_state(restored)
        inst.free_state(restored)
        again = []
        for i in range(1600, 1800):
            inst.step(i * H, H)
            again.append(read())
        bad = bytearray(data)
        bad[len(bad) // 2] ^= 0x10
        with pytest.raises(FmuError):
            inst.deserialize_state(bytes(bad))
    finally:
        inst.free()
    assert max(r[1] for r in first) > 1.0  # in contact with the wall
    assert again == first


@pytest.mark.parametrize("fmi", [2, 3])
def test_fmpy_simulate_with_only_the_default_experiment(closed_loops, fmi, tmp_path):
    """`fmpy simulate FMU`, no options: the default experiment (20 s; fmpy coarsens the step to
    keep 1000 points, so every host step spans several samples)."""
    out = tmp_path / "out.csv"
    fmpy_cli = str(Path(sys.executable).parent / "fmpy")
    fmu = str(path_of(closed_loops, fmi, "observer"))
    done = subprocess.run([fmpy_cli, "simulate", fmu, "--output-file", str(out)],
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    rows = np.genfromtxt(out, delimiter=",", names=True)
    assert rows["time"][-1] == pytest.approx(20.0)
    assert rows["plantcontact_force"].max() > 50.0  # the impact peak (88 N at 400 Hz)


def test_the_parts_compose_through_one_table_and_rename_nothing():
    """native/closedloop: the two models are compiled unchanged, their model API static in each
    part's translation unit (MODEL_LINKAGE), and used through one Part table each; no macro
    renames a model's function or table."""
    folder = Path(__file__).resolve().parents[1] / "native" / "closedloop"
    for path in sorted(folder.glob("*.[ch]")):
        text = path.read_text()
        assert not re.search(r"#define\s+(model_\w+|N?_?MODEL_STATE_REALS)\b", text), path.name
    assert "const Part PART_TABLE" in (folder / "part_api.h").read_text()


def test_model_exchange_is_not_offered(closed_loops):
    """Co-simulation only: no ModelExchange element, and an ME instantiation is refused."""
    from fmpy import extract
    from fmpy.fmi2 import FMU2Model

    fmu = path_of(closed_loops, 2, "observer")
    md = read_model_description(str(fmu))
    assert md.modelExchange is None
    identifier = md.coSimulation.modelIdentifier
    model = FMU2Model(guid=md.guid, unzipDirectory=extract(str(fmu)),
                      modelIdentifier=identifier, instanceName="me")  # fmt: skip
    with pytest.raises(Exception, match="nstantiate"):
        model.instantiate()


def test_a_bad_parameter_is_refused_naming_it(closed_loops):
    inst = open_fmu(path_of(closed_loops, 2, "observer"), "loop")
    try:
        with pytest.raises(FmuError, match=r"plant\.a1 must be >= 0"):
            inst.set({"plant.a1": -1.0})
    finally:
        inst.free()


def test_a_refused_step_leaves_the_loop_at_its_start(closed_loops, native_ssp):
    """A host step over more samples than controller.max_samples_per_step is refused (one line
    naming the parameter) and changes nothing: stepping on gives the master's rows."""
    reference = master_run(native_ssp, "observer", 1.0)
    names = reference.names[1:]
    inst = open_fmu(path_of(closed_loops, 2, "observer"), "loop")
    try:
        inst.setup(0.0, 1.0)
        inst.set({"controller.max_samples_per_step": 10})
        inst.enter_initialization()
        inst.exit_initialization()
        read = inst.real_getter(names)
        rows = [read()]
        with pytest.raises(FmuError, match="max_samples_per_step"):
            inst.step(0.0, 1.0)
        for i in range(400):
            inst.step(i * H, H)
            rows.append(read())
    finally:
        inst.free()
    assert np.abs(np.array(rows) - reference.data[:, 1:]).max() <= FLOOR


@pytest.mark.parametrize("fmi", [2, 3])
def test_a_step_whose_outputs_overflow_is_refused(closed_loops: Path, fmi: int):
    """fuzz target `closedloop_params` (fuzz/corpus/closedloop_params/nan-output-huge-gain):
    controller.K1 = 2**960 with limit_torque made an output NaN within 7 steps that all returned
    OK. Now the step whose outputs would not be finite is refused, naming the output."""
    with pytest.raises(
        FmuError,
        match=r"t=0.005 returned Discard .*output controller.qd_hat1 is not finite \(nan\)",
    ):
        run_alone(
            path_of(closed_loops, fmi, "observer"),
            ["plant.x"],
            8 * H,
            parameters={"controller.K1": 2.0**960, "controller.limit_torque": True},
        )
