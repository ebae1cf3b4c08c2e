"""Parameter sweeps: a grid (or a seeded random sample) over parameters of the system, every run a
task on dask.distributed, the metrics of every run in one table, and maps of them.

- Names are the master's, "component.variable" (vector shorthand: controller.K sets K1..K3), a
  few aliases (ALIASES) and pseudo-parameters of the system (SYSTEM_PARAMETERS): system.rate (Hz,
  the master's communication step and the controller's sample period are both 1/rate),
  system.algorithm, system.scenario (the SSD's parameter set, i.e. the velocity source),
  system.friction_scale (the plant's joint friction times this; the controller keeps its model),
  system.encoder_bits (plant.q_quant = 2 pi / 2**bits; 0 = no quantization).
- Everything is checked before any work starts: names (unknown ones with close matches), values
  (one Master is configured per run, which checks types and the whole number of steps), and the
  scheduler's reachability. Errors are SweepError (a ValueError: one line from the CLI).
- Execution: a LocalCluster on this machine's cores (one single-threaded process per worker:
  pythonfmu FMUs must not share threads) or an existing scheduler. The SSP archive is sent to
  every worker once; each worker process reads it once (cache by digest) and creates a Master per
  run. A run that fails or diverges is a row with its status and reason; so is a task whose
  worker died.
- The table (sweep_table): every row written as its run finishes, resume, one writer per table;
  the command line and Ctrl-C/SIGTERM handling: sweep_cli. A run stopped by a signal is not a
  row (RunInterruptedError): the sweep stops.
- Metrics per run (run_metrics): analysis.summary()'s numbers flattened, plus tracking error in
  contact, the time of first contact and the x-velocity jitter in free motion.
"""

from __future__ import annotations

import contextlib
import difflib
import hashlib
import itertools
import math
import os
import random
import re
import socket
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from impedance_cosim.apps.sweep_table import (  # noqa: F401 (read_table: API)
    parse_value,
    read_table,
    save_figure,
)
from impedance_cosim.cosim.master import ALGORITHMS, Master, MasterError, RunResult

REPO = Path(__file__).resolve().parents[2]
DEFAULT_SSP = REPO / "fmus" / "PaperScenario-native.ssp"

SYSTEM_PARAMETERS = {
    "system.rate": "sample rate [Hz]: master step = controller.sample_period = 1/rate",
    "system.algorithm": f"master algorithm: {' | '.join(ALGORITHMS)}",
    "system.scenario": "parameter set of the SSD (observer | difference | measured)",
    "system.friction_scale": "plant joint friction f1..f3 times this (controller model fixed)",
    "system.encoder_bits": "plant.q_quant = 2 pi / 2**bits (0: no quantization)",
}
ALIASES = {
    "plant.noise": "plant.q_noise",
    "plant.quant": "plant.q_quant",
    "plant.quantization": "plant.q_quant",
    "plant.payload": "plant.m3",
    "system.velocity": "system.scenario",
}
TEXT_PARAMETERS = ("system.algorithm", "system.scenario")

METRICS = (
    "t_end_s",
    "contact_start_s",
    "impact_peak_N",
    "impact_peak_time_s",
    "settled_force_N",
    "tracking_error_before_contact_m",
    "tracking_error_in_contact_m",
    "observer_error_max_m_s",
    "observer_error_rms_after_2s_m_s",
    "peak_torque_N_m",
    "peak_torque1_N_m",
    "peak_torque2_N_m",
    "peak_torque3_N_m",
    "xd_jitter_m_s",
)
DEFAULT_PLOTS = (
    "peak_torque_N_m",
    "settled_force_N",
    "impact_peak_N",
    "observer_error_rms_after_2s_m_s",
    "tracking_error_in_contact_m",
)


MAX_RUNS = 100_000  # planning alone configures one Master per run (~3 ms each)


class SweepError(ValueError):
    """Bad sweep input (unknown parameter, empty grid, unreachable scheduler...): one line."""


# --- the plan: axes, points, checks -------------------------------------------------------------


@dataclass
class Plan:
    """What to run: the swept axes (name -> values in order), one point per run, run options."""

    ssp: Path
    axes: dict[str, list[Any]]
    points: list[dict[str, Any]]
    options: dict[str, Any]
    mode: str = "grid"  # or "random"
    fixed: dict[str, Any] = field(default_factory=dict)


