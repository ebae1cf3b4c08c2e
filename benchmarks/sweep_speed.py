"""Sweep speed (not a test: prints numbers).

Default: a 64-run sweep on dask (LocalCluster, one single-threaded worker process per core)
against the same 64 runs in series in this process, for the Python FMUs and the native ones;
checks that both give the same table.

--study: the native stability study (`sweep --study`, 692 runs of 20 s) as whole commands, the
way a user runs it: `--serial` and `--workers N`, alternating, wall time and CPU time (the
command and its worker processes); the ratio; the per-run overhead (everything but the C loop's
stepping) measured in one process, phase by phase; and with --before COMMIT the same commands
on that commit (a git worktree with its own FMUs), side by side. Every table is checked equal
(run for run, less wall_s) to the serial one of this checkout.

    python benchmarks/sweep_speed.py                # both archives, 64 runs of 20 s
    python benchmarks/sweep_speed.py --only python --stop 10
    python benchmarks/sweep_speed.py --study [--before 0fa2614] [--rounds 2]
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from impedance_cosim.apps import sweep

GRID = [  # 4 x 4 x 2 x 2 = 64 runs, all stable (full length) under Gauss-Seidel at 400 Hz
    "controller.K=10,25,50,100",
    "plant.q_noise=0,1e-5,1e-4,1e-3",
    "system.scenario=observer,difference",
    "controller.G=800,1000",
]
ARCHIVES = {
    "python": sweep.REPO / "fmus" / "PaperScenario.ssp",
    "native": sweep.REPO / "fmus" / "PaperScenario-native.ssp",
}
HERE = Path(__file__).resolve().parent.parent


def same(a: list[dict], b: list[dict]) -> bool:
    keys = ["status", "error", *sweep.METRICS]
    return all({k: x[k] for k in keys} == {k: y[k] for k in keys} for x, y in zip(a, b))


def grid_case(args: argparse.Namespace) -> None:
    print(f"{os.cpu_count()} cores, {args.workers} workers, {args.stop:g} s runs")
    print(
        f"{'FMUs':7} {'runs':>4} {'serial s':>9} {'dask s':>7} {'speed-up':>8} "
        f"{'cluster start s':>15} {'dask on a running cluster s':>27} {'speed-up':>8}"
    )
    for name in [args.only] if args.only else list(ARCHIVES):
        plan = sweep.plan_sweep(GRID, ssp=ARCHIVES[name], stop=args.stop)
        sweep.run_serial(sweep.Plan(plan.ssp, plan.axes, plan.points[:1], plan.options))  # warm
        t0 = time.perf_counter()
        serial = sweep.run_serial(plan)
        t_serial = time.perf_counter() - t0
        t0 = time.perf_counter()
        with sweep.dask_client(workers=args.workers) as client:
            t_start = time.perf_counter() - t0
            t1 = time.perf_counter()
            rows = sweep.run_dask(plan, client)
            t_run = time.perf_counter() - t1
        t_dask = time.perf_counter() - t0
        assert same(serial, rows), "dask and serial tables differ"
        print(
            f"{name:7} {len(rows):4d} {t_serial:9.2f} {t_dask:7.2f} {t_serial / t_dask:7.2f}x "
            f"{t_start:15.2f} {t_run:27.2f} {t_serial / t_run:7.2f}x"
        )


# --- the study as whole commands --------------------------------------------------------------


def command(tree: Path, out: Path, mode: list[str]) -> tuple[float, float]:
    """(wall s, CPU s of the command and every process it waited for) of one study command."""
    cmd = [sys.executable, "-m", "impedance_cosim.cli", "sweep", "--study", "--no-plots",
           "--no-report", "--no-progress", "--out", str(out), *mode]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(tree)}
    started = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=tree, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)  # fmt: skip
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - started
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} in {tree}: exit {proc.returncode}: "
                         f"{proc.stderr.read()[-2000:]}")  # fmt: skip
    cpu = usage.ru_utime + usage.ru_stime  # the workers are its children, waited for by it
    return wall, cpu


def tables(out: Path) -> dict[str, list[dict]]:
    """Every map_<name>.csv of a study folder, rows less wall_s."""
    found = {}
    for path in sorted(out.glob("map_*.csv")):
        with path.open(newline="") as f:
            found[path.name] = [{k: v for k, v in r.items() if k != "wall_s"}
                                for r in csv.DictReader(f)]  # fmt: skip
    return found


@contextlib.contextmanager
def worktree(commit: str):
    """A detached worktree of `commit` with its own FMUs built (removed afterwards)."""
    with tempfile.TemporaryDirectory(prefix="impcosim_sweep_before_") as tmp:
        tree = Path(tmp) / "tree"
        subprocess.run(["git", "-C", str(HERE), "worktree", "add", "--detach", "-q", str(tree),
                        commit], check=True)  # fmt: skip
        try:
            build = "from impedance_cosim.packaging.build_all import build_all; build_all()"
            subprocess.run([sys.executable, "-c", build], cwd=tree, check=True,
                           env={**os.environ, "PYTHONPATH": str(tree)},
                           stdout=subprocess.DEVNULL)  # fmt: skip
            yield tree
        finally:
            subprocess.run(["git", "-C", str(HERE), "worktree", "remove", "--force", str(tree)],
                           check=False)  # fmt: skip


def per_run_overhead() -> None:
    """The study's runs in one process as a dask worker runs them (worker.run_batch, instances
    reused), CPU time by phase; overhead = everything but the C loop's stepping."""
    from impedance_cosim.apps.sweep import table, worker
    from impedance_cosim.apps.sweep.plan import archive_payload
    from impedance_cosim.cosim.master import c_loop
    from impedance_cosim.cosim.master import master as master_module
    from impedance_cosim.cosim.ssp.read import read_ssp

    clock = time.process_time
    spent: dict[str, float] = {}

    def timed(owner, name: str, key: str) -> None:
        original = getattr(owner, name)

        def wrapper(*a, **k):
            t = clock()
            try:
                return original(*a, **k)
            finally:
                spent[key] = spent.get(key, 0.0) + clock() - t

        setattr(owner, name, wrapper)

    native = ARCHIVES["native"]
    t = clock()
    system = read_ssp(native)
    maps = [sweep.plan_sweep([f"{k}={','.join(map(str, v))}" for k, v in m.grid.items()],
                             ssp=native, system=system) for m in sweep.STUDY.values()]  # fmt: skip
    points = [p for m in maps for p in m.points]
    planning = clock() - t
    payload, digest = str(native.resolve()), archive_payload(native)[1]
    worker.run_batch(payload, digest, points[:1], maps[0].options)  # the worker's setup
    original_stepper = c_loop.stepper

    def stepper(*a, **k):
        steps = original_stepper(*a, **k)

        def timed_steps(*b):
            t = clock()
            try:
                return steps(*b)
            finally:
                spent["stepping"] = spent.get("stepping", 0.0) + clock() - t

        return timed_steps

    c_loop.stepper = stepper
    timed(master_module.Master, "__init__", "master set-up (parameters, checks)")
    timed(master_module, "open_fmu", "FMU instantiation (new instances)")
    timed(master_module.Master, "_initialize", "FMU set-up, parameters, initialization")
    timed(worker.POOL, "give", "fmi2Terminate + fmi2Reset")
    timed(worker, "run_metrics", "metrics")
    try:
        t = clock()
        rows = worker.run_batch(payload, digest, points, maps[0].options)
        total = clock() - t
        with tempfile.TemporaryDirectory() as tmp:
            plan = sweep.Plan(native, {}, points, maps[0].options)
            t = clock()
            with table.open_table(Path(tmp) / "t.csv", plan) as tab:
                for i, row in enumerate(rows):
                    tab.add(i, row)
            writing = clock() - t
    finally:
        c_loop.stepper = original_stepper
    n = len(points)
    stepping = spent.pop("stepping")
    print(f"\nper-run overhead, the study's {n} runs in one process as a worker runs them "
          f"(CPU time): all {total:.2f} s, the C loop's stepping {stepping:.2f} s")  # fmt: skip
    print(f"{'phase':42} {'s':>7} {'ms per run':>10}")
    spent["planning (this process)"] = planning
    spent["table writing (this process)"] = writing
    inside = sum(v for k, v in spent.items() if "this process" not in k)
    spent["the rest of a run (master loop set-up, rows)"] = total - stepping - inside
    for key, value in spent.items():
        print(f"{key:42} {value:7.2f} {1e3 * value / n:10.2f}")
    overhead = total - stepping + planning + writing
    print(f"{'overhead: all but stepping':42} {overhead:7.2f} {1e3 * overhead / n:10.2f}")


