"""The Python API: run the paper's system from Python and get its signals, summary and provenance.

    import impedance_cosim as ic

    r = ic.simulate("observer", stop_time=5.0, overrides={"controller.K": 80})
    r["plant.x"], r.time, r.summary, r.provenance, r.to_dataframe(), r.figure_1()

- The system archive is `fmus/PaperScenario.ssp`, built (as `impedance-cosim run` does) when it
  is missing or older than the code it is built from; `ssp=` runs another archive.
- Bad arguments raise at once, before anything runs, with a one-line message: ValueError
  (malformed argument), MasterError (the system rejects it: unknown scenario or parameter, wrong
  step; a stop time shorter than one step is a NoStepError, also a ValueError), SspError (a bad
  archive).
- A run that diverges or fails does not raise: like the CLI it keeps what it computed. The
  Result has `status` "diverged" (a signal left the bound: `divergence` says where, `summary`
  says so; the rows up to it are the result) or "failed" (an FMU reported an error), `ok` False,
  `error` the reason; `result.check()` raises RunFailedError when a program prefers an exception.
- Ctrl-C (Jupyter's interrupt) stops a run between blocks of steps and raises RunInterrupted (a
  KeyboardInterrupt) whose `result` is the Result with the rows computed so far; in `sweep` its
  `results` are the Results of the runs that finished before (None for `result` when the signal
  came between runs).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import math
import sys
import time
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from impedance_cosim.apps import analysis
from impedance_cosim.apps.options import DEFAULT_SSP
from impedance_cosim.cosim.fmus.output import echo_fmu_output
from impedance_cosim.cosim.master.master import Master, MasterError, RunResult
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.results import provenance
from impedance_cosim.cosim.results.result import Divergence, run_status
from impedance_cosim.cosim.ssp.read import SspError, SystemDescription, read_ssp
from impedance_cosim.util.interrupt import RunInterrupted, StopSignals, signal_name

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["Result", "RunFailedError", "simulate", "sweep", "MasterError", "SspError", "Divergence"]


class RunFailedError(RuntimeError):
    """Raised by Result.check() for a run that did not reach its stop time."""


class Result:
    """One run: its signals (numpy arrays by name), summary numbers and provenance."""

    def __init__(self, run: RunResult, record: dict[str, Any]) -> None:
        self.names: list[str] = list(run.names)
        self.data: np.ndarray = run.data  # one row per sample, one column per name
        self.scenario: str = run.parameter_set
        self.error: str | None = run.error
        self.divergence: Divergence | None = run.divergence  # where a diverged run left the bound
        self.wall_time: float = run.wall_time
        self.provenance: dict[str, Any] = record
        entry = record["runs"][0]
        self.units: dict[str, str] = dict(entry.get("units", {}))
        self.summary: dict[str, Any] | None = entry.get("summary")  # None for a failed run

    @property
    def ok(self) -> bool:
        """True when the run reached its stop time."""
        return self.error is None

    @property
    def status(self) -> str:
        """ "ok", "diverged" (a result: `divergence` says where) or "failed" (results.run_status,
        as in run.json and the CLI's exit status 0, 3, 1)."""
        return run_status(self.error, self.divergence)

    @property
    def time(self) -> np.ndarray:
        """The sample times [s]."""
        return self.data[:, 0]

    @property
    def signals(self) -> dict[str, np.ndarray]:
        """Every recorded signal by name ("time", "plant.x", "controller.tau1", ...)."""
        return {n: self.data[:, k] for k, n in enumerate(self.names)}

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.data[:, self.names.index(name)]
        except ValueError:
            import difflib

            close = difflib.get_close_matches(str(name), self.names, n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise KeyError(f"no recorded signal {name!r}{hint}") from None

    def __contains__(self, name: object) -> bool:
        return name in self.names

    def check(self) -> Result:
        """This result, or RunFailedError with the reason when the run failed."""
        if not self.ok:
            raise RunFailedError(f"{self.scenario}: {self.error} ({len(self.data)} rows kept)")
        return self

    def to_dataframe(self):
        """The signals as a pandas DataFrame (one column per name, "time" first; the units in
        `df.attrs["units"]`). Needs pandas."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError(
                "Result.to_dataframe needs pandas, which is not installed: pip install pandas"
                " (the signals are numpy arrays in result.signals without it)"
            ) from None
        df = pd.DataFrame(self.data, columns=self.names)
        df.attrs["units"] = dict(self.units)
        return df

    def to_csv(self, path: str | Path) -> Path:
        """Write the signals as the CLI's CSV (fmpy.util.read_csv reads it); returns the path.
        The file is whole or not there: WriteError (an OSError) naming path when it cannot be."""
        from impedance_cosim.cosim.results.result import write_csv
        from impedance_cosim.util.atomic import WriteError

        path = Path(path)
        try:
            write_csv(path, self.names, self.data)
        except WriteError as exc:  # one line naming path and its folder; nothing left there
            raise exc.with_note("the rows are still in this Result") from None
        return path

    def figure_1(self, path: str | Path | None = None) -> Figure:
        """The paper's Fig. 1 (path, force, torques) as a matplotlib Figure, saved to path if
        given (the format from its suffix)."""
        return self._figure(analysis.figure_1, path)

    def figure_2(self, path: str | Path | None = None) -> Figure:
        """Fig. 2: observed vs actual velocity and the observer error."""
        return self._figure(analysis.figure_2, path)

    def figure_3(self, path: str | Path | None = None) -> Figure:
        """Fig. 3: desired vs actual velocity and the tracking error."""
        return self._figure(analysis.figure_3, path)

    def report(self, path: str | Path) -> Path:
        """Write this run as one self-contained HTML page, the CLI's report.html for a Result: the
        summary next to the paper's values, Figs. 1-3 inline, provenance, units; returns the path.
        OSError (one line naming the path) when it cannot be written."""
        from impedance_cosim.apps.report import write_result_report

        if not isinstance(path, (str, Path)):
            raise ValueError(f"path must be the file to write, like 'report.html' (got {path!r})")
        signals = self.signals if self.summary and self.ok else None  # as the CLI draws them
        try:
            return write_result_report(Path(path), self.provenance, signals)
        except OSError as exc:
            raise OSError(str(exc)) from None  # one line: the path and the reason

    def _figure(self, draw, path: str | Path | None) -> Figure:
        if not len(self.data):
            raise ValueError(f"{self.scenario}: no rows to plot ({self.error})")
        return draw(self.signals, Path(path) if path is not None else None)

    def __repr__(self) -> str:
        status = {"ok": "ok", "diverged": self.error}.get(self.status, f"failed: {self.error}")
        rows = f"{len(self.data)} rows to {self.time[-1]:g} s" if len(self.data) else "no rows"
        return f"<Result {self.scenario!r}: {status}, {rows}>"

    def __str__(self) -> str:
        text = repr(self)
        return text + "\n" + analysis.format_summary(self.summary) if self.summary else text


def simulate(
    scenario: str | None = "observer",
    *,
    ssp: str | Path | None = None,
    stop_time: float | None = None,
    step_size: float | None = None,
    algorithm: str | None = None,
    overrides: Mapping[str, Any] | None = None,
    fmu_files: Mapping[str, str | Path] | None = None,
    progress: bool = False,
) -> Result:
    """Run one scenario of the system (a parameter set of the SSD: "observer" (the paper),
    "difference", "measured"; None: the SSD's first) and return its Result.

    stop_time, step_size [s] and algorithm ("gauss-seidel" or "jacobi") default to the SSD's;
    overrides set parameters, {"controller.K": 80, "plant.q_noise": 1e-4} ("controller.K" sets
    K1..K3); fmu_files runs other FMU files in place of components ({"plant": "my.fmu"});
    progress shows a progress bar on stderr."""
    options = _options(stop_time, step_size, algorithm, overrides, fmu_files, progress)
    given = {"ssp": ssp, **{k: v for k, v in options.items() if k != "progress"}}
    call = _call_text("simulate", [scenario], given)
    with _system(ssp) as (system, path):
        return _run(system, path, scenario, options, call)


def sweep(
    parameter: str,
    values: Iterable[Any],
    scenario: str | None = "observer",
    *,
    ssp: str | Path | None = None,
    stop_time: float | None = None,
    step_size: float | None = None,
    algorithm: str | None = None,
    overrides: Mapping[str, Any] | None = None,
    progress: bool = False,
) -> list[Result]:
    """Run the scenario once per value of one parameter ("controller.G1", [500, 1000, 2000]),
    one after the other in this process (the archive read once); one Result per value, each
    with its own provenance (its call: the equivalent simulate(...)). Every value is checked
    before the first run. For large grids, on many cores or machines, use `impedance-cosim
    sweep` (dask)."""
    if not isinstance(parameter, str) or "." not in parameter:
        raise ValueError(f"parameter must be written component.variable (got {parameter!r})")
    if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
        raise ValueError(f"values must be a list of values (got {values!r})")
    values = list(values)
    if not values:
        raise ValueError("values is empty: nothing to sweep")
    options = _options(stop_time, step_size, algorithm, overrides, None, False)
    if parameter in options["overrides"]:  # the swept values would silently replace it
        raise ValueError(f"overrides sets {parameter}, the swept parameter: give it in one place")
    runs = [{**options, "overrides": {**options["overrides"], parameter: v}} for v in values]
    from impedance_cosim.util.progress import Progress

    results: list[Result] = []
    with _system(ssp) as (system, path):
        for run in runs:  # every value checked before the first run
            _master(system, scenario, run)
        try:  # a signal between runs is taken before the next one (during one: the master's)
            with StopSignals() as between, Progress(len(runs), "sweep", "run", progress) as bar:
                for i, run in enumerate(runs):
                    _stop_between(between, results)
                    given = {"ssp": ssp, **run}
                    call = _call_text("simulate", [scenario], given)
                    results.append(_run(system, path, scenario, run, call))
                    bar.update(i + 1)
                _stop_between(between, results)
        except RunInterrupted as exc:  # the finished runs go with it, never lost
            exc.results = list(results)
            exc.message = f"{exc.message}; {len(results)} of {len(runs)} runs finished (.results)"
            exc.args = (exc.message,)
            raise
    return results


def _stop_between(stop: StopSignals, results: list[Result]) -> None:
    """RunInterrupted (no partial run) when a signal came since the last run finished."""
    if stop.signum is not None:
        name = signal_name(stop.signum)
        raise RunInterrupted(f"interrupted by {name} between runs", stop.signum, None, results)


# --- the pieces -------------------------------------------------------------------------------


@contextlib.contextmanager
def _system(ssp: str | Path | None) -> Iterator[tuple[SystemDescription, Path]]:
    """The system archive (the default one built when stale), read, and closed after use."""
    if ssp is not None and not isinstance(ssp, (str, Path)):
        raise ValueError(f"ssp must be a path to a .ssp archive (got {ssp!r})")
    path = Path(ssp) if ssp is not None else DEFAULT_SSP
    if ssp is None:  # the build's report goes to stderr: stdout is the caller's
        from impedance_cosim.apps.build_cmd import ensure_built

        with contextlib.redirect_stdout(sys.stderr):
            ensure_built(argparse.Namespace(ssp=None), path)
    try:
        system = read_ssp(path)
    except SspError as exc:
        raise SspError(str(exc)) from None  # a short traceback: the message says it all
    try:
        yield system, path
    finally:
        system.close()


def _options(stop_time, step_size, algorithm, overrides, fmu_files, progress) -> dict[str, Any]:
    """The keyword arguments, checked (ValueError with one line naming the argument)."""
    for name, value in (("stop_time", stop_time), ("step_size", step_size)):
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
            raise ValueError(f"{name} must be a number of seconds (got {value!r})")
        if not 0 < float(value) < math.inf:
            raise ValueError(f"{name} must be a finite number > 0 (got {value!r})")
    if algorithm is not None and not isinstance(algorithm, str):
        raise ValueError(f"algorithm must be 'gauss-seidel' or 'jacobi' (got {algorithm!r})")
    for name, mapping in (("overrides", overrides), ("fmu_files", fmu_files)):
        if mapping is None:
            continue
        if not isinstance(mapping, Mapping):
            raise ValueError(f"{name} must be a dict like {{'controller.K': 80}} (got {mapping!r})")
        bad = [k for k in mapping if not isinstance(k, str)]
        if bad:
            raise ValueError(f"{name}: names must be strings (got {bad[0]!r})")
    bad = [v for v in (fmu_files or {}).values() if not isinstance(v, (str, Path))]
    if bad:
        raise ValueError(f"fmu_files: each value must be the path of an FMU (got {bad[0]!r})")
    if not isinstance(progress, bool):
        raise ValueError(f"progress must be True or False (got {progress!r})")
    return {
        "stop_time": None if stop_time is None else float(stop_time),
        "step_size": None if step_size is None else float(step_size),
        "algorithm": algorithm,
        "overrides": dict(overrides or {}),
        "fmu_files": {k: Path(v) for k, v in (fmu_files or {}).items()},
        "progress": progress,
    }


def _master(system: SystemDescription, scenario: str | None, options: dict[str, Any]) -> Master:
    """The master for one run; MasterError (short traceback) when the system rejects it."""
    if scenario is not None and not isinstance(scenario, str):
        raise ValueError(f"scenario must be a name like 'observer' (got {scenario!r})")
    try:
        run = RunOptions(
            parameter_set=scenario,
            overrides=options["overrides"],
            algorithm=options["algorithm"],
            step_size=options["step_size"],
            stop_time=options["stop_time"],
            fmu_files=options["fmu_files"] or None,
        )
        return Master(system, run)
    except MasterError as exc:  # the same class (NoStepError is also a ValueError)
        raise type(exc)(str(exc)) from None


def _run(
    system: SystemDescription, ssp: Path, scenario: str | None, options: dict[str, Any], call: str
) -> Result:
    """Run one scenario and wrap it with its summary and provenance."""
    started, t0 = provenance.now_utc(), time.perf_counter()
    master = _master(system, scenario, options)
    overrides = options["overrides"]
    stderr, fmu_output = sys.stderr, io.StringIO()
    try:
        with contextlib.redirect_stderr(fmu_output):
            run = master.run(progress=stderr if options.get("progress") else False)
    except RunInterrupted as exc:
        entry = provenance.run_entry(master, exc.result, overrides, status="interrupted")
        if exc.result is not None:
            record = provenance.record([entry], started, time.perf_counter() - t0, call=call,
                                       ssp=ssp)  # fmt: skip
            exc.result = Result(exc.result, record)
        raise
    finally:  # what Python FMUs printed, less their error reports (those are in run.error)
        echo_fmu_output(fmu_output.getvalue(), stderr)
    entry = provenance.run_entry(master, run, overrides)
    if run.status == "diverged":
        entry["summary"] = analysis.diverged_summary(run)
    if run.ok:
        try:
            entry["summary"] = analysis.summary(run)
        except (KeyError, IndexError, ValueError) as exc:  # e.g. another FMU without a signal
            entry["summary"] = None
            entry["summary_error"] = f"no summary: {exc}"
    record = provenance.record([entry], started, time.perf_counter() - t0, call=call, ssp=ssp)
    return Result(run, record)


def _call_text(function: str, args: list[Any], kwargs: Mapping[str, Any]) -> str:
    """The call as one would type it: simulate('observer', stop_time=5.0, ...), the keyword
    arguments that were given only."""
    shown = [repr(str(a) if isinstance(a, Path) else a) for a in args]
    for k, v in kwargs.items():
        if v is None or v == {} or k == "progress":
            continue
        if isinstance(v, Path):
            v = str(v)
        elif isinstance(v, Mapping):
            v = {n: str(x) if isinstance(x, Path) else x for n, x in v.items()}
        shown.append(f"{k}={v!r}")
    return f"{function}({', '.join(shown)})"
