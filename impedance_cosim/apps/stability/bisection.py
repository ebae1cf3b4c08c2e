"""Stability boundaries by bisection: the critical sample rate (to 1 Hz), the critical observer
gain K at 400 Hz and the critical wall stiffness at 400 Hz, per velocity source x loop timing x
sensor condition, each run of the bisections a dask task (the sweep's run_point on the native
FMUs: "stable" = the run stayed bounded over the scenario, status ok).

A bisection assumes one boundary inside its bracket: it runs both ends first and reports "no
boundary" (with which side holds) when they agree. Many bisections advance together: each
finished run submits that case's next point, so the cluster stays busy.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Iterable
from concurrent.futures import CancelledError
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from impedance_cosim.apps.sweep.execute import (
    RunsLostError,
    archive_on_workers,
    finished_tasks,
    task_result,
)
from impedance_cosim.apps.sweep.plan import run_options
from impedance_cosim.apps.sweep.worker import RunInterruptedError, run_point

SOURCES = ("observer", "difference", "measured")
TIMINGS = ("gauss-seidel", "jacobi")  # sample-and-hold; torque one sample late
DISCRETIZATIONS = ("euler", "implicit", "exponential")
SENSORS: dict[str, dict[str, Any]] = {  # the levels of the sweeps' noise and quantization maps
    "ideal": {},
    "noise 1e-4": {"plant.q_noise": 1e-4},
    "noise 1e-3": {"plant.q_noise": 1e-3},
    "noise 1e-2": {"plant.q_noise": 1e-2},
    "12-bit": {"system.encoder_bits": 12},
    "10-bit": {"system.encoder_bits": 10},
    "8-bit": {"system.encoder_bits": 8},
}
# quantity -> (bracket, stable end, log-scale bisection, tolerance: absolute or relative)
QUANTITIES: dict[str, tuple[tuple[float, float], str, bool, float]] = {
    "rate": ((100.0, 1000.0), "high", False, 1.0),  # Hz, to 1 Hz
    "K": ((1.0, 1e5), "low", True, 0.01),  # 1/s at 400 Hz, to 1 %
    "wall_k": ((1e3, 1e9), "low", True, 0.01),  # N/m at 400 Hz, to 1 %
}
RATE = 400.0  # Hz, where K and the wall stiffness are bisected


class StabilityError(ValueError):
    """A bad study request (unknown name, empty selection): one line for the CLI."""


@dataclass(frozen=True)
class Case:
    """One boundary to find."""

    quantity: str
    velocity: str
    timing: str
    sensor: str
    discretization: str = "euler"

    def point(self, x: float) -> dict[str, Any]:
        """The sweep point (run_point's names) of this case at value x."""
        p: dict[str, Any] = {
            "system.scenario": self.velocity,
            "system.algorithm": self.timing,
            "system.rate": RATE,
            **SENSORS[self.sensor],
        }
        if self.discretization != "euler":
            p["controller.observer_discretization"] = self.discretization
        if self.quantity == "rate":
            p["system.rate"] = int(x)
        elif self.quantity == "K":
            p.update({f"controller.K{i}": float(x) for i in (1, 2, 3)})
        else:
            p["plant.wall_k"] = float(x)
        return p


@dataclass
class Bisection:
    """The bracket of one case: lo and hi values with their outcomes, and every run made."""

    case: Case
    lo: float
    hi: float
    runs: list[tuple[float, bool, str]] = field(default_factory=list)

    def _log(self) -> bool:
        return QUANTITIES[self.case.quantity][2]

    def outcome(self, x: float) -> bool | None:
        return next((ok for v, ok, _ in self.runs if v == x), None)

    def next_points(self) -> list[float]:
        """The values to run next ([] when done)."""
        lo_ok, hi_ok = self.outcome(self.lo), self.outcome(self.hi)
        if lo_ok is None or hi_ok is None:
            return [x for x, o in ((self.lo, lo_ok), (self.hi, hi_ok)) if o is None]
        if lo_ok == hi_ok or self.converged():
            return []
        if self._log():
            return [math.sqrt(self.lo * self.hi)]
        return [float(math.floor((self.lo + self.hi) / 2))]

    def converged(self) -> bool:
        tol = QUANTITIES[self.case.quantity][3]
        return self.hi / self.lo <= 1 + tol if self._log() else self.hi - self.lo <= tol

    def record(self, x: float, stable: bool, error: str) -> None:
        """A finished run: narrow the bracket (the side whose outcome x shares moves to x)."""
        self.runs.append((x, stable, error))
        lo_ok, hi_ok = self.outcome(self.lo), self.outcome(self.hi)
        if x in (self.lo, self.hi) or lo_ok is None or hi_ok is None:
            return
        if stable == lo_ok:
            self.lo = x
        else:
            self.hi = x

    def row(self) -> dict[str, Any]:
        """The table row: the critical value (the last stable one) and its unstable neighbour."""
        c = self.case
        lo_ok, hi_ok = self.outcome(self.lo), self.outcome(self.hi)
        row = {"quantity": c.quantity, "velocity": c.velocity, "timing": c.timing,
               "sensor": c.sensor, "discretization": c.discretization, "critical": None,
               "unstable_at": None, "runs": len(self.runs), "note": ""}  # fmt: skip
        if lo_ok is None or hi_ok is None:
            row["note"] = "not run"
        elif lo_ok == hi_ok:
            state = "stable" if lo_ok else "unstable"
            row["note"] = f"{state} over the whole bracket {self.lo:g}..{self.hi:g}"
        else:
            stable, unstable = (self.lo, self.hi) if lo_ok else (self.hi, self.lo)
            row.update(critical=stable, unstable_at=unstable)
            errors = [e for v, ok, e in self.runs if v == unstable and e]
            row["note"] = errors[0] if errors else ""
        return row


def cases(
    quantities: Iterable[str] = tuple(QUANTITIES),
    sensors: Iterable[str] = tuple(SENSORS),
    velocities: Iterable[str] = SOURCES,
    timings: Iterable[str] = TIMINGS,
) -> list[Case]:
    """The study's cases: rate and wall stiffness for every source x timing x sensor; K for the
    observer (the gain of nothing else) x timing x sensor x observer discretization."""
    for name, allowed, what in ((quantities, QUANTITIES, "quantity"), (sensors, SENSORS, "sensor"),
                                (velocities, SOURCES, "velocity source"),
                                (timings, TIMINGS, "timing")):  # fmt: skip
        for item in name:
            if item not in allowed:
                raise StabilityError(f"unknown {what} {item!r} (have {', '.join(allowed)})")
    out = []
    for q in quantities:
        for sensor in sensors:
            for timing in timings:
                if q == "K":
                    if "observer" in velocities:
                        out += [Case(q, "observer", timing, sensor, d) for d in DISCRETIZATIONS]
                else:
                    out += [Case(q, v, timing, sensor) for v in velocities]
    if not out:
        raise StabilityError("nothing to run: the selection is empty")
    return out


def _stable(row: dict[str, Any]) -> tuple[bool, str]:
    return row["status"] == "ok", row.get("error") or ""


def bisect_all(
    todo: list[Case],
    submit: Callable[[Case, float], Any],
    wait: Callable[[], tuple[Case, float, dict]],
    progress: Callable[[int, int], None] | None = None,
    known: Callable[[Case, float], dict | None] | None = None,
    finished_run: Callable[[Case, float, dict], None] | None = None,
) -> list[Bisection]:
    """Drive every case's bisection: submit(case, x) starts a run, wait() returns one finished
    run (case, x, row); progress(runs finished, bisections finished) after each. known(case, x):
    the row of a run kept from an interrupted study (None: run it), taken instead of a run;
    finished_run(case, x, row) as each new run finishes (to keep it). Returns the finished
    bisections in the order of todo."""
    state = {c: Bisection(c, *QUANTITIES[c.quantity][0]) for c in todo}
    flying: set[tuple[Case, float]] = set()

    def feed(b: Bisection) -> None:
        while True:  # the kept runs first, as far as they take the bisection
            wanted = [x for x in b.next_points()
                      if (b.case, x) not in flying and b.outcome(x) is None]  # fmt: skip
            kept = [(x, row) for x in wanted if known and (row := known(b.case, x)) is not None]
            for x, row in kept:
                b.record(x, *_stable(row))
            if not kept:
                break
        for x in wanted:
            flying.add((b.case, x))
            submit(b.case, x)

    for b in state.values():
        feed(b)
    done = 0
    while flying:
        case, x, row = wait()
        flying.discard((case, x))
        if finished_run:
            finished_run(case, x, row)
        state[case].record(x, *_stable(row))
        done += 1
        feed(state[case])
        if progress:
            finished = sum(1 for b in state.values() if not b.next_points())
            progress(done, finished)
    return [state[c] for c in todo]


def max_runs(quantity: str) -> int:
    """The most runs one bisection of this quantity takes: both ends, then halving the bracket
    (its logarithm for a log-scale bisection) until the tolerance."""
    (lo, hi), _stable_end, log, tol = QUANTITIES[quantity]
    width = math.log(hi / lo) / math.log(1 + tol) if log else (hi - lo) / tol
    return 2 + math.ceil(math.log2(width)) + (not log)  # +1: the linear midpoint is floored


def check_cases(todo: list[Case], ssp: Path, options: dict[str, Any]) -> None:
    """Configure (not run) a Master for both ends of every case, so that a parameter the system
    lacks is one clear error now, not a bracket of "unstable" runs."""
    from impedance_cosim.cosim.master.master import Master
    from impedance_cosim.cosim.ssp.read import read_ssp

    system = read_ssp(ssp)
    for case in todo:
        for x in QUANTITIES[case.quantity][0]:
            Master(system, run_options(case.point(x), options))


def run_study(
    todo: list[Case],
    ssp: Path,
    stop: float = 20.0,
    client=None,
    progress: Callable[[int, int], None] | None = None,
    known: Callable[[Case, float], dict | None] | None = None,
    finished_run: Callable[[Case, float, dict], None] | None = None,
) -> list[dict[str, Any]]:
    """Every case's bisection, on the dask client's workers (serially in this process when
    client is None); the table rows in the order of todo; progress, known and finished_run as in
    bisect_all. RunsLostError when dask cancels a run (no verdict on its point)."""
    data = Path(ssp).read_bytes()
    digest = hashlib.sha256(data).hexdigest()
    options = {"stop": stop, "divergence_limit": 1e6}
    check_cases(todo, ssp, options)
    hooks = {"progress": progress, "known": known, "finished_run": finished_run}
    if client is None:
        queue: list[tuple[Case, float]] = []

        def submit(case: Case, x: float) -> None:
            queue.append((case, x))

        def wait() -> tuple[Case, float, dict]:
            case, x = queue.pop(0)
            return case, x, run_point(data, digest, case.point(x), options)

        return [b.row() for b in bisect_all(todo, submit, wait, **hooks)]

    payload, digest = archive_on_workers(client, ssp)
    running: dict[str, tuple[Case, float, Any]] = {}  # task key -> case, value, future
    stream = finished_tasks()  # this thread never waits inside a dask call (Ctrl-C)

    def submit_d(case: Case, x: float) -> None:
        f = client.submit(run_point, payload, digest, case.point(x), options, pure=False)
        running[f.key] = (case, x, f)
        stream.add(f)

    def wait_d() -> tuple[Case, float, dict]:
        f, result = next(stream)
        case, x, _ = running.pop(f.key)
        try:
            return case, x, task_result(f, result)
        except RunInterruptedError:
            raise
        except CancelledError:  # e.g. the scheduler went away: no verdict on this point
            lost = f"dask lost the run at {case.quantity} = {x:g} ({f.status})"
            raise RunsLostError(lost) from None
        except Exception as exc:  # the worker died: an unstable point with the reason
            return case, x, {"status": "failed", "error": f"task failed: {type(exc).__name__}: "
                             + " ".join(str(exc).split())}  # fmt: skip

    try:
        return [b.row() for b in bisect_all(todo, submit_d, wait_d, **hooks)]
    finally:  # on an exception (e.g. Ctrl-C): cancel the runs still in flight
        client.cancel([f for _, _, f in running.values() if not f.done()])


COLUMNS = ["quantity", "velocity", "timing", "sensor", "discretization", "critical",
           "unstable_at", "runs", "note"]  # fmt: skip
