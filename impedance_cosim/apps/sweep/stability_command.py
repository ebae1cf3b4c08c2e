"""`impedance-cosim stability`: the stability study's tables and figures (docs/stability.md).

Parts: boundaries (bisection, docs/boundaries.csv + boundaries.png), linear (the linearised
loop's critical rates next to the simulated ones, docs/linear.csv + spectral_radius.png), fig4
(the Fig. 4 candidate conditions, docs/fig4_conditions.csv + fig4_candidates.png) and gain (the
observer discretizations at 400 Hz, docs/observer_discretization.csv).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import hashlib
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from impedance_cosim.apps.sweep import stability as st
from impedance_cosim.apps.sweep.plan import default_ssp
from impedance_cosim.apps.sweep.worker import run_point
from impedance_cosim.util.progress import Progress

PARTS = ("boundaries", "linear", "fig4", "gain")
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


# --- parts --------------------------------------------------------------------------------------


def boundaries(args: argparse.Namespace, ssp: Path) -> list[dict[str, Any]]:
    todo = st.cases(args.quantity or tuple(st.QUANTITIES), args.sensor or tuple(st.SENSORS),
                    args.velocity or st.SOURCES, args.timing or st.TIMINGS)  # fmt: skip
    most = sum(st.max_runs(c.quantity) for c in todo)
    with contextlib.ExitStack() as stack:
        client = None
        if not args.serial:
            from impedance_cosim.apps.sweep.cluster import dask_client

            client = stack.enter_context(dask_client(workers=args.workers))
        display = stack.enter_context(Progress(most, "stability", "run", not args.no_progress))

        def progress(runs: int, finished: int) -> None:
            display.update(runs, f"{finished}/{len(todo)} bisections done (at most {most} runs)")

        return st.run_study(todo, ssp, args.stop, client, progress)


def linear(args: argparse.Namespace, ssp: Path, simulated: list[dict]) -> list[dict[str, Any]]:
    """Per velocity source x timing (ideal sensors): the rate where the linearised loop's spectral
    radius crosses 1 at the free-motion and the contact point, next to the bisected one."""
    from impedance_cosim.apps import linearize as lin

    ref = lin.reference_run({}, {})
    sim = {(r["velocity"], r["timing"]): r["critical"] for r in simulated
           if r["quantity"] == "rate" and r["sensor"] == "ideal"}  # fmt: skip
    rows = []
    for timing in args.timing or st.TIMINGS:
        for v in args.velocity or st.SOURCES:
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
            rows.append(row)
    return rows


def radius_curves(rows: list[dict], path: Path) -> None:
    """Spectral radius against the rate, per timing (panel), source (colour) and point (line)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from impedance_cosim.apps import linearize as lin
    from impedance_cosim.util.atomic import atomic_write

    ref = lin.reference_run({}, {})
    rates = np.arange(150.0, 601.0, 10.0)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    colours = dict(zip(st.SOURCES, ("tab:blue", "tab:red", "tab:green")))
    for ax, timing in zip(axes, st.TIMINGS):
        for v in st.SOURCES:
            for point, style in zip(lin.POINTS, ("--", "-")):
                rho = [lin.loop_radius(r, timing, v, point, reference=ref)[0] for r in rates]
                ax.plot(rates, rho, style, color=colours[v], lw=1,
                        label=f"{v}, {point}")  # fmt: skip
            sim = next((r["simulated_Hz"] for r in rows
                        if r["velocity"] == v and r["timing"] == timing), None)  # fmt: skip
            if sim:
                ax.plot([sim], [1.0], "o", color=colours[v], mfc="none", ms=8)
        ax.axhline(1.0, color="k", lw=0.6)
        ax.set_ylim(0.95, 1.25)
        name = "sample-and-hold (Gauss-Seidel)" if timing == "gauss-seidel" else "one-sample delay"
        ax.set_title(f"{name}: spectral radius of the loop", fontsize=9)
        ax.set_xlabel("sample rate (Hz); circles: bisected critical rate (simulation)")
    axes[0].set_ylabel("max |eigenvalue| per sample")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    with atomic_write(path, "wb") as f:
        fig.savefig(f, format="png", dpi=110)
    plt.close(fig)


