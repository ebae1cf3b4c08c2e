"""Model Exchange of the native PumaPlant against its co-simulation interface (not a test: prints
numbers). Needs the native FMUs (impedance-cosim build).

1. The default experiment (the arm falls under gravity, no torque), fmpy's CVode at several
   relative tolerances (the DefaultExperiment's 1e-9 is what `fmpy simulate` uses).
2. The paper scenario's torques (our master on PaperScenario-native.ssp) replayed open loop into
   the ME plant: max joint-angle difference to the CS plant over 20 s, contact-time difference,
   wall time. Also with the torque steps placed exactly at t_i (fmpy's root function then hands
   CVode the previous torque after every restart; see impedance_cosim/cosim/engines/replay.py).

    python benchmarks/model_exchange.py
"""

from __future__ import annotations

import time

import numpy as np
from fmpy import simulate_fmu

from impedance_cosim.cosim.engines.replay import cs_crossing_times, me_replay
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.packaging.build import DEFAULT_OUT

PLANT = DEFAULT_OUT / "native" / "PumaPlant.fmu"
ANGLES = ("q1_true", "q2_true", "q3_true")
WALL_X = 0.65
DT = 1 / 400


def default_experiment() -> None:
    cs = simulate_fmu(str(PLANT), fmi_type="CoSimulation", output_interval=DT)
    print("default experiment (20 s fall), ME under CVode vs CS:")
    print(f"{'CVode rtol':>12} {'max|q err| rad':>15} {'wall s':>7}")
    for rtol in (None, 1e-6, 1e-8, 1e-10):
        start = time.perf_counter()
        me = simulate_fmu(
            str(PLANT), fmi_type="ModelExchange", output_interval=DT, relative_tolerance=rtol
        )
        seconds = time.perf_counter() - start
        err = max(np.abs(me[n] - cs[n]).max() for n in ANGLES)
        label = "1e-09 (default)" if rtol is None else f"{rtol:.0e}"
        print(f"{label:>12} {err:>15.1e} {seconds:>7.1f}")


def paper_scenario() -> None:
    run = Master(read_ssp(DEFAULT_OUT / "PaperScenario-native.ssp")).run()
    t = run["time"]
    tau = np.column_stack([run[f"controller.tau{i}"][1:] for i in (1, 2, 3)])
    q_cs = np.column_stack([run[f"plant.{n}"] for n in ANGLES])
    cs_times, _ = cs_crossing_times(PLANT, t, tau, WALL_X)
    print(f"\npaper scenario torques replayed, CS contact times {[f'{c:.6f}' for c in cs_times]} s")
    print(f"{'CVode rtol':>10} {'input steps':>12} {'max|q err| rad':>15} {'contact dt s':>13}"
          f" {'wall s':>7}")  # fmt: skip
    for rtol, shift in [(1e-10, 1e-10), (1e-12, 1e-10), (1e-13, 1e-10), (1e-14, 1e-10),
                        (1e-14, 0.0)]:  # fmt: skip
        start = time.perf_counter()
        result, log = me_replay(PLANT, t, tau, rtol, shift)
        seconds = time.perf_counter() - start
        q_me = np.column_stack([result[n] for n in ANGLES])
        on_grid = np.isclose(log[:, 0] / DT, np.round(log[:, 0] / DT), rtol=0.0, atol=1e-6)
        events = log[~on_grid, 0]
        if len(events) == len(cs_times):
            dt = f"{np.abs(events - cs_times).max():.1e}"
        else:
            dt = f"{len(events)} events"
        where = "t_i" if shift == 0.0 else "t_i(1-1e-10)"
        err = np.abs(q_me - q_cs).max()
        print(f"{rtol:>10.0e} {where:>12} {err:>15.1e} {dt:>13} {seconds:>7.1f}")


if __name__ == "__main__":
    default_experiment()
    paper_scenario()
