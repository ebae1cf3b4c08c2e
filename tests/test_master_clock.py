"""The event-exact master drives the FMI 3.0 controller's input clock in Co-Simulation (issue 37,
cosim/master/events.py): eventModeUsed and earlyReturnAllowed, each communication step cut at the
tick the controller announced, the tick taken in Event Mode (fmi3SetClock,
fmi3UpdateDiscreteStates) on the plant's outputs at the tick."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from impedance_cosim.cosim.master.events import ClockedEventInstance, EventExactMaster
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

DT = 1 / 400


def _run(ssp, algorithm: str, step: float = DT, cls=EventExactMaster):
    """2 s of the observer scenario; (the master, its result)."""
    options = RunOptions(parameter_set="observer", algorithm=algorithm, stop_time=2.0,
                         step_size=step)  # fmt: skip
    master = cls(read_ssp(ssp), options)
    result = master.run()
    assert result.ok, result.error
    return master, result


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_clocked_controller_at_1_400_equals_the_fmi2_run_bit_for_bit(
    fmu_dir, fmi3_dir, native_ssp, algorithm
):
    """Every communication step ends on a tick: the controller signals it at the step's end and
    takes it when the next step starts, on the plant's outputs there (Gauss-Seidel and Jacobi
    alike: the rows hold the outputs before the tick, Jacobi's plant the torque from before it).
    801 ticks in 2 s (the one at the stop time after the last row), each at k/400 s; every
    recorded value equals the FMI 2.0 run's."""
    master, exact = _run(fmu_dir / "PaperScenario-fmi3.ssp", algorithm)
    _, fmi2 = _run(native_ssp, algorithm, cls=Master)
    assert exact.names == fmi2.names and np.array_equal(exact.data, fmi2.data)
    ticks = np.array(master.ticks["controller"])
    assert len(ticks) == 801 and exact.info["ticks"] == master.ticks
    assert np.max(np.abs(ticks - np.arange(801) * DT)) <= 1e-9 * DT
    assert set(master.events) == {"plant"}  # the clock's ticks are not contact events


def test_ticks_inside_a_step_are_taken_at_their_time(fmu_dir, fmi3_dir, monkeypatch):
    """At 1/1000 s steps the master cuts the steps at the ticks inside them (k/400 s for odd
    k, 0.5 ms into a step; the others are on its end), where plant and controller both are;
    the controller never returns early (no tick is inside a step it takes). Every tick once,
    within 1e-9 sample periods of k/400 s (measured 8.9e-14: the end of a step the master
    computed as t + h). The plant integrates over other steps (1 ms and the cuts) than at
    1/400 s, so the rows at common times (every 5 ms) are not bit for bit: measured over 2 s,
    torques within 4.6e-11 and the plant's outputs within 2.6e-9 (plant.phid) of each
    signal's range. Bound 1e-8. (Jacobi is not compared: its delay is one communication step,
    1 ms here, 2.5 ms at 1/400 s: another loop.)"""
    early = []
    step = ClockedEventInstance.step

    def watching(self, t, h):
        step(self, t, h)
        early.append(self._step_out[2].value)

    monkeypatch.setattr(ClockedEventInstance, "step", watching)
    ssp = fmu_dir / "PaperScenario-fmi3.ssp"
    master, fine = _run(ssp, "gauss-seidel", 1 / 1000)
    assert len(early) == 2000 + 400 and not any(early)  # 2000 steps, 400 of them cut at a tick
    _, coarse = _run(ssp, "gauss-seidel")
    ticks = np.array(master.ticks["controller"])
    k = np.round(ticks / DT)
    assert len(ticks) == 801 and np.array_equal(k, np.arange(801))
    assert np.max(np.abs(ticks - k * DT)) <= 1e-9 * DT
    a, b = fine.data[::5], coarse.data[::2]
    assert np.max(np.abs(a[:, 0] - b[:, 0])) <= 1e-12
    scale = np.max(np.abs(b[:, 1:]), axis=0)
    scale[scale == 0.0] = 1.0
    assert np.max(np.abs(a[:, 1:] - b[:, 1:]) / scale) <= 1e-8


def test_an_early_return_the_master_did_not_plan_stops_the_run(fmu_dir, fmi3_dir, monkeypatch):
    """earlyReturnAllowed is what keeps a tick inside a step from being sampled on stale inputs:
    a master that did not cut the step there (here: told of no next tick) gets the FMU's early
    return at the tick, and the run fails naming it instead of going on."""
    take = ClockedEventInstance.take_tick

    def forgetting(self):
        take(self)
        self.next_tick = np.inf

    monkeypatch.setattr(ClockedEventInstance, "take_tick", forgetting)
    options = RunOptions(parameter_set="observer", stop_time=0.01, step_size=1 / 1000)
    result = EventExactMaster(read_ssp(fmu_dir / "PaperScenario-fmi3.ssp"), options).run()
    assert result.status == "failed" and len(result.data) == 3  # t = 0, 1, 2 ms
    assert "controller: the step from t=0.002 to 0.003 ended at t=0.0025" in result.error
