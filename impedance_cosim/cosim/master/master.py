"""The co-simulation master: runs an SSP system of FMUs at a fixed communication step.

- Parameters: the chosen parameter set of the SSD's ParameterBindings (default: the first), then
  the user's overrides ("component.variable" = value; "controller.K" sets K1..K3).
- Initialization: every FMU enters initialization mode, then the master exchanges the connected
  values until they stop changing (a fixed point; our FMUs need two passes), then exits.
- Stepping, t_i = start + i * h exactly (no accumulated time):
  * Gauss-Seidel: the components in order (default controller, then plant: the paper's
    sample-and-hold) each take their inputs from the latest outputs, then step;
  * Jacobi: all inputs are taken from the outputs at t_i, then all components step;
    `extrapolation="linear"`: y(t_i) + h dy/dt(t_i) where the source gives dy/dt
    (extrapolation.py).
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
- Every FMI status is checked. A failing FMU stops the run ("failed"); a non-finite value or a
  value beyond `divergence_limit` stops it as "diverged" (RunResult.divergence names the signal
  and time). Either way the rows computed so far are kept in the result.
- Rows reach an optional sink as they are computed (results.py writes them to a CSV); SIGINT or
  SIGTERM stops a run between blocks of steps and raises RunInterrupted with the rows so far
  (interrupt.py). A run whose rows would not fit in memory is refused before it starts.
"""

from __future__ import annotations

import sys
import time as wallclock
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from impedance_cosim.cosim.fmus.fmi2 import FmuError, FmuInstance
from impedance_cosim.cosim.fmus.fmi3 import open_fmu, signals
from impedance_cosim.cosim.master import c_loop, realtime
from impedance_cosim.cosim.master import extrapolation as extra
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.master.realtime import RealtimeOptions, realtime_stats
from impedance_cosim.cosim.master.setup import (
    MasterError,
    collect_parameters,
    read_descriptions,
    real_outputs,
)
from impedance_cosim.cosim.results.result import Divergence, Feed, RunResult, Sink, size_problem
from impedance_cosim.cosim.ssp.read import SspError, SystemDescription
from impedance_cosim.util.interrupt import RunInterrupted, StopSignals, signal_name
from impedance_cosim.util.progress import StepProgress

