"""`impedance-cosim sweep`: its options, the checks before any work, the run with every finished
row written to the table at once, and Ctrl-C/SIGTERM: the sweep stops (a run under way is
dropped), the table keeps every finished run, one line says how far it got and how to resume
(--resume), exit status 128 + signal (130 for Ctrl-C).
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import functools
import math
import signal
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from impedance_cosim.apps.sweep.execute import RunProgress, RunsLostError, run_plan
from impedance_cosim.apps.sweep.maps import DEFAULT_PLOTS, label, plot_map
from impedance_cosim.apps.sweep.metrics import METRICS
from impedance_cosim.apps.sweep.plan import (
    DEFAULT_SSP,
    MAX_RUNS,
    SweepError,
    default_ssp,
    known_parameters,
    parse_axis,
    plan_sweep,
    workers_problem,
)
from impedance_cosim.apps.sweep.study import STUDY, run_study
from impedance_cosim.apps.sweep.table import open_table
from impedance_cosim.apps.sweep.worker import STOP, RunInterruptedError
from impedance_cosim.cosim.master.setup import ALGORITHMS
from impedance_cosim.cosim.results import provenance


def add_parser(sub) -> None:
    """Register `impedance-cosim sweep`."""
    p = sub.add_parser(
        "sweep",
        help="parameter sweep on dask: metrics table (CSV) and maps (PNG)",
        description="Run a grid (or seeded random sample) of co-simulations, one dask task per "
        "run, and write one table of metrics plus maps. Parameters: component.variable (vector "
        "shorthand controller.K = K1..K3), aliases and system.* pseudo-parameters "
        "(--list-parameters).",
    )
    _add_points(p)
    _add_system(p)
    _add_execution(p)
    _add_outputs(p)
    p.add_argument(
        "--study",
        nargs="*",
        choices=list(STUDY),
        default=None,
        metavar="MAP",
        help=f"run the stability study's maps ({', '.join(STUDY)}; default all): "
        "map_<name>.csv/.png into --out",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="finish an interrupted sweep: keep the finished runs of the table in --out (same "
        "command otherwise) and run only the others",
    )
    p.add_argument("--list-parameters", action="store_true", help="list the sweepable names")
    p.set_defaults(func=_cmd_sweep)


def _add_points(p: argparse.ArgumentParser) -> None:
    """The swept points: --grid or --random (with --seed), and the fixed --set values."""
    p.add_argument(
        "--grid",
        action="append",
        metavar="NAME=VALUES",
        default=[],
        help="a swept parameter: v1,v2,... or lin:START:STOP:N or log:START:STOP:N; "
        "with --random also range:LOW:HIGH or logrange:LOW:HIGH (repeatable)",
    )
    p.add_argument(
        "--random",
        type=int,
        default=None,
        metavar="N",
        help="N seeded random points instead of the full grid",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of --random (default 0)")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a fixed parameter for every run (repeatable)",
    )


def _add_system(p: argparse.ArgumentParser) -> None:
    """The system and how it runs: archive, parameter set, algorithm, stop time, step."""
    p.add_argument(
        "--ssp",
        default=None,
        help=f"system archive (default {DEFAULT_SSP.name}: the native FMUs, built if missing or"
        " out of date; `run` defaults to the Python FMUs, the reference, while a sweep's many runs"
        " take the C edition of the same models, which gives the same results bit for bit and"
        " runs far faster)",
    )
    p.add_argument("--scenario", default=None, help="parameter set (default: the SSD's first)")
    p.add_argument(
        "--algorithm",
        choices=ALGORITHMS,
        default=None,
        help="master algorithm (default: the archive's, gauss-seidel, controller first; jacobi:"
        " every FMU steps on the others' outputs of the step before, one sample of delay; or"
        " sweep it: --grid system.algorithm=gauss-seidel,jacobi)",
    )
    p.add_argument("--stop", type=float, default=None, help="stop time [s] (default 20)")
    p.add_argument("--step", type=float, default=None, help="communication step [s] (1/400)")


def _add_execution(p: argparse.ArgumentParser) -> None:
    """Where the runs go: a dask scheduler, local workers, or this process."""
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="an existing dask scheduler (tcp://host:8786); default: a LocalCluster",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="LocalCluster worker processes (default: this machine's cores)",
    )
    p.add_argument(
        "--connect-timeout",
        type=float,
        default=3.0,
        help="seconds to reach the scheduler (default 3)",
    )
    p.add_argument("--serial", action="store_true", help="no dask: the runs in this process")


def _add_outputs(p: argparse.ArgumentParser) -> None:
    """What is written: the folder, the maps, the report, the progress display."""
    p.add_argument("--out", default="results/sweep", help="output folder (default results/sweep)")
    p.add_argument(
        "--plot",
        action="append",
        default=None,
        metavar="METRIC",
        help=f"metric to map (repeatable; default {', '.join(DEFAULT_PLOTS)})",
    )
    p.add_argument("--no-plots", action="store_true", help="only the table")
    p.add_argument("--no-report", action="store_true", help="no report.html (maps and table)")
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress display (a bar on a terminal, a line every 10 s otherwise)",
    )


@contextlib.contextmanager
def stop_on_signals() -> Iterator[None]:
    """While active (main thread only), SIGINT and SIGTERM set STOP and raise
    KeyboardInterrupt, so every with-block (table, cluster) closes on the way out."""
    STOP["signal"] = None
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handle(signum: int, _frame: object) -> None:
        STOP["signal"] = STOP["signal"] or signal.Signals(signum).name
        raise KeyboardInterrupt

    names = [s for s in ("SIGINT", "SIGTERM") if hasattr(signal, s)]
    previous = {s: signal.signal(getattr(signal, s), handle) for s in names}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(getattr(signal, s), handler if handler is not None else signal.SIG_DFL)
        STOP["signal"] = None


def _check_options(args: argparse.Namespace) -> None:
    """SweepError for an option value that cannot work, before anything is read or started."""
    if workers_problem(args.workers):
        raise SweepError(workers_problem(args.workers))
    if args.scheduler and args.workers:
        raise SweepError("--workers is for the LocalCluster; a --scheduler has its own workers")
    if not (math.isfinite(args.connect_timeout) and 0 < args.connect_timeout <= 600):
        raise SweepError(f"--connect-timeout must be 0..600 s (got {args.connect_timeout})")
    for name in ("stop", "step"):
        value = getattr(args, name)
        if value is not None and not (math.isfinite(value) and value > 0):
            raise SweepError(f"--{name} must be a finite number > 0 (got {value})")
    if args.random is not None and not 1 <= args.random <= MAX_RUNS:
        raise SweepError(f"--random must be 1..{MAX_RUNS} runs (got {args.random})")
    for metric in args.plot or []:
        if metric not in METRICS:
            close = difflib.get_close_matches(metric, METRICS, n=3)
            raise SweepError(
                f"unknown metric {metric!r} (have {', '.join(METRICS)})"
                + (f"; did you mean {', '.join(close)}?" if close else "")
            )
    from impedance_cosim.apps.options import check_out

    check_out(args.out)  # empty, a file, too long a name, read-only: one line, nothing written
    runs = 1
    for item in args.grid:
        _name, values = parse_axis(item, max_count=MAX_RUNS)  # before the archive is read or built
        runs *= len(values) if isinstance(values, list) else 1
    if args.random is None and runs > MAX_RUNS:
        raise SweepError(f"the grid has {runs:.3g} runs, more than {MAX_RUNS}: fewer values")


def _kept(tables: list) -> str:
    """How far the sweep got and how to finish it."""
    finished = sum(len(t.done) for t in tables)
    total = sum(len(t.points) for t in tables)
    where = ", ".join(str(t.path) for t in tables)
    return (
        f"{finished} of {total} runs finished, kept in {where}; to finish, run the same command "
        "with --resume"
    )


def _cmd_sweep(args: argparse.Namespace) -> int:
    _check_options(args)
    tables: list = []  # the tables opened so far (for the line on an interruption)
    started, t0 = provenance.now_utc(), time.perf_counter()
    with stop_on_signals(), contextlib.ExitStack() as held:
        try:
            return _sweep(args, tables, held)
        except RunsLostError as exc:
            print(f"impedance-cosim sweep: error: {exc}; {_kept(tables)}", file=sys.stderr)
            return 1
        except (KeyboardInterrupt, RunInterruptedError) as exc:
            signum = getattr(exc, "signum", None)  # the master's own interruption carries it
            name = STOP["signal"] or (signal.Signals(signum).name if signum else "SIGINT")
            news = _kept(tables) if tables else "before any run started"
            lead = "\n" if sys.stderr.isatty() else ""
            print(f"{lead}impedance-cosim sweep: interrupted by {name}: {news}", file=sys.stderr)
            return 128 + getattr(signal, name, signal.SIGINT)
        finally:  # each table's provenance, on every exit path
            for table in tables:
                _write_provenance(args, table, started, time.perf_counter() - t0)


def _study_reports(args: argparse.Namespace, out: Path, tables: list, written: list) -> None:
    """A page per map of the study (map_<name>.report.html): its table, plots and provenance."""
    from impedance_cosim.apps import report

    for table in tables:
        stem = table.path.stem
        maps = [p for p in written if p.suffix == ".png" and p.stem.startswith(stem)]
        record = {"command": args.command_line, "table": str(table.path), **table.plan}
        title = f"impedance-cosim sweep --study: {stem}"
        name = f"{stem}.report.html"
        page = report.write_sweep_report(out, table.path, maps, record, title, name)
        print(f"  {page}")


def _write_provenance(args: argparse.Namespace, table, started: str, wall: float) -> None:
    """<table>.run.json beside the table: how it was made (see cosim.results.provenance)."""
    statuses: dict[str, int] = {}
    for cells in table.cells.values():
        status = cells[table.names.index("status")]
        statuses[status] = statuses.get(status, 0) + 1
    record = provenance.table_record(table.path, table.plan, statuses, started, wall,
                                     command=getattr(args, "command_line", None))  # fmt: skip
    try:
        provenance.write(table.path.with_name(table.path.stem + ".run.json"), record)
    except OSError as exc:  # the table itself is kept; say what is missing
        print(f"impedance-cosim sweep: warning: no provenance for {table.path}: {exc}",
              file=sys.stderr)  # fmt: skip


def _lock_out(out: Path, held: contextlib.ExitStack) -> None:
    """--out created and locked (the lock every command writing a folder takes) until the
    command ends, after every check."""
    from impedance_cosim.apps.options import prepare_out
    from impedance_cosim.util.atomic import FolderLock

    held.enter_context(FolderLock(prepare_out(out), "--out"))


def _sweep(args: argparse.Namespace, tables: list, held: contextlib.ExitStack) -> int:
    if args.scheduler:  # before anything else: fail fast
        from impedance_cosim.apps.sweep.cluster import check_scheduler

        check_scheduler(args.scheduler, args.connect_timeout)
    ssp = Path(args.ssp) if args.ssp else None
    if args.list_parameters:
        from impedance_cosim.cosim.ssp.read import read_ssp

        for name, text in known_parameters(read_ssp(ssp or default_ssp())).items():
            print(f"{name:28} {text}")
        return 0
    progress = not args.no_progress
    out = Path(args.out)
    factory = None if args.serial else functools.partial(_client, args)
    if args.study is not None:
        return _study(args, ssp or default_ssp(), factory, tables, held)
    if not args.grid:
        raise SweepError("nothing to sweep: give at least one --grid component.variable=values")
    plan = plan_sweep(
        args.grid,
        ssp=ssp or default_ssp(),
        random_runs=args.random,
        seed=args.seed,
        fixed=args.set,
        scenario=args.scenario,
        algorithm=args.algorithm,
        stop=args.stop,
        step=args.step,
    )
    path = out / "sweep.csv"
    started = time.perf_counter()
    _lock_out(out, held)
    with open_table(path, plan, args.resume) as table:
        tables.append(table)
        kept = len(table.done)
        idle = len(table.done) == len(plan.points) or not factory
        with (
            contextlib.nullcontext() if idle else factory(len(plan.points) - kept) as c,
            RunProgress(len(plan.points) - kept, progress) as tick,
        ):
            rows = run_plan(plan, table, c, tick)
    _report_grid(args, plan, rows, table, time.perf_counter() - started, kept)
    return 0


def _report_grid(args: argparse.Namespace, plan, rows: list, table, elapsed: float, kept: int):
    """After a grid: the runs' count and time, the unbounded ones, the maps and the report."""
    out = Path(args.out)
    path = out / "sweep.csv"
    bad = [r for r in rows if r["status"] != "ok"]
    resumed = f" ({kept} kept from the table)" if args.resume else ""
    print(
        f"{len(rows)} runs in {elapsed:.1f} s{resumed}, {len(rows) - len(bad)} bounded, "
        f"{len(bad)} not -> {path}"
    )
    for r in bad[:10]:
        where = ", ".join(f"{k}={label(r[k])}" for k in plan.axes)
        print(f"  {where}: {r['status']}: {r['error']}")
    if len(bad) > 10:
        print(f"  ... and {len(bad) - 10} more (see the table)")
    maps = [] if args.no_plots else [out / f"sweep_{m}.png" for m in args.plot or DEFAULT_PLOTS]
    for png in maps:
        plot_map(rows, list(plan.axes), png.stem.removeprefix("sweep_"), png, mode=plan.mode)
        print(f"  {png}")
    if not args.no_report:
        from impedance_cosim.apps import report

        record = {"command": args.command_line, "table": str(path), **table.plan}
        print(f"  {report.write_sweep_report(out, rows, maps, record)}")


