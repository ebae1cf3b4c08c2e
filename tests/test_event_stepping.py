"""Event-exact stepping (cosim/master/events.py): the FMI 3.0 plant stopped at each contact switch
inside the master's communication steps, each event handled in Event Mode, on the FMI 3.0
archive."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from impedance_cosim.cosim.master.events import (
    ClockedEventInstance,
    EventExactMaster,
    EventInstance,
)
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

DT = 1 / 400


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_event_exact_run_stops_at_each_switch_and_keeps_the_sampled_rows(
    fmu_dir, fmi3_dir, monkeypatch, algorithm
):
    """The plant's events are inside communication steps, off the 400 Hz grid, and each first
    shows in the grid row after it; the controller samples at the same instants on the same
    inputs, so the recorded rows equal the fixed-step run's, bit for bit."""
    handled: list[float] = []
    iterate = EventInstance._event_iteration

    def counting(self):
        if not isinstance(self, ClockedEventInstance):  # the controller's ticks: test_master_clock
            handled.append(self.events[-1] if self.events else None)
        return iterate(self)

    monkeypatch.setattr(EventInstance, "_event_iteration", counting)
    system = read_ssp(fmu_dir / "PaperScenario-fmi3.ssp")
    fixed = Master(system, RunOptions(parameter_set="observer", algorithm=algorithm)).run()
    master = EventExactMaster(system, RunOptions(parameter_set="observer", algorithm=algorithm))
    exact = master.run()
    assert fixed.ok and exact.ok, (fixed.error, exact.error)
    assert exact.info["loop"] == "python" and set(master.events) == {"plant"}
    events = master.events["plant"]
    assert len(events) >= 1 and handled == [None, *events]  # initialization, then each event
    times, force = fixed["time"], fixed["plant.contact_force"]
    for t in events:
        k = int(np.searchsorted(times, t, side="right"))
        assert times[k - 1] < t < times[k]  # strictly inside a communication step
        assert (force[k] > 0.0) != (force[k - 1] > 0.0)  # the row after shows the switch
    assert np.array_equal(exact.data, fixed.data)


@pytest.mark.slow
def test_run_cli_event_exact_writes_the_fixed_step_rows(fmu_dir, fmi3_dir, tmp_path):
    """`run --event-exact` over the first contact (3.85 s): the same CSV as the fixed step."""
    csvs = []
    for flag in ([], ["--event-exact"]):
        out = tmp_path / f"out{len(flag)}"
        cmd = [sys.executable, "-m", "impedance_cosim.cli", "run", "--ssp",
               str(fmu_dir / "PaperScenario-fmi3.ssp"), "--stop", "4", "--no-figures",
               "--no-progress", "--out", str(out), *flag]  # fmt: skip
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        (csv,) = out.rglob("*.csv")
        csvs.append(csv.read_bytes())
        summary = json.loads((out / "observer_summary.json").read_text())
    assert csvs[0] == csvs[1] and len(csvs[0]) > 1000
    (switch,) = summary["events"]["plant"]  # the contact closes once before 4 s
    assert 3.8 < switch < 3.9 and f"plant events (event-exact): {switch:.9f} s" in done.stdout
    assert "controller clock ticks (event-exact): 1601, 0.000000000 to 4.000000000 s" in done.stdout


def test_run_cli_event_exact_without_an_event_mode_fmu_is_refused(native_ssp, tmp_path):
    """`run --event-exact` on FMI 2.0 FMUs (no event mode) refuses in one line, exit 2, instead
    of a run that silently steps as usual."""
    cmd = [sys.executable, "-m", "impedance_cosim.cli", "run", "--ssp", str(native_ssp),
           "--stop", "0.1", "--no-figures", "--no-progress", "--out", str(tmp_path / "out"),
           "--event-exact"]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "needs an FMI 3.0 co-simulation FMU with event mode" in lines[0]
