"""Parameter sweeps: a grid (or a seeded random sample) over parameters of the system, every run
on dask (or in series), the metrics of every run in one table, and maps of them (the stability
study, `impedance-cosim stability`, is apps.stability, built on these runs).

The modules, each importing only those above it:
  points     the points of a grid or of a seeded random sample, from the axes
  plan       what to run: swept axes, one point per run, checked before any work (SweepError)
  metrics    what a run measures (METRICS, run_metrics)
  table      the table on disk: rows appended as runs finish, resume, one writer per table
  worker     one run in the process that runs it (the functions dask tasks call)
  execute    a plan's runs: in series, or batched on dask; the progress display
  cluster    the dask cluster: a LocalCluster or a checked scheduler (imports distributed)
  maps       the figures of a sweep
  study      `sweep --study`: the five stability maps
  command    `impedance-cosim sweep`: options, Ctrl-C/SIGTERM

This package exposes the Python API of sweeps (plan_sweep, run_serial, run_dask, dask_client,
read_table ...). Example: rows = run_serial(plan_sweep(["controller.K=10,50"], stop=2.0)).
"""

from __future__ import annotations

from typing import Any

from impedance_cosim.apps.sweep.execute import RunsLostError, run_dask, run_plan, run_serial
from impedance_cosim.apps.sweep.maps import DEFAULT_PLOTS, plot_map
from impedance_cosim.apps.sweep.metrics import METRICS, run_metrics
from impedance_cosim.apps.sweep.plan import (
    ALIASES,
    DEFAULT_SSP,
    MAX_RUNS,
    REPO,
    SYSTEM_PARAMETERS,
    Plan,
    SweepError,
    known_parameters,
    parse_axis,
    plan_sweep,
    run_options,
)
from impedance_cosim.apps.sweep.study import STUDY, run_study
from impedance_cosim.apps.sweep.table import SweepTable, TableError, open_table, read_table
from impedance_cosim.apps.sweep.worker import RunInterruptedError, run_point

__all__ = [
    "ALIASES",
    "DEFAULT_PLOTS",
    "DEFAULT_SSP",
    "MAX_RUNS",
    "METRICS",
    "REPO",
    "STUDY",
    "SYSTEM_PARAMETERS",
    "Plan",
    "RunInterruptedError",
    "RunsLostError",
    "SweepError",
    "SweepTable",
    "TableError",
    "check_scheduler",
    "dask_client",
    "known_parameters",
    "run_options",
    "open_table",
    "parse_axis",
    "plan_sweep",
    "plot_map",
    "read_table",
    "run_dask",
    "run_metrics",
    "run_plan",
    "run_point",
    "run_serial",
    "run_study",
]


def __getattr__(name: str) -> Any:
    """dask_client and check_scheduler from cluster, imported on first use (distributed: 0.3 s)."""
    if name in ("dask_client", "check_scheduler"):
        from impedance_cosim.apps.sweep import cluster

        return getattr(cluster, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