def _client(args: argparse.Namespace, runs: int | None = None):
    """The dask client, said on stdout first (the first sign of the cluster, reported after our
    signal handlers are in place); a LocalCluster of at most as many workers as runs."""
    from impedance_cosim.apps.sweep.cluster import dask_client, local_workers

    if args.scheduler:
        print(f"dask: the scheduler at {args.scheduler}", flush=True)
        return dask_client(args.scheduler, None, args.connect_timeout)
    n = local_workers(args.workers, runs)
    print(f"dask: starting a LocalCluster of {n} worker processes", flush=True)
    return dask_client(None, n, args.connect_timeout)


def _study(args: argparse.Namespace, ssp: Path, factory, tables: list, held) -> int:
    """`sweep --study`: the stability study's maps, then their reports."""
    if args.grid or args.random is not None:
        raise SweepError("--study runs its own grids: give it no --grid/--random")
    names = args.study or list(STUDY)
    out = Path(args.out)
    started = time.perf_counter()
    _lock_out(out, held)
    written = run_study(names, out, ssp, factory, not args.no_progress, args.stop, args.resume,
                        tables, plots=not args.no_plots)  # fmt: skip
    print(f"study ({', '.join(names)}): {time.perf_counter() - started:.1f} s")
    for path in written:
        print(f"  {path}")
    if not args.no_report:
        _study_reports(args, out, tables, written)
    return 0
