"""Running a sweep's plan: in series in this process (the reference), or on dask with several
runs per task and FMU instances reused in a worker.

A 20 s run of the native FMUs takes ~40 ms; one dask task per run spent a large part of that on
task overhead. Here each task runs a batch of points (worker.run_batch) sized from the cost
measured so far: the runs' wall time per master step, aiming at `target_s` per task (a few
hundred ms), and smaller towards the end so that no worker idles while another finishes a long
batch (guided self-scheduling). At most two batches per worker are in flight, so sizes follow the
measurements. Each worker keeps its FMU instances between runs (fmu_pool: fmi2Reset instead of a
new instance). Rows are recorded as their batch finishes (Ctrl-C keeps every finished batch); a
batch whose task failed (e.g. its worker died) is run again one point per task, so a crashing
point costs only its own row; runs that dask cancelled are lost (RunsLostError)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from impedance_cosim.apps.sweep.metrics import METRICS
from impedance_cosim.apps.sweep.plan import Plan, archive_payload, run_options
from impedance_cosim.apps.sweep.worker import RunInterruptedError, run_batch, run_point
from impedance_cosim.cosim.fmus.pool import InstancePool
from impedance_cosim.util.progress import Progress

TARGET_S = 0.3  # aimed wall time of one task
IN_FLIGHT = 2  # batches submitted per worker

Record = Callable[[int, dict], None]  # record(index in the plan, row) as a run finishes
ProgressHook = Callable[[int, dict], None]  # progress(runs finished so far, the last row)


class RunsLostError(Exception):
    """Dask cancelled runs (e.g. the scheduler went away): no verdict on those points; the sweep
    stops after the others (--resume runs them again)."""


class RunProgress:
    """The progress of a sweep's runs on stderr (util.progress: a tqdm bar on a terminal, plain
    lines otherwise): runs finished and how many did not stay bounded. A ProgressHook that counts
    its calls (so one display can follow several plans) and a with-block that closes it."""

    def __init__(self, total: int, enabled: bool = True, desc: str = "sweep") -> None:
        self.display = Progress(total, desc, "run", enabled=enabled)
        self.done = self.bad = 0

    def __call__(self, _n: int, row: dict) -> None:
        self.done += 1
        self.bad += row.get("status") != "ok"
        self.display.update(self.done, f"{self.bad} not bounded")

    def __enter__(self) -> RunProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.display.close()


def run_serial(
    plan: Plan,
    progress: ProgressHook | None = None,
    indices: Iterable[int] | None = None,
    record: Record | None = None,
    fresh: bool = False,
) -> list[dict]:
    """The plan's runs (or those at `indices`) one after another in this process, on FMU
    instances reused from run to run as a dask worker does (fresh=True: new instances per run,
    the reference they are checked against); `record(index, row)` as each finishes."""
    data, digest = archive_payload(plan.ssp)
    pool = None if fresh else InstancePool()  # freed at the end: nothing stays loaded
    rows = []
    try:
        for i in range(len(plan.points)) if indices is None else indices:
            rows.append(run_point(data, digest, plan.points[i], plan.options, instances=pool))
            if record:
                record(i, rows[-1])
            if progress:
                progress(len(rows), rows[-1])
    finally:
        if pool is not None:
            pool.clear()
    return rows


def steps(point: dict, options: dict) -> float:
    """The master steps of a run (relative, for sizing batches: stop / step, 1 where unset)."""
    run = run_options(point, options)
    return (run.stop_time or 1.0) / (run.step_size or 1.0)


class Batcher:
    """Cuts the remaining points into batches of about `target_s` each (see module docstring)."""

    def __init__(self, costs: dict[int, float], workers: int, target_s: float = TARGET_S):
        self.costs, self.workers, self.target_s = costs, max(1, workers), target_s
        self.todo = list(costs)  # indices, plan order
        self.seconds = self.units = 0.0  # measured: run wall time and their costs

    def measured(self, index: int, wall_s: float | None) -> None:
        if wall_s is not None and math.isfinite(wall_s):
            self.seconds += wall_s
            self.units += self.costs[index]

    def next(self) -> list[int]:
        """The next batch (empty when none is left): one point until a run has been timed."""
        if not self.todo:
            return []
        if not self.units:
            size = 1
        else:
            per_unit = self.seconds / self.units
            left = sum(self.costs[i] for i in self.todo)
            budget = min(self.target_s / per_unit, left / (2 * self.workers))
            size, total = 0, 0.0
            for i in self.todo:
                if size and total + self.costs[i] > budget:
                    break
                size, total = size + 1, total + self.costs[i]
        batch, self.todo = self.todo[:size], self.todo[size:]
        return batch


def archive_on_workers(client: Any, ssp: Path) -> tuple[Any, str]:
    """(payload for the tasks, digest) of the archive: its path for a LocalCluster (workers on
    this machine read it, each checks the digest), else its bytes scattered to every worker (a
    worker lost during the broadcast: sent again to those left). No call that needs every
    worker (client.run): a worker killed in it failed the whole sweep ("Stream is closed")."""
    data, digest = archive_payload(ssp)
    if getattr(client, "cluster", None) is not None:
        return str(Path(ssp).resolve()), digest
    for attempt in range(3):
        try:
            return client.scatter(data, broadcast=True, hash=False), digest
        except Exception:  # noqa: BLE001 (a closed stream: which errors dask raises varies)
            if attempt == 2:
                raise
    raise AssertionError("unreachable")


def finished_tasks() -> Any:
    """A stream of (future, result) as dask tasks finish (add futures to it), the results fetched
    by dask's own thread: the caller never waits inside a dask call, where a Ctrl-C would leave
    distributed's event loop with an exception of its own on stderr."""
    from distributed import as_completed

    return as_completed([], with_results=True, raise_errors=False)


