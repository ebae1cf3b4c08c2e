"""A plant model's free motion, for the tests that compare plants (PumaPlant against MuJoCo's and
Pinocchio's)."""

from __future__ import annotations

import numpy as np


def free_motion(model, steps: int, h: float = 1 / 400) -> np.ndarray:
    """Outputs of a model left alone (zero torque, falling under gravity) at every step."""
    rows = [model.outputs()]
    for i in range(steps):
        model.do_step(i * h, h, (0.0, 0.0, 0.0))
        rows.append(model.outputs())
    return np.array(rows)