def parse_axis(item: str, max_count: int = MAX_RUNS) -> tuple[str, Any]:
    """ "name=v1,v2" | "name=lin:a:b:n" | "name=log:a:b:n" -> (name, [values]);
    "name=range:a:b" | "name=logrange:a:b" -> (name, ("range"|"logrange", a, b)) for --random."""
    name, sep, spec = item.partition("=")
    name, spec = name.strip(), spec.strip()
    if not sep or not name:
        raise SweepError(f"--grid expects component.variable=values (got {item!r})")
    kind, _, rest = spec.partition(":")
    if kind in ("lin", "log", "range", "logrange") and rest:
        parts = rest.split(":")
        try:
            numbers = [float(p) for p in parts]
        except ValueError:
            raise SweepError(f"{name}: bad {kind}: specification {spec!r}") from None
        if not all(math.isfinite(v) for v in numbers):
            raise SweepError(f"{name}: {kind}: needs finite numbers (got {spec!r})")
        if kind in ("range", "logrange"):
            if len(numbers) != 2 or not numbers[0] < numbers[1]:
                raise SweepError(f"{name}: {kind}:LOW:HIGH needs LOW < HIGH (got {spec!r})")
            if kind == "logrange" and numbers[0] <= 0:
                raise SweepError(f"{name}: logrange needs positive bounds (got {spec!r})")
            return name, (kind, *numbers)
        if len(numbers) != 3 or not numbers[2].is_integer() or not 1 <= numbers[2] <= max_count:
            raise SweepError(
                f"{name}: {kind}:START:STOP:COUNT needs a count 1..{max_count} (got {spec!r})"
            )
        a, b, n = numbers[0], numbers[1], int(numbers[2])
        if kind == "log" and (a <= 0 or b <= 0):
            raise SweepError(f"{name}: log spacing needs positive bounds (got {spec!r})")
        grid = np.geomspace(a, b, n) if kind == "log" else np.linspace(a, b, n)
        return name, [float(v) for v in grid]
    values = [parse_value(v) for v in spec.split(",") if v.strip()]
    if not values:
        raise SweepError(f"empty grid for {name}: give at least one value ({name}=v1,v2,...)")
    return name, values


def known_parameters(system) -> dict[str, str]:
    """Every name a sweep accepts -> a short description (kind/unit)."""
    from fmpy import read_model_description

    names: dict[str, str] = dict(SYSTEM_PARAMETERS)
    for comp in system.components:
        md = read_model_description(str(comp.fmu))
        params = [v for v in md.modelVariables if v.causality == "parameter"]
        for v in params:
            names[f"{comp.name}.{v.name}"] = f"{v.type} [{v.unit or '-'}] start {v.start}"
        for v in params:
            m = re.fullmatch(r"(.+?)_?[123]", v.name)
            if m and f"{comp.name}.{m.group(1)}" not in names:
                names[f"{comp.name}.{m.group(1)}"] = f"{v.type}: sets {m.group(1)}1..3"
    for alias, target in ALIASES.items():
        names.setdefault(alias, f"alias of {target}")
    return names


def resolve_name(name: str, known: Mapping[str, str], system) -> str:
    """The canonical name of a sweep parameter, or SweepError with close matches."""
    name = ALIASES.get(name, name)
    if name in known:
        return name
    comp, _, var = name.partition(".")
    for c in system.components:
        if c.name == comp:
            from fmpy import read_model_description

            md = read_model_description(str(c.fmu))
            v = next((v for v in md.modelVariables if v.name == var), None)
            if v is not None:
                raise SweepError(
                    f"{name} is a{'n' if v.causality[0] in 'aeiou' else ''} "
                    f"{v.causality}, not a parameter"
                )
    close = difflib.get_close_matches(name, list(known), n=5, cutoff=0.6)
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    raise SweepError(
        f"unknown parameter {name!r}{hint} (`impedance-cosim sweep --list-parameters` lists all)"
    )


