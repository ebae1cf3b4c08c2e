"""The FMI 3.0 edition of the native FMUs (native/src/fmi3_glue.c,
impedance_cosim/packaging/build_fmi3.py): standard compliance, the same interface as the FMI 2.0
FMUs, our master on the FMI 3 system archive equal to the FMI 2 run, fmpy simulate (Co-Simulation
and Model Exchange), and the clocked controller under Scheduled Execution."""

from __future__ import annotations

import ctypes
import json
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi3 import FMU3ScheduledExecution, FMU3Slave
from fmpy.validation import validate_fmu

from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.results.result import read_csv
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.cosim.system.paper import CONNECTIONS
from impedance_cosim.packaging import toolchains
from impedance_cosim.packaging.build_fmi3 import CLOCKED_NAME
from impedance_cosim.packaging.regression import REFERENCES, compare

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

DT = 1 / 400
PLANT, CONTROLLER, CLOCKED = "PumaPlant.fmu", "ImpedanceController.fmu", f"{CLOCKED_NAME}.fmu"
FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}
SCENARIOS = ("observer", "difference", "measured")


def _root(path) -> ET.Element:
    with zipfile.ZipFile(path) as z:
        return ET.fromstring(z.read("modelDescription.xml"))


@pytest.mark.parametrize("name", [PLANT, CONTROLLER, CLOCKED])
def test_fmi3_fmu_is_valid_with_platforms_sources_and_documentation(fmi3_dir, name):
    path = fmi3_dir / name
    assert validate_fmu(str(path)) == []
    root = _root(path)
    assert root.get("fmiVersion") == "3.0"
    identifier = "ImpedanceController" if name == CLOCKED else name[:-4]
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
        build = ET.fromstring(z.read("sources/buildDescription.xml"))
    for tc in toolchains.TOOLCHAINS:
        if tc.platform == "linux64" or tc.problem() is None:
            folder = toolchains.FMI3_PLATFORMS[tc.platform]
            assert f"binaries/{folder}/{identifier}{tc.suffix}" in names
    assert not any(n.startswith(("binaries/linux64", "binaries/win64")) for n in names)
    assert {"documentation/index.html", "documentation/licenses/license.txt"} <= names
    compiled = [f.get("name") for f in build.iter("SourceFile")]
    # the FMI 3.0 glue and the instance core, each its own translation unit; no FMI 2.0 glue
    assert {"fmi3_glue.c", "instance.c", "instance_me.c"} <= set(compiled)
    assert {"sources/instance.c", "sources/fmi3Functions.h"} <= names
    assert not {"sources/fmi2_glue.c", "sources/fmi2_me.c"} & names
    with zipfile.ZipFile(path) as z:
        page = z.read("documentation/index.html").decode()
    assert "instantiationToken" in page and "causality independent" in page
    interfaces = {e.tag: e for e in root if e.tag in ("CoSimulation", "ModelExchange",
                                                    "ScheduledExecution")}  # fmt: skip
    expected = {"ScheduledExecution"} if name == CLOCKED else {"CoSimulation", "ModelExchange"}
    assert set(interfaces) == expected
    for element in interfaces.values():
        assert element.get("canGetAndSetFMUState") == "true"
        assert element.get("canSerializeFMUState") == "true"


@pytest.mark.parametrize("name", [PLANT, CONTROLLER, CLOCKED])
def test_fmi3_variables_are_the_fmi2_variables(fmi3_dir, native_dir, name):
    """Same names, value references, causalities, units and start values as the FMI 2.0 FMU
    (so the SSD's connections hold), FMI 3 types, plus an independent time variable."""
    md2 = read_model_description(str(native_dir / (CONTROLLER if name == CLOCKED else name)))
    md3 = read_model_description(str(fmi3_dir / name))
    v3 = {v.name: v for v in md3.modelVariables}
    for v in md2.modelVariables:
        w = v3.pop(v.name)
        assert (w.valueReference, w.causality, w.unit) == (v.valueReference, v.causality, v.unit)
        assert w.type == FMI3_TYPES[v.type]
        assert str(w.start) == str(v.start)
    time = v3.pop("time")
    assert (time.causality, time.type, time.unit) == ("independent", "Float64", "s")
    assert time.valueReference == len(md2.modelVariables)
    if name == PLANT:
        assert [v.name for v in v3.values()] == ["event_indicator1"]
        assert [e.variable.name for e in md3.eventIndicators] == ["event_indicator1"]
    elif name == CONTROLLER:  # the clock of event mode in Co-Simulation, nothing clocked
        clock = v3.pop("sample_clock")
        assert (clock.type, clock.causality, clock.intervalVariability) == (
            "Clock", "input", "fixed")  # fmt: skip
        assert not [v for v in md3.modelVariables if v.clocks]
    elif name == CLOCKED:
        clock = v3.pop("sample_clock")
        assert (clock.type, clock.causality, clock.intervalVariability) == (
            "Clock", "input", "fixed")  # fmt: skip
        clocked = [
            v
            for v in md3.modelVariables
            if v.causality in ("input", "output") and v.type != "Clock"
        ]
        assert clocked and all([c.name for c in v.clocks] == [clock.name] for v in clocked)
    assert not v3 or name == PLANT


