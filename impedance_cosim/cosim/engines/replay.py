"""Replaying a recorded torque sequence into the plant FMU, to compare its interfaces: as fmpy
`input` for Model Exchange (the host's solver integrates), and step by step in co-simulation
with the wall-contact times located to 1e-12 s.

The torque is piecewise constant: `tau[i]` is held over [t_i, t_i+1] (the master's row at t_i+1).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

# fmpy's CVode root function applies the inputs at t without after_event, so a step placed
# exactly at t_i would give the solver the previous torque after each restart at t_i. Placing
# it at t_i (1 - SHIFT), within fmpy's isclose (rel_tol 1e-9), keeps the event at t_i and makes
# every evaluation at or after t_i see the new torque.
SHIFT = 1e-10


def held_input(
    t: np.ndarray, values: np.ndarray, names: tuple[str, ...], shift: float = SHIFT
) -> np.ndarray:
    """fmpy input (structured array) holding values[i] over [t[i], t[i+1]]: each change is a
    pair of equal time points (an input event), placed at t_i (1 - shift)."""
    if len(t) != len(values) + 1 or values.shape[1] != len(names):
        raise ValueError(f"need len(t) = len(values) + 1 and {len(names)} columns")
    times = np.repeat(np.asarray(t, dtype=float), 2)[1:-1]
    times[1:] *= 1.0 - shift
    signal = np.zeros(len(times), dtype=[("time", float)] + [(n, float) for n in names])
    signal["time"] = times
    for k, name in enumerate(names):
        signal[name] = np.repeat(values[:, k], 2)
    return signal


def _fmpy_instance(cls: Any, fmu: Path, interface: str) -> tuple[Any, Any]:
    """The FMU's model description and fmpy's object (cls) over its interface's library."""
    from impedance_cosim.cosim.fmus.files import extractions

    _, md, unzip = extractions.acquire(Path(fmu))  # checked, shared, removed at exit
    identifier = getattr(md, interface).modelIdentifier
    return md, cls(guid=md.guid, unzipDirectory=unzip, modelIdentifier=identifier,
                   instanceName="replay")  # fmt: skip


def cs_crossing_times(
    fmu: Path, t: np.ndarray, tau: np.ndarray, level: float, output: str = "x"
) -> tuple[list[float], np.ndarray]:
    """Step the co-simulation plant with the held torques; return the times where `output`
    crosses `level` (bisected to 1e-12 s by restoring the FMU state: the plant's result does not
    depend on the step size) and the joint angles q1_true..q3_true at every t_i."""
    from fmpy.fmi2 import FMU2Slave

    md, cs = _fmpy_instance(FMU2Slave, fmu, "coSimulation")
    vr = {v.name: v.valueReference for v in md.modelVariables}
    cs.instantiate()
    cs.setupExperiment(startTime=float(t[0]))
    cs.enterInitializationMode()
    cs.exitInitializationMode()
    taus, x, q = (
        [vr["tau1"], vr["tau2"], vr["tau3"]],
        [vr[output]],
        [vr[f"q{i}_true"] for i in (1, 2, 3)],
    )
    times, angles = [], [cs.getReal(q)]
    above = cs.getReal(x)[0] > level
    for i in range(len(tau)):
        h = t[i + 1] - t[i]
        cs.setReal(taus, [float(v) for v in tau[i]])
        start = cs.getFMUstate()
        cs.doStep(t[i], h)
        if (cs.getReal(x)[0] > level) != above:
            lo, hi = 0.0, h
            while hi - lo > 1e-12:
                mid = 0.5 * (lo + hi)
                cs.setFMUstate(start)
                cs.doStep(t[i], mid)
                lo, hi = (lo, mid) if (cs.getReal(x)[0] > level) != above else (mid, hi)
            times.append(float(t[i] + hi))
            above = not above
            cs.setFMUstate(start)
            cs.doStep(t[i], h)
        cs.freeFMUstate(start)
        angles.append(cs.getReal(q))
    cs.terminate()
    cs.freeInstance()
    return times, np.array(angles)


def me_replay(
    fmu: Path, t: np.ndarray, tau: np.ndarray, relative_tolerance: float, shift: float = SHIFT
) -> tuple[np.ndarray, np.ndarray]:
    """Run the plant FMU as Model Exchange under fmpy's CVode with the held torques; return
    fmpy's result (rows at t) and a log of (time, event indicators..., states...) after every
    solver step and event (state events are the rows off the t grid)."""
    import ctypes

    from fmpy import simulate_fmu
    from fmpy.fmi2 import FMU2Model

    md, model = _fmpy_instance(FMU2Model, fmu, "modelExchange")
    nx, nz = len(md.derivatives), md.numberOfEventIndicators
    model.instantiate()
    x, z = (ctypes.c_double * nx)(), (ctypes.c_double * max(nz, 1))()
    log = []

    def record(time: float, _recorder) -> bool:
        model.fmi2GetEventIndicators(model.component, z, nz)
        model.fmi2GetContinuousStates(model.component, x, nx)
        log.append((time, *z[:nz], *x))
        return True

    try:
        result = simulate_fmu(
            str(fmu),
            fmi_type="ModelExchange",
            input=held_input(t, tau, ("tau1", "tau2", "tau3"), shift),
            output_interval=float(t[1] - t[0]),
            stop_time=float(t[-1]),
            relative_tolerance=relative_tolerance,
            record_events=False,
            fmu_instance=model,
            step_finished=record,
        )
    finally:
        model.freeInstance()
    return result, np.array(log)
