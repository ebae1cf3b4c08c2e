"""The closed loop on the plain models, without FMI: the reference the master is checked against.

Gauss-Seidel, controller first (the paper's sample-and-hold): at t_i the controller samples the
plant's outputs at t_i, and the plant integrates over [t_i, t_i + h] with that torque held.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from controller_model.model import ControllerModel
from impedance_cosim.cosim.system.paper import CONNECTIONS
from plant_model.model import PlantModel

# The system's wiring, from its one definition (impedance_cosim.cosim.system.paper.CONNECTIONS).
PLANT_TO_CONTROLLER = tuple((sc, ec) for se, sc, ee, ec in CONNECTIONS if se == "plant")
CONTROLLER_TO_PLANT = tuple((sc, ec) for se, sc, ee, ec in CONNECTIONS if se == "controller")


def output_names(model_class: type) -> list[str]:
    """Names of a model's outputs, in table order."""
    return [v.name for v in model_class.variables() if v.causality == "output"]


def run_models(
    plant_parameters: dict[str, Any] | None = None,
    controller_parameters: dict[str, Any] | None = None,
    stop_time: float = 20.0,
    step: float = 1 / 400,
    algorithm: str = "gauss-seidel",
) -> dict[str, np.ndarray]:
    """Run the closed loop; return time and every output ("plant.x", "controller.tau1", ...),
    recorded like the master does: at t_0 after initialization, then at each t_i+1 the outputs
    after the step that ends there. Jacobi: the plant gets the torque from before the
    controller's step (one step of delay)."""
    p_names, c_names = output_names(PlantModel), output_names(ControllerModel)
    feed, tau_idx = wiring()
    plant = PlantModel(plant_parameters or {}, 0.0, None)
    p_out = plant.outputs()
    controller = ControllerModel(controller_parameters or {}, 0.0, tuple(p_out[i] for i in feed))
    n = round(stop_time / step)
    rows = np.empty((n + 1, 1 + len(p_names) + len(c_names)))
    rows[0] = (0.0, *p_out, *controller.outputs())
    for i in range(n):
        p_out = loop_step(plant, controller, i * step, step, algorithm, p_out)
        rows[i + 1] = ((i + 1) * step, *p_out, *controller.outputs())
    names = ["time", *(f"plant.{n}" for n in p_names), *(f"controller.{n}" for n in c_names)]
    return {name: rows[:, k] for k, name in enumerate(names)}


@functools.cache
def wiring() -> tuple[tuple[int, ...], tuple[int, ...]]:
    """(plant output index per controller input, controller output index per plant input)."""
    p_index = {n: i for i, n in enumerate(output_names(PlantModel))}
    c_index = {n: i for i, n in enumerate(output_names(ControllerModel))}
    c_inputs = [v.name for v in ControllerModel.variables() if v.causality == "input"]
    feed = [p_index[dict((c, p) for p, c in PLANT_TO_CONTROLLER)[name]] for name in c_inputs]
    return tuple(feed), tuple(c_index[c] for c, _ in CONTROLLER_TO_PLANT)


def loop_step(
    plant: PlantModel,
    controller: ControllerModel,
    t: float,
    step: float,
    algorithm: str,
    p_out: tuple,
) -> tuple:
    """One macro step from t, given the plant's outputs at t; returns its outputs at t + step.
    Gauss-Seidel: the controller samples at t and its torque drives the plant over the step;
    Jacobi: the plant gets the torque held from before the controller's step."""
    feed, tau_idx = wiring()
    held = controller.outputs()
    controller.do_step(t, step, tuple(p_out[j] for j in feed))  # samples at t_i
    c_out = controller.outputs() if algorithm == "gauss-seidel" else held
    plant.do_step(t, step, tuple(c_out[j] for j in tau_idx))
    return plant.outputs()
