"""The paper scenario in another engine, libcosim, next to our master (not a test: prints numbers).

Runs fmus/PaperScenario.ssp (built if missing) in libcosim's fixed-step algorithm (Jacobi; see
impedance_cosim/cosim/engines/others.py for its conventions), then in our master as Jacobi and as
Gauss-Seidel, and prints the wall times and the largest differences on the main signals. --csv
writes libcosim's rows (time and every output).

    pip install libcosimpy==0.0.6
    python benchmarks/other_engine.py [--set observer] [--stop 20] [--csv libcosim.csv]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from impedance_cosim.cosim.engines.others import EngineError, run_in_libcosim
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.packaging.build import DEFAULT_OUT
from impedance_cosim.packaging.build_all import build_all

STEP = 1 / 400
SIGNALS = ["plant.x", "plant.y", "plant.contact_force", "plant.qd1", "plant.qd2", "plant.qd3"]
SIGNALS += ["controller.tau1", "controller.tau2", "controller.tau3"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--set", default="observer", help="parameter set (scenario)")
    parser.add_argument("--stop", type=float, default=20.0)
    parser.add_argument("--csv", help="write libcosim's rows to this file")
    args = parser.parse_args()
    ssp = DEFAULT_OUT / "PaperScenario.ssp"
    if not ssp.is_file():
        build_all()

    start = time.perf_counter()
    try:
        theirs = run_in_libcosim(ssp, args.set, args.stop, STEP)
    except EngineError as exc:
        raise SystemExit(f"libcosim: {exc}") from None
    print(f"libcosim: {args.set}, {args.stop:g} s at 400 Hz, {time.perf_counter() - start:.2f} s")
    if args.csv:
        names = list(theirs)
        np.savetxt(args.csv, np.column_stack([theirs[n] for n in names]), delimiter=",",
                   header=",".join(names), comments="", fmt="%.17g")  # fmt: skip
    labels = [s.split(".")[1] for s in SIGNALS]
    print(f"{'our master':14} {'wall s':>6} " + " ".join(f"{n:>8}" for n in labels))
    for algorithm in ("jacobi", "gauss-seidel"):
        start = time.perf_counter()
        ours = Master(
            read_ssp(ssp),
            RunOptions(parameter_set=args.set, algorithm=algorithm, stop_time=args.stop),
        ).run()
        wall = time.perf_counter() - start
        rows = len(ours.data)  # a run that diverged keeps its rows up to there
        diffs = [np.max(np.abs(theirs[s][:rows] - ours[s])) for s in SIGNALS]
        cells = [f"{d:{max(8, len(n))}.1e}" for d, n in zip(diffs, labels)]
        print(f"{algorithm:14} {wall:6.2f} " + " ".join(cells))
        if ours.error:
            print(f"  (our master: {ours.error})")
    print("(largest |libcosim - ours| per signal)")


if __name__ == "__main__":
    main()
