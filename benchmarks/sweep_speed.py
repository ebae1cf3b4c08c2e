"""A 64-run sweep on dask (LocalCluster, one single-threaded worker process per core) against the
same 64 runs in series in this process. Not a test: prints wall times and speed-ups, with and
without the cluster's start-up, for the Python FMUs and the native ones; checks that both give
the same table.

    python benchmarks/sweep_speed.py                # both archives, 20 s runs
    python benchmarks/sweep_speed.py --only python --stop 10
"""

from __future__ import annotations

import argparse
import os
import time

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


def same(a: list[dict], b: list[dict]) -> bool:
    keys = ["status", "error", *sweep.METRICS]
    return all({k: x[k] for k in keys} == {k: y[k] for k in keys} for x, y in zip(a, b))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=list(ARCHIVES), default=None)
    parser.add_argument("--stop", type=float, default=20.0)
    parser.add_argument("--workers", type=int, default=os.cpu_count())
    args = parser.parse_args()
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


if __name__ == "__main__":
    main()
