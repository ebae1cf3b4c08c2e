"""Input extrapolation under Jacobi (master option extrapolation="linear"), measured. Not a test:
prints

1. accuracy, observer scenario, native FMUs, 20 s: max and rms error of the contact force and
   the tool position (x, y) of Gauss-Seidel and of Jacobi with and without extrapolation at
   400 Hz, against a fine-step reference (Gauss-Seidel at a 1/4000 s communication step, the
   controller still sampling at 400 Hz: the paper's sample-and-hold without co-simulation error),
   and for Jacobi also against that reference one sample earlier (row k against ref(t_k - h));
2. the critical sample rates (bisection to 1 Hz over 100-1000 Hz, 20 s runs, ideal sensors,
   the stability study's Bisection and sweep points) per velocity source, Jacobi with and
   without extrapolation;
3. the same from the linearised loop (apps/linearize.py, "jacobi-linear"), free motion and
   contact points, as docs/stability.md compares them for plain Jacobi;
4. the cost: the master's stepping time per step (C loop, observer, 20 s, best of 5 runs).

    python benchmarks/extrapolation.py [accuracy] [bisection] [linear] [speed]
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from impedance_cosim.apps import linearize as lin
from impedance_cosim.apps.stability.bisection import QUANTITIES, Bisection, Case
from impedance_cosim.apps.sweep.plan import run_options
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp

SSP = Path(__file__).resolve().parent.parent / "fmus" / "PaperScenario-native.ssp"
SIGNALS = ("plant.contact_force", "plant.x", "plant.y")
FINE = 10  # reference steps per sample
SOURCES = ("observer", "difference", "measured")
EXTRAPOLATIONS = ("none", "linear")


def accuracy() -> None:
    """Part 1: errors against the fine-step reference."""
    system = read_ssp(SSP)
    h = 1 / 400
    ref = Master(
        system,
        RunOptions(
            parameter_set="observer",
            overrides={"controller.sample_period": h},
            algorithm="gauss-seidel",
            step_size=h / FINE,
        ),
    ).run()
    assert ref.ok, ref.error
    grid = ref.data[::FINE]
    print("## accuracy: observer, 20 s, 400 Hz, against Gauss-Seidel at 1/4000 s")
    print("| master | " + " | ".join(f"{s} max | {s} rms" for s in SIGNALS) + " |")
    print("|---|" + "---|---|" * len(SIGNALS))
    for algorithm, extrapolation in (("gauss-seidel", "none"), ("jacobi", "none"),
                                     ("jacobi", "linear")):  # fmt: skip
        r = Master(
            system,
            RunOptions(parameter_set="observer", algorithm=algorithm, extrapolation=extrapolation),
        ).run()
        if not r.ok:
            print(f"| {algorithm}, {extrapolation} | {r.error} |")
            continue
        for late in (0, 1) if algorithm == "jacobi" else (0,):  # 1: against ref(t - h)
            cells = []
            for s in SIGNALS:
                mine, theirs = r.data[late:, r.names.index(s)], grid[:, ref.names.index(s)]
                e = mine - theirs[: len(mine)]
                unit, scale = ("N", 1.0) if s.endswith("force") else ("mm", 1e3)
                cells += [f"{np.abs(e).max() * scale:.4g} {unit}",
                          f"{np.sqrt(np.mean(e**2)) * scale:.4g} {unit}"]  # fmt: skip
            what = ", against the reference one sample earlier" if late else ""
            print(f"| {algorithm}, extrapolation {extrapolation}{what} | " + " | ".join(cells)
                  + " |")  # fmt: skip


def critical_rate(system, velocity: str, extrapolation: str) -> Bisection:
    """One bisection of the sample rate (the stability study's bracket and rule), serial."""
    case = Case("rate", velocity, "jacobi", "ideal")
    b = Bisection(case, *QUANTITIES["rate"][0])
    while points := b.next_points():
        for x in points:
            options = replace(
                run_options(case.point(x), {"stop": 20.0}), extrapolation=extrapolation
            )
            r = Master(system, options).run()
            b.record(x, r.ok, r.error or "")
    return b


def bisection() -> None:
    """Part 2: critical sample rates from the simulation."""
    system = read_ssp(SSP)
    print("## critical sample rate, Jacobi, bisection (20 s native runs, ideal sensors)")
    print("| velocity | extrapolation none | extrapolation linear | runs | wall |")
    print("|---|---|---|---|---|")
    for velocity in SOURCES:
        started, cells, runs = time.perf_counter(), [], 0
        for extrapolation in EXTRAPOLATIONS:
            row = critical_rate(system, velocity, extrapolation).row()
            runs += row["runs"]
            cells.append(f"{row['critical']:g} Hz" if row["critical"] else row["note"])
        wall = time.perf_counter() - started
        print(f"| {velocity} | {cells[0]} | {cells[1]} | {runs} | {wall:.0f} s |")


def linear() -> None:
    """Part 3: critical sample rates of the linearised loop."""
    ref = lin.reference_run({}, {})
    print("## critical sample rate, Jacobi, linearised loop (free / contact point)")
    print("| velocity | extrapolation | free | contact | unstable mode |")
    print("|---|---|---|---|---|")
    for velocity in SOURCES:
        for extrapolation in EXTRAPOLATIONS:
            algorithm = "jacobi-linear" if extrapolation == "linear" else "jacobi"
            rates = []
            for point in ("free", "contact"):

                def radius(rate: float, at: tuple = (algorithm, velocity, point)) -> float:
                    return lin.loop_radius(rate, *at, reference=ref)[0]

                rates.append(lin.critical_rate(radius))
            shown = [f"{r:.1f} Hz" if r else "no crossing in 100-1000 Hz" for r in rates]
            top = max((r for r in rates if r), default=None)
            tail = "-"
            if top:  # the mode that goes unstable: just below the higher critical rate
                point = ("free", "contact")[rates.index(top)]
                period = lin.loop_radius(top - 1.0, algorithm, velocity, point, reference=ref)[1]
                tail = f"period {period:.1f} samples" if period else "real (period 2 samples)"
            print(f"| {velocity} | {extrapolation} | {shown[0]} | {shown[1]} | {tail} |")


def speed() -> None:
    """Part 4: stepping time per step, with and without extrapolation."""
    system = read_ssp(SSP)
    print("## cost: stepping time per step (C loop, observer, 8000 steps, best of 5)")
    for algorithm, extrapolation in (("gauss-seidel", "none"), ("jacobi", "none"),
                                     ("jacobi", "linear")):  # fmt: skip
        best = min(
            Master(system, RunOptions(parameter_set="observer", algorithm=algorithm, loop="c",
                                      extrapolation=extrapolation)).run().info["stepping_s"]
            for _ in range(5)
        )  # fmt: skip
        print(f"{algorithm}, extrapolation {extrapolation}: {best / 8000 * 1e6:.2f} us per step")


if __name__ == "__main__":
    parts = sys.argv[1:] or ["accuracy", "bisection", "linear", "speed"]
    for part in parts:
        {"accuracy": accuracy, "bisection": bisection, "linear": linear, "speed": speed}[part]()
        print()