def test_only_fmi3_functions_are_exported(fmi3_dir, tmp_path):
    if shutil.which("nm") is None:
        pytest.skip("nm not installed")
    unzip = extract(str(fmi3_dir / PLANT), str(tmp_path / "p"))
    lib = f"{unzip}/binaries/x86_64-linux/PumaPlant.so"
    out = subprocess.run(["nm", "-D", "--defined-only", lib], capture_output=True, text=True)
    symbols = [line.split()[-1] for line in out.stdout.splitlines()]
    assert "fmi3DoStep" in symbols and "fmi3ActivateModelPartition" in symbols
    assert all(s.startswith("fmi3") for s in symbols), symbols


# --- our master on the FMI 3 system archive ----------------------------------------------------


@pytest.fixture(scope="module")
def fmi2_and_fmi3_runs(fmu_dir, native_dir, fmi3_dir):
    """The 20 s paper scenario, every velocity source, FMI 2.0 and FMI 3.0 native FMUs
    (Gauss-Seidel), and the observer scenario under Jacobi."""
    runs = {}
    for tag in ("native", "fmi3"):
        system = read_ssp(fmu_dir / f"PaperScenario-{tag}.ssp")
        for scenario in SCENARIOS:
            runs[tag, scenario, "gauss-seidel"] = Master(
                system, RunOptions(parameter_set=scenario)
            ).run()
        runs[tag, "observer", "jacobi"] = Master(
            system, RunOptions(parameter_set="observer", algorithm="jacobi")
        ).run()
    return runs


@pytest.mark.parametrize(
    "scenario, algorithm", [(s, "gauss-seidel") for s in SCENARIOS] + [("observer", "jacobi")]
)
def test_master_runs_fmi3_equal_to_fmi2_bit_for_bit(fmi2_and_fmi3_runs, scenario, algorithm):
    fmi2 = fmi2_and_fmi3_runs["native", scenario, algorithm]
    fmi3 = fmi2_and_fmi3_runs["fmi3", scenario, algorithm]
    assert fmi2.ok and fmi3.ok, (fmi2.error, fmi3.error)
    assert fmi3.info["loop"] == fmi2.info["loop"] == "c"
    assert fmi3.names == fmi2.names and fmi3.data.shape == (8001, len(fmi2.names))
    assert np.array_equal(fmi3.data, fmi2.data)
    assert np.abs(fmi3["plant.contact_force"]).max() > 1.0  # the run did touch the wall


def test_run_cli_selects_the_fmi3_archive(fmu_dir, tmp_path):
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "impedance_cosim.cli", "run", "--ssp",
           str(fmu_dir / "PaperScenario-fmi3.ssp"), "--stop", "0.5", "--no-figures",
           "--no-progress", "--out", str(out)]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert list(out.rglob("*.csv"))


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_c_loop_steps_fmi3_as_the_python_loop_bit_for_bit(fmu_dir, fmi3_dir, algorithm):
    """The compiled loop calls fmi3SetFloat64/fmi3DoStep/fmi3GetFloat64 (native FMI 3.0 FMUs,
    and the Python ones over 2 s): the same rows as the Python loop; a refused step is reported
    the same way, naming fmi3DoStep."""
    system = read_ssp(fmu_dir / "PaperScenario-fmi3.ssp")
    python = fmi3_dir / "python"
    cases = [
        ({}, {}, None),
        ({"plant": python / PLANT, "controller": python / CONTROLLER}, {}, 2.0),
        ({}, {"plant.max_rhs_evaluations": 25}, None),  # refused at the first contact
    ]
    for files, overrides, stop in cases:
        options = RunOptions(parameter_set="observer", overrides=overrides, algorithm=algorithm,
                             stop_time=stop, fmu_files=files)  # fmt: skip
        runs = {loop: Master(system, replace(options, loop=loop)).run() for loop in ("c", "python")}
        assert runs["c"].info["loop"] == "c"
        assert np.array_equal(runs["c"].data, runs["python"].data)
        assert runs["c"].ok == runs["python"].ok == (not overrides)
    assert "plant: fmi3DoStep at t=3.8475 returned Discard" in runs["c"].error


