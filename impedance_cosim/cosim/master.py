"""The co-simulation master: runs an SSP system of FMUs at a fixed communication step.

- Parameters: the chosen parameter set of the SSD's ParameterBindings (default: the first), then
  the user's overrides ("component.variable" = value; "controller.K" sets K1..K3).
- Initialization: every FMU enters initialization mode, then the master exchanges the connected
  values until they stop changing (a fixed point; our FMUs need two passes), then exits.
- Stepping, t_i = start + i * h exactly (no accumulated time):
  * Gauss-Seidel: the components in order (default controller, then plant: the paper's
    sample-and-hold) each take their inputs from the latest outputs, then step;
  * Jacobi: all inputs are taken from the outputs at t_i, then all components step.
- Recording: one row at t_0 (after initialization) and one at each t_i+1 = the outputs after the
  step that ends there (as FMI defines them: a sampled output holds the last sample's value), every
  Real output of every component ("plant.x", "controller.tau1", ...), so every connection too.
- Real time (`realtime=True`, or realtime.RealtimeOptions to also lock memory, run SCHED_FIFO,
  pin a CPU, set the busy-wait): step i starts at the wall-clock time t0_wall + i * h, t0_wall
  taken after initialization (the loop is realtime.paced_steps). Per step the result gets three
  extra columns: `rt.start_late_s` (actual start - scheduled start: the jitter),
  `rt.compute_s` (the step's duration) and `rt.lateness_s` (completion - deadline
  t0_wall + (i + 1) h; > 0 is a deadline miss); RunResult.info["realtime"] holds the statistics
  (see realtime_stats) and the options' notes (what the OS granted or refused).
- Every FMI status is checked. A failing FMU, a non-finite value or a value beyond
  `divergence_limit` stops the run with a message naming the signal and time; the rows computed so
  far are kept in the result.
- Rows reach an optional sink as they are computed (results.py writes them to a CSV); SIGINT or
  SIGTERM stops a run between blocks of steps and raises RunInterrupted with the rows so far
  (interrupt.py). A run whose rows would not fit in memory is refused before it starts.
"""

from __future__ import annotations

import ctypes
import math
import sys
import time as wallclock
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from impedance_cosim.cosim import fastloop, realtime
from impedance_cosim.cosim.fmu import (
    STATUS,
    FmuError,
    FmuInstance,
    check_fmu,
    fmi_value,
    model_description,
)
from impedance_cosim.cosim.fmu3 import is_fmi3, open_fmu, ssp_type
from impedance_cosim.cosim.realtime import RealtimeOptions
from impedance_cosim.cosim.results import Feed, Sink, size_problem
from impedance_cosim.cosim.ssp import SspError, SystemDescription
from impedance_cosim.fmi.variables import ENUMERATIONS
from impedance_cosim.util.interrupt import RunInterrupted, StopSignals, signal_name

ALGORITHMS = ("gauss-seidel", "jacobi")
CHUNK = 400  # steps per call into the loop (progress bar, interrupts)
RT_COLUMNS = ["rt.start_late_s", "rt.compute_s", "rt.lateness_s"]
MAX_INIT_PASSES = 20


class MasterError(RuntimeError):
    """The system cannot be run as configured (bad parameter name, missing connector...)."""


@dataclass
class RunResult:
    """Recorded signals (rows up to where the run stopped) and why it stopped, if it failed."""

    names: list[str]
    data: np.ndarray
    step_size: float
    algorithm: str
    parameter_set: str
    error: str | None = None
    wall_time: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.data[:, self.names.index(name)]
        except ValueError:
            raise KeyError(f"no recorded signal {name!r}") from None

    @property
    def ok(self) -> bool:
        return self.error is None


def split_name(name: str) -> tuple[str, str]:
    """ "component.variable" -> (component, variable), with a clear error."""
    if "." not in name:
        raise MasterError(f"parameter {name!r} must be written component.variable")
    comp, var = name.split(".", 1)
    return comp, var


def real_outputs(description: Any) -> list[str]:
    """Names of an FMU's Real outputs, in model order (the recorded signals)."""
    return [
        v.name
        for v in description.modelVariables
        if v.causality == "output" and ssp_type(v.type) == "Real"
    ]