def _check_axis_values(name: str, values: Sequence[Any], system) -> None:
    for v in values:
        if isinstance(v, float) and not math.isfinite(v):
            raise SweepError(f"{name}: {v!r} is not a finite number")
        if name == "system.rate" and not (isinstance(v, int | float) and v > 0):
            raise SweepError(f"system.rate must be a positive number of Hz (got {v!r})")
        if name == "system.algorithm" and v not in ALGORITHMS:
            raise SweepError(f"system.algorithm must be one of {', '.join(ALGORITHMS)} (got {v!r})")
        if name == "system.scenario" and v not in system.parameter_sets:
            raise SweepError(
                f"system.scenario must be one of {', '.join(system.parameter_sets)} (got {v!r})"
            )
        if name == "system.friction_scale" and not (isinstance(v, int | float) and v >= 0):
            raise SweepError(f"system.friction_scale must be a number >= 0 (got {v!r})")
        if name == "system.encoder_bits" and not (isinstance(v, int) and 0 <= v <= 52):
            raise SweepError(f"system.encoder_bits must be an integer 0..52 (got {v!r})")


def master_arguments(point: Mapping[str, Any], options: Mapping[str, Any]) -> dict[str, Any]:
    """Master(...) keyword arguments for one run: the options, then the point's parameters."""
    overrides: dict[str, Any] = {}
    args = {
        "parameter_set": options.get("scenario"),
        "algorithm": options.get("algorithm"),
        "step_size": options.get("step"),
        "stop_time": options.get("stop"),
        "divergence_limit": options.get("divergence_limit", 1e6),
    }
    for name, value in {**options.get("fixed", {}), **point}.items():
        if name == "system.rate":
            args["step_size"] = 1.0 / value
            overrides["controller.sample_period"] = 1.0 / value
        elif name == "system.algorithm":
            args["algorithm"] = value
        elif name == "system.scenario":
            args["parameter_set"] = value
        elif name == "system.friction_scale":
            for i, f in enumerate(options["plant_friction"], start=1):
                overrides[f"plant.f{i}"] = value * f
        elif name == "system.encoder_bits":
            overrides["plant.q_quant"] = 0.0 if value == 0 else 2 * math.pi / 2**value
        else:
            overrides[name] = value
    args["overrides"] = overrides
    return args


def plan_sweep(
    grid: Sequence[str] = (),
    *,
    ssp: str | Path | None = None,
    random_runs: int | None = None,
    seed: int = 0,
    fixed: Sequence[str] = (),
    scenario: str | None = None,
    algorithm: str | None = None,
    stop: float | None = None,
    step: float | None = None,
    divergence_limit: float = 1e6,
    system=None,
) -> Plan:
    """Parse and check a sweep (grid items "name=values"); SweepError before any work starts."""
    from impedance_cosim.cosim.ssp import read_ssp

    ssp = Path(ssp) if ssp else DEFAULT_SSP
    if not grid:
        raise SweepError("nothing to sweep: give at least one --grid component.variable=values")
    system = system or read_ssp(ssp)
    known = known_parameters(system)
    axes: dict[str, Any] = {}
    for item in grid:
        name, values = parse_axis(item)
        name = resolve_name(name, known, system)
        if name in axes:
            raise SweepError(f"{name} is swept twice")
        if isinstance(values, tuple) and random_runs is None:
            raise SweepError(
                f"{name}: {values[0]}:LOW:HIGH is for --random sweeps; a grid needs "
                "values or lin:/log:START:STOP:COUNT"
            )
        if not isinstance(values, tuple):
            _check_axis_values(name, values, system)
        axes[name] = values
    fixed_values = {}
    for item in fixed:
        name, sep, value = item.partition("=")
        if not sep or not value.strip():
            raise SweepError(f"--set expects component.variable=value (got {item!r})")
        name = resolve_name(name.strip(), known, system)
        fixed_values[name] = parse_value(value)
        _check_axis_values(name, [fixed_values[name]], system)
    if random_runs is not None:
        if not 1 <= random_runs <= MAX_RUNS:
            raise SweepError(f"--random needs 1..{MAX_RUNS} runs (got {random_runs})")
        rng = random.Random(seed)
        points = []
        for _ in range(random_runs):
            point = {}
            for name, values in axes.items():
                if isinstance(values, tuple):
                    kind, lo, hi = values
                    v = (
                        math.exp(rng.uniform(math.log(lo), math.log(hi)))
                        if kind == "logrange"
                        else rng.uniform(lo, hi)
                    )
                    if name in ("system.rate", "system.encoder_bits"):
                        v = int(round(v))  # whole Hz: a whole number of steps per second
                    point[name] = v
                else:
                    point[name] = rng.choice(values)
            points.append(point)
        mode = "random"
    else:
        runs = math.prod(len(v) for v in axes.values())
        if runs > MAX_RUNS:
            raise SweepError(f"the grid has {runs:.3g} runs, more than {MAX_RUNS}: fewer values")
        points = [dict(zip(axes, combo)) for combo in itertools.product(*axes.values())]
        mode = "grid"
    nominal = Master(system, parameter_set=scenario)  # checks the scenario name
    plant_md = {v.name: v for v in nominal.descriptions["plant"].modelVariables}
    friction = [
        float(nominal.parameters["plant"].get(f"f{i}", plant_md[f"f{i}"].start)) for i in (1, 2, 3)
    ]
    options = {
        "scenario": scenario,
        "algorithm": algorithm,
        "stop": stop,
        "step": step,
        "divergence_limit": divergence_limit,
        "fixed": fixed_values,
        "plant_friction": friction,
    }
    for i, point in enumerate(points):
        where = ", ".join(f"{k}={v}" for k, v in point.items())
        try:
            Master(system, **master_arguments(point, options))  # also refuses absurd run sizes
        except (MasterError, ValueError) as exc:
            raise SweepError(f"run {i + 1} of {len(points)} ({where}): {exc}") from None
    return Plan(ssp=ssp, axes=axes, points=points, options=options, mode=mode, fixed=fixed_values)


