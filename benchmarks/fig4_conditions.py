"""Does numerical differentiation destabilise the loop (the paper's Fig. 4)? Not a test: prints,
for joint sensors without and with quantization or noise, the observer and the backward
difference in the loop side by side (20 s paper scenario, plain models, 400 Hz).

    python benchmarks/fig4_conditions.py
"""

from __future__ import annotations

import math

import numpy as np

from impedance_cosim.cosim.master.plain_loop import run_models

SENSORS = [
    ("ideal", {}),
    ("16-bit encoder", {"q_quant": 2 * math.pi / 2**16}),
    ("12-bit encoder", {"q_quant": 2 * math.pi / 2**12}),
    ("noise 1e-5 rad", {"q_noise": 1e-5}),
    ("noise 1e-4 rad", {"q_noise": 1e-4}),
    ("noise 1e-3 rad", {"q_noise": 1e-3}),
]


def row(sensor: dict, source: str) -> str:
    try:
        r = run_models(sensor, {"velocity_source": source}, stop_time=20.0)
    except Exception as exc:  # a diverging run ends in a model error
        return f"failed: {exc}"
    t, force = r["time"], r["plant.contact_force"]
    settled = force[(t >= 5.5) & (t <= 6.1)].mean()
    tau = max(np.abs(r[f"controller.tau{i}"]).max() for i in (1, 2, 3))
    jitter = np.std(np.diff(r["plant.xd"][(t > 6.5) & (t < 13)]))
    return f"{force.max():7.1f} {settled:9.2f} {tau:11.1f} {jitter:14.2e}"


def main() -> None:
    print(f"{'joint sensors':16} {'velocity':10} {'F peak N':>8} {'F settled':>9} "
          f"{'max|tau| Nm':>11} {'xd jitter m/s':>14}")  # fmt: skip
    for label, sensor in SENSORS:
        for source in ("observer", "difference"):
            print(f"{label:16} {source:10} {row(sensor, source)}")


if __name__ == "__main__":
    main()
