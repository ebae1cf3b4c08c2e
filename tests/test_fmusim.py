"""The FMI 3.0 plant and controller under a third-party host: the Reference FMUs' fmusim (0.0.39,
the last release with it), built from its sources and named by IMPCOSIM_FMUSIM (skipped otherwise:
it is not on PyPI or in Debian; docs/fmi3.md says how to build it). fmusim drives the plant alone
with the torques of our `run --event-exact` closed loop, held over each step as our master holds
them; with its event mode, early return and intermediate values on it must stop at the contact
switch our run found, and on the grid both runs must agree with ours. The controller alone must take
every sample of its clock in fmusim's Co-Simulation (with and without event mode) and Model Exchange
as in fmpy's host."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from impedance_cosim.cosim.results.result import read_csv

FMUSIM = os.environ.get("IMPCOSIM_FMUSIM")
pytestmark = pytest.mark.skipif(not FMUSIM, reason="IMPCOSIM_FMUSIM does not name an fmusim")

H, STOP = 0.0025, 6.0  # through the first contact (3.85 s)
EVENTS = ["--event-mode-used", "--early-return-allowed", "--record-intermediate-values"]
PLANT = ("q1_true", "q2_true", "q3_true", "qd1", "qd2", "qd3", "x", "y", "contact_force")


@pytest.fixture(scope="module")
def ours(fmi3_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, float, Path]:
    """Our event-exact run of the FMI 3.0 archive: its rows, its plant event and, as fmusim's
    input file, the torque the plant held over each step (Gauss-Seidel: the controller steps
    first, so row i + 1's torque is the one held over [t_i, t_i+1]; a repeated time is fmusim's
    way to change an input at once)."""
    out = tmp_path_factory.mktemp("event_exact")
    archive = fmi3_dir.parent / "PaperScenario-fmi3.ssp"
    argv = [sys.executable, "-m", "impedance_cosim", "run", "--ssp", str(archive),
            "--event-exact", "--stop", str(STOP), "--out", str(out), "--no-figures",
            "--no-report", "--no-progress"]  # fmt: skip
    subprocess.run(argv, check=True, capture_output=True, timeout=600)
    rows = read_csv(out / "observer.csv")
    (event,) = json.loads((out / "observer_summary.json").read_text())["events"]["plant"]
    t = rows["time"]
    tau = np.stack([rows[f"controller.tau{i}"] for i in (1, 2, 3)], axis=1)
    lines = ["time,tau1,tau2,tau3"]
    for i in range(len(t)):
        held = [tau[i]] if i == len(t) - 1 else ([tau[i]] if i else []) + [tau[i + 1]]
        lines += [",".join(repr(float(x)) for x in (t[i], *v)) for v in held]
    inputs = out / "torques.csv"
    inputs.write_text("\n".join(lines) + "\n")
    return rows, event, inputs


def fmusim(fmi3_dir: Path, inputs: Path, out: Path, *options: str) -> dict:
    subprocess.run([str(FMUSIM), "--interface-type", "cs", "--stop-time", str(STOP),
                    "--output-interval", str(H), "--input-file", str(inputs), "--output-file",
                    str(out), *options, str(fmi3_dir / "PumaPlant.fmu")],
                   check=True, capture_output=True, timeout=600)  # fmt: skip
    return read_csv(out)


def on_grid(rows: dict, n: int) -> np.ndarray:
    """The index of the last row at each grid time t_i = i H (fmusim repeats a row at an event)."""
    steps = rows["time"] / H
    last = {int(round(s)): k for k, s in enumerate(steps) if abs(s - round(s)) <= 1e-9}
    return np.array([last[i] for i in range(n)])


@pytest.mark.parametrize("options", [[], EVENTS], ids=["plain", "event-mode"])
def test_fmusim_runs_the_fmi3_plant_as_our_event_exact_run(fmi3_dir, ours, tmp_path, options):
    rows, event, inputs = ours
    theirs = fmusim(fmi3_dir, inputs, tmp_path / "fmusim.csv", *options)
    grid = on_grid(theirs, len(rows["time"]))
    for name in PLANT:  # our CSV and fmusim's keep 17 and 16 digits: agreement to rounding
        ours_, theirs_ = rows[f"plant.{name}"], theirs[name][grid]
        scale = max(np.abs(ours_).max(), 1.0)
        assert np.abs(ours_ - theirs_).max() <= 1e-9 * scale, name
    off_grid = sorted({t for t in theirs["time"] if abs(t / H - round(t / H)) > 1e-9})
    if options:  # it stopped at the contact switch, where ours did
        assert len(off_grid) == 1 and abs(off_grid[0] - event) <= 1e-9, (off_grid, event)
    else:
        assert off_grid == []


# --- the FMI 3.0 controller: its clock's ticks in fmusim's Co-Simulation and Model Exchange ---

T_CTRL = 0.5  # 200 ticks; the inputs stay at their start values, so every host samples alike


def controller_reference(fmi3_dir: Path) -> np.ndarray:
    """tau1..3 after the sample at each tick t_k = k/400 (row k), from fmpy's FMU3Slave stepping
    the controller without event mode at its sample period (a step from t_k samples at t_k)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    path = str(fmi3_dir / "ImpedanceController.fmu")
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    taus = [vr[f"tau{i}"] for i in (1, 2, 3)]
    identifier = md.coSimulation.modelIdentifier
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=identifier,
                    instanceName="reference")  # fmt: skip
    fmu.instantiate()
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    rows = []
    for k in range(round(T_CTRL / H) + 1):
        fmu.doStep(k * H, H)
        rows.append(fmu.getFloat64(taus))
    fmu.terminate()
    fmu.freeInstance()
    return np.array(rows)