def connector_problems(comp, fmu_vars: Mapping[str, Any], fmu_name: str) -> list[str]:
    """How an FMU's variables (name -> fmpy ScalarVariable) differ from a component's SSD
    connectors: a missing variable, another causality, type or unit (one line each)."""
    problems = []
    for c in comp.connectors.values():
        v = fmu_vars.get(c.name)
        where = f"{comp.name}.{c.name}"
        if v is None:
            problems.append(f"{where}: no such variable in {fmu_name}")
            continue
        if v.causality != c.kind:
            problems.append(f"{where}: causality {v.causality} in the FMU, {c.kind} in the SSD")
        if ssp_type(v.type) != c.type:
            problems.append(f"{where}: type {v.type} in the FMU, {c.type} in the SSD")
        if c.type == "Real" and (v.unit or None) != (c.unit or None):
            problems.append(f"{where}: unit {v.unit} in the FMU, {c.unit} in the SSD")
    return problems


class _Slot:
    """One component during a run: its FMU instance and fast accessors."""

    def __init__(self, name: str, fmu: FmuInstance) -> None:
        self.name = name
        self.fmu = fmu
        self.outputs = real_outputs(fmu.description)
        self.read = fmu.real_getter(self.outputs)
        self.values: list[float] = []
        self.inputs: list[str] = []
        self.sources: list[tuple[int, int]] = []  # (slot index, output index) per input
        self.write = None