# --- one run (on a worker or in-process) --------------------------------------------------------

_SYSTEMS: dict[str, Any] = {}  # per process: SSP digest -> SystemDescription (FMUs extracted once)


def _system(payload: bytes | str, digest: str):
    system = _SYSTEMS.get(digest)
    if system is None:
        from impedance_cosim.cosim.ssp import read_ssp

        if isinstance(payload, bytes):
            with tempfile.TemporaryDirectory(prefix="impcosim_sweep_") as tmp:
                path = Path(tmp) / "system.ssp"
                path.write_bytes(payload)
                system = read_ssp(path)
        else:
            system = read_ssp(payload)
        _SYSTEMS[digest] = system
    return system


def prepare_worker(payload: bytes | str, digest: str) -> str:
    """Read the archive into this process's cache and take a few steps (loads the FMUs' libraries
    and the compiled master loop), so a worker's first run costs what its others do."""
    system = _system(payload, digest)
    h = system.step_size or 1 / 400
    Master(system, step_size=h, stop_time=system.start_time + 10 * h).run()
    return digest


def _finite(v: Any) -> Any:
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def run_metrics(s: RunResult) -> dict[str, Any]:
    """The metrics of a finished run (see module docstring); None where not defined."""
    from impedance_cosim.apps import analysis

    values = analysis.summary(s)
    t, force = s["time"], s["plant.contact_force"]
    out: dict[str, Any] = {m: None for m in METRICS}
    out["t_end_s"] = float(t[-1])
    for key in (
        "impact_peak_N",
        "impact_peak_time_s",
        "settled_force_N",
        "tracking_error_before_contact_m",
        "observer_error_max_m_s",
        "observer_error_rms_after_2s_m_s",
    ):
        out[key] = _finite(values.get(key))
    phases = values["contact_phases_s"]
    out["contact_start_s"] = float(phases[0][0]) if phases else None
    touching = force > 0
    if touching.any():
        ey = analysis.at_samples(s, "controller.e_y")
        out["tracking_error_in_contact_m"] = _finite(np.abs(ey[touching]).max())
    torques = values["peak_torque_N_m"]
    for i, v in enumerate(torques, start=1):
        out[f"peak_torque{i}_N_m"] = _finite(v)
    out["peak_torque_N_m"] = _finite(max(torques))
    free = t >= 2.0
    for a, b in phases:
        free &= (t < a - 0.5) | (t > b + 0.5)
    pairs = free[:-1] & free[1:]
    if pairs.sum() > 10:
        out["xd_jitter_m_s"] = _finite(np.std(np.diff(s["plant.xd"])[pairs]))
    return out


class RunInterruptedError(Exception):
    """A run stopped by SIGINT/SIGTERM: no result; the sweep stops (--resume runs it again)."""