def controller_in_fmusim(fmi3_dir: Path, out: Path, interface: str, interval: float, *options):
    subprocess.run([str(FMUSIM), "--interface-type", interface, "--stop-time", str(T_CTRL),
                    "--output-interval", str(interval), "--output-file", str(out), *options,
                    str(fmi3_dir / "ImpedanceController.fmu")],
                   check=True, capture_output=True, timeout=600)  # fmt: skip
    rows = read_csv(out)
    return rows["time"], np.stack([rows[f"tau{i}"] for i in (1, 2, 3)], axis=1)


def close(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal to fmusim's CSV digits (16 significant)."""
    return bool(np.all(np.abs(a - b) <= 1e-14 * np.maximum(np.abs(b), 1.0)))


@pytest.mark.parametrize(
    "interface, options, shift",
    [("cs", [], 1), ("cs", EVENTS, 0), ("me", [], 0)],
    ids=["cs", "cs-event-mode", "me-time-events"],
)
def test_fmusim_samples_the_fmi3_controller_at_every_tick(
    fmi3_dir, tmp_path, interface, options, shift
):
    """At a step of one sample period, the last row at t_k holds the sample of t_k where fmusim
    handles the tick as an event (Co-Simulation with event mode: the tick at the step's end;
    Model Exchange: the time event the FMU announced) and of t_k-1 without (the step from t_k-1
    sampled at its start)."""
    ref = controller_reference(fmi3_dir)
    t, tau = controller_in_fmusim(fmi3_dir, tmp_path / "c.csv", interface, H, *options)
    last = {round(x / H): k for k, x in enumerate(t)}  # the last row at each tick
    assert sorted(last) == list(range(len(ref)))
    for k, row in last.items():
        assert close(tau[row], ref[max(k - shift, 0)]), (k, tau[row], ref[max(k - shift, 0)])


def test_fmusim_reads_the_controller_in_its_intermediate_update_at_each_tick(fmi3_dir, tmp_path):
    """fmusim's communication step of 4 sample periods, event mode, early return allowed and
    intermediate values recorded: the controller calls its intermediate update at each tick inside
    a step (fmusim reads the outputs held up to the tick and asks no early return), samples the
    tick inside the step, and ends each step on a tick in Event Mode."""
    ref = controller_reference(fmi3_dir)
    t, tau = controller_in_fmusim(fmi3_dir, tmp_path / "c.csv", "cs", 4 * H, *EVENTS)
    for k in range(1, len(ref)):
        at = [row for row, x in enumerate(t) if abs(x - k * H) <= 1e-9 * H]
        assert at, f"no row at tick {k}"
        assert close(tau[at[0]], ref[k - 1])  # read in the update: held up to the tick
        assert close(tau[at[-1]], ref[k] if k % 4 == 0 else ref[k - 1])
