"""Reference results kept in the repository, as the FMI Reference FMUs keep their *_ref.csv:
each FMU's default experiment, and the paper's closed-loop scenario. Tests compare fresh runs
against them; regenerate deliberately after an intended change of results with

    python -m impedance_cosim.packaging.regression --write
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import numpy as np

from controller_model.model import ControllerModel
from impedance_cosim.cosim.master.plain_loop import output_names, run_models
from impedance_cosim.cosim.results.result import read_csv, write_csv
from impedance_cosim.packaging.build import REPO
from plant_model.model import PlantModel

DT = 1 / 400
STOP = 20.0
PAPER_COLUMNS = (
    "plant.q1_true", "plant.q2_true", "plant.q3_true", "plant.qd1", "plant.qd2", "plant.qd3",
    "plant.x", "plant.y", "plant.xd", "plant.yd", "plant.contact_force",
    "controller.tau1", "controller.tau2", "controller.tau3",
    "controller.qd_obs1", "controller.qd_obs2", "controller.qd_obs3",
    "controller.x_v", "controller.y_v", "controller.e_x", "controller.e_y",
)  # fmt: skip


def default_experiment(model_class: type, every: int = 40) -> dict[str, np.ndarray]:
    """A model alone over its default experiment (0..20 s at 1/400 s, inputs at their start
    values), as `fmpy simulate` runs the FMU; every `every`-th row is kept."""
    inputs = tuple(v.start for v in model_class.variables() if v.causality == "input")
    model = model_class({}, 0.0, inputs)
    n = round(STOP / DT)
    rows = [(0.0, *model.outputs())]
    for i in range(n):
        model.do_step(i * DT, DT, inputs)
        if (i + 1) % every == 0:
            rows.append(((i + 1) * DT, *model.outputs()))
    data = np.array(rows)
    names = ["time", *output_names(model_class)]
    return {name: data[:, k] for k, name in enumerate(names)}


def paper_scenario(every: int = 10) -> dict[str, np.ndarray]:
    """The paper's observer scenario (closed loop, 20 s at 400 Hz), every `every`-th row."""
    run = run_models(stop_time=STOP, step=DT)
    return {k: run[k][::every] for k in ("time", *PAPER_COLUMNS)}


REFERENCES: dict[Path, Callable[[], dict[str, np.ndarray]]] = {
    REPO / "plant_model" / "PumaPlant_ref.csv": lambda: default_experiment(PlantModel),
    REPO / "controller_model" / "ImpedanceController_ref.csv": lambda: default_experiment(
        ControllerModel
    ),
    REPO / "ssp" / "PaperScenario_ref.csv": paper_scenario,
}


def compare(result: dict[str, np.ndarray], ref: dict[str, np.ndarray], rtol: float) -> list[str]:
    """Differences beyond rtol * (column range + 1e-12), by column; empty when they agree."""
    problems = []
    for name, expected in ref.items():
        if name not in result:
            problems.append(f"{name}: missing")
            continue
        got = result[name]
        if got.shape != expected.shape:
            problems.append(f"{name}: {got.shape[0]} rows, reference has {expected.shape[0]}")
            continue
        scale = np.ptp(expected) + np.abs(expected).max() * 1e-3 + 1e-12
        worst = np.abs(got - expected).max()
        if not worst <= rtol * scale:
            problems.append(f"{name}: max difference {worst:.3g} > {rtol:g} * {scale:.3g}")
    return problems


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", action="store_true", help="regenerate the reference files")
    args = parser.parse_args()
    for path, make in REFERENCES.items():
        data = make()
        if args.write:
            write_csv(path, list(data), np.column_stack(list(data.values())))
            print(f"wrote {path.relative_to(REPO)} ({len(data['time'])} rows)")
        else:
            problems = compare(data, read_csv(path), 1e-9)
            print(f"{path.relative_to(REPO)}: {'OK' if not problems else problems}")


if __name__ == "__main__":
    main()