def task_result(future: Any, result: Any) -> Any:
    """What a task from finished_tasks() returned; what it raised is raised here; CancelledError
    when dask cancelled or lost it (e.g. the scheduler went away)."""
    from concurrent.futures import CancelledError

    if future.status == "finished":
        return result
    if future.status == "error":
        raise result[1]
    raise result if isinstance(result, CancelledError) else CancelledError(future.status)


def _failed_row(point: dict, exc: BaseException) -> dict[str, Any]:
    row = dict(point)
    reason = " ".join(str(exc).split())
    row.update(status="failed", error=f"task failed: {type(exc).__name__}: {reason}")
    row.update({m: None for m in METRICS}, wall_s=None)
    return row


def run_dask(
    plan: Plan,
    client: Any,
    progress: ProgressHook | None = None,
    indices: Iterable[int] | None = None,
    record: Record | None = None,
    target_s: float = TARGET_S,
) -> list[dict]:
    """The plan's runs (or those at `indices`) in batches on the client's workers; rows in the
    plan's order; `record(index, row)` for every row of a batch as the batch finishes. On an
    exception (e.g. Ctrl-C) the batches not yet finished are cancelled."""
    from concurrent.futures import CancelledError

    order = list(range(len(plan.points)) if indices is None else indices)
    payload, digest = archive_on_workers(client, plan.ssp)
    workers = len(client.scheduler_info().get("workers", {})) or 1
    batcher = Batcher({i: steps(plan.points[i], plan.options) for i in order}, workers, target_s)
    singles: list[int] = []  # points of failed batches, run again one per task
    batches: dict[str, tuple[Any, list[int]]] = {}  # task key -> (future, its points)
    pending = finished_tasks()
    rows: dict[int, dict] = {}
    lost: str | None = None  # dask cancelled a batch: submit no more

    def submit() -> None:
        batch = [singles.pop(0)] if singles else batcher.next()
        if batch and lost is None:
            points = [plan.points[i] for i in batch]
            future = client.submit(run_batch, payload, digest, points, plan.options, pure=False)
            batches[future.key] = (future, batch)
            pending.add(future)

    try:
        for _ in range(IN_FLIGHT * workers):
            submit()
        for future, result in pending:
            batch = batches.pop(future.key)[1]
            try:
                results = task_result(future, result)
            except RunInterruptedError:  # a worker's run was stopped by a signal: stop the sweep
                raise
            except CancelledError as exc:  # e.g. the scheduler went away: not the points' fault
                lost = lost or " ".join(str(exc).split())
                continue
            except Exception as exc:  # the worker died (e.g. a crash inside an FMU)
                if len(batch) > 1:
                    singles.extend(batch)
                    submit()
                    continue
                results = [_failed_row(plan.points[batch[0]], exc)]
            for i, row in zip(batch, results, strict=True):
                rows[i] = row
                batcher.measured(i, row.get("wall_s"))
                if record:
                    record(i, row)
                if progress:
                    progress(len(rows), row)
            submit()
    finally:
        if batches:
            client.cancel([f for f, _ in batches.values() if not f.done()])
    if lost is not None or len(rows) < len(order):
        missing = len(order) - len(rows)
        raise RunsLostError(f"dask lost {missing} of {len(order)} runs ({lost or 'not run'})")
    return [rows[i] for i in order]


def run_plan(plan: Plan, table: Any, client: Any, progress: ProgressHook | None) -> list[dict]:
    """The plan's runs not yet in the table (table.SweepTable), each row into the table as it
    finishes, on the client's workers (in this process when client is None); all rows (in the
    plan's order) once every run has finished."""
    todo = [i for i in range(len(plan.points)) if i not in table.done]
    if todo:
        if client is not None:
            run_dask(plan, client, progress, todo, table.add)
        else:
            run_serial(plan, progress, todo, table.add)
    return [dict(r) for r in table.rows()]


def run_plans(plans: dict[str, Plan], tables: dict[str, Any], client: Any,
              progress: ProgressHook | None) -> dict[str, list[dict]]:  # fmt: skip
    """Several plans (e.g. the study's maps), each into its own table. On a cluster, plans on the
    same archive with the same options run as one stream of batches: one setup of the workers and
    no idle tail between plans (rows identical: every run is independent)."""
    first = next(iter(plans.values()), None)
    same = first is not None and all(
        p.ssp == first.ssp and p.options == first.options for p in plans.values()
    )
    if client is None or not same:
        return {name: run_plan(p, tables[name], client, progress) for name, p in plans.items()}
    where: list[tuple[str, int]] = []  # index in the stream -> (plan, index in that plan)
    for name, p in plans.items():
        where += [(name, i) for i in range(len(p.points)) if i not in tables[name].done]
    if where:
        points = [plans[name].points[i] for name, i in where]
        stream = Plan(first.ssp, {}, points, first.options)

        def record(k: int, row: dict) -> None:
            name, i = where[k]
            tables[name].add(i, row)

        run_dask(stream, client, progress, None, record)
    return {name: [dict(r) for r in tables[name].rows()] for name in plans}