class RunsLostError(Exception):
    """Dask cancelled runs (e.g. the scheduler went away): no verdict on those points; the sweep
    stops after the others (--resume runs them again)."""


STOP: dict[str, str | None] = {"signal": None}  # set by the sweep's signal handler (sweep_cli)


def _interrupted(error: str | None) -> bool:
    """The master's error for a run it stopped on a signal (see cli/master: "interrupted ...")."""
    return bool(error) and error.lower().startswith("interrupted")


def run_point(
    payload: bytes | str, digest: str, point: dict, options: dict, instances: Any = None
) -> dict[str, Any]:
    """One run of the sweep -> its table row (failures are rows); RunInterruptedError (or a
    KeyboardInterrupt) when a signal stopped it, whatever the FMUs made of the signal.
    instances: an fmu_pool.InstancePool to take the FMU instances from (sweep_batch)."""
    started = time.perf_counter()
    row: dict[str, Any] = dict(point)
    row.update(status="ok", error="")
    row.update({m: None for m in METRICS})
    try:
        system = _system(payload, digest)
        result = Master(system, **master_arguments(point, options), instances=instances).run()
        if STOP["signal"] or _interrupted(result.error):
            raise RunInterruptedError(result.error or f"interrupted ({STOP['signal']})")
        row["t_end_s"] = float(result.data[-1, 0]) if len(result.data) else None
        if result.ok:
            row.update(run_metrics(result))
        else:
            row["status"] = "diverged" if result.error.startswith("diverged") else "failed"
            row["error"] = result.error
    except RunInterruptedError:
        raise
    except Exception as exc:  # a row, never a crashed sweep
        if STOP["signal"]:  # e.g. a Python FMU turned the KeyboardInterrupt into an FMI error
            raise RunInterruptedError(f"interrupted ({STOP['signal']})") from None
        row.update(status="failed", error=" ".join(f"{type(exc).__name__}: {exc}".split()))
    row["wall_s"] = time.perf_counter() - started
    return row


# --- execution ----------------------------------------------------------------------------------


def _payload(ssp: Path) -> tuple[bytes, str]:
    data = Path(ssp).read_bytes()
    return data, hashlib.sha256(data).hexdigest()


Record = Callable[[int, dict], None]


def run_serial(
    plan: Plan,
    progress: Callable[[int, dict], None] | None = None,
    indices: Iterable[int] | None = None,
    record: Record | None = None,
) -> list[dict]:
    """The plan's runs (or those at `indices`) one after another in this process (the reference
    for the dask runs); `record(index, row)` as each finishes."""
    data, digest = _payload(plan.ssp)
    rows = []
    for i in range(len(plan.points)) if indices is None else indices:
        rows.append(run_point(data, digest, plan.points[i], plan.options))
        if record:
            record(i, rows[-1])
        if progress:
            progress(len(rows), rows[-1])
    return rows


def check_scheduler(address: str, timeout: float = 3.0) -> None:
    """SweepError unless a dask scheduler answers at address within timeout seconds (a TCP
    connection, then dask's handshake and an identity call: a port that is not a scheduler fails
    within the timeout instead of hanging)."""
    import asyncio

    from distributed.comm import connect
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.security import Security

    try:
        scheme, location = parse_address(address if "://" in address else f"tcp://{address}")
        host, port = parse_host_port(location, default_port=8786)
    except (ValueError, TypeError) as exc:
        raise SweepError(f"bad scheduler address {address!r}: {exc}") from None
    if scheme not in ("tcp", "tls"):
        raise SweepError(f"scheduler address {address!r}: only tcp:// and tls:// are supported")
    started = time.monotonic()
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise SweepError(
            f"cannot reach the dask scheduler at {address} ({reason}); is `dask scheduler` "
            "running there?"
        ) from None

    async def identity() -> Any:
        security = Security().get_connection_args("client")  # tls: dask's configured certificates
        comm = await connect(f"{scheme}://{host}:{port}", timeout=timeout, **security)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    left = max(timeout - (time.monotonic() - started), 0.1)
    try:
        reply = asyncio.run(asyncio.wait_for(identity(), left))
    except Exception as exc:  # e.g. MemoryError: garbage can ask for any amount of memory
        if isinstance(exc, TimeoutError | asyncio.TimeoutError):
            detail = f"no dask answer within {timeout:g} s"
        else:
            detail = f"its answer is not dask's: {type(exc).__name__}"
    else:
        kind = reply.get("type") if isinstance(reply, dict) else None
        if kind == "Scheduler":
            return
        detail = f"it answers as {kind!r}"
    raise SweepError(f"{address} accepts connections but is not a dask scheduler ({detail})")


