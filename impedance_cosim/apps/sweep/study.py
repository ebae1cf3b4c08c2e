"""The stability study (`impedance-cosim sweep --study`): five maps of grids (delay, noise,
quantization, observer gain, model mismatch; 692 runs), all runs on one cluster, each map a
table map_<name>.csv and its figures map_<name>*.png (see docs/sweeps.md)."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from impedance_cosim.apps.sweep.execute import RunProgress, run_plans
from impedance_cosim.apps.sweep.maps import plot_map
from impedance_cosim.apps.sweep.plan import DEFAULT_SSP, plan_sweep
from impedance_cosim.apps.sweep.table import open_table

RATES = [100, 200, 400, 800, 1600]
GS_J = ["gauss-seidel", "jacobi"]


@dataclass(frozen=True)
class StudyMap:
    """One map of the study: a grid, the axes' plotting order and the metrics to draw."""

    title: str
    grid: dict[str, list[Any]]
    plots: tuple[str, ...] = ("peak_torque_N_m",)


STUDY = {
    "delay": StudyMap(
        "velocity source vs sample rate and loop timing: peak joint torque [N m]",
        {
            "system.rate": [50, 75, 100, 150, 200, 300, 400, 600, 800, 1200, 1600, 2000],
            "system.scenario": ["observer", "difference", "measured"],
            "system.algorithm": GS_J,
        },
    ),
    "noise": StudyMap(
        "joint sensor noise (rad) vs sample rate: peak joint torque [N m]",
        {
            "system.rate": RATES,
            "plant.q_noise": [0, 1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2],
            "system.algorithm": GS_J,
            "system.scenario": ["observer", "difference"],
        },
        ("peak_torque_N_m", "settled_force_N"),
    ),
    "quantization": StudyMap(
        "encoder resolution (bits, 0 = ideal) vs sample rate: peak joint torque [N m]",
        {
            "system.rate": RATES,
            "system.encoder_bits": [6, 8, 10, 12, 14, 16, 0],
            "system.algorithm": GS_J,
            "system.scenario": ["observer", "difference"],
        },
    ),
    "gain": StudyMap(
        "observer gain K vs sample rate (observer in the loop): peak joint torque [N m]",
        {
            "system.rate": RATES,
            "controller.K": [2, 5, 10, 25, 50, 100, 200, 400, 800],
            "system.algorithm": GS_J,
            "plant.q_noise": [0, 1e-3],
        },
    ),
    "mismatch": StudyMap(
        "model mismatch, plant vs controller model (m3 = 1 kg, friction x1): peak torque [N m]",
        {
            "plant.m3": [0.25, 0.5, 1, 2, 4, 8, 16],
            "system.friction_scale": [0, 0.5, 1, 2, 4],
            "system.algorithm": GS_J,
            "system.scenario": ["observer", "difference"],
        },
        ("peak_torque_N_m", "settled_force_N", "tracking_error_in_contact_m"),
    ),
}


def run_study(
    names: Sequence[str],
    out: Path,
    ssp: Path | None,
    client_factory: Callable[[], Any] | None,
    progress: bool,
    stop: float | None = None,
    resume: bool = False,
    tables: list | None = None,
    plots: bool = True,
) -> list[Path]:
    """Run the study's maps (all runs on one cluster), write map_<name>.csv and, with plots,
    its .png files (--no-plots: none, so no serial tail of drawing); with resume, the runs
    already in the tables are not run again; the tables opened are appended to `tables` (to say
    how far an interrupted study got)."""
    from impedance_cosim.cosim.ssp.read import read_ssp

    system = read_ssp(ssp or DEFAULT_SSP)
    plans = {
        name: plan_sweep(
            [f"{k}={','.join(map(str, v))}" for k, v in STUDY[name].grid.items()],
            ssp=ssp,
            stop=stop,
            system=system,
        )
        for name in names
    }
    with contextlib.ExitStack() as open_tables:
        opened = {
            name: open_tables.enter_context(open_table(out / f"map_{name}.csv", plan, resume))
            for name, plan in plans.items()
        }
        if tables is not None:
            tables.extend(opened.values())
        total = sum(len(p.points) - len(opened[n].done) for n, p in plans.items())
        with contextlib.ExitStack() as stack:
            client = stack.enter_context(client_factory()) if client_factory else None
            tick = stack.enter_context(RunProgress(total, progress))
            results = run_plans(plans, opened, client, tick)
    written = []
    for name, rows in results.items():
        written.append(out / f"map_{name}.csv")
        for k, metric in enumerate(STUDY[name].plots if plots else ()):
            png = out / (f"map_{name}.png" if k == 0 else f"map_{name}_{metric}.png")
            title = STUDY[name].title if k == 0 else f"{STUDY[name].title.split(':')[0]}: {metric}"
            plot_map(rows, list(plans[name].axes), metric, png, title)
            written.append(png)
    return written
