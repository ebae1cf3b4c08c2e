"""The FMI 3.0 controller's intermediate update at its clock's ticks (native/src/fmi3_cosim.c,
native/controller/model_me.c): with eventModeUsed and an intermediateUpdate callback, fmi3DoStep
calls it at each tick inside the step, the outputs readable there (the torques held up to the
tick); on earlyReturnRequested (where allowed) the step ends at the tick and the sample is taken
in Event Mode, else the tick is sampled inside the step as without early return. The closed loop
of tests/test_fmi3_clock_cs.py, on fmpy's FMU3Slave."""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description
from test_fmi3_clock_cs import DT, ERROR, Fmu, Loop, _steps
from test_fmi3_clock_cs import fmi2_run as fmi2_run  # the fixture

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

TAU = ["tau1", "tau2", "tau3"]


class Callback:
    """The importer's intermediateUpdate: records each call (time, flags, the torques and time
    read inside, what fmi3DoStep inside it answers) and requests the early return if asked."""

    def __init__(self, request: bool):
        self.request = request
        self.calls: list[tuple] = []
        self.fmu: Fmu | None = None

    def __call__(self, _env, t, set_requested, get_allowed, finished, can_return, requested, when):
        fmu = self.fmu
        values = fmu.fmu.getFloat64([fmu.vr[n] for n in [*TAU, "time"]])
        refused = fmu.fmu._functions["fmi3DoStep"](fmu.fmu.component, t, DT, True, *[None] * 4)
        flags = (set_requested, get_allowed, finished, can_return)
        self.calls.append((t, flags, values[:3], values[3], refused, fmu.log[-1]))
        requested[0] = self.request
        when[0] = t


def _loop(fmu_dir, fmi3_dir, callback: Callback | None = None, **controller) -> Loop:
    if callback is not None:
        controller["intermediateUpdate"] = callback
    loop = Loop(fmu_dir, fmi3_dir, **controller)
    if callback is not None:
        callback.fmu = loop.ctrl
    return loop


def _inside(steps, seconds) -> list[float]:
    """The ticks k/400 s strictly inside the communication steps."""
    k = np.arange(1, round(seconds / DT) + 1)
    ticks = k * DT
    return [float(x) for x in ticks if any(t + 1e-9 * DT < x < t + h - 1e-9 * DT for t, h in steps)]


def test_the_controller_declares_the_intermediate_update(fmi3_dir):
    md = read_model_description(str(fmi3_dir / "ImpedanceController.fmu"))
    cs = md.coSimulation
    assert str(cs.providesIntermediateUpdate).lower() == "true"
    assert str(cs.canReturnEarlyAfterIntermediateUpdate).lower() == "true"
    with zipfile.ZipFile(fmi3_dir / "ImpedanceController.fmu") as z:  # fmpy does not read it
        root = ET.fromstring(z.read("modelDescription.xml"))
    ports = [v for v in root.find("ModelVariables") if v.get("causality") in ("input", "output")]
    flags = {(v.get("causality"), v.get("intermediateUpdate", "false")) for v in ports}
    assert flags == {("input", "false"), ("output", "true")}
    vr = {v.name: v.valueReference for v in md.modelVariables}
    Fmu(
        fmi3_dir,
        "ImpedanceController",
        eventModeUsed=True,
        requiredIntermediateVariables=[vr["tau1"]],
    )
    with pytest.raises(Exception, match="instantiate"):  # an input is no intermediate variable
        Fmu(
            fmi3_dir,
            "ImpedanceController",
            eventModeUsed=True,
            requiredIntermediateVariables=[vr["q1"]],
        )


