"""The parts of `impedance-cosim stability` (docs/stability.md), each keeping every finished run in
its PartLog (stability_log) as it finishes and taking the runs kept there instead of running
them again: boundaries (bisection: each run), linear (its bisections if boundaries did not make
them, then each row), fig4 (each run, with what the figure and the later runs need), gain (each
run). Their tables: write_csv / read_csv.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import hashlib
from pathlib import Path
from typing import Any

import numpy as np

from impedance_cosim.apps.stability import bisection as st
from impedance_cosim.apps.stability.log import Key, PartLog
from impedance_cosim.apps.sweep.worker import run_point
from impedance_cosim.util.progress import Progress

LINEAR_COLUMNS = ["velocity", "timing", "predicted_free_Hz", "predicted_contact_Hz",
                  "predicted_Hz", "simulated_Hz", "difference_percent",
                  "mode_period_samples"]  # fmt: skip
FIG4_COLUMNS = ["condition", "velocity", "status", "t_end_s", "onset_s", "period_samples",
                "growth_per_sample", "linear_period_samples",
                "linear_growth_per_sample"]  # fmt: skip
GAIN_COLUMNS = ["discretization", "K", "sensor", "status", "peak_torque_N_m", "settled_force_N",
                "impact_peak_N", "observer_error_rms_after_2s_m_s", "xd_jitter_m_s"]  # fmt: skip
GAIN_K = (50.0, 200.0, 350.0, 1000.0, 5000.0)
FIG4_POINT = 0.1  # s: where the Fig. 4 runs are linearised (their oscillation grows from t = 0)
FIG4_SHOWN = 0.25  # s: the figure shows the first 0.25 s of every run


def write_csv(path: Path, columns: list[str], rows: list[dict[str, Any]]) -> None:
    """The table, atomically; floats in repr (17 significant digits), None as empty."""
    from impedance_cosim.util.atomic import atomic_write

    def cell(v: Any) -> str:
        if v is None:
            return ""
        return repr(float(v)) if isinstance(v, float | np.floating) else str(v)

    with atomic_write(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for r in rows:
            w.writerow([cell(r.get(c)) for c in columns])


def read_csv(path: Path) -> list[dict[str, Any]]:
    """A study table back (numbers as floats, empty as None)."""

    def value(s: str) -> Any:
        if s == "":
            return None
        try:
            return float(s)
        except ValueError:
            return s

    with open(path, newline="") as f:
        return [{k: value(v) for k, v in row.items()} for row in csv.DictReader(f)]


# --- what a kept record must look like to be used (anything else is run again) ---------------


def _scalar(v: Any) -> bool:
    return (
        v is None or isinstance(v, str) or (isinstance(v, int | float) and not isinstance(v, bool))
    )


def _numbers(v: Any) -> bool:
    return isinstance(v, list) and all(isinstance(x, float | int) for x in v)


def _row_ok(data: Any, columns: list[str]) -> bool:
    return isinstance(data, dict) and set(data) <= set(columns) and all(map(_scalar, data.values()))


def valid_record(key: Key, data: dict) -> bool:
    """A kept bisection run (status, error), table row or Fig. 4 run of the right shape."""
    if key[0] == "run" and len(key) == 7:  # a bisection run: case fields and value
        return isinstance(data.get("status"), str) and isinstance(data.get("error"), str)
    if key[0] == "linear":
        return _row_ok(data, LINEAR_COLUMNS)
    if key[0] == "gain":
        return _row_ok(data, GAIN_COLUMNS)
    if key[0] == "fig4":
        signals = [data.get(k) for k in ("t", "xd", "xd_hat")]
        full = data.get("xd_full", [])
        return (_row_ok(data.get("row"), FIG4_COLUMNS) and all(map(_numbers, signals))
                and len({len(s) for s in signals}) == 1 and _numbers(full))  # fmt: skip
    return False


# --- parts --------------------------------------------------------------------------------------


def boundaries(args: argparse.Namespace, ssp: Path, log: PartLog) -> list[dict[str, Any]]:
    """The bisected boundaries of the selection: every run into the log as it finishes."""
    todo = st.cases(args.quantity or tuple(st.QUANTITIES), args.sensor or tuple(st.SENSORS),
                    args.velocity or st.SOURCES, args.timing or st.TIMINGS)  # fmt: skip
    most = sum(st.max_runs(c.quantity) for c in todo)

    def key(case: st.Case, x: float) -> Key:
        return ("run", *dataclasses.astuple(case), float(x))

    def keep(case: st.Case, x: float, row: dict) -> None:
        log.add(key(case, x), {"status": row["status"], "error": row.get("error") or ""})

    with contextlib.ExitStack() as stack:
        client = None
        if not args.serial:
            from impedance_cosim.apps.sweep.cluster import dask_client

            client = stack.enter_context(dask_client(workers=args.workers))
        display = stack.enter_context(Progress(most, "stability", "run", not args.no_progress))

        def progress(runs: int, finished: int) -> None:
            display.update(runs, f"{finished}/{len(todo)} bisections done (at most {most} runs)")

        return st.run_study(todo, ssp, args.stop, client, progress,
                            lambda c, x: log.get(key(c, x)), keep)  # fmt: skip


def linear(args: argparse.Namespace, ssp: Path, simulated: list[dict],
           log: PartLog) -> list[dict[str, Any]]:  # fmt: skip
    """Per velocity source x timing (ideal sensors): the rate where the linearised loop's spectral
    radius crosses 1 at the free-motion and the contact point, next to the bisected one (bisected
    here, into the log, when the boundaries part did not)."""
    from impedance_cosim.apps import linearize as lin

    if not any(r["quantity"] == "rate" and r["sensor"] == "ideal" for r in simulated):
        sel = argparse.Namespace(**{**vars(args), "quantity": ["rate"], "sensor": ["ideal"]})
        simulated = boundaries(sel, ssp, log)
    keys = [(v, t) for t in args.timing or st.TIMINGS for v in args.velocity or st.SOURCES]
    missing = any(log.get(("linear", v, t)) is None for v, t in keys)
    ref = lin.reference_run({}, {}) if missing else None
    sim = {(r["velocity"], r["timing"]): r["critical"] for r in simulated
           if r["quantity"] == "rate" and r["sensor"] == "ideal"}  # fmt: skip
    rows = []
    for v, timing in keys:
        if (kept := log.get(("linear", v, timing))) is not None:
            rows.append(kept)
            continue
        row: dict[str, Any] = {"velocity": v, "timing": timing}
        for point in lin.POINTS:
            row[f"predicted_{point}_Hz"] = lin.critical_rate(
                lambda r, p=point, t=timing, s=v: lin.loop_radius(r, t, s, p, reference=ref)[0],
                150.0, 1000.0, 0.25)  # fmt: skip
        found = [row[f"predicted_{p}_Hz"] for p in lin.POINTS if row[f"predicted_{p}_Hz"]]
        row["predicted_Hz"] = max(found) if found else None
        row["simulated_Hz"] = sim.get((v, timing))
        if row["predicted_Hz"] and row["simulated_Hz"]:
            row["difference_percent"] = 100 * (row["predicted_Hz"] / row["simulated_Hz"] - 1)
            point = max(lin.POINTS, key=lambda p: row[f"predicted_{p}_Hz"] or 0.0)
            period = lin.loop_radius(row["predicted_Hz"] - 1, timing, v, point, reference=ref)
            row["mode_period_samples"] = period[1]
        row = {k: plain(x) for k, x in row.items()}
        log.add(("linear", v, timing), row)
        rows.append(row)
    return rows


def fig4_part(args: argparse.Namespace, ssp: Path, log: PartLog) -> tuple[list[dict], list[dict]]:
    """The Fig. 4 conditions (with the baseline), each with both velocity sources: the table
    rows and the runs for the figure (fig4.plot). Each run into the log as it finishes, with the
    first 0.25 s of its signals (the figure) and, for the observer, its whole x-velocity (the
    reference of the difference's run)."""
    from impedance_cosim.apps import fig4
    from impedance_cosim.apps import linearize as lin
    from impedance_cosim.cosim.ssp.read import read_ssp

    conditions = [c for c in fig4.CONDITIONS if not args.condition or c.name in args.condition]
    if conditions[0] != fig4.CONDITIONS[0]:
        conditions = [fig4.CONDITIONS[0], *conditions]
    system = None

    def run(c: fig4.Condition, source: str, reference: np.ndarray | None = None) -> dict:
        nonlocal system
        if (kept := log.get(("fig4", c.name, source))) is not None:
            return kept
        system = system or read_ssp(ssp)
        r = fig4.run_condition(system, c, source, reference=reference)
        row = dict(r["row"])
        if not any(k.startswith("plant.q_") for k in c.overrides):  # sensors: not linear
            pp = {k.split(".", 1)[1]: v for k, v in c.overrides.items()}
            rho, period = lin.loop_radius(400.0, c.algorithm, source, FIG4_POINT, pp,
                                          reference=lin.reference_run(pp, {}))  # fmt: skip
            row.update(linear_growth_per_sample=rho, linear_period_samples=period)
        shown = r["t"] <= FIG4_SHOWN
        data = {
            "row": {k: plain(v) for k, v in row.items()},
            **{k: r[k][shown].tolist() for k in ("t", "xd", "xd_hat")},
        }
        if source == "observer":
            data["xd_full"] = r["xd"].tolist()
        log.add(("fig4", c.name, source), data)
        return data

    baseline = run(conditions[0], "observer")
    runs = []
    for c in conditions:
        obs = run(c, "observer")
        ref = obs if obs["row"]["status"] == "ok" else baseline  # the stable reference
        diff = run(c, "difference", np.array(ref["xd_full"]))
        runs += [obs, diff]
    plotted = [{**r, **{k: np.array(r[k]) for k in ("t", "xd", "xd_hat")}} for r in runs]
    return [r["row"] for r in runs], plotted


def gain(args: argparse.Namespace, ssp: Path, log: PartLog) -> list[dict[str, Any]]:
    """Each observer discretization at 400 Hz (sample-and-hold) over a range of K, with ideal and
    1e-3 rad noisy encoders: the sweep's metrics (peak torque, settled force, noise)."""
    data = ssp.read_bytes()
    digest = hashlib.sha256(data).hexdigest()
    rows = []
    for d in st.DISCRETIZATIONS:
        for k in GAIN_K:
            for sensor in ("ideal", "noise 1e-3"):
                if (kept := log.get(("gain", d, k, sensor))) is not None:
                    rows.append(kept)
                    continue
                point = {"system.scenario": "observer", "system.rate": 400,
                         "controller.observer_discretization": d, **st.SENSORS[sensor],
                         **{f"controller.K{i}": k for i in (1, 2, 3)}}  # fmt: skip
                r = run_point(data, digest, point, {"stop": args.stop})
                row = {"discretization": d, "K": k, "sensor": sensor, **r}
                row = {c: plain(row.get(c)) for c in GAIN_COLUMNS}
                log.add(("gain", d, k, sensor), row)
                rows.append(row)
    return rows


def plain(v: Any) -> Any:
    """A number as JSON keeps it exactly (numpy scalars as Python ones)."""
    return v.item() if isinstance(v, np.generic) else v
