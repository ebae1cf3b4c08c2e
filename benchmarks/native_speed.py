"""Time the 20 s paper scenario with the native FMUs and with the Python FMUs under our master
(not a test: prints wall times, real-time factors and speed-ups).

    python benchmarks/native_speed.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import time

from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.packaging.build import DEFAULT_OUT
from impedance_cosim.packaging.build_all import build_all

STOP = 20.0


def best_of(ssp, repeat: int, loop: str) -> tuple[float, float]:
    """Best wall time of a whole run (set-up, loading, initialization, stepping) and of its
    stepping phase alone."""
    system = read_ssp(ssp)
    best, best_steps = float("inf"), float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        result = Master(system, RunOptions(loop=loop)).run()
        best = min(best, time.perf_counter() - start)
        best_steps = min(best_steps, result.info["stepping_s"])
        assert result.ok, result.error
    return best, best_steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5, help="runs per case (best is kept)")
    args = parser.parse_args()
    python_ssp = DEFAULT_OUT / "PaperScenario.ssp"
    native_ssp = DEFAULT_OUT / "PaperScenario-native.ssp"
    if not (python_ssp.is_file() and native_ssp.is_file()):
        build_all()
    rows = []
    for flavour, ssp in (("native", native_ssp), ("python", python_ssp)):
        for loop in ("c", "python"):
            rows.append((flavour, loop, *best_of(ssp, args.repeat, loop)))
    print(f"20 s paper scenario, 8000 steps at 400 Hz, best of {args.repeat}")
    print(f"{'FMUs':8} {'loop':7} {'whole run s':>11} {'x real time':>12} "
          f"{'stepping s':>11} {'x real time':>12}")  # fmt: skip
    for flavour, loop, t, ts in rows:
        print(f"{flavour:8} {loop:7} {t:11.3f} {STOP / t:12.0f} {ts:11.3f} {STOP / ts:12.0f}")
    times = {(f, loop): t for f, loop, t, _ in rows}
    speedup = times[("python", "c")] / times[("native", "c")]
    print(f"native vs python FMUs (C loop): {speedup:.0f}x faster")


if __name__ == "__main__":
    main()