@pytest.mark.parametrize("h", [1 / 150, "variable"])
def test_early_return_requested_at_each_tick_inside_a_step(fmu_dir, fmi3_dir, h):
    """A call at every tick inside a step, at the tick, the held torques readable, only getters
    allowed; the requested early return ends the step there: the same samples, bit for bit, as
    the early return without a callback."""
    steps = _steps(h, 1.0)
    callback = Callback(request=True)
    runs = [_loop(fmu_dir, fmi3_dir, cb, eventModeUsed=True, earlyReturnAllowed=True)
            for cb in (callback, None)]  # fmt: skip
    for loop in runs:
        loop.run(steps)
    assert runs[0].samples == runs[1].samples and len(runs[0].samples) == 401
    times = [c[0] for c in callback.calls]
    assert times == pytest.approx(_inside(steps, 1.0), abs=1e-9 * DT) and len(times) > 100
    samples = dict(runs[0].samples)
    held = [tau for t, tau in runs[0].samples]
    for k, (t, flags, tau, now, refused, line) in enumerate(callback.calls):
        assert flags == (False, True, True, True) and now == t and t in samples
        assert tau == held[[s for s, _ in runs[0].samples].index(t) - 1]  # before the tick
        assert refused == ERROR and "inside the intermediate update callback" in line, k


@pytest.mark.parametrize("h", [1 / 1000, 1 / 150, "variable"])
def test_without_a_request_the_ticks_are_sampled_inside_the_step_as_today(fmu_dir, fmi3_dir, h):
    """Not requested (early return allowed), or requested where not allowed (canReturnEarly
    false): no early return, the callback at every tick inside a step, the plant gets the same
    torques in every step as without a callback or event mode, bit for bit."""
    steps = _steps(h, 1.0)
    callbacks = [Callback(request=False), Callback(request=True)]
    runs = [
        _loop(fmu_dir, fmi3_dir, callbacks[0], eventModeUsed=True, earlyReturnAllowed=True),
        _loop(fmu_dir, fmi3_dir, callbacks[1], eventModeUsed=True),
        _loop(fmu_dir, fmi3_dir),
    ]
    for loop in runs:
        loop.run(steps)
    assert runs[0].applied == runs[2].applied == runs[1].applied
    assert len(runs[0].applied) == len(steps)
    for callback, can_return in zip(callbacks, (True, False)):
        times = [c[0] for c in callback.calls]
        assert times == pytest.approx(_inside(steps, 1.0), abs=1e-9 * DT)
        assert {c[1] for c in callback.calls} == {(False, True, True, can_return)}


def test_at_1_400_no_tick_inside_a_step_and_the_fmi2_torques_bit_for_bit(
    fmu_dir, fmi3_dir, fmi2_run
):
    callback = Callback(request=True)
    loop = _loop(fmu_dir, fmi3_dir, callback, eventModeUsed=True, earlyReturnAllowed=True)
    loop.run(_steps(DT, 2.0))
    assert callback.calls == [] and len(loop.samples) == 801
    assert np.array_equal(np.array([tau for _, tau in loop.samples[:800]]), fmi2_run[1:])


def test_no_callback_without_event_mode(fmu_dir, fmi3_dir):
    callback = Callback(request=True)
    runs = [_loop(fmu_dir, fmi3_dir, callback, earlyReturnAllowed=True), _loop(fmu_dir, fmi3_dir)]
    for loop in runs:
        loop.run(_steps(1 / 150, 0.5))
    assert callback.calls == [] and runs[0].applied == runs[1].applied


def test_a_step_past_max_samples_per_step_is_refused_before_any_callback(fmu_dir, fmi3_dir):
    """The callback may let every tick pass: the whole step is bounded as without event mode."""
    callback = Callback(request=False)
    loop = _loop(fmu_dir, fmi3_dir, callback, eventModeUsed=True, earlyReturnAllowed=True)
    loop.event(0.0)
    with pytest.raises(Exception, match="fmi3DoStep"):
        loop.ctrl.fmu.doStep(0.0, 200001 * DT)
    assert "max_samples_per_step" in loop.ctrl.log[-1] and callback.calls == []
    assert loop.ctrl.fmu.doStep(0.0, 2.5 * DT)[:3] == (False, False, False)
    assert len(callback.calls) == 2
