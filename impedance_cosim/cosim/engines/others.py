"""Run the SSP archive in other co-simulation engines, to cross-check our master.

libcosim (Open Simulation Platform), through libcosimpy 0.0.6 from PyPI (`pip install
libcosimpy==0.0.6`: a self-contained wheel, no Debian packages needed). What it does with
fmus/PaperScenario.ssp, read from libcosim's sources and checked on runs here:

- Loading: `CosimExecution.from_ssp_file` takes the .ssp itself (or the .ssd or its folder),
  extracts it into a temporary folder and removes it again. Each component's instance name is its
  SSD name ("controller", "plant"); slave indices follow no documented order (here controller 0,
  plant 1), so look them up by name.
- Parameters: libcosim applies only ParameterBindings inside a Component (system-level ones are
  silently ignored) and reads only SystemStructure.ssd, and its C API cannot name a parameter set.
  Our SSDs bind each scenario's set on the components, one scenario per SSD, so a scenario's own
  archive (PaperScenario-<scenario>.ssp) runs as it is (parameter_set=None). Given a set name,
  this function also reads that set with our own `read_ssp` (from any variant SSD) and gives
  each value to libcosim as an initial value (set before initialization).
- Time: integer nanoseconds. The step size must be a whole number of ns (0.0025 s = 2,500,000 ns);
  FMUs get t_i = (i * h_ns) / 1e9 and a step length t_{i+1} - t_i, both computed from the
  integers, so both can differ by an ulp from our master's t_0 + i * h and h.
- Initialization: the start values are set, all FMUs enter initialization mode, then the connected
  values are exchanged N times (N = number of FMUs, so twice here: our FMUs need two passes), then
  all exit initialization mode and the outputs are exchanged once more. The connections therefore
  start from the initialized outputs, as in our master (not from 0 as in fmpy's SSP runner).
- Stepping: the fixed-step algorithm is Jacobi: every FMU steps from t_i with the inputs set at the
  end of the previous step (called from libcosim's worker threads), then all outputs are copied
  to the inputs.
  The plant therefore gets the controller's torque one step late (the torque from the sample at
  t_{i-1}), unlike our Gauss-Seidel default: compare with `RunOptions(algorithm="jacobi")`.
- Recording (time-series observer): step 0 holds the outputs after initialization, step i + 1 the
  outputs after the step ending at t_{i+1}: the same rows as our master's RunResult.
- Errors: a step an FMU refuses fails the step; `simulate_until` returns False, the process lives
  on, and libcosim's last error message names only the component ("plant: Step not complete"):
  the FMU's own message goes to libcosim's log (level error) and, from our FMUs, to stderr. An FMU
  error during initialization (e.g. a bad parameter value) instead aborts the whole process
  (SIGABRT: libcosim's worker thread throws, nothing catches it): check parameters first, or run
  this function in a subprocess when they may be bad.
- Logging: libcosim logs at debug level to stderr unless told otherwise (a global setting of the
  process); `log_level` sets it.
- libcosimpy's `time_series_real_samples` drops one sample from the end for each sample whose step
  number is 0, so step 0 is read on its own (see `_samples`).

On the same time grid (t_i and step lengths as above) our Jacobi master gives bit-identical
results; on its own grid the two runs differ by round-off only, at most 7e-11 over the 20 s
observer scenario (tests/test_other_engine.py checks both). Our Gauss-Seidel run differs by the
one-step torque delay (up to 4 N of contact force, 1 N m of torque).
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from impedance_cosim.cosim.system.paper import CONNECTIONS

LOG_LEVELS = ("trace", "debug", "info", "warning", "error", "fatal")
NS_PER_S = 1_000_000_000


class EngineError(RuntimeError):
    """The other engine could not load or run the system; the message says why."""


def _whole_ns(seconds: float, what: str) -> int:
    ns = round(seconds * NS_PER_S)
    if ns <= 0 or abs(ns - seconds * NS_PER_S) > 1e-6:
        raise ValueError(f"{what} must be a positive whole number of nanoseconds (got {seconds})")
    return ns


def typed_value(value: str, kind: str) -> Any:
    """An SSV parameter value (text) as the Python value of its SSP type (Real, Integer, Boolean,
    String): what an engine's setter or a container's start value takes."""
    if kind == "Real":
        return float(value)
    if kind == "Integer":
        return int(value)
    if kind == "Boolean":
        return value.strip().lower() in ("true", "1")
    return value


def _samples(observer: Any, slave: int, ref: int, steps: int) -> np.ndarray:
    """Values of one observed Real variable at steps 0..steps, checking the step numbers.

    libcosimpy trims its arrays by the count of step numbers equal to 0, so a request from step 0
    loses its last sample: step 0 is read as the first of two samples, the rest from step 1.
    """
    _, first_steps, first = observer.time_series_real_samples(slave, ref, 0, 2)
    _, rest_steps, rest = observer.time_series_real_samples(slave, ref, 1, steps)
    if list(first_steps[:1]) != [0] or list(rest_steps) != list(range(1, steps + 1)):
        raise EngineError(f"libcosim's observer lost samples of variable {ref} of slave {slave}")
    return np.array([first[0], *rest])


def run_in_libcosim(
    ssp_path: str | Path,
    parameter_set: str | None = "observer",
    stop_time: float = 20.0,
    step_size: float = 0.0025,
    log_level: str = "warning",
) -> dict[str, np.ndarray]:
    """Run an SSP archive in libcosim's fixed-step (Jacobi) algorithm for stop_time seconds from
    the SSD's start time (0 in ours); conventions above. parameter_set None: only what libcosim
    applies itself (the component-level bindings of SystemStructure.ssd: a scenario's own
    archive); a name: that set of the archive (read by our reader, from any variant SSD) is
    given to libcosim as initial values on top.

    Returns "time" (t_i = (start_ns + i * h_ns) / 1e9 s, the start time being the SSD's) and
    every Real output as "component.variable", each an array of stop_time / step_size + 1
    values: the outputs after initialization, then after each step. Raises ImportError without
    libcosimpy, ValueError for a bad argument and EngineError when libcosim fails to load or run
    the system.
    """
    if log_level not in LOG_LEVELS:
        raise ValueError(f"log_level must be one of {LOG_LEVELS} (got {log_level!r})")
    h_ns = _whole_ns(step_size, "step_size")
    steps = round(stop_time / step_size)
    if steps < 1 or abs(steps * h_ns - stop_time * NS_PER_S) > 1e-3:
        raise ValueError(f"stop_time {stop_time} is not a whole number of {step_size} s steps")

    from libcosimpy._internal import get_last_error_message
    from libcosimpy.CosimEnums import CosimVariableCausality, CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    params = _parameter_set(ssp_path, parameter_set)
    log_output_level(CosimLogLevel[log_level.upper()])
    try:
        execution = CosimExecution.from_ssp_file(str(ssp_path), step_size=h_ns)
    except AssertionError:
        raise EngineError(f"libcosim cannot load {ssp_path}: {get_last_error_message()}") from None
    slaves = {info.name.decode(): info.index for info in execution.slave_infos()}
    variables = {
        name: {v.name.decode(): v for v in execution.slave_variables(index)}
        for name, index in slaves.items()
    }

    _set_initial_values(execution, slaves, variables, params)
    observer = CosimObserver.create_time_series(buffer_size=steps + 1)
    execution.add_observer(observer)
    outputs = [
        (f"{component}.{name}", slaves[component], v.reference)
        for component, vs in variables.items()
        for name, v in vs.items()
        if v.causality == CosimVariableCausality.OUTPUT.value
        and v.type == CosimVariableType.REAL.value
    ]
    for _, index, ref in outputs:
        observer.start_time_series(index, ref, CosimVariableType.REAL)

    start_ns = execution.status().current_time
    if not execution.simulate_until(start_ns + steps * h_ns):
        reached = execution.status().current_time / NS_PER_S
        raise EngineError(f"libcosim stopped at t={reached:g} s: {get_last_error_message()}")

    result = {"time": (start_ns + np.arange(steps + 1) * h_ns) / NS_PER_S}
    for key, index, ref in outputs:
        result[key] = _samples(observer, index, ref, steps)
    return result


def _parameter_set(ssp_path: str | Path, parameter_set: str | None) -> list:
    """The parameters of the named set of the archive (read by our reader), [] for None."""
    from impedance_cosim.cosim.ssp.read import read_ssp

    if parameter_set is None:
        return []
    with tempfile.TemporaryDirectory(prefix="impcosim_libcosim_") as tmp:
        sets = read_ssp(ssp_path, extract_to=Path(tmp)).parameter_sets
    if parameter_set not in sets:
        raise ValueError(f"no parameter set {parameter_set!r} in {ssp_path} (have {list(sets)})")
    return sets[parameter_set]


def _set_initial_values(execution, slaves: dict, variables: dict, params: list) -> None:
    """Each parameter as libcosim's initial value of its variable (EngineError if refused)."""
    from libcosimpy._internal import get_last_error_message
    from libcosimpy.CosimEnums import CosimVariableType

    setters = {
        CosimVariableType.REAL.value: execution.real_initial_value,
        CosimVariableType.INTEGER.value: execution.integer_initial_value,
        CosimVariableType.BOOLEAN.value: execution.boolean_initial_value,
        CosimVariableType.STRING.value: execution.string_initial_value,
    }
    for p in params:
        component, name = p.name.split(".", 1)
        v = variables.get(component, {}).get(name)
        if v is None:
            raise EngineError(f"parameter {p.name}: no such variable in libcosim's system")
        if not setters[v.type](slaves[component], v.reference, typed_value(p.value, p.type)):
            reason = get_last_error_message()
            raise EngineError(f"parameter {p.name}: libcosim refused it: {reason}")


# --- other engines' time grids and start values, for RunOptions(step_times=..., zero_start_inputs=)


class AccumulatedTimes:
    """Step times t_i+1 = t_i + h accumulated in floating point, as fmpy's simulate_ssp and ecospy
    step (a callable for RunOptions(step_times=...): step i -> (t_i, h))."""

    def __init__(self, start: float, step: float) -> None:
        self.step = step
        self.times = [start]

    def __call__(self, i: int) -> tuple[float, float]:
        while len(self.times) <= i:
            self.times.append(self.times[-1] + self.step)
        return self.times[i], self.step


def nanosecond_times(start: float, step: float) -> Callable[[int], tuple[float, float]]:
    """libcosim's grid: t_i = (start_ns + i h_ns) / 1e9 and length t_i+1 - t_i (see above)."""
    start_ns, h_ns = round(start * NS_PER_S), _whole_ns(step, "step")

    def times(i: int) -> tuple[float, float]:
        t = (start_ns + i * h_ns) / NS_PER_S
        return t, (start_ns + (i + 1) * h_ns) / NS_PER_S - t

    return times


# --- fmpy's simulate_ssp and ecospy: each run with the engine's own API only ---------------------


def fmpy_bindings(ssp_path: str | Path):
    """The ParameterBindings of an archive's SystemStructure.ssd as one fmpy ParameterSet with
    whole "component.variable" names: simulate_ssp applies no binding itself."""
    from fmpy.ssp.ssd import ParameterSet, read_ssd

    bound = ParameterSet(name="bound")
    for c in read_ssd(str(ssp_path)).system.elements:
        for p in (p for b in c.parameterBindings for s in b.parameterValues for p in s.parameters):
            p.name = f"{c.name}.{p.name}"  # component-relative names, as fmpy wants them whole
            bound.parameters.append(p)
    return bound


def run_in_fmpy(ssp_path: str | Path, stop_time: float, step_size: float) -> dict[str, np.ndarray]:
    """fmpy's simulate_ssp on an archive's SystemStructure.ssd. It applies no ParameterBinding
    itself, so the bindings (read with fmpy's own read_ssd) are passed as its parameter_set.
    Returns every connector as "component.connector": row i holds the values after step i (fmpy
    stamps it with the step's start time, which is left out), stop_time / step_size rows."""
    from fmpy.ssp.simulation import simulate_ssp

    rows = simulate_ssp(
        str(ssp_path),
        stop_time=stop_time,
        step_size=step_size,
        parameter_set=fmpy_bindings(ssp_path),
    )
    n = round(stop_time / step_size)  # fmpy's accumulated time may add one more step
    return {name: rows[name][:n] for name in rows.dtype.names if name != "time"}


def run_in_ecospy(
    ssp_path: str | Path, parameter_set: str | None, stop_time: float, step_size: float,
    names: list[str],
) -> dict[str, np.ndarray]:  # fmt: skip
    """ecospy on an archive's SystemStructure.ssd, applying the named parameter set (ecospy
    applies bindings only when their set is named). Returns the Real variables `names`
    ("component.variable") after initialization and after each step (stop_time / step_size + 1
    rows). ImportError/OSError when ecospy (or Debian's libtbb12) is missing."""
    import ecospy

    sim = ecospy.EcosSimulation(step_size=step_size, ssp_path=str(ssp_path))
    try:
        if not sim.init(parameter_set=parameter_set):
            raise EngineError(f"ecospy could not initialize {ssp_path}")
        n = round(stop_time / step_size)
        rows = []
        for i in range(n + 1):
            rows.append([sim.get_real(name.replace(".", "::")) for name in names])
            if i < n:
                sim.step()
        sim.terminate()
    finally:
        sim.free()
    values = np.array(rows)
    return {name: values[:, k] for k, name in enumerate(names)}


# --- comparing their rows with our master's ----------------------------------------------------

CONNECTED = sorted({f"{s}.{c}" for s, c, _, _ in CONNECTIONS})  # every connected output


def largest_difference(ours: dict, theirs: dict, shift: int = 0) -> tuple[float, str]:
    """Largest |difference| over the connected outputs, their row i against our row i + shift
    (fmpy's rows are one step behind), and the output where it is."""
    diffs = {n: float(np.max(np.abs(ours[n][shift : shift + len(theirs[n])] - theirs[n])))
             for n in CONNECTED}  # fmt: skip
    name = max(diffs, key=diffs.__getitem__)
    return diffs[name], name


def first_beyond(rows: dict, limit: float = 1e6, name: str = "controller.tau1") -> int | None:
    """The first row whose |name| exceeds limit (the unstable scenarios' divergence), or None."""
    beyond = np.nonzero(np.abs(rows[name]) > limit)[0]
    return int(beyond[0]) if len(beyond) else None