def boundaries_figure(rows: list[dict], path: Path) -> None:
    """Critical rate per sensor condition (source x timing markers), critical K per sensor
    condition (timing x discretization), critical wall stiffness per source and timing."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from impedance_cosim.util.atomic import atomic_write

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    sensors = list(st.SENSORS)
    markers = {"gauss-seidel": "o", "jacobi": "s"}
    palette = ("tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple")
    colours = dict(zip(st.SOURCES + st.DISCRETIZATIONS[1:], palette))
    for ax, q in zip(axes, ("rate", "K", "wall_k")):
        series: dict[tuple[str, str], list[tuple[int, float]]] = {}
        lo, hi = st.QUANTITIES[q][0]
        for r in rows:
            if r["quantity"] != q:
                continue
            key = r["discretization"] if q == "K" else r["velocity"]
            x = sensors.index(r["sensor"]) if q != "wall_k" else st.SOURCES.index(r["velocity"])
            if r["critical"] in (None, ""):  # no boundary: a triangle at the bracket's end
                up = str(r["note"]).startswith("stable")
                ax.plot([x], [hi if up else lo], "^" if up else "v", ms=7, mfc="none",
                        color=colours.get(key, "tab:blue"))  # fmt: skip
                continue
            series.setdefault((key, r["timing"]), []).append((x, float(r["critical"])))
        for (key, timing), pts in sorted(series.items()):
            xs, ys = zip(*sorted(pts))
            ax.plot(xs, ys, marker=markers[timing], ls="-" if timing == "gauss-seidel" else ":",
                    color=colours.get(key, "tab:blue"), label=f"{key}, {timing}")  # fmt: skip
        ax.set_title("triangles: stable (up) / unstable (down) over the whole bracket", fontsize=8)
        if q != "wall_k":
            ax.set_xticks(range(len(sensors)), sensors, rotation=30, fontsize=8)
        else:
            ax.set_xticks(range(3), st.SOURCES, fontsize=8)
        ax.legend(fontsize=7)
    axes[0].set_ylabel("critical sample rate (Hz): stable above")
    axes[1].set_ylabel("critical observer gain K (1/s) at 400 Hz: stable below")
    axes[1].set_yscale("log")
    axes[2].set_ylabel("critical wall stiffness (N/m) at 400 Hz")
    axes[2].set_yscale("log")
    fig.tight_layout()
    with atomic_write(path, "wb") as f:
        fig.savefig(f, format="png", dpi=110)
    plt.close(fig)


def fig4_part(args: argparse.Namespace, ssp: Path, out: Path) -> list[dict[str, Any]]:
    from impedance_cosim.apps import fig4
    from impedance_cosim.apps import linearize as lin

    conditions = [c for c in fig4.CONDITIONS if not args.condition or c.name in args.condition]
    runs = fig4.run_all(ssp, conditions if conditions[0] == fig4.CONDITIONS[0]
                        else [fig4.CONDITIONS[0], *conditions])  # fmt: skip
    rows = []
    for r in runs:
        row = dict(r["row"])
        c = next(c for c in fig4.CONDITIONS if c.name == row["condition"])
        if not any(k.startswith("plant.q_") for k in c.overrides):  # sensors: not linear
            pp = {k.split(".", 1)[1]: v for k, v in c.overrides.items()}
            ref = lin.reference_run(pp, {})
            rho, period = lin.loop_radius(400.0, c.algorithm, row["velocity"], FIG4_POINT, pp,
                                          reference=ref)  # fmt: skip
            row.update(linear_growth_per_sample=rho, linear_period_samples=period)
        rows.append(row)
    if not args.no_figures and not args.condition:
        fig4.plot(runs, out / "fig4_candidates.png")
    return rows


def gain(args: argparse.Namespace, ssp: Path) -> list[dict[str, Any]]:
    """Each observer discretization at 400 Hz (sample-and-hold) over a range of K, with ideal and
    1e-3 rad noisy encoders: the sweep's metrics (peak torque, settled force, noise)."""
    data = ssp.read_bytes()
    digest = hashlib.sha256(data).hexdigest()
    rows = []
    for d in st.DISCRETIZATIONS:
        for k in GAIN_K:
            for sensor in ("ideal", "noise 1e-3"):
                point = {"system.scenario": "observer", "system.rate": 400,
                         "controller.observer_discretization": d, **st.SENSORS[sensor],
                         **{f"controller.K{i}": k for i in (1, 2, 3)}}  # fmt: skip
                r = run_point(data, digest, point, {"stop": args.stop})
                rows.append({"discretization": d, "K": k, "sensor": sensor, **r})
    return rows