# Our local workers run one CPU-bound task at a time on few cores: slower housekeeping (ticks,
# memory and system monitors, the profiler, work stealing) took runs from 11% to 4.5% slower than
# in a plain process (32 runs on 2 cores: 1.73x -> 1.83x faster than serial).
QUIET_WORKERS = {
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "5s",
    "distributed.worker.profile.enabled": False,
    "distributed.scheduler.work-stealing": False,
}


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None, timeout: float = 3.0):
    """A dask Client: on an existing scheduler, or on a LocalCluster of single-threaded worker
    processes (this machine's cores by default); the cluster is closed on exit."""
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        check_scheduler(scheduler, timeout)
        try:
            client = Client(scheduler, timeout=f"{timeout}s")
        except OSError as exc:
            raise SweepError(
                f"cannot connect to the dask scheduler at {scheduler}: {exc}"
            ) from None
        logging.disable(logging.CRITICAL)  # a lost scheduler: our one line, not dask's tracebacks
        try:
            with client:
                yield client
        finally:
            logging.disable(logging.NOTSET)
        return
    import dask

    n = workers or os.cpu_count() or 1
    with (
        dask.config.set(QUIET_WORKERS),
        LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            silence_logs=logging.ERROR,
        ) as cluster,
        Client(cluster) as client,
    ):
        from impedance_cosim.apps.sweep_worker import IgnoreSigint

        client.register_plugin(IgnoreSigint())  # Ctrl-C is the main process's (sweep_worker)
        yield client


def run_dask(
    plan: Plan,
    client,
    progress: Callable[[int, dict], None] | None = None,
    indices: Iterable[int] | None = None,
    record: Record | None = None,
) -> list[dict]:
    """The plan's runs (or those at `indices`) on the client's workers, several runs per task
    (sweep_batch); rows in the plan's order; `record(index, row)` as each batch finishes. On an
    exception (e.g. Ctrl-C) the runs not yet finished are cancelled."""
    from impedance_cosim.apps import sweep_batch

    return sweep_batch.run_dask(plan, client, progress, indices, record)


class ProgressBar:
    """A one-line progress bar on stderr: runs done, failures, elapsed time."""

    def __init__(self, total: int, enabled: bool = True) -> None:
        self.total, self.enabled = total, enabled
        self.bad = 0
        self.start = time.perf_counter()

    def __call__(self, done: int, row: dict) -> None:
        self.bad += row.get("status") != "ok"
        if not self.enabled:
            return
        frac = done / max(self.total, 1)
        bar = "#" * int(30 * frac)
        sys.stderr.write(
            f"\r[{bar:<30}] {done}/{self.total} runs, {self.bad} not bounded, "
            f"{time.perf_counter() - self.start:.1f} s"
        )
        if done == self.total:
            sys.stderr.write("\n")
        sys.stderr.flush()


# --- the table (impedance_cosim.apps.sweep_table) -------------------------------------------------


def columns(plan_axes: Iterable[str]) -> list[str]:
    """The table's columns: run number, swept values, status, error, metrics, wall time."""
    return ["run", *plan_axes, "status", "error", *METRICS, "wall_s"]


# --- plots --------------------------------------------------------------------------------------


def _short(name: str) -> str:
    return name.removeprefix("system.")


