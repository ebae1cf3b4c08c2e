"""What a sweep runs: the swept axes, one point per run and the options of every run (the Plan),
all checked before any work starts.

- Names are the master's, "component.variable" (vector shorthand: controller.K sets K1..K3), a
  few aliases (ALIASES) and pseudo-parameters of the system (SYSTEM_PARAMETERS): system.rate (Hz,
  the master's communication step and the controller's sample period are both 1/rate),
  system.algorithm, system.scenario (the SSD's parameter set, i.e. the velocity source),
  system.friction_scale (the plant's joint friction times this; the controller keeps its model),
  system.encoder_bits (plant.q_quant = 2 pi / 2**bits; 0 = no quantization).
- Checks: names (unknown ones with close matches) and values (one Master is configured per run,
  which checks types and the whole number of steps). Errors are SweepError (a ValueError: one
  line from the CLI).
"""

from __future__ import annotations

import difflib
import hashlib
import math
import os
import re
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from impedance_cosim.apps.options import FMUS_DIR, PACKAGED_FMUS, REPO  # noqa: F401 (sweep's)
from impedance_cosim.apps.sweep.points import grid_points, random_points
from impedance_cosim.cosim.master.master import Master, MasterError
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.master.setup import ALGORITHMS

DEFAULT_SSP = FMUS_DIR / "PaperScenario-native.ssp"

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

MAX_RUNS = 100_000  # planning alone configures one Master per run (~3 ms each)


class SweepError(ValueError):
    """Bad sweep input (unknown parameter, empty grid, unreachable scheduler...): one line."""


def cores() -> int:
    """The CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except (AttributeError, OSError):
        return os.cpu_count() or 1


WORKERS_PER_CORE = 4  # LocalCluster workers beyond 4 per core only slow the runs down


def workers_problem(workers: int | None) -> str | None:
    """Why --workers cannot be used (one line), or None: at least 1, at most 4 per core (10**5
    workers started one process each for minutes, silently, deaf to SIGTERM)."""
    if workers is None:
        return None
    if workers < 1:
        return f"--workers must be >= 1 (got {workers})"
    limit = WORKERS_PER_CORE * cores()
    if workers > limit:
        return (f"--workers {workers} is more than {WORKERS_PER_CORE} per core of this machine "
                f"({cores()} cores): at most {limit}")  # fmt: skip
    return None


@dataclass
class Plan:
    """What to run: the swept axes (name -> values in order), one point per run, run options."""

    ssp: Path
    axes: dict[str, list[Any]]
    points: list[dict[str, Any]]
    options: dict[str, Any]
    mode: str = "grid"  # or "random"
    fixed: dict[str, Any] = field(default_factory=dict)


def parse_value(text: str) -> Any:
    """A table cell or command-line value: int, float or the text itself."""
    text = text.strip()
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


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
    items = spec.split(",")
    if not any(v.strip() for v in items):
        raise SweepError(f"empty grid for {name}: give at least one value ({name}=v1,v2,...)")
    empty = next((i for i, v in enumerate(items, start=1) if not v.strip()), None)
    if empty is not None:
        raise SweepError(f"--grid {item.strip()}: value {empty} of {len(items)} is empty")
    return name, [parse_value(v) for v in items]


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


def run_options(point: Mapping[str, Any], options: Mapping[str, Any]) -> RunOptions:
    """The master's options for one run: the sweep's options, then the point's parameters."""
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
    return RunOptions(**args, overrides=overrides)


# the parameters a system.* name sets besides itself (a run sets them from its value)
SETS_ALSO = {
    "system.rate": ("controller.sample_period",),
    "system.friction_scale": ("plant.f1", "plant.f2", "plant.f3"),
    "system.encoder_bits": ("plant.q_quant",),
}


def _set_by(name: str, known: Mapping[str, str]) -> set[str]:
    """The parameters a sweep name sets: a group its members ("controller.K" sets K1..K3), a
    system.* name what it derives ("system.friction_scale" sets plant.f1..3)."""
    members = set()
    for n in (name, *SETS_ALSO.get(name, ())):
        group = {f"{n}{sep}{i}" for sep in ("", "_") for i in (1, 2, 3)} & set(known)
        members |= group or {n}
    return members


