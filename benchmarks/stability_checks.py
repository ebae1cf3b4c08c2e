"""Checks behind docs/stability.md that are not part of the study's tables. Not a test: prints

1. every rate near the observer's and the difference's sample-and-hold boundary, run for 10 s and
   20 s (native FMUs): how fuzzy the simulated boundary is;
2. the linearised critical rate (contact point) with the impedance damping B halved, and the
   joint-velocity part of the unstable mode just below the critical rate: which mode limits the
   true velocity and the observer;
3. the linearised critical observer gain K at 400 Hz (free-motion and contact points) per timing
   and observer discretization, to compare with the bisected ones in docs/boundaries.csv.

    python benchmarks/stability_checks.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from impedance_cosim.apps import linearize as lin
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp

SSP = Path(__file__).resolve().parent.parent / "fmus" / "PaperScenario-native.ssp"


def scan() -> None:
    system = read_ssp(SSP)
    for source, rates in (("observer", range(236, 250)), ("difference", range(198, 208))):
        for rate in rates:
            cells = []
            for stop in (10.0, 20.0):
                r = Master(
                    system,
                    RunOptions(
                        parameter_set=source,
                        step_size=1 / rate,
                        stop_time=stop,
                        overrides={"controller.sample_period": 1 / rate},
                    ),
                ).run()
                cells.append("bounded" if r.ok else f"diverges at {r.data[-1, 0]:.2f} s")
            print(f"{source:10} {rate} Hz: 10 s {cells[0]:22} 20 s {cells[1]}")


def damping() -> None:
    ref = lin.reference_run({}, {})
    for source in ("measured", "observer"):
        for scale in (0.5, 1.0):
            b = 2 * 1000**0.5 * scale
            cp = {"B1": b, "B2": b, "B3": b}
            rate = lin.critical_rate(
                lambda r, s=source, c=cp: lin.loop_radius(
                    r, "gauss-seidel", s, "contact", controller_parameters=c, reference=ref
                )[0],
                80.0, 1000.0, 0.5)  # fmt: skip
            m = lin.operating_point(5.5, rate - 2.0, "gauss-seidel", {},
                                    {**cp, "velocity_source": source}, ref)  # fmt: skip
            lam, vec = np.linalg.eig(lin.jacobian(m, m.state()))
            v = vec[:, np.argmax(np.abs(lam))]
            qd = np.abs(v[3:6]) / np.abs(v[3:6]).max()
            print(
                f"{source:10} B x {scale}: linearised critical rate {rate:.1f} Hz; below it"
                f" lambda = {lam[np.argmax(np.abs(lam))]:.3f}, |qd| part {np.round(qd, 2)}"
            )


def gain_limits() -> None:
    ref = lin.reference_run({}, {})
    cases = [("gauss-seidel", "euler"), ("jacobi", "euler"), ("jacobi", "implicit"),
             ("jacobi", "exponential"), ("gauss-seidel", "exponential")]  # fmt: skip
    for timing, form in cases:
        for point in lin.POINTS:

            def radius(k: float, t=timing, f=form, p=point) -> float:
                cp = {"K1": k, "K2": k, "K3": k, "observer_discretization": f}
                return lin.loop_radius(400.0, t, "observer", p, controller_parameters=cp,
                                       reference=ref)[0]  # fmt: skip

            lo, hi = 50.0, 1e5
            if radius(hi) <= 1.0:
                print(f"{timing:12} {form:11} {point:7}: stable up to K = 1e5")
                continue
            while hi / lo > 1.001:
                mid = (lo * hi) ** 0.5
                lo, hi = (lo, mid) if radius(mid) > 1.0 else (mid, hi)
            print(f"{timing:12} {form:11} {point:7}: linearised critical K = {lo:.1f}")


if __name__ == "__main__":
    scan()
    damping()
    gain_limits()
