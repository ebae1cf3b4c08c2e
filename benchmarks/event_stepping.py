"""Event-exact stepping against the fixed step (issue 23), on the FMI 3.0 archive (not a test).

For each run (the 20 s paper scenario, each velocity source, Gauss-Seidel, and the observer under
Jacobi) it runs our master twice: fixed step, and EventExactMaster (cosim/master/events.py: the
plant returns early at each contact switch, the master handles the event in Event Mode and
completes the communication step). It prints the number of contact events, the exact switch times
against the first grid row that shows the change (contact_force > 0 or back to 0), the impact peak
of each run, and the largest difference of any recorded output between the two runs, with wall
times.

    python benchmarks/event_stepping.py [--stop 20]   (build first: impedance-cosim build)
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from impedance_cosim.cosim.master.events import EventExactMaster
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.packaging.build import DEFAULT_OUT

RUNS = [("observer", "gauss-seidel"), ("difference", "gauss-seidel"),
        ("measured", "gauss-seidel"), ("observer", "jacobi")]  # fmt: skip


def grid_lag(times: np.ndarray, force: np.ndarray, events: list[float]) -> list[float]:
    """For each switch time, how much later the first recorded row shows it (s)."""
    lags = []
    for t_event in events:
        k = int(np.searchsorted(times, t_event, side="right"))  # first row after the switch
        if k < len(times):
            lags.append(float(times[k] - t_event))
    return lags


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stop", type=float, default=20.0, help="stop time (s)")
    args = parser.parse_args()
    ssp = DEFAULT_OUT / "PaperScenario-fmi3.ssp"
    if not ssp.exists():
        sys.exit(f"error: {ssp} missing: run `impedance-cosim build`")
    system = read_ssp(ssp)
    print(f"{'run':<26} {'events':>6} {'max lag ms':>10} {'peak fixed N':>13} "
          f"{'peak event N':>13} {'max |diff|':>10} {'wall fixed/event s':>19}")  # fmt: skip
    for scenario, algorithm in RUNS:
        t0 = time.perf_counter()
        fixed = Master(
            system, RunOptions(parameter_set=scenario, algorithm=algorithm, stop_time=args.stop)
        ).run()
        t1 = time.perf_counter()
        exact_master = EventExactMaster(
            system, RunOptions(parameter_set=scenario, algorithm=algorithm, stop_time=args.stop)
        )
        exact = exact_master.run()
        t2 = time.perf_counter()
        if not (fixed.ok and exact.ok):
            sys.exit(f"error: {scenario}/{algorithm}: {fixed.error or exact.error}")
        events = exact_master.events.get("plant", [])
        lags = grid_lag(fixed["time"], fixed["plant.contact_force"], events)
        diff = float(np.abs(fixed.data - exact.data).max())
        print(f"{scenario + ' / ' + algorithm:<26} {len(events):>6} "
              f"{1e3 * max(lags, default=0.0):>10.4f} "
              f"{fixed['plant.contact_force'].max():>13.6f} "
              f"{exact['plant.contact_force'].max():>13.6f} {diff:>10.3g} "
              f"{t1 - t0:>9.2f}/{t2 - t1:<9.2f}")  # fmt: skip
        print("  switch times (s): " + ", ".join(f"{t:.9f}" for t in events))


if __name__ == "__main__":
    main()