class Master:
    """Prepare and run one system (see module docstring)."""

    def __init__(
        self,
        system: SystemDescription,
        parameter_set: str | None = None,
        overrides: Mapping[str, Any] | None = None,
        algorithm: str | None = None,
        step_size: float | None = None,
        stop_time: float | None = None,
        divergence_limit: float = 1e6,
        fmu_files: Mapping[str, Path] | None = None,
        loop: str = "auto",
        realtime: bool | RealtimeOptions = False,
        step_times: Callable[[int], tuple[float, float]] | None = None,
        zero_start_inputs: bool = False,
        instances: Any = None,
    ) -> None:
        self.system = system
        # Another engine's conventions, to compare with it (Python loop only; engines.py has
        # them): step_times(i) gives step i's start time and length (default t_0 + i h, h);
        # zero_start_inputs: the first step's connected inputs are 0.0, not the initialized
        # outputs (with Jacobi).
        self.step_times = step_times
        self.zero_start_inputs = zero_start_inputs
        self.algorithm = algorithm or system.algorithm or "gauss-seidel"
        if self.algorithm not in ALGORITHMS:
            raise MasterError(f"algorithm must be one of {ALGORITHMS} (got {self.algorithm!r})")
        self.step_size = step_size if step_size is not None else system.step_size
        if self.step_size is None or not 0 < self.step_size < math.inf:
            raise MasterError(f"step size must be a finite number > 0 (got {self.step_size})")
        self.start_time = system.start_time
        self.stop_time = stop_time if stop_time is not None else system.stop_time
        if self.stop_time is None or not self.start_time < self.stop_time < math.inf:
            raise MasterError(f"stop time must be finite and > start time (got {self.stop_time})")
        steps = (self.stop_time - self.start_time) / self.step_size
        if not math.isfinite(steps):
            raise MasterError(f"stop time {self.stop_time:g} s at step {self.step_size:g} s is too"
                              " many steps")  # fmt: skip
        if abs(steps - round(steps)) > 1e-9 * max(1.0, steps):
            raise MasterError(
                f"the run length {self.stop_time - self.start_time:g} s is not a whole number of"
                f" {self.step_size:g} s steps"
            )
        self.divergence_limit = divergence_limit
        if loop not in ("auto", "c", "python"):
            raise MasterError(f"loop must be auto, c or python (got {loop!r})")
        if (step_times or zero_start_inputs) and (loop == "c" or realtime):
            raise MasterError("step_times and zero_start_inputs need the Python loop")
        if zero_start_inputs and self.algorithm != "jacobi":
            raise MasterError("zero_start_inputs needs the Jacobi algorithm")
        loop = "python" if step_times or zero_start_inputs else loop
        self.loop = loop
        self.realtime = realtime
        self.instances = instances  # an fmu_pool.InstancePool: reuse FMU instances across runs
        sets = system.parameter_sets
        if parameter_set is None:
            parameter_set = next(iter(sets), "")
        elif parameter_set not in sets:
            raise MasterError(f"no parameter set {parameter_set!r} in the SSD (have {list(sets)})")
        self.parameter_set = parameter_set
        order = system.order or [c.name for c in system.components]
        names = [c.name for c in system.components]
        if sorted(order) != sorted(names):
            raise MasterError(f"the step order {order} does not list the components {names}")
        self.order = order
        self.fmu_files = {c.name: Path(c.fmu) for c in system.components}
        for name, path in (fmu_files or {}).items():
            if name not in self.fmu_files:
                raise MasterError(f"no component {name!r} to replace (have {names})")
            self.fmu_files[name] = Path(path)
        self.parameters = self._collect_parameters(overrides or {})
        columns = 1 + sum(len(real_outputs(md)) for md in self.descriptions.values())
        columns += len(RT_COLUMNS) if realtime else 0
        too_big = size_problem(int(round(steps)), columns, self.stop_time, self.step_size)
        if too_big:
            raise MasterError(too_big)

    # --- configuration checks -------------------------------------------------------------------

    def _collect_parameters(self, overrides: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
        """Parameter values per component, checked against the FMUs' variables and units."""
        self.descriptions = {}
        for name, path in self.fmu_files.items():
            if not path.is_file():
                raise MasterError(f"component {name}: FMU {path} does not exist")
            try:
                self.descriptions[name] = model_description(path)
            except Exception as exc:
                raise MasterError(f"component {name}: cannot read {path.name}: {exc}") from None
            try:
                check_fmu(path, self.descriptions[name])
            except FmuError as exc:
                raise MasterError(f"component {name}: {exc}") from None
        variables = {
            name: {v.name: v for v in md.modelVariables} for name, md in self.descriptions.items()
        }
        self._check_connectors(variables)
        values: dict[str, dict[str, Any]] = {name: {} for name in self.fmu_files}
        for p in self.system.parameter_sets.get(self.parameter_set, []):
            comp, var = split_name(p.name)
            v = self._parameter_variable(
                variables, comp, var, f"in parameter set {self.parameter_set!r}"
            )
            if p.unit and v.unit and p.unit != v.unit:
                raise MasterError(f"parameter {p.name}: unit {p.unit} but the FMU's is {v.unit}")
            values[comp][var] = self._value(v, p.value, p.name)
        for name, value in overrides.items():
            comp, var = split_name(name)
            targets = [var]
            if comp in variables and var not in variables[comp]:
                vector = [f"{var}{i}" for i in (1, 2, 3)] + [f"{var}_{i}" for i in (1, 2, 3)]
                targets = [n for n in vector if n in variables[comp]] or [var]
            for t in targets:
                v = self._parameter_variable(variables, comp, t, "given with --set")
                values[comp][t] = self._value(v, value, f"{comp}.{t}")
        return values

    def _parameter_variable(self, variables, comp: str, var: str, where: str):
        if comp not in variables:
            raise MasterError(f"unknown component {comp!r} {where} (have {list(variables)})")
        v = variables[comp].get(var)
        if v is None:
            raise MasterError(f"unknown parameter {comp}.{var} {where}")
        if v.causality != "parameter":
            raise MasterError(f"{comp}.{var} is a{'n' if v.causality[0] in 'aeiou' else ''} "
                              f"{v.causality}, not a parameter")  # fmt: skip
        return v

    @staticmethod
    def _value(v, value: Any, name: str) -> Any:
        enum = ENUMERATIONS.get(getattr(v.declaredType, "name", ""))
        try:
            if enum and isinstance(value, str) and not value.strip().lstrip("+-").isdigit():
                try:  # an item name of our enumerations ("difference" for velocity_source)
                    value = enum.value(value.strip())
                except ValueError as exc:
                    raise ValueError(f"variable {name}: {exc}") from None
            return fmi_value(v.type, value, name)
        except ValueError as exc:
            raise MasterError(str(exc)) from None

    def _check_connectors(self, variables) -> None:
        """Every SSD connector exists in its FMU with the same causality, type and unit."""
        problems = []
        for comp in self.system.components:
            fmu_name = self.fmu_files[comp.name].name
            problems += connector_problems(comp, variables[comp.name], fmu_name)
        if problems:
            raise MasterError("the FMUs do not match the SSD: " + "; ".join(problems))

    # --- run ------------------------------------------------------------------------------------

    def run(self, progress: bool | TextIO = False, sink: Sink | None = None) -> RunResult:
        """Run the system; never raises for a failure during the run (see RunResult.error).

        progress: a progress bar on stderr (or on the stream given). sink(names, rows), if given,
        gets the header (no rows) first, then each block of rows as it is computed (all at the
        end in real time), on every exit path. The first SIGINT or SIGTERM stops the run after
        the block under way: RunInterrupted, carrying the rows so far, is raised once the FMUs
        are freed (see interrupt.py)."""
        with StopSignals() as stop:
            result = self._run(progress, sink, stop)
        if stop.signum is not None:
            t = result.data[-1, 0] if len(result.data) else self.start_time
            result.error = f"interrupted by {signal_name(stop.signum)} at t={t:.9g} s"
            result.info["interrupted"] = stop.signum
            raise RunInterrupted(result.error, stop.signum, result)
        return result

    def _run(self, progress: bool | TextIO, sink: Sink | None, stop: StopSignals) -> RunResult:
        outputs = {n: real_outputs(self.descriptions[n]) for n in self.order}
        names = ["time", *(f"{n}.{o}" for n in self.order for o in outputs[n])]
        record = [*names, *RT_COLUMNS] if self.realtime else names
        h, t0 = self.step_size, self.start_time
        n = int(round((self.stop_time - t0) / h))
        data = np.empty((n + 1, len(names)))
        rows, error = 0, None
        timing = np.zeros((n + 1, len(RT_COLUMNS))) if self.realtime else None
        info: dict[str, Any] = {}
        feed = Feed(sink, record)
        feed(data, rows, timing)
        started = wallclock.perf_counter()
        bar = _Progress(n, h, sys.stderr if progress is True else progress) if progress else None
        ordered: list[_Slot] = []
        try:
            for name in self.order:
                path = self.fmu_files[name]
                fmu = self.instances.take(path, name, open_fmu) if self.instances else None
                ordered.append(_Slot(name, fmu or open_fmu(path, name)))
            self._wire(ordered)
            self._initialize(ordered)
            data[0] = (t0, *(v for s in ordered for v in s.values))
            rows = 1
            feed(data, rows, timing)
            error = self._check_row(names, data[0], t0)
            fmi3 = [s.name for s in ordered if is_fmi3(s.fmu.description)]
            if self.loop == "c" and fmi3:
                raise MasterError(f"the C loop runs FMI 2.0 FMUs only ({', '.join(fmi3)}: 3.0)")
            fast = fastloop.load() if self.loop != "python" and not fmi3 else None
            if self.loop == "c" and fast is None:
                raise MasterError("the C loop cannot be compiled here (no C compiler?)")
            step = self._c_steps(fast, ordered, data, names) if fast else self._python_steps
            stepping = wallclock.perf_counter()
            if self.realtime and not error:
                rt = self.realtime if isinstance(self.realtime, RealtimeOptions) else None
                rt = rt or RealtimeOptions()
                with realtime.applied(rt) as notes:
                    rows, error = realtime.paced_steps(
                        lambda i: step(ordered, data, names, i, 1),
                        n,
                        h,
                        timing,
                        rt.spin_s,
                        lambda: stop.signum is not None,
                        bar.update if bar else None,
                    )
                info["realtime"] = {**realtime_stats(timing[1:rows], h), "notes": notes}
            while not error and rows < n + 1 and stop.signum is None:
                chunk = min(n + 1 - rows, CHUNK)
                done, error = step(ordered, data, names, rows - 1, chunk)
                rows += done
                feed(data, rows, timing)
                if bar:
                    bar.update(rows - 1)
            info["stepping_s"] = wallclock.perf_counter() - stepping
            info["loop"] = "c" if fast else "python"
        except (FmuError, MasterError, SspError, ValueError, KeyError) as exc:
            error = str(exc)
        finally:
            if bar:
                bar.close()
            for s in ordered:
                try:
                    s.fmu.terminate()
                    clean = error is None
                except FmuError:
                    clean = False
                self.instances.give(s.fmu, clean) if self.instances else s.fmu.free()
            feed(data, rows, timing)
        data = data[:rows]
        if self.realtime:
            names = record
            data = np.hstack((data, timing[:rows]))
        return RunResult(
            names=names,
            data=data,
            step_size=h,
            algorithm=self.algorithm,
            parameter_set=self.parameter_set,
            error=error,
            wall_time=wallclock.perf_counter() - started,
            info=info,
        )

    def _wire(self, ordered: list[_Slot]) -> None:
        """Each component's inputs: the (component, output) that feeds it, per the SSD."""
        index = {s.name: i for i, s in enumerate(ordered)}
        for se, sc, ee, ec in self.system.connections:
            dst = ordered[index[ee]]
            dst.inputs.append(ec)
            dst.sources.append((index[se], ordered[index[se]].outputs.index(sc)))
        for s in ordered:
            s.write = s.fmu.real_setter(s.inputs)

    def _python_steps(self, ordered, data, names, first: int, count: int):
        """Steps first .. first + count - 1 in Python; returns (rows filled, error or None)."""
        h, t0 = self.step_size, self.start_time
        jacobi = self.algorithm == "jacobi"
        for i in range(first, first + count):
            t, h_i = self.step_times(i) if self.step_times else (t0 + i * h, h)
            try:
                if jacobi:
                    zero = self.zero_start_inputs and i == 0
                    for s in ordered:
                        s.write([0.0 if zero else ordered[j].values[k] for j, k in s.sources])
                    for s in ordered:
                        s.fmu.step(t, h_i)
                    for s in ordered:
                        s.values = s.read()
                else:
                    for s in ordered:
                        s.write([ordered[j].values[k] for j, k in s.sources])
                        s.fmu.step(t, h_i)
                        s.values = s.read()
            except FmuError as exc:
                return i - first, str(exc)
            t_next = t0 + (i + 1) * h
            data[i + 1] = (t_next, *(v for s in ordered for v in s.values))
            error = self._check_row(names, data[i + 1], t_next)
            if error:
                return i + 1 - first, error
        return count, None

    def _c_steps(self, lib, ordered, data, names):
        """The same steps in the compiled loop (native/master/loop.c); returns a step function."""
        offsets, col = {}, 1
        for s in ordered:
            offsets[s.name] = col
            col += len(s.outputs)
        comps = (fastloop.Comp * len(ordered))()
        keep = []  # the ctypes arrays must outlive the loop
        for c, s in zip(comps, ordered, strict=True):
            in_vr = (ctypes.c_uint * max(1, len(s.inputs)))(*(s.fmu.vr(n) for n in s.inputs))
            in_col = (ctypes.c_int * max(1, len(s.inputs)))(
                *(offsets[ordered[j].name] + k for j, k in s.sources)
            )
            out_vr = (ctypes.c_uint * max(1, len(s.outputs)))(*(s.fmu.vr(n) for n in s.outputs))
            keep += [in_vr, in_col, out_vr]
            functions = s.fmu.slave._functions
            c.component = s.fmu.slave.component
            c.set_real = ctypes.cast(functions["fmi2SetReal"], ctypes.c_void_p).value
            c.get_real = ctypes.cast(functions["fmi2GetReal"], ctypes.c_void_p).value
            c.do_step = ctypes.cast(functions["fmi2DoStep"], ctypes.c_void_p).value
            c.n_in, c.in_vr, c.in_col = len(s.inputs), in_vr, in_col
            c.n_out, c.out_vr, c.out_col = len(s.outputs), out_vr, offsets[s.name]
        assert data.flags["C_CONTIGUOUS"] and data.dtype == np.float64
        jacobi = int(self.algorithm == "jacobi")

        def steps(_ordered, _data, _names, first: int, count: int):
            err = fastloop.LoopError()
            done = lib.run_loop(comps, len(ordered), jacobi, self.start_time, self.step_size,
                                first, count, self.divergence_limit,
                                data.ctypes.data, data.shape[1], ctypes.byref(err))  # fmt: skip
            _ = keep
            if err.comp >= 0:
                s = ordered[err.comp]
                s.fmu.fatal |= err.status == 4
                call = ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal")[err.call]
                t = self.start_time + (first + done) * self.step_size
                detail = "; ".join(s.fmu.errors()[-3:]) or "no message logged"
                status = STATUS[err.status] if 0 <= err.status < len(STATUS) else err.status
                return done, f"{s.name}: {call} at t={t} returned {status} ({detail})"
            if err.column >= 0:
                row = data[first + done]
                return done, self._check_row(names, row, row[0])
            return done, None

        return steps

    def _initialize(self, ordered: list[_Slot]) -> None:
        for s in ordered:
            s.fmu.setup(self.start_time, self.stop_time)
            s.fmu.set(self.parameters[s.name])
            s.fmu.enter_initialization()

        # First values: components whose outputs depend on no input (declared in ModelStructure)
        # are read first, so the others start from real inputs rather than their start values.
        def independent(s: _Slot) -> bool:
            outs = s.fmu.description.outputs
            # (an FMU with Model Exchange also lists its continuous states there: not inputs)
            return bool(outs) and all(
                u.dependencies is not None and all(d.causality != "input" for d in u.dependencies)
                for u in outs
            )

        for s in sorted(ordered, key=lambda s: not independent(s)):
            ready = [(j, k) for j, k in s.sources if ordered[j].values]
            if s.sources and len(ready) == len(s.sources):
                s.write([ordered[j].values[k] for j, k in s.sources])
            s.values = s.read()
        for _ in range(MAX_INIT_PASSES):
            changed = False
            for s in ordered:
                new = [ordered[j].values[k] for j, k in s.sources]
                s.write(new)
                values = s.read()
                changed |= values != s.values
                s.values = values
            if not changed:
                break
        else:
            raise MasterError(f"initial values did not settle in {MAX_INIT_PASSES} passes")
        for s in ordered:
            s.fmu.exit_initialization()
            s.values = s.read()

    def _check_row(self, names: list[str], row: np.ndarray, t: float) -> str | None:
        bad = ~np.isfinite(row) | (np.abs(row) > self.divergence_limit)
        if not bad.any():
            return None
        k = int(np.argmax(bad))
        return f"diverged at t={t:g} s: {names[k]} = {row[k]:.6g} (limit {self.divergence_limit:g})"


def realtime_stats(timing: np.ndarray, h: float) -> dict[str, Any]:
    """Statistics of the steps' timing rows (RT_COLUMNS): deadline misses (a step completed after
    its deadline), start jitter (actual - scheduled start) p50/p99/max, step duration p99/max,
    worst lateness; times in seconds."""
    if not len(timing):
        return {"steps": 0, "rate_hz": 1.0 / h, "deadline_misses": 0}
    start, compute, late = timing[:, 0], timing[:, 1], timing[:, 2]
    return {
        "steps": len(timing),
        "rate_hz": 1.0 / h,
        "deadline_misses": int(np.count_nonzero(late > 0.0)),
        "jitter_p50_s": float(np.percentile(start, 50)),
        "jitter_p99_s": float(np.percentile(start, 99)),
        "jitter_max_s": float(start.max()),
        "compute_p50_s": float(np.percentile(compute, 50)),
        "compute_p99_s": float(np.percentile(compute, 99)),
        "compute_max_s": float(compute.max()),
        "lateness_max_s": float(late.max()),
    }


def format_realtime(stats: dict[str, Any]) -> str:
    """The real-time statistics as summary lines."""
    if not stats.get("steps"):
        return "real time: no step taken"
    ms = 1e3
    return (
        f"real time at {stats['rate_hz']:g} Hz: {stats['deadline_misses']} deadline misses in"
        f" {stats['steps']} steps\n"
        f"start jitter: p50 {ms * stats['jitter_p50_s']:.3f} ms, p99"
        f" {ms * stats['jitter_p99_s']:.3f} ms, max {ms * stats['jitter_max_s']:.3f} ms\n"
        f"step duration: p50 {ms * stats['compute_p50_s']:.3f} ms, p99"
        f" {ms * stats['compute_p99_s']:.3f} ms, max {ms * stats['compute_max_s']:.3f} ms"
        f" (worst slack {-ms * stats['lateness_max_s']:.3f} ms)"
    ) + "".join(f"\nreal time: {note}" for note in stats.get("notes", []))


class _Progress:
    """A one-line progress bar on stderr, shown once a run has taken more than a second."""

    def __init__(self, steps: int, h: float, stream: TextIO) -> None:
        self.steps, self.h, self.stream = steps, h, stream
        self.start = wallclock.perf_counter()
        self.last = 0.0
        self.shown = False

    def update(self, i: int) -> None:
        now = wallclock.perf_counter() - self.start
        if now < 1.0 or now - self.last < 0.2:
            return
        self.last, self.shown = now, True
        frac = i / self.steps
        bar = "#" * int(30 * frac)
        rtf = i * self.h / now
        self.stream.write(
            f"\r[{bar:<30}] {100 * frac:5.1f}%  t={i * self.h:7.2f} s  {rtf:6.1f}x real time"
        )
        self.stream.flush()

    def close(self) -> None:
        if self.shown:
            self.stream.write("\n")
