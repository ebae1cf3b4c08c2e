"""Each scenario's archive in libcosim, ecospy and fmpy's simulate_ssp against our Jacobi master.

    python benchmarks/engine_conformance.py [--stop-observer 20] [--python]

Prints, per engine and scenario: the engine's wall time, the largest difference over the connected
signals against our master's Jacobi run on the engine's own conventions (time grid, start values)
and on ours (t_0 + i h, connections from the initialized outputs), and the time |tau1| first
exceeds 1e6 N m (the divergence of the unstable scenarios). Native FMUs by default (--python: the
Python ones). Build first: impedance-cosim build.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from impedance_cosim.cosim.engines import others
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.cosim.system.paper import SCENARIOS

H = 0.0025
FMUS = Path(__file__).resolve().parent.parent / "fmus"


def ours(archive: Path, stop: float, **conventions) -> dict[str, np.ndarray]:
    with read_ssp(archive) as system:
        result = Master(
            system,
            RunOptions(algorithm="jacobi", stop_time=stop, divergence_limit=1e300, **conventions),
        ).run()
    return {n: result[n] for n in others.CONNECTED}


def diverges(run: dict, shift: int = 0) -> str:
    row = others.first_beyond(run)
    return f"{(row + shift) * H:.4f} s" if row is not None else "-"


# Each engine's conventions for our master (step times, start values) and its row offset.
CONVENTIONS = {
    "libcosim": ({"step_times": others.nanosecond_times(0.0, H)}, 0),
    "ecospy": ({"step_times": others.AccumulatedTimes(0.0, H)}, 0),
    "fmpy": ({"step_times": others.AccumulatedTimes(0.0, H), "zero_start_inputs": True}, 1),
}


def run(engine: str, archive: Path, scenario: str, stop: float) -> dict[str, np.ndarray]:
    if engine == "libcosim":
        return others.run_in_libcosim(archive, None, stop, H, log_level="error")
    if engine == "ecospy":
        return others.run_in_ecospy(archive, scenario, stop, H, others.CONNECTED)
    return others.run_in_fmpy(archive, stop, H)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stop-observer", type=float, default=20.0)
    parser.add_argument("--python", action="store_true", help="the Python FMUs' archives")
    args = parser.parse_args()
    stops = {"observer": args.stop_observer, "difference": 0.495, "measured": 2.75}
    base = "PaperScenario" if args.python else "PaperScenario-native"
    print(f"{'engine':9} {'scenario':10} {'stop':>6} {'wall':>8} {'vs ours, its grid':>18}"
          f" {'vs ours, t0+ih':>15} {'|tau1|>1e6 at':>14} {'ours':>9}")  # fmt: skip
    for scenario in SCENARIOS:
        archive = FMUS / f"{base}-{scenario}.ssp"
        stop = stops[scenario]
        default = ours(archive, stop)
        for engine, (conventions, shift) in CONVENTIONS.items():
            t0 = time.perf_counter()
            theirs = run(engine, archive, scenario, stop)
            wall = time.perf_counter() - t0
            same = others.largest_difference(ours(archive, stop, **conventions), theirs, shift)[0]
            on_ours = others.largest_difference(default, theirs, shift)[0]
            print(f"{engine:9} {scenario:10} {stop:6g} {wall:7.2f}s {same:18.3g}"
                  f" {on_ours:15.3g} {diverges(theirs, shift):>14}"
                  f" {diverges(default):>9}")  # fmt: skip


if __name__ == "__main__":
    main()