def _label(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


def plot_map(
    rows: list[dict],
    axes: Sequence[str],
    metric: str,
    path: Path,
    title: str | None = None,
    log: bool | None = None,
    mode: str = "grid",
) -> None:
    """One metric over the swept axes: a curve (one axis), heatmaps (x = axes[0], y = axes[1],
    panel rows = axes[2], panel columns = axes[3]) or a scatter (random sweeps). Runs that did not
    stay bounded are black cells / red crosses labelled with the time they stopped."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm, Normalize

    axes = [a for a in axes if len({_label(r[a]) for r in rows}) > 1] or list(axes[:1])
    values = [r.get(metric) for r in rows if r.get("status") == "ok" and r.get(metric) is not None]
    positive = [v for v in values if v > 0]
    if log is None:
        log = bool(positive) and len(positive) == len(values) and max(values) / min(values) > 30
    lo, hi = (
        (min(positive or [1e-12]), max(positive or [1.0]))
        if log
        else (min(values or [0.0]), max(values or [1.0]))
    )
    norm = LogNorm(lo, max(hi, lo * 1.001)) if log else Normalize(lo, hi if hi > lo else lo + 1)
    title = title or metric

    def order(name: str) -> list[Any]:
        seen: dict[str, Any] = {}
        for r in rows:
            seen.setdefault(_label(r[name]), r[name])
        return list(seen.values())

    if len(axes) == 1 or mode == "random":
        fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
        x = axes[0]
        ok = [r for r in rows if r.get("status") == "ok" and r.get(metric) is not None]
        bad = [r for r in rows if r.get("status") != "ok"]
        if len(axes) == 1:
            ax.plot([r[x] for r in ok], [r[metric] for r in ok], "o-", ms=4)
            ax.set_ylabel(metric)
            if log:
                ax.set_yscale("log")
            for r in bad:
                ax.axvline(r[x], color="r", lw=0.8, ls=":")
                ax.annotate(
                    f"x {r['status']}",
                    (r[x], 0.02),
                    xycoords=("data", "axes fraction"),
                    color="r",
                    fontsize=7,
                    rotation=90,
                )
        else:
            y = axes[1]
            sc = ax.scatter(
                [r[x] for r in ok],
                [r[y] for r in ok],
                c=[r[metric] for r in ok],
                norm=norm,
                cmap="viridis",
                s=25,
            )
            ax.scatter(
                [r[x] for r in bad],
                [r[y] for r in bad],
                marker="x",
                color="r",
                s=30,
                label="not bounded",
            )
            fig.colorbar(sc, ax=ax, label=metric)
            ax.set_ylabel(y)
            if bad:
                ax.legend(fontsize=8)
        numeric = [r[x] for r in rows if isinstance(r[x], int | float) and r[x] > 0]
        if numeric and len(numeric) == len(rows) and max(numeric) / min(numeric) > 20:
            ax.set_xscale("log")
        ax.set_xlabel(x)
        ax.set_title(title, fontsize=10)
        save_figure(fig, path, dpi=90)
        plt.close(fig)
        return

    x, y = axes[0], axes[1]
    prow = axes[2] if len(axes) > 2 else None
    pcol = axes[3] if len(axes) > 3 else None
    xs, ys = order(x), order(y)
    rvals = order(prow) if prow else [None]
    cvals = order(pcol) if pcol else [None]
    extra = axes[4:]
    if extra:  # more than four swept axes: one panel per remaining combination, in a row
        cvals = [None]
    w = max(3.2, 0.42 * len(xs) + 1.2)
    h = max(2.4, 0.3 * len(ys) + 1.0)
    fig, grid = plt.subplots(
        len(rvals),
        len(cvals),
        figsize=(w * len(cvals) + 1.2, h * len(rvals) + 0.6),
        squeeze=False,
        constrained_layout=True,
    )
    cmap = matplotlib.colormaps["viridis"].with_extremes(bad="black")
    image = None
    annotate = len(xs) <= 14 and len(ys) <= 12
    for ri, rv in enumerate(rvals):
        for ci, cv in enumerate(cvals):
            ax = grid[ri][ci]
            sel = [
                r
                for r in rows
                if (prow is None or _label(r[prow]) == _label(rv))
                and (pcol is None or _label(r[pcol]) == _label(cv))
            ]
            m = np.full((len(ys), len(xs)), np.nan)
            text: dict[tuple[int, int], tuple[str, str]] = {}
            xi = {_label(v): i for i, v in enumerate(xs)}
            yi = {_label(v): i for i, v in enumerate(ys)}
            for r in sel:
                j, i = xi[_label(r[x])], yi[_label(r[y])]
                if r.get("status") == "ok" and r.get(metric) is not None:
                    m[i, j] = r[metric]
                    text[i, j] = (f"{r[metric]:.3g}", "white")
                elif r.get("status") == "ok":
                    text[i, j] = ("-", "0.5")
                else:
                    t_end = r.get("t_end_s")
                    text[i, j] = (f"{t_end:.2g}s" if t_end is not None else "fail", "#ff8080")
                    m[i, j] = np.nan
            masked = np.ma.masked_invalid(m)
            image = ax.imshow(masked, origin="lower", aspect="auto", cmap=cmap, norm=norm)
            if annotate:
                for (i, j), (s, colour) in text.items():
                    ax.text(j, i, s, ha="center", va="center", fontsize=6, color=colour)
            ax.set_xticks(range(len(xs)), [_label(v) for v in xs], fontsize=7, rotation=45)
            ax.set_yticks(range(len(ys)), [_label(v) for v in ys], fontsize=7)
            ax.set_xlabel(x, fontsize=8)
            ax.set_ylabel(y, fontsize=8)
            parts = [f"{_short(prow)}={_label(rv)}" if prow else "",
                     f"{_short(pcol)}={_label(cv)}" if pcol else ""]  # fmt: skip
            ax.set_title(", ".join(p for p in parts if p), fontsize=7)
    fig.suptitle(f"{title}\nblack, label in red: not bounded (stopped at that time)", fontsize=8)
    if image is not None:
        fig.colorbar(image, ax=grid, label=metric, shrink=0.8)
    save_figure(fig, path, dpi=80)
    plt.close(fig)


# --- the study: stability maps ------------------------------------------------------------------

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


def sweep_table(path: Path, plan: Plan, resume: bool = False):
    """The plan's table at path (rows written as runs finish; see sweep_table.SweepTable)."""
    from impedance_cosim.apps.sweep_table import SweepTable, plan_record

    options = {k: v for k, v in plan.options.items() if k != "plant_friction"}
    record = plan_record(_payload(plan.ssp)[1], plan.axes, plan.points, options, plan.mode)
    return SweepTable(path, columns(plan.axes), record, plan.points, resume=resume)


def run_plan(plan: Plan, table, client, progress: Callable[[int, dict], None] | None) -> list[dict]:
    """The plan's runs not yet in the table, each row into the table as it finishes; all rows
    (in the plan's order) once every run has finished."""
    todo = [i for i in range(len(plan.points)) if i not in table.done]
    if todo:
        run = run_dask if client is not None else run_serial
        run(plan, *([client] if client is not None else []), progress, todo, table.add)
    return [dict(r) for r in table.rows()]


def run_study(
    names: Sequence[str],
    out: Path,
    ssp: Path | None,
    client_factory: Callable[[], Any] | None,
    progress: bool,
    stop: float | None = None,
    resume: bool = False,
    tables: list | None = None,
) -> list[Path]:
    """Run the study's maps (all runs on one cluster), write map_<name>.csv and .png files;
    with resume, the runs already in the tables are not run again; the tables opened are
    appended to `tables` (to say how far an interrupted study got)."""
    from impedance_cosim.cosim.ssp import read_ssp

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
            name: open_tables.enter_context(sweep_table(out / f"map_{name}.csv", plan, resume))
            for name, plan in plans.items()
        }
        if tables is not None:
            tables.extend(opened.values())
        total = sum(len(p.points) - len(opened[n].done) for n, p in plans.items())
        bar = ProgressBar(total, progress)
        done = 0

        def tick(_n: int, row: dict) -> None:
            nonlocal done
            done += 1
            bar(done, row)

        results = {}
        with contextlib.ExitStack() as stack:
            client = stack.enter_context(client_factory()) if client_factory else None
            for name, plan in plans.items():
                results[name] = run_plan(plan, opened[name], client, tick)
    written = []
    for name, rows in results.items():
        written.append(out / f"map_{name}.csv")
        for k, metric in enumerate(STUDY[name].plots):
            png = out / (f"map_{name}.png" if k == 0 else f"map_{name}_{metric}.png")
            title = STUDY[name].title if k == 0 else f"{STUDY[name].title.split(':')[0]}: {metric}"
            plot_map(rows, list(plans[name].axes), metric, png, title)
            written.append(png)
    return written


# --- command line (impedance_cosim.apps.sweep_cli) ------------------------------------------------


def add_parser(sub) -> None:
    """Register `impedance-cosim sweep` (its options and command live in sweep_cli)."""
    from impedance_cosim.apps.sweep_cli import add_parser as add

    add(sub)
