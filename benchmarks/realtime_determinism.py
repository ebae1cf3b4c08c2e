"""Deadline misses and start jitter of the real-time master with and without the real-time options
(memory locked, SCHED_FIFO, pinned to a CPU, longer busy-wait), on an idle machine and under a
load of one busy process (`python -c 'while True: pass'`, free or pinned to the loop's CPU).
Not a test: prints one table row per case (runs of the 20 s scenario, native FMUs by default).

    python benchmarks/realtime_determinism.py                 # 10 runs of 20 s per case (~40 min)
    python benchmarks/realtime_determinism.py --runs 3 --stop 10
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import time

import numpy as np

from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.master.realtime import RealtimeOptions
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.packaging.build import DEFAULT_OUT
from impedance_cosim.packaging.build_all import build_all


@contextlib.contextmanager
def busy_process(cpu: int | None):
    """One busy Python process (pinned to `cpu` if given) for the body; killed after (by PID)."""
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        if cpu is not None:
            os.sched_setaffinity(proc.pid, {cpu})
        time.sleep(0.2)
        yield
    finally:
        proc.kill()
        proc.wait()


def measure(system, stop: float, runs: int, options) -> dict:
    misses, p99, jmax, late = [], [], [], []
    notes: list[str] = []
    for _ in range(runs):
        result = Master(system, RunOptions(stop_time=stop, realtime=options)).run()
        assert result.ok, result.error
        stats = result.info["realtime"]
        misses.append(stats["deadline_misses"])
        p99.append(stats["jitter_p99_s"])
        jmax.append(stats["jitter_max_s"])
        late.append(stats["lateness_max_s"])
        notes = stats.get("notes", [])
    return {"misses": misses, "p99": p99, "max": jmax, "late": late, "notes": notes}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--stop", type=float, default=20.0)
    parser.add_argument("--ssp", default=str(DEFAULT_OUT / "PaperScenario-native.ssp"))
    parser.add_argument("--cpu", type=int, default=max(os.sched_getaffinity(0)),
                        help="the CPU the options pin the loop to")  # fmt: skip
    parser.add_argument("--fifo", type=int, default=80, help="SCHED_FIFO priority")
    parser.add_argument("--spin", type=float, default=0.001, help="busy-wait with the options [s]")
    args = parser.parse_args()
    if not os.path.isfile(args.ssp):
        build_all()
    system = read_ssp(args.ssp)
    with_options = RealtimeOptions(
        lock_memory=True, fifo_priority=args.fifo, cpu=args.cpu, spin_s=args.spin
    )
    configs = {"default (sleep + 0.5 ms spin)": True, "all options": with_options}
    loads = {"idle": None, "1 busy process": "free", f"1 busy process on CPU {args.cpu}": "pin"}
    steps = round(args.stop * 400)
    print(f"load average at start: {' '.join(f'{v:.1f}' for v in os.getloadavg())} "
          f"({os.cpu_count()} cores); {args.runs} runs of {args.stop:g} s ({steps} steps) each, "
          f"{os.path.basename(args.ssp)}")  # fmt: skip
    print("| options | load | deadline misses per run | start jitter p99 ms (median of runs) "
          "| start jitter max ms (worst run) | worst lateness ms |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    notes = set()
    for load, mode in loads.items():
        for name, options in configs.items():
            cpu = None if mode != "pin" else args.cpu
            with busy_process(cpu) if mode else contextlib.nullcontext():
                r = measure(system, args.stop, args.runs, options)
            notes.update(r["notes"])
            print(f"| {name} | {load} | {', '.join(map(str, r['misses']))} "
                  f"| {1e3 * float(np.median(r['p99'])):.3f} | {1e3 * max(r['max']):.2f} "
                  f"| {1e3 * max(r['late']):.2f} |", flush=True)  # fmt: skip
    print(f"options granted: {'; '.join(sorted(notes))}")
    print(f"load average at the end: {' '.join(f'{v:.1f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