def test_c_loop_is_refused_for_a_clocked_fmu(fmu_dir, fmi3_dir):
    """Scheduled Execution (the clocked controller) needs the Python loop: loop="c" says why,
    the default picks the Python loop."""
    system = read_ssp(fmu_dir / "PaperScenario-fmi3.ssp")
    files = {"controller": fmi3_dir / CLOCKED}
    run = Master(system, RunOptions(stop_time=0.1, loop="c", fmu_files=files)).run()
    assert not run.ok
    assert "controller is an FMI 3.0 Scheduled Execution FMU (clocks)" in run.error
    assert Master(system, RunOptions(stop_time=0.1, fmu_files=files)).run().info["loop"] == "python"


# --- other hosts ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", [PLANT, CONTROLLER])
def test_fmpy_simulate_cli_runs_fmi3_as_the_fmi2_reference(fmi3_dir, tmp_path, name):
    """`fmpy simulate` on the FMI 3.0 FMU alone (default experiment, 20 s) reproduces the FMI
    2.0 FMUs' reference results (tests/reference/), as test_native.py checks for FMI 2.0."""
    out = tmp_path / "out.csv"
    fmpy_cli = str(Path(sys.executable).with_name("fmpy"))
    cmd = [fmpy_cli, "simulate", str(fmi3_dir / name), "--output-interval", str(DT)]
    subprocess.run([*cmd, "--output-file", str(out)], check=True, timeout=120)
    result = read_csv(out)
    ref_path = next(p for p in REFERENCES if p.name == name.replace(".fmu", "_ref.csv"))
    every_40th = {k: v[::40] for k, v in result.items()}
    assert compare(every_40th, read_csv(ref_path), rtol=1e-9) == []


def test_plant_model_exchange_agrees_with_co_simulation(fmi3_dir, native_dir):
    """As for FMI 2.0 (test_model_exchange.py): the default experiment (the unpowered arm
    falling for 20 s) under fmpy's CVode equals the co-simulation to 1e-6, and the FMI 3.0
    co-simulation equals the FMI 2.0 one bit for bit."""
    path = str(fmi3_dir / PLANT)
    me = simulate_fmu(path, fmi_type="ModelExchange", output_interval=DT)
    cs = simulate_fmu(path, fmi_type="CoSimulation", output_interval=DT)
    cs2 = simulate_fmu(str(native_dir / PLANT), fmi_type="CoSimulation", output_interval=DT)
    assert len(me) == len(cs) == 8001
    for name in ("q1_true", "q2_true", "q3_true", "x", "y"):
        assert np.abs(me[name] - cs[name]).max() < 1e-6
        assert np.array_equal(cs[name], cs2[name])
    assert np.abs(cs["q1_true"][-1] - cs["q1_true"][0]) > 1.0  # the arm did fall


# --- the clocked controller (Scheduled Execution) ---------------------------------------------


def _instance(cls, path, name):
    md = read_model_description(str(path))
    log: list[str] = []
    fmu = cls(
        guid=md.guid,
        unzipDirectory=extract(str(path)),
        modelIdentifier=(md.scheduledExecution or md.coSimulation).modelIdentifier,
        instanceName=name,
    )
    fmu.instantiate(logMessage=lambda _e, _s, _c, m: log.append(m.decode()))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    return fmu, vr, log


def _set_parameters(fmu, path, values: dict) -> None:
    md = read_model_description(str(path))
    by_name = {v.name: v for v in md.modelVariables}
    for name, value in values.items():
        v = by_name[name]
        getattr(fmu, f"set{v.type}")([v.valueReference], [value])