def study_case(args: argparse.Namespace) -> None:
    sides = {"this checkout": HERE}
    with contextlib.ExitStack() as stack:
        if args.before:
            sides[args.before] = stack.enter_context(worktree(args.before))  # after: checked
        modes = {
            "serial": ["--serial"],
            f"{args.workers} workers": ["--workers", str(args.workers)],
        }
        best: dict[tuple[str, str], tuple[float, float]] = {}
        reference = None
        load = os.getloadavg()[0]
        for _ in range(args.rounds):
            for side, tree in sides.items():
                for mode, flags in modes.items():
                    with tempfile.TemporaryDirectory(prefix="impcosim_study_") as out:
                        wall, cpu = command(tree, Path(out), flags)
                        got = tables(Path(out))
                    reference = reference or got  # this checkout's serial tables, first
                    assert got == reference, f"{side}, {mode}: the tables differ"
                    old = best.get((side, mode))
                    best[(side, mode)] = (wall, cpu) if old is None or wall < old[0] else old
    print(f"\nthe native study (`sweep --study --no-plots --no-report`, 692 runs of 20 s), whole "
          f"commands, best of {args.rounds}; {os.cpu_count()} cores; load average "
          f"{load:.1f} at the start, {os.getloadavg()[0]:.1f} at the end")  # fmt: skip
    print(f"{'':16} {'serial s':>9} {'CPU s':>7} {f'{args.workers} workers s':>12} {'CPU s':>7} "
          f"{'speed-up':>9}")  # fmt: skip
    for side in reversed(sides):  # the earlier commit first
        (ws, cs), (wd, cd) = best[(side, "serial")], best[(side, f"{args.workers} workers")]
        print(f"{side:16} {ws:9.2f} {cs:7.2f} {wd:12.2f} {cd:7.2f} {ws / wd:8.2f}x")
    print("every table the same run for run (less wall_s)")
    per_run_overhead()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=list(ARCHIVES), default=None)
    parser.add_argument("--stop", type=float, default=20.0)
    parser.add_argument("--workers", type=int, default=os.cpu_count())
    parser.add_argument("--study", action="store_true", help="the native study as commands")
    parser.add_argument("--before", metavar="COMMIT", help="--study: also on this commit")
    parser.add_argument("--rounds", type=int, default=1, help="--study: alternations (best)")
    args = parser.parse_args()
    if not ARCHIVES["native"].is_file():
        from impedance_cosim.packaging.build_all import build_all

        build_all()
    study_case(args) if args.study else grid_case(args)


if __name__ == "__main__":
    main()
