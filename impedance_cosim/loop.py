"""The closed loop on the plain models, without FMI: the reference the FMU runs are checked against.

Gauss-Seidel, controller first (the paper's sample-and-hold): at t_i the controller samples the
plant's outputs at t_i, and the plant integrates over [t_i, t_i + h] with that torque held.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from controller_model.model import ControllerModel
from plant_model.model import PlantModel

# (plant output, controller input) and (controller output, plant input) pairs of the system.
PLANT_TO_CONTROLLER = (
    ("q1", "q1"), ("q2", "q2"), ("q3", "q3"),
    ("fx", "fx"), ("fy", "fy"), ("n", "n"),
    ("qd1", "qd_meas1"), ("qd2", "qd_meas2"), ("qd3", "qd_meas3"),
)  # fmt: skip
CONTROLLER_TO_PLANT = (("tau1", "tau1"), ("tau2", "tau2"), ("tau3", "tau3"))


def output_names(model_class: type) -> list[str]:
    """Names of a model's outputs, in table order."""
    return [v.name for v in model_class.variables() if v.causality == "output"]


def run_models(
    plant_parameters: dict[str, Any] | None = None,
    controller_parameters: dict[str, Any] | None = None,
    stop_time: float = 20.0,
    step: float = 1 / 400,
) -> dict[str, np.ndarray]:
    """Run the closed loop; return time and every output ("plant.x", "controller.tau1", ...)
    at t_i = i * step, i = 0..n (the controller's values are those applied over [t_i, t_i+1])."""
    p_names, c_names = output_names(PlantModel), output_names(ControllerModel)
    p_index = {n: i for i, n in enumerate(p_names)}
    c_index = {n: i for i, n in enumerate(c_names)}
    c_inputs = [v.name for v in ControllerModel.variables() if v.causality == "input"]
    feed = [p_index[dict((c, p) for p, c in PLANT_TO_CONTROLLER)[name]] for name in c_inputs]
    tau_idx = [c_index[c] for c, _ in CONTROLLER_TO_PLANT]

    plant = PlantModel(plant_parameters or {}, 0.0, None)
    p_out = plant.outputs()
    controller = ControllerModel(controller_parameters or {}, 0.0, tuple(p_out[i] for i in feed))
    n = round(stop_time / step)
    rows = np.empty((n + 1, 1 + len(p_names) + len(c_names)))
    for i in range(n + 1):
        t = i * step
        if i < n:  # sample at t_i (sample 0 was taken at initialization: this is a no-op)
            controller.do_step(t, step, tuple(p_out[j] for j in feed))
        c_out = controller.outputs()
        rows[i] = (t, *p_out, *c_out)  # the last row holds the controller's last sample
        if i == n:
            break
        plant.do_step(t, step, tuple(c_out[j] for j in tau_idx))
        p_out = plant.outputs()
    names = ["time", *(f"plant.{n}" for n in p_names), *(f"controller.{n}" for n in c_names)]
    return {name: rows[:, k] for k, name in enumerate(names)}