def test_clocked_controller_ticks_8000_times_with_the_fmi2_torques(
    fmu_dir, fmi3_dir, fmi2_and_fmi3_runs
):
    """A host that honours the sample clock: it reads the clock's interval after initialization,
    and at every tick sets the controller's clocked inputs from the plant, activates the model
    partition and hands the torques to the FMI 3.0 plant for one interval. Over 20 s that is
    8000 ticks, and the torques (and the plant) equal the FMI 2.0 Gauss-Seidel run's."""
    system = read_ssp(fmu_dir / "PaperScenario-fmi3.ssp")
    params = Master(system, RunOptions(parameter_set="observer")).parameters
    plant, pvr, plog = _instance(FMU3Slave, fmi3_dir / PLANT, "plant")
    ctrl, cvr, clog = _instance(FMU3ScheduledExecution, fmi3_dir / CLOCKED, "controller")
    for fmu, name, path in ((plant, "plant", PLANT), (ctrl, "controller", CLOCKED)):
        fmu.enterInitializationMode(startTime=0.0, stopTime=20.0)
        _set_parameters(fmu, fmi3_dir / path, params[name])
    links = [(pvr[s], cvr[e]) for sc, s, ec, e in CONNECTIONS if sc == "plant"]
    torques = [(cvr[s], pvr[e]) for sc, s, ec, e in CONNECTIONS if sc == "controller"]
    ctrl.setFloat64([c for _, c in links], plant.getFloat64([p for p, _ in links]))
    plant.setFloat64([p for _, p in torques], ctrl.getFloat64([c for c, _ in torques]))
    plant.exitInitializationMode()
    ctrl.exitInitializationMode()
    clock = cvr["sample_clock"]
    intervals, qualifiers = (ctypes.c_double * 1)(), (ctypes.c_int * 1)()
    ctrl.getIntervalDecimal((ctypes.c_uint32 * 1)(clock), intervals, qualifiers)
    interval = intervals[0]
    assert interval == DT and qualifiers[0] == 2  # fmi3IntervalChanged
    expected = fmi2_and_fmi3_runs["native", "observer", "gauss-seidel"]
    tau_rows, x_rows, ticks, k = [], [], 0, 0
    while k * interval < 20.0 - 1e-9:
        t = k * interval
        ctrl.setFloat64([c for _, c in links], plant.getFloat64([p for p, _ in links]))
        # fmpy's activateModelPartition also calls fmi3ExitConfigurationMode (an error outside
        # configuration mode): the host calls the FMI function itself
        assert ctrl.fmi3ActivateModelPartition(ctrl.component, clock, t) == 0
        ticks += 1
        tau = ctrl.getFloat64([c for c, _ in torques])
        plant.setFloat64([p for _, p in torques], tau)
        plant.doStep(t, interval)
        tau_rows.append(tau)
        x_rows.append(plant.getFloat64([pvr["x"]])[0])
        k += 1
    assert ticks == 8000
    tau_fmi2 = np.column_stack([expected[f"controller.tau{i}"] for i in (1, 2, 3)])
    assert np.array_equal(np.array(tau_rows), tau_fmi2[1:])
    assert np.array_equal(np.array(x_rows), expected["plant.x"][1:])
    for fmu in (plant, ctrl):
        fmu.terminate()
        fmu.freeInstance()
    assert not [m for m in plog + clog if "rror" in m]


# ecospy in a process of its own, left with os._exit: ecospy 0.7.2's fmi4c frees a Clock's
# intervalVariability twice when it frees the FMU (fmi4c.c, parseStringAttributeEzXmlAndRemember-
# Pointer then freeDuplicatedConstChar), an abort once the run is over
ECOSPY_RUN = """
import json, os, sys
import ecospy
sim = ecospy.EcosSimulation(step_size=float(sys.argv[2]), ssp_path=sys.argv[1])
assert sim.init()
signals = json.loads(sys.argv[3])
rows = []
for i in range(8001):
    rows.append([sim.get_real(name.replace(".", "::")) for name in signals])
    if i < 8000:
        sim.step()
sim.terminate()
print(json.dumps(rows), flush=True)
os._exit(0)
"""


def test_ecospy_runs_the_fmi3_archive_as_our_jacobi_master(fmu_dir, fmi2_and_fmi3_runs):
    """ecospy 0.7.2 (FMI 3 via fmi4c) runs PaperScenario-fmi3.ssp unchanged (the FMUs' start
    values are the paper's observer scenario) for 20 s and agrees with our Jacobi run."""
    try:
        import ecospy  # noqa: F401
    except (ImportError, OSError) as exc:  # OSError: libtbb12 missing
        pytest.skip(f"ecospy unavailable: {exc}")
    signals = ["plant.x", "plant.y", "plant.contact_force",
               *(f"controller.tau{i}" for i in (1, 2, 3))]  # fmt: skip
    ssp = str(fmu_dir / "PaperScenario-fmi3.ssp")
    out = subprocess.run([sys.executable, "-c", ECOSPY_RUN, ssp, repr(DT), json.dumps(signals)],
                         capture_output=True, text=True, check=True, timeout=600)  # fmt: skip
    rows = json.loads(out.stdout.strip().splitlines()[-1])
    ours = fmi2_and_fmi3_runs["fmi3", "observer", "jacobi"]
    theirs = np.array(rows)
    for k, name in enumerate(signals):
        scale = np.abs(ours[name]).max()
        assert np.abs(theirs[:, k] - ours[name]).max() <= 1e-12 * max(scale, 1.0), name
    assert ours["plant.contact_force"].max() > 1.0


