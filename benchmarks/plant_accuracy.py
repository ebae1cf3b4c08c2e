"""Accuracy of the plant's integrator over the paper's 20 s scenario (not a test: prints numbers).

The torque sequence comes from the closed loop (plain models, 400 Hz). The plant integrates it
with its adaptive Dormand-Prince 5(4) + contact-event location at several tolerances; the
reference is scipy's DOP853 at rtol 1e-10, atol 1e-12 with its own event handling.

    python benchmarks/plant_accuracy.py
"""

from __future__ import annotations

import time

import numpy as np
from plant_reference import reference_states

from impedance_cosim.cosim.master.plain_loop import run_models
from plant_model.model import PlantModel

DT = 1 / 400
STOP = 20.0


def plant_states(torques, parameters) -> tuple[np.ndarray, float]:
    plant = PlantModel(parameters, 0.0, None)
    out = [(*plant.q, *plant.qd)]
    start = time.perf_counter()
    for i, tau in enumerate(torques):
        plant.do_step(i * DT, DT, tau)
        out.append((*plant.q, *plant.qd))
    return np.array(out), time.perf_counter() - start


def main() -> None:
    run = run_models(stop_time=STOP, step=DT)
    n = round(STOP / DT)
    # the torque applied over step i is recorded at t_i+1 (row i + 1)
    torques = np.column_stack([run[f"controller.tau{i}"][1 : n + 1] for i in (1, 2, 3)])
    torques = [tuple(row) for row in torques]
    start = time.perf_counter()
    ref = reference_states({}, torques, DT)
    print(f"reference (scipy DOP853, rtol 1e-10): {time.perf_counter() - start:.1f} s")
    print(f"{'plant rtol':>10} {'max|q err| rad':>15} {'max|qd err| rad/s':>18} {'cpu s':>7}")
    for rtol, atol in [(1e-6, 1e-8), (1e-8, 1e-10), (1e-9, 1e-11), (1e-10, 1e-12)]:
        states, seconds = plant_states(torques, {"rtol": rtol, "atol": atol})
        err = np.abs(states - ref)
        print(f"{rtol:>10.0e} {err[:, :3].max():>15.2e} {err[:, 3:].max():>18.2e} {seconds:>7.2f}")


if __name__ == "__main__":
    main()
