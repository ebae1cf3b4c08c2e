"""Every figure of the README's performance tables, measured side by side in one run (not a test):
the master's speed (plain models, our master, fmpy's simulate_ssp), the native FMUs' speed, and
sweep speed-ups: serial (single runs in this process, the reference) against a LocalCluster
(with and without its start) and against an external `dask scheduler` + `dask worker`s on
loopback, for 64 native runs, the native stability study (every map of `sweep --study`) and 64
Python runs, the distribution bundle (its size and build time, benchmarks/dist_bundle.py), and the
engine table (every engine on every scenario archive, benchmarks/engines_table.py) and the
paper scenario with MuJoCo's plant (benchmarks/mujoco_compare.py). Every dask
table is checked equal to the serial one.

    python benchmarks/run_all.py            # ~5 min on 2 idle cores
    python benchmarks/run_all.py --quick    # shorter runs, fewer of them (~1 min)
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import time

from master_speed import time_fmpy

from impedance_cosim.apps import sweep
from impedance_cosim.apps.sweep import execute as sweep_batch
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.master.plain_loop import run_models
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.packaging.build import DEFAULT_OUT
from impedance_cosim.packaging.build_all import build_all

GRID = [  # 4 x 4 x 2 x 2 = 64 runs, all stable under Gauss-Seidel at 400 Hz
    "controller.K=10,25,50,100",
    "plant.q_noise=0,1e-5,1e-4,1e-3",
    "system.scenario=observer,difference",
    "controller.G=800,1000",
]
QUICK_GRID = GRID[:2]  # 16 runs


def best(repeat: int, fn) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def master_table(stop: float, repeat: int, fmpy: bool) -> None:
    python, native = DEFAULT_OUT / "PaperScenario.ssp", DEFAULT_OUT / "PaperScenario-native.ssp"
    steps = round(stop * 400)
    rows = [("plain Python models, no FMI", best(repeat, lambda: run_models(stop_time=stop)), None)]
    for name, ssp, loop in (
        ("Python FMUs, our master (C loop)", python, "c"),
        ("Python FMUs, our master (Python loop)", python, "python"),
        ("native FMUs, our master (C loop)", native, "c"),
        ("native FMUs, our master (Python loop)", native, "python"),
    ):
        system = read_ssp(ssp)
        stepping = []

        def run(system=system, loop=loop, stepping=stepping) -> None:
            result = Master(system, RunOptions(stop_time=stop, loop=loop)).run()
            assert result.ok, result.error
            stepping.append(result.info["stepping_s"])

        rows.append((name, best(repeat, run), min(stepping)))
    if fmpy:
        t = time_fmpy(python, stop, 1 / 400)
        rows.append(("Python FMUs, fmpy simulate_ssp (Jacobi)", t, None))
    models = rows[0][1]
    print(f"\n{stop:g} s paper scenario, {steps} steps at 400 Hz, best of {repeat}")
    print(f"{'':42} {'wall s':>8} {'x real time':>12} {'overhead us/step':>17} "
          f"{'stepping s':>11} {'x real time':>12}")  # fmt: skip
    for name, t, ts in rows:
        overhead = f"{1e6 * (t - models) / steps:17.1f}" if name.startswith("Python FMUs") else ""
        stepping = f"{ts:11.3f} {stop / ts:12.0f}" if ts else ""
        print(f"{name:42} {t:8.3f} {stop / t:12.1f} {overhead:>17} {stepping}")
    print(f"native vs Python FMUs (C loop, whole run): {rows[1][1] / rows[3][1]:.0f}x faster")


@contextlib.contextmanager
def external_cluster(workers: int):
    """`dask scheduler` and `dask worker` processes on 127.0.0.1 (an ephemeral port); yields
    the scheduler's address and the seconds its start took (until every worker is in)."""
    from distributed import Client

    started = time.perf_counter()
    procs = [subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
         "--port", "0", "--no-dashboard"], stderr=subprocess.PIPE, text=True,
    )]  # fmt: skip
    try:
        address = None
        while address is None:
            line = procs[0].stderr.readline()
            if not line:
                raise RuntimeError("the dask scheduler did not start")
            if "Scheduler at:" in line:
                address = line.split()[-1]
        for _ in range(workers):
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                 "--no-dashboard"], stderr=subprocess.DEVNULL,
            ))  # fmt: skip
        with Client(address) as client:
            client.wait_for_workers(workers, timeout=60)
        yield address, time.perf_counter() - started
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def same(a: list[dict], b: list[dict]) -> bool:
    keys = ["status", "error", *sweep.METRICS]
    return len(a) == len(b) and all(
        {k: x[k] for k in keys} == {k: y[k] for k in keys} for x, y in zip(a, b, strict=True)
    )


def cpu_seconds(pids: list[int]) -> float:
    """User + system CPU time used so far by these processes (psutil)."""
    import psutil

    return sum(sum(psutil.Process(pid).cpu_times()[:2]) for pid in pids)


def timed(fn, pids: list[int]) -> tuple[float, float, object]:
    """(wall s, CPU s of pids, result) of fn()."""
    cpu, start = cpu_seconds(pids), time.perf_counter()
    result = fn()
    return time.perf_counter() - start, cpu_seconds(pids) - cpu, result


