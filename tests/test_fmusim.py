"""The FMI 3.0 plant under a third-party host: the Reference FMUs' fmusim (0.0.39, the last
release with it), built from its sources and named by IMPCOSIM_FMUSIM (skipped otherwise: it is
not on PyPI or in Debian; docs/fmi3.md says how to build it). fmusim drives the plant alone with
the torques of our `run --event-exact` closed loop, held over each step as our master holds them;
with its event mode, early return and intermediate values on it must stop at the contact switch
our run found, and on the grid both runs must agree with ours."""

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