# --- command ------------------------------------------------------------------------------------


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


def add_parser(sub) -> None:
    """Register `impedance-cosim stability`."""
    p = sub.add_parser(
        "stability",
        help="stability study: bisected boundaries, linearised loop, Fig. 4 conditions, observer"
        " discretizations (docs/stability.md)",
    )
    p.add_argument("parts", nargs="*", default=None, metavar="PART",
                   help=f"which parts ({', '.join(PARTS)}; default all)")  # fmt: skip
    p.add_argument("--out", default="results/stability", help="output folder")
    p.add_argument("--ssp", default=None, help="system archive (default: the native one)")
    p.add_argument("--stop", type=float, default=20.0, help="run length in s (default 20)")
    for name, allowed in (("quantity", st.QUANTITIES), ("sensor", st.SENSORS),
                          ("velocity", st.SOURCES), ("timing", st.TIMINGS)):  # fmt: skip
        p.add_argument(f"--{name}", action="append", choices=list(allowed), default=None,
                       help=f"only this {name} (repeatable)")  # fmt: skip
    p.add_argument("--condition", action="append", default=None,
                   help="fig4: only this condition (repeatable; no figure)")  # fmt: skip
    p.add_argument("--serial", action="store_true", help="no dask: the runs in this process")
    p.add_argument("--workers", type=int, default=None, help="LocalCluster workers")
    p.add_argument("--no-figures", action="store_true", help="only the tables")
    p.add_argument("--no-progress", action="store_true", help="no progress display")
    p.set_defaults(func=_cmd_stability)


def _cmd_stability(args: argparse.Namespace) -> int:
    from impedance_cosim.apps import fig4

    args.parts = args.parts or list(PARTS)
    for part in args.parts:
        if part not in PARTS:
            raise st.StabilityError(f"unknown part {part!r} (have {', '.join(PARTS)})")
    for name in args.condition or []:
        if name not in [c.name for c in fig4.CONDITIONS]:
            names = ", ".join(c.name for c in fig4.CONDITIONS)
            raise st.StabilityError(f"unknown condition {name!r} (have {names})")
    if args.workers is not None and args.workers < 1:
        raise st.StabilityError(f"--workers must be >= 1 (got {args.workers})")
    if not (math.isfinite(args.stop) and args.stop >= 1 and args.stop.is_integer()):
        raise st.StabilityError(  # so that every whole-Hz rate divides the run
            f"--stop must be a whole number of seconds >= 1 (got {args.stop})"
        )
    ssp = Path(args.ssp) if args.ssp else default_ssp()
    if not ssp.is_file():
        raise FileNotFoundError(f"no system archive {ssp}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    simulated: list[dict] = []
    if "boundaries" in args.parts:
        simulated = boundaries(args, ssp)
        write_csv(out / "boundaries.csv", st.COLUMNS, simulated)
        print(f"wrote {out / 'boundaries.csv'}")
        if not args.no_figures:
            boundaries_figure(simulated, out / "boundaries.png")
    if "linear" in args.parts:
        if not any(r["quantity"] == "rate" and r["sensor"] == "ideal" for r in simulated):
            sel = argparse.Namespace(**{**vars(args), "quantity": ["rate"], "sensor": ["ideal"]})
            simulated = boundaries(sel, ssp)
        rows = linear(args, ssp, simulated)
        write_csv(out / "linear.csv", LINEAR_COLUMNS, rows)
        print(f"wrote {out / 'linear.csv'}")
        if not args.no_figures:
            radius_curves(rows, out / "spectral_radius.png")
    if "fig4" in args.parts:
        write_csv(out / "fig4_conditions.csv", FIG4_COLUMNS, fig4_part(args, ssp, out))
        print(f"wrote {out / 'fig4_conditions.csv'}")
    if "gain" in args.parts:
        write_csv(out / "observer_discretization.csv", GAIN_COLUMNS, gain(args, ssp))
        print(f"wrote {out / 'observer_discretization.csv'}")
    sys.stdout.flush()
    return 0