def run_plans(plans, client=None, **kwargs) -> list[dict]:
    rows = []
    for plan in plans:
        if client is None:
            rows += sweep.run_serial(plan)
        else:
            rows += sweep_batch.run_dask(plan, client, **kwargs)
    return rows


def sweep_table(cases: dict[str, list], workers: int, external: bool) -> None:
    print(f"\nsweeps: {os.cpu_count()} cores, {workers} single-threaded workers; CPU s = CPU "
          "time of this process and the workers during the sweep (its ratio to serial: what the "
          "speed-up would be on free cores, less the waiting)")  # fmt: skip
    head = ("case", "runs", "serial s", "Local+start s", "x", "Local s", "x", "CPU s", "external s",
            "x", "CPU s")  # fmt: skip
    print(f"{head[0]:26} {head[1]:>4} " + " ".join(f"{h:>13}" for h in head[2:]))
    me = [os.getpid()]
    for name, plans in cases.items():
        for plan in plans[:1]:  # warm this process (library loads, compiled loop)
            sweep.run_serial(sweep.Plan(plan.ssp, plan.axes, plan.points[:1], plan.options))
        t_serial, cpu_serial, serial = timed(lambda plans=plans: run_plans(plans), me)
        start = time.perf_counter()
        with sweep.dask_client(workers=workers) as client:
            rows = run_plans(plans, client)  # workers just started: they load everything
            t_with_start = time.perf_counter() - start
            pids = me + list(client.run(os.getpid).values())
            t_local, cpu_local, warm = timed(lambda c=client, p=plans: run_plans(p, c), pids)
            assert same(serial, warm), f"{name}: LocalCluster table differs from serial"
        assert same(serial, rows), f"{name}: LocalCluster table differs from serial"
        ext = f"{'-':>13} {'-':>13} {'-':>13}"
        if external:
            with external_cluster(workers) as (address, _), sweep.dask_client(address) as client:
                run_plans(plans[:1], client)  # the workers read the system once
                pids = me + list(client.run(os.getpid).values())
                t_ext, cpu_ext, ext_rows = timed(lambda c=client, p=plans: run_plans(p, c), pids)
            assert same(serial, ext_rows), f"{name}: external cluster table differs from serial"
            ext = f"{t_ext:13.2f} {t_serial / t_ext:12.2f}x {cpu_ext:13.2f}"
        print(
            f"{name:26} {len(serial):4d} {t_serial:13.2f} {t_with_start:13.2f} "
            f"{t_serial / t_with_start:12.2f}x {t_local:13.2f} {t_serial / t_local:12.2f}x "
            f"{cpu_local:13.2f} {ext}   (serial CPU {cpu_serial:.2f} s)",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="5 s runs, 16-run grids, no study")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--no-external", action="store_true", help="skip the external cluster")
    parser.add_argument(
        "--only", choices=["master", "sweeps", "bundle", "engines", "mujoco"], default=None
    )
    args = parser.parse_args()
    if not (DEFAULT_OUT / "PaperScenario-native.ssp").is_file():
        build_all()
    load = os.getloadavg()
    print(f"load average at start: {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} "
          f"({os.cpu_count()} cores)")  # fmt: skip
    stop = 5.0 if args.quick else 20.0
    if args.only in (None, "master"):
        master_table(stop, 2 if args.quick else 5, fmpy=not args.quick)
    if args.only in (None, "sweeps"):
        native = DEFAULT_OUT / "PaperScenario-native.ssp"
        python = DEFAULT_OUT / "PaperScenario.ssp"
        grid = QUICK_GRID if args.quick else GRID
        first = sweep.plan_sweep(grid, ssp=native, stop=stop)
        cases = {f"native, {len(first.points)} runs": [first]}
        if not args.quick:
            system = read_ssp(native)
            maps = [
                sweep.plan_sweep(
                    [f"{k}={','.join(map(str, v))}" for k, v in m.grid.items()],
                    ssp=native,
                    stop=stop,
                    system=system,
                )
                for m in sweep.STUDY.values()
            ]
            # `sweep --study` on a cluster runs its maps as one stream (execute.run_plans)
            points = [point for m in maps for point in m.points]
            cases["native, study (all maps)"] = [sweep.Plan(native, {}, points, maps[0].options)]
        python_plan = sweep.plan_sweep(grid, ssp=python, stop=stop)
        cases[f"Python, {len(python_plan.points)} runs"] = [python_plan]
        sweep_table(cases, args.workers, not args.no_external)
    if args.only in (None, "bundle"):
        import dist_bundle  # beside this script

        print("\nthe distribution bundle (impedance-cosim dist), built from scratch once:")
        dist_bundle.measure(1)
    if args.only in (None, "engines"):
        import engines_table  # beside this script

        print("\nevery engine on every scenario archive (docs/system.md):")
        engines_table.table()
    if args.only in (None, "mujoco"):
        import mujoco_compare  # beside this script

        print("\nthe paper scenario with MuJoCo's plant (docs/mujoco.md):")
        mujoco_compare.compare(DEFAULT_OUT / "PaperScenario.ssp", DEFAULT_OUT / "MujocoPlant.fmu",
                               stop)  # fmt: skip
    print(f"\nload average at the end: {' '.join(f'{v:.1f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
