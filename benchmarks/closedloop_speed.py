"""Speed of the closed-loop FMU (fmus/native/PaperClosedLoop-observer.fmu) against our master
running the same loop on the two native FMUs (fmus/PaperScenario-native.ssp, Gauss-Seidel, C
loop): the paper's 20 s, best of N runs each, every output read at every step in both; the
rows are checked equal first (not a test: the numbers depend on the machine).

    python benchmarks/closedloop_speed.py [--repeat 5] [--fmus fmus]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from impedance_cosim.cosim.fmus.fmi3 import open_fmu
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp

H, STOP = 1 / 400, 20.0


def master(fmus: Path) -> tuple[float, np.ndarray, list[str]]:
    """Wall time of the master's run (initialization included) and its rows."""
    with read_ssp(fmus / "PaperScenario-native.ssp") as system:
        start = time.perf_counter()
        result = Master(
            system, RunOptions(parameter_set="observer", algorithm="gauss-seidel")
        ).run()
        wall = time.perf_counter() - start
    assert result.error is None, result.error
    return wall, result.data[:, 1:], result.names[1:]


def run_alone(fmu: Path, names: list[str], stop: float, h: float = H, parameters=None):
    """The FMU stepped alone from t_i = i h (as the master steps); rows of names at each t_i
    (also tests/test_closedloop.py's)."""
    inst = open_fmu(fmu, "loop")
    try:
        inst.setup(0.0, stop)
        inst.set(parameters or {})
        inst.enter_initialization()
        inst.exit_initialization()
        read = inst.real_getter(names)
        rows = [read()]
        for i in range(round(stop / h)):
            inst.step(i * h, h)
            rows.append(read())
        inst.terminate()
    finally:
        inst.free()
    return np.array(rows)


def closed_loop(fmus: Path, names: list[str]) -> tuple[float, np.ndarray]:
    """Wall time of the closed-loop FMU stepped from Python (ctypes), and its rows."""
    start = time.perf_counter()
    rows = run_alone(fmus / "native" / "PaperClosedLoop-observer.fmu", names, STOP)
    return time.perf_counter() - start, rows


def main() -> None:
    """Print both wall times and real-time factors."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--fmus", type=Path, default=Path(__file__).parents[1] / "fmus")
    args = parser.parse_args()
    runs_m = [master(args.fmus) for _ in range(args.repeat)]
    names = runs_m[0][2]
    runs_c = [closed_loop(args.fmus, names) for _ in range(args.repeat)]
    difference = float(np.abs(runs_c[0][1] - runs_m[0][1]).max())
    print(f"largest difference, closed-loop FMU vs master: {difference:.3g} ({len(names)} outputs)")
    best_m = min(r[0] for r in runs_m)
    best_c = min(r[0] for r in runs_c)
    print(f"master, two native FMUs (C loop): {best_m:.3f} s, {STOP / best_m:.0f}x real time")
    print(f"closed-loop FMU (Python stepping): {best_c:.3f} s, {STOP / best_c:.0f}x real time")


if __name__ == "__main__":
    main()
