"""How a result was made: the record kept next to it as `run.json` (and on API results).

One record per command or API call: what was asked (command line or call), package versions,
host, start time and wall time; one entry per run in it: system archive and FMU files with sha256,
scenario, overrides as given and the parameter values in effect, algorithm, step, stop, status,
and the units of every recorded signal (the CSV keeps fmpy's plain header, so fmpy still reads
it: the units go here)."""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
import platform
from collections.abc import Mapping, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

FORMAT = "impedance-cosim run record 1"
PACKAGES = ("impedance-cosim", "fmpy", "numpy", "scipy", "pythonfmu", "dask", "tqdm", "matplotlib")


def file_sha256(path: Path) -> str:
    """sha256 of a file's bytes, read in blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def versions() -> dict[str, str | None]:
    """Versions of Python and of the packages a result depends on (None: not installed)."""
    out: dict[str, str | None] = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def now_utc() -> str:
    """The current time, ISO 8601 in UTC to the second."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def signal_units(master: Any, names: Sequence[str]) -> dict[str, str]:
    """Unit of each recorded signal ("plant.x" -> "m"), from the FMUs' model descriptions
    (a variable's own unit, else its type's); signals without a unit are left out."""
    units = {"time": "s"}
    for name in names:
        comp, _, var = name.partition(".")
        md = getattr(master, "descriptions", {}).get(comp)
        if md is None:
            continue
        for v in md.modelVariables:
            if v.name == var:
                unit = v.unit or getattr(v.declaredType, "unit", None)
                if unit:
                    units[name] = unit
                break
    return units


def run_entry(
    master: Any,
    result: Any | None,
    overrides: Mapping[str, Any] | None = None,
    csv: Path | None = None,
    status: str | None = None,
) -> dict[str, Any]:
    """The record of one run of the master (result None: the run did not end normally)."""
    fmus = {}
    in_archive = {c.name: c for c in master.system.components}
    for comp, path in master.fmu_files.items():
        md = master.descriptions.get(comp)
        c = in_archive.get(comp)
        from_archive = c is not None and c.fmu is not None and Path(c.fmu) == path
        fmus[comp] = {
            # the member of the system archive, or the file given instead of it (swap, API)
            "file": c.source if from_archive else str(path.resolve()),
            "in_system_archive": from_archive,
            "sha256": file_sha256(path),
            "model": getattr(md, "modelName", None),
            "fmi_version": getattr(md, "fmiVersion", None),
            "guid": getattr(md, "guid", None),
            "generation_tool": getattr(md, "generationTool", None),
        }
    entry: dict[str, Any] = {
        "scenario": master.parameter_set,
        "overrides": {k: _plain(v) for k, v in (overrides or {}).items()},
        "parameters": {
            c: {k: _plain(v) for k, v in p.items()} for c, p in master.parameters.items()
        },
        "algorithm": master.algorithm,
        "extrapolation": master.options.extrapolation,
        "step_size": master.step_size,
        "start_time": master.start_time,
        "stop_time": master.stop_time,
        "realtime": bool(master.options.realtime),
        "fmus": fmus,
    }
    if result is not None:
        span = float(result.data[-1, 0] - result.data[0, 0]) if len(result.data) else 0.0
        entry.update(
            status=status or result.status,
            error=result.error,
            rows=int(len(result.data)),
            wall_time_s=round(result.wall_time, 6),
            real_time_factor=round(span / max(result.wall_time, 1e-9), 3),
            units=signal_units(master, result.names),
        )
    else:
        entry["status"] = status or "failed"
    if csv is not None:
        entry["csv"] = csv.name
    return entry


def record(
    runs: list[dict[str, Any]],
    started: str,
    wall_time: float,
    command: Sequence[str] | None = None,
    call: str | None = None,
    ssp: Path | None = None,
) -> dict[str, Any]:
    """The whole record: the command line (or the API call), the system archive, the runs."""
    out: dict[str, Any] = {"format": FORMAT}
    if command is not None:
        out["command"] = list(command)
    if call is not None:
        out["call"] = call
    if ssp is not None:
        out["system"] = {"ssp": str(ssp), "sha256": file_sha256(ssp)}
    out.update(
        started=started,
        wall_time_s=round(wall_time, 3),
        versions=versions(),
        host={"platform": platform.platform(), "machine": platform.machine()},
        runs=runs,
    )
    return out


def table_record(
    table: Path,
    plan: Mapping[str, Any],
    rows: Mapping[str, int],
    started: str,
    wall_time: float,
    command: Sequence[str] | None = None,
) -> dict[str, Any]:
    """The record of a sweep table: the same as a run's (command, versions, host, times), with the
    table's plan (archive sha256, axes, options, points digest) and its rows by status."""
    out = record([], started, wall_time, command=command)
    del out["runs"]
    out.update(table=table.name, plan=dict(plan), rows=dict(rows))
    return out


def write(path: Path, data: Mapping[str, Any]) -> None:
    """Write a record as JSON, whole or not at all (atomic rename)."""
    from impedance_cosim.util.atomic import atomic_write

    with atomic_write(path) as f:
        f.write(json.dumps(data, indent=2, allow_nan=False, default=str) + "\n")


def _plain(value: Any) -> Any:
    """A JSON-safe value (NaN and infinities as text: JSON has none)."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, (bool, int, float, str)) or value is None:
        return value
    return str(value)