# --- early return at the wall contact ----------------------------------------------------------


def test_plant_returns_early_at_the_contact_when_allowed(fmi3_dir):
    """With earlyReturnAllowed, fmi3DoStep stops at each contact switch (closing and opening)
    with the wrist on the wall; the importer completes the step from there and ends where the
    plant without early return ends, bit for bit. Without it the plant never returns early."""
    from conftest import contact_torques

    path = fmi3_dir / PLANT
    assert _root(path).find("CoSimulation").get("mightReturnEarlyFromDoStep") == "true"
    root = _root(fmi3_dir / CONTROLLER)
    # the controller's early return and intermediate update: at its clock's ticks in event mode
    # (test_fmi3_clock_cs.py, test_fmi3_clock_update.py)
    assert root.find("CoSimulation").get("mightReturnEarlyFromDoStep") == "true"
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    plain, early = (
        FMU3Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier="PumaPlant",
                  instanceName=f"p{k}") for k in (0, 1)
    )  # fmt: skip
    plain.instantiate(earlyReturnAllowed=False)
    early.instantiate(earlyReturnAllowed=True)
    for fmu in (plain, early):
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
    taus, stops, states = [vr[f"tau{i}"] for i in (1, 2, 3)], [], []
    for i, tau in enumerate(contact_torques(6.0)):
        t = i * DT
        for fmu in (plain, early):
            fmu.setFloat64(taus, list(tau))
        assert plain.doStep(t, DT)[2] is False
        _, _, returned_early, reached = early.doStep(t, DT)
        if returned_early:
            assert t < reached < t + DT
            x, now = early.getFloat64([vr["x"], vr["time"]])
            stops.append((reached, x - 0.65, now))
            assert early.doStep(reached, t + DT - reached)[2:] == (False, t + DT)
    assert len(stops) == 4  # two contacts: each closes and opens
    assert all(abs(gap) < 1e-9 and now == reached for reached, gap, now in stops)
    names = ["q1_true", "q2_true", "q3_true", "qd1", "qd2", "qd3", "contact_force"]
    states = [fmu.getFloat64([vr[n] for n in names]) for fmu in (plain, early)]
    assert states[0] == states[1]
    for fmu in (plain, early):
        fmu.terminate()
        fmu.freeInstance()


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_our_master_honours_the_clock(
    fmu_dir, fmi3_dir, fmi2_and_fmi3_runs, monkeypatch, algorithm
):
    """Our master runs the clocked controller (ClockedInstance: a tick activation for every
    tick in each communication step): 8000 ticks over 20 s and the FMI 2.0 run bit for bit; at a
    1/200 s master step the clock still ticks 400 times per second (two per step)."""
    from impedance_cosim.cosim.fmus import fmi3 as fmu3

    ticks: list[int] = []
    step = fmu3.ClockedInstance.step

    def counting(self, t, h):
        step(self, t, h)
        ticks.append(self.ticks)

    monkeypatch.setattr(fmu3.ClockedInstance, "step", counting)
    system = read_ssp(fmu_dir / "PaperScenario-fmi3.ssp")
    files = {"controller": fmi3_dir / CLOCKED}
    run = Master(
        system, RunOptions(parameter_set="observer", algorithm=algorithm, fmu_files=files)
    ).run()
    assert run.ok, run.error
    assert ticks[-1] == 8000 and len(ticks) == 8000
    assert np.array_equal(run.data, fmi2_and_fmi3_runs["native", "observer", algorithm].data)
    ticks.clear()
    coarse = Master(
        system,
        RunOptions(parameter_set="observer", step_size=1 / 200, stop_time=1.0, fmu_files=files),
    ).run()
    assert coarse.ok and ticks[-1] == 400 and len(ticks) == 200


def test_the_glue_includes_no_c_file_and_renames_no_function():
    """native/src: each .c file is a translation unit of its own (no `#include "x.c"`), and no
    header renames FMI functions with macros (the FMI 3.0 glue calls the instance core)."""
    src = Path(__file__).resolve().parents[1] / "native" / "src"
    for path in sorted(src.glob("*.[ch]")):
        text = path.read_text()
        assert not re.search(r'#include\s+"[^"]+\.c"', text), path.name
        assert not re.search(r"#define\s+fmi[23]\w+\s+\w", text), path.name