def _check_fixed(system, options: Mapping[str, Any], axes: Mapping[str, Any], known) -> None:
    """--set values: each valid (checked as a run would set them, even for a swept name) and
    none setting what the grid sweeps (the run's value would silently win); SweepError."""
    fixed = options["fixed"]
    if not fixed:
        return
    try:  # the SSD's stop time and step: only what --set gives is checked here
        Master(system, run_options({}, {**options, "stop": None, "step": None}))
    except (MasterError, ValueError) as exc:
        raise SweepError(f"--set: {exc}") from None
    for name in fixed:
        swept = [a for a in axes if _set_by(a, known) & _set_by(name, known)]
        if swept:
            raise SweepError(f"--set {name}={fixed[name]}: {name} is swept by --grid"
                             f" {swept[0]}=...; give it in one place")  # fmt: skip


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
    from impedance_cosim.cosim.ssp.read import read_ssp

    ssp = Path(ssp) if ssp else DEFAULT_SSP
    if not grid:
        raise SweepError("nothing to sweep: give at least one --grid component.variable=values")
    system = system or read_ssp(ssp)
    known = known_parameters(system)
    axes = _axes(grid, known, system, random_runs is not None)
    fixed_values = _fixed_values(fixed, known, system)
    if random_runs is None:
        runs = math.prod(len(v) for v in axes.values())
        if runs > MAX_RUNS:
            raise SweepError(f"the grid has {runs:.3g} runs, more than {MAX_RUNS}: fewer values")
        points, mode = grid_points(axes), "grid"
    elif not 1 <= random_runs <= MAX_RUNS:
        raise SweepError(f"--random needs 1..{MAX_RUNS} runs (got {random_runs})")
    else:
        points, mode = random_points(axes, random_runs, seed), "random"
    nominal = Master(system, RunOptions(parameter_set=scenario))  # checks the scenario name
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
    _check_fixed(system, options, axes, known)
    for i, point in enumerate(points):
        where = ", ".join(f"{k}={v}" for k, v in point.items())
        try:
            Master(system, run_options(point, options))  # also refuses absurd run sizes
        except (MasterError, ValueError) as exc:
            raise SweepError(f"run {i + 1} of {len(points)} ({where}): {exc}") from None
    return Plan(ssp=ssp, axes=axes, points=points, options=options, mode=mode, fixed=fixed_values)


def _axes(grid: Sequence[str], known: dict, system, random: bool) -> dict[str, Any]:
    """The swept axes by resolved name: a list of values, or (kind, low, high) for --random."""
    axes: dict[str, Any] = {}
    for item in grid:
        name, values = parse_axis(item)
        name = resolve_name(name, known, system)
        if name in axes:
            raise SweepError(f"{name} is swept twice")
        if isinstance(values, tuple) and not random:
            raise SweepError(
                f"{name}: {values[0]}:LOW:HIGH is for --random sweeps; a grid needs "
                "values or lin:/log:START:STOP:COUNT"
            )
        if not isinstance(values, tuple):
            _check_axis_values(name, values, system)
        axes[name] = values
    return axes


def _fixed_values(fixed: Sequence[str], known: dict, system) -> dict[str, Any]:
    """The --set items (name=value) by resolved name, each value checked."""
    values: dict[str, Any] = {}
    for item in fixed:
        name, sep, value = item.partition("=")
        if not sep or not value.strip():
            raise SweepError(f"--set expects component.variable=value (got {item!r})")
        name = resolve_name(name.strip(), known, system)
        values[name] = parse_value(value)
        _check_axis_values(name, [values[name]], system)
    return values


def archive_payload(ssp: Path) -> tuple[bytes, str]:
    """The system archive's bytes (sent to the workers) and their sha256 (names it everywhere)."""
    data = Path(ssp).read_bytes()
    return data, hashlib.sha256(data).hexdigest()


def default_ssp() -> Path:
    """The native system archive, built first if missing or older than its sources."""
    from impedance_cosim.apps.build_cmd import stale

    if DEFAULT_SSP.parent != PACKAGED_FMUS and stale(DEFAULT_SSP):  # an install's: as shipped
        from impedance_cosim.packaging.build_all import build_all

        print("building the FMUs and the system archives ...", file=sys.stderr)
        build_all(DEFAULT_SSP.parent, None)
    return DEFAULT_SSP