CHUNK = 400  # steps per call into the loop (progress bar, interrupts)
RT_COLUMNS = ["rt.start_late_s", "rt.compute_s", "rt.lateness_s"]
MAX_INIT_PASSES = 20


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
        options: RunOptions | None = None,
        instances: Any = None,
    ) -> None:
        """Check the options against the system and read its FMUs' descriptions (MasterError).

        instances: an fmu_pool.InstancePool, to reuse FMU instances across runs."""
        self.system = system
        self.options = options = (options or RunOptions()).for_system(system)
        self.algorithm = options.algorithm
        self.step_size = options.step_size
        self.start_time = system.start_time
        self.stop_time = options.stop_time
        steps = round((self.stop_time - self.start_time) / self.step_size)  # checked: whole
        self.instances = instances
        parameter_set = options.parameter_set
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
        for name, path in (options.fmu_files or {}).items():
            if name not in self.fmu_files:
                raise MasterError(f"no component {name!r} to replace (have {names})")
            self.fmu_files[name] = Path(path)
        self.descriptions = read_descriptions(self.fmu_files)
        self.parameters = collect_parameters(
            system,
            parameter_set,
            self.descriptions,
            self.fmu_files,
            options.overrides or {},
            options.overrides_origin,  # where a bad override came from, for its message
        )
        extra.check(options.extrapolation, self.algorithm, system.connections, self.descriptions,
                    self.fmu_files)  # fmt: skip
        columns = 1 + sum(len(real_outputs(md)) for md in self.descriptions.values())
        columns += len(RT_COLUMNS) if options.realtime else 0
        too_big = size_problem(steps, columns, self.stop_time, self.step_size)
        if too_big:
            raise MasterError(too_big)

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
        record = [*names, *RT_COLUMNS] if self.options.realtime else names
        h, t0 = self.step_size, self.start_time
        n = int(round((self.stop_time - t0) / h))
        data = np.empty((n + 1, len(names)))
        rows, error = 0, None
        timing = np.zeros((n + 1, len(RT_COLUMNS))) if self.options.realtime else None
        info: dict[str, Any] = {}
        feed = Feed(sink, record)
        feed(data, rows, timing)
        started = wallclock.perf_counter()
        bar = self._progress(n, progress)
        ordered: list[_Slot] = []
        try:
            self._open(ordered)
            data[0] = (t0, *(v for s in ordered for v in s.values))
            rows = 1
            feed(data, rows, timing)
            if self.options.extrapolation != "none":
                extra.prepare(ordered)  # the sources' output derivatives at t_0
            error = self._check_row(names, data[0], t0)
            fast, step = self._stepper(ordered, data)
            stepping = wallclock.perf_counter()
            if self.options.realtime and not error:
                rt = self.options.realtime
                rt = rt if isinstance(rt, RealtimeOptions) else RealtimeOptions()
                with realtime.applied(rt) as notes:
                    rows, error = realtime.paced_steps(
                        lambda i: step(ordered, data, names, i, 1),
                        n,
                        h,
                        timing,
                        rt.spin_s,
                        lambda: stop.signum is not None,
                        bar.update_steps if bar else None,
                    )
                info["realtime"] = {**realtime_stats(timing[1:rows], h), "notes": notes}
            while not error and rows < n + 1 and stop.signum is None:
                chunk = min(n + 1 - rows, CHUNK)
                done, error = step(ordered, data, names, rows - 1, chunk)
                rows += done
                feed(data, rows, timing)
                if bar:
                    bar.update_steps(rows - 1)
            info["stepping_s"] = wallclock.perf_counter() - stepping
            info["loop"] = "c" if fast else "python"
        except (FmuError, MasterError, SspError, ValueError, KeyError) as exc:
            error = str(exc)
        finally:
            if bar:
                bar.close()
            self._release(ordered, error)
            feed(data, rows, timing)
        data = data[:rows]
        divergence = error if isinstance(error, Divergence) else None
        error = None if error is None else str(error)
        if self.options.realtime:
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
            divergence=divergence,
        )

    def _open(self, ordered: list[_Slot]) -> None:
        """Open (or take from the pool) each FMU into ordered, as it opens (so that a failure
        later still releases those opened), wire and initialize them."""
        for name in self.order:
            path = self.fmu_files[name]
            fmu = self.instances.take(path, name, open_fmu) if self.instances else None
            ordered.append(_Slot(name, fmu or open_fmu(path, name)))
        self._wire(ordered)
        try:
            self._initialize(ordered)
        except FmuError as exc:  # the phase, after the component's name
            comp, sep, rest = str(exc).partition(": ")
            raise FmuError(f"{comp}: in initialization: {rest}" if sep else
                           f"in initialization: {exc}") from None  # fmt: skip

    def _stepper(self, ordered: list[_Slot], data: np.ndarray):
        """(the compiled loop or None, the step function): the C loop where it can run the
        system and is asked for or allowed, else the Python loop."""
        unsupported = c_loop.unsupported(ordered)
        if self.options.loop == "c" and unsupported:
            raise MasterError(f"the C loop cannot run this system: {unsupported}")
        fast = c_loop.load() if self.options.loop != "python" and not unsupported else None
        if self.options.loop == "c" and fast is None:
            raise MasterError("the C loop cannot be compiled here (no C compiler?)")
        if not fast:
            return None, self._python_steps
        options = self.options
        return fast, c_loop.stepper(fast, ordered, data, self.algorithm == "jacobi",
                                      self.start_time, self.step_size, options.divergence_limit,
                                      self._check_row, options.extrapolation != "none")  # fmt: skip

    def _release(self, ordered: list[_Slot], error) -> None:
        """Terminate each FMU and free it, or give it back to the pool (reset) when it ended
        cleanly: without error, or diverged (its FMUs returned no error)."""
        for s in ordered:
            try:
                s.fmu.terminate()
                clean = error is None or isinstance(error, Divergence)
            except FmuError:
                clean = False
            self.instances.give(s.fmu, clean) if self.instances else s.fmu.free()

    def _progress(self, steps: int, progress: bool | TextIO) -> StepProgress | None:
        """The progress display on stderr (or the stream given), or None when not wanted."""
        if not progress:
            return None
        stream = sys.stderr if progress is True else progress
        return StepProgress(steps, self.parameter_set or "run", self.start_time, self.step_size,
                            stream)  # fmt: skip

    def _wire(self, ordered: list[_Slot]) -> None:
        """Each component's inputs: the (component, output) that feeds it, per the SSD."""
        index = {s.name: i for i, s in enumerate(ordered)}
        for se, sc, ee, ec in self.system.connections:
            dst = ordered[index[ee]]
            size = self.system.component(ee).connectors[ec].size  # SSP 2.0 array connectors
            for s_el, e_el in zip(signals(sc, size), signals(ec, size), strict=True):
                dst.inputs.append(e_el)
                dst.sources.append((index[se], ordered[index[se]].outputs.index(s_el)))
        for s in ordered:
            s.write = s.fmu.real_setter(s.inputs)

    def _python_steps(self, ordered, data, names, first: int, count: int):
        """Steps first .. first + count - 1 in Python; returns (rows filled, error or None)."""
        h, t0 = self.step_size, self.start_time
        step_times, zero_start = self.options.step_times, self.options.zero_start_inputs
        for i in range(first, first + count):
            t, h_i = step_times(i) if step_times else (t0 + i * h, h)
            try:
                self._step_all(ordered, t, h_i, zero_start and i == 0)
            except FmuError as exc:
                return i - first, str(exc)
            t_next = t0 + (i + 1) * h
            data[i + 1] = (t_next, *(v for s in ordered for v in s.values))
            error = self._check_row(names, data[i + 1], t_next)
            if error:
                return i + 1 - first, error
        return count, None

    def _step_all(self, ordered: list[_Slot], t: float, h: float, zero: bool = False) -> None:
        """Every component from t to t + h, its inputs set as the algorithm says (Gauss-Seidel:
        each just before its step, Jacobi: all before the steps); each slot's values updated."""
        if self.algorithm != "jacobi":
            for s in ordered:
                s.write(self._inputs(s, ordered, h))
                s.fmu.step(t, h)
                s.values = s.read()
            return
        for s in ordered:
            s.write(self._inputs(s, ordered, h, zero))
        for s in ordered:
            s.fmu.step(t, h)
        for s in ordered:
            s.values = s.read()
        if self.options.extrapolation != "none":
            extra.refresh(ordered)

    def _inputs(self, s: _Slot, ordered: list[_Slot], h: float, zero: bool = False) -> list[float]:
        """The values of s's connected inputs for a step of h: its sources' latest outputs, 0.0
        (zero: Jacobi's zero_start_inputs) or extrapolated over h (Jacobi's extrapolation)."""
        if self.options.extrapolation != "none":
            return extra.inputs(s, ordered, h)
        return [0.0 if zero else ordered[j].values[k] for j, k in s.sources]

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

    def _check_row(self, names: list[str], row: np.ndarray, t: float) -> Divergence | None:
        """The first signal of row beyond the divergence limit (or not finite), or None."""
        limit = self.options.divergence_limit
        bad = ~np.isfinite(row) | (np.abs(row) > limit)
        if not bad.any():
            return None
        k = int(np.argmax(bad))
        return Divergence(float(t), names[k], float(row[k]), limit)
