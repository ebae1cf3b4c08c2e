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

from impedance_cosim.cosim.engines.others import (
    AccumulatedTimes,
    nanosecond_times,
    run_in_ecospy,
    run_in_fmpy,
    run_in_libcosim,
)
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.cosim.system.paper import CONNECTIONS, SCENARIOS

H = 0.0025
SIGNALS = sorted({f"{se}.{sc}" for se, sc, _, _ in CONNECTIONS})
FMUS = Path(__file__).resolve().parent.parent / "fmus"


def ours(archive: Path, stop: float, **conventions) -> dict[str, np.ndarray]:
    with read_ssp(archive) as system:
        result = Master(system, algorithm="jacobi", stop_time=stop, divergence_limit=1e300,
                        **conventions).run()  # fmt: skip
    return {n: result[n] for n in SIGNALS}


def worst(a: dict, b: dict, shift: int = 0) -> float:
    return max(float(np.max(np.abs(a[n][shift : shift + len(b[n])] - b[n]))) for n in SIGNALS)


def diverges(run: dict, shift: int = 0) -> str:
    beyond = np.nonzero(np.abs(run["controller.tau1"]) > 1e6)[0]
    return f"{(beyond[0] + shift) * H:.4f} s" if len(beyond) else "-"


# Each engine's conventions for our master (step times, start values) and its row offset.
CONVENTIONS = {
    "libcosim": ({"step_times": nanosecond_times(0.0, H)}, 0),
    "ecospy": ({"step_times": AccumulatedTimes(0.0, H)}, 0),
    "fmpy": ({"step_times": AccumulatedTimes(0.0, H), "zero_start_inputs": True}, 1),
}


def run(engine: str, archive: Path, scenario: str, stop: float) -> dict[str, np.ndarray]:
    if engine == "libcosim":
        return run_in_libcosim(archive, None, stop, H, log_level="error")
    if engine == "ecospy":
        return run_in_ecospy(archive, scenario, stop, H, SIGNALS)
    return run_in_fmpy(archive, stop, H)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stop-observer", type=float, default=20.0)
    parser.add_argument("--python", action="store_true", help="the Python FMUs' archives")
    args = parser.parse_args()
    stops = {"observer": args.stop_observer, "difference": 0.5, "measured": 2.75}
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
            same = worst(ours(archive, stop, **conventions), theirs, shift)
            print(f"{engine:9} {scenario:10} {stop:6g} {wall:7.2f}s {same:18.3g}"
                  f" {worst(default, theirs, shift):15.3g} {diverges(theirs, shift):>14}"
                  f" {diverges(default):>9}")  # fmt: skip


if __name__ == "__main__":
    main()
