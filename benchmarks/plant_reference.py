"""Tight reference solutions of the plant, independent of the plant's own integrator.

scipy's DOP853 (rtol 1e-10 by default) integrates eq. (1) with the clamped wall law and scipy's
own event location, one torque-hold interval at a time. Used to measure the plant FMU's accuracy
(benchmarks/plant_accuracy.py and tests/test_plant.py, which loads this file).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from impedance_cosim.physics.wall import wall_force
from plant_model.model import PlantModel


def reference_states(
    parameters: dict[str, Any],
    torques: Sequence[Sequence[float]],
    dt: float,
    rtol: float = 1e-10,
    atol: float = 1e-12,
) -> np.ndarray:
    """States (q, qd) at t = 0, dt, 2 dt, ... when torques[i] is held over [i dt, (i+1) dt).

    Returns an array of shape (len(torques) + 1, 6)."""
    plant = PlantModel(parameters, 0.0, None)  # initial state and parameters only
    arm, wall = plant.arm, plant.wall

    def rhs(_t: float, y: np.ndarray, tau: Sequence[float]) -> list[float]:
        q, qd = tuple(y[:3]), tuple(y[3:])
        x, xd = plant._ee_x(q, qd)
        fx = wall_force(wall, x, xd)
        j = arm.jacobian(q)[0]
        net = (tau[0] - fx * j[0], tau[1] - fx * j[1], tau[2] - fx * j[2])
        return [*qd, *arm.forward_dynamics(q, qd, net)]

    def gap(_t: float, y: np.ndarray, _tau: Sequence[float]) -> float:
        return plant._ee_x(tuple(y[:3]), tuple(y[3:]))[0] - wall.wall_x

    gap.terminal = True  # type: ignore[attr-defined]
    y = np.array([*plant.q, *plant.qd], dtype=float)
    out = [y.copy()]
    for i, tau in enumerate(torques):
        t, t_end = i * dt, (i + 1) * dt
        events = gap
        while True:
            sol = solve_ivp(
                rhs, (t, t_end), y, method="DOP853", rtol=rtol, atol=atol,
                events=events, args=(tuple(tau),),
            )  # fmt: skip
            if not sol.success:
                raise RuntimeError(f"reference integration failed at t={t}: {sol.message}")
            y, t = sol.y[:, -1], sol.t[-1]
            if sol.status != 1:  # reached t_end
                break
            # At a contact switch: step 1 ns past it without events (else the root at the
            # restart point triggers again), then resume with event detection.
            t_past = min(t + 1e-9, t_end)
            sol = solve_ivp(rhs, (t, t_past), y, method="DOP853", rtol=rtol, atol=atol,
                            args=(tuple(tau),))  # fmt: skip
            y, t = sol.y[:, -1], t_past
            if t >= t_end:
                break
        out.append(y.copy())
    return np.array(out)
