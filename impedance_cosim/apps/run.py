"""`impedance-cosim run`: a scenario of the system to CSV, summary and figures (with its Fig. 4
pair; under sample-and-hold also the pair under one sample of delay, the paper's Fig. 4), the
FMUs built first when they are missing or out of date (apps/build_cmd.py).

A diverged run is a result (cosim.results.result): its rows, its summary, its Fig. 4, exit status 3;
a failed one is exit status 1. A command writes into a staging folder inside the results folder
(`.staging-<pid>/`). When it completes (exit 0 or 3) its files replace those of an earlier one,
and the earlier one's result files (known names only) that this one did not write are removed,
said in one line: the folder describes this command alone. When it fails or is interrupted,
every earlier file is left as it was and this command's files, run.json and report.html too,
are kept beside them as `<name>.partial`."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import shutil
import signal
import sys
import time
from pathlib import Path

from impedance_cosim.apps.build_cmd import ensure_built
from impedance_cosim.apps.options import (
    DEFAULT_SSP,
    check_out,
    output_every,
    parse_overrides,
    prepare_out,
)
from impedance_cosim.cosim.fmus.output import echo_fmu_output
from impedance_cosim.cosim.results import provenance


def cmd_run(args: argparse.Namespace) -> int:
    """Check everything (options, archive, every scenario to run), then create --out, lock it
    and run: bad input writes nothing."""
    from impedance_cosim.cosim.ssp.read import read_ssp
    from impedance_cosim.util.atomic import FolderLock

    overrides = parse_overrides(args.set or [])
    out = check_out(args.out)
    ssp = Path(args.ssp) if args.ssp else DEFAULT_SSP
    ensure_built(args, ssp)
    system = args.system = read_ssp(ssp)  # closed by _dispatch()
    if getattr(args, "list_parameters", False):
        from impedance_cosim.apps.parameters import parameter_lines

        print("\n".join(parameter_lines(system, args.scenario)))
        return 0
    pair = [] if args.no_figures else ["observer", "difference"]
    for scenario in [args.scenario, *(s for s in pair if s in system.parameter_sets)]:
        master = _master(args, system, overrides, scenario, args.algorithm)
        steps = round((master.stop_time - master.start_time) / master.step_size)
        interval = getattr(args, "output_interval", None)
        args.output_every = output_every(interval, master.step_size, steps)
    with FolderLock(prepare_out(out), "--out"):
        return _run_scenarios(args, ssp, overrides, out)


def _master(
    args: argparse.Namespace, system, overrides: dict, scenario: str | None, algorithm: str | None
):
    """The master of one run of the command (MasterError for anything it refuses)."""
    from impedance_cosim.cosim.master.events import EventExactMaster
    from impedance_cosim.cosim.master.master import Master
    from impedance_cosim.cosim.master.options import RunOptions
    from impedance_cosim.cosim.master.realtime import realtime_setting

    cls = EventExactMaster if getattr(args, "event_exact", False) else Master
    options = RunOptions(
        parameter_set=scenario,
        overrides=overrides,
        algorithm=algorithm,
        step_size=args.step,
        stop_time=args.stop,
        fmu_files=getattr(args, "fmu_files", None),
        realtime=realtime_setting(args),
        overrides_origin="given with --set",
        extrapolation=getattr(args, "extrapolation", "none"),
    )
    return cls(system, options)


def _run_scenarios(args: argparse.Namespace, ssp: Path, overrides: dict, out: Path) -> int:
    """The chosen scenario (CSV as it runs, summary, figures) and, for Fig. 4, its pair; 1 when
    any of them failed."""
    system = args.system
    progress = not args.no_progress  # a bar on a terminal, plain periodic lines otherwise
    runs: list[dict] = []  # provenance of each run, written to run.json on every exit path
    written: list[Path] = []  # the result files this command wrote (the rest are stale)
    started, t0 = provenance.now_utc(), time.perf_counter()
    stage = staging_folder(out)  # where this command writes until it has completed

    def run(scenario: str | None, algorithm: str | None = args.algorithm, role: str | None = None):
        master = _master(args, system, overrides, scenario, algorithm)
        stem = master.parameter_set or "run"
        fmt, every = getattr(args, "result_format", "csv"), getattr(args, "output_every", 1)
        name = f"{stem}-{master.algorithm}.{fmt}" if role else f"{stem}.{fmt}"
        path, kept = out / name, out / (name + PARTIAL)  # where it goes; if the command fails
        stream = results_stream(stage / name, fmt, every, master)
        result = _run_into(master, stream, kept, progress, overrides, runs, written)
        runs[-1]["results"] = {"file": path.name, "format": fmt, "rows": stream.rows,
                               "output_interval_s": every * master.step_size}  # fmt: skip
        if role:
            runs[-1]["role"] = role
        span = result.data[-1, 0] - result.data[0, 0] if len(result.data) else 0.0
        rtf = span / max(result.wall_time, 1e-9)
        status = {"ok": "ok", "diverged": str(result.divergence)}.get(result.status, "FAILED")
        rows = f"{len(result.data)} rows" + (f", {stream.rows} written" if every > 1 else "")
        where = kept if result.status == "failed" else path
        print(f"{stem}{f' ({role})' if role else ''}: {status}, {rows} -> {where} "
              f"({result.wall_time:.2f} s wall, {rtf:.1f}x real time)")  # fmt: skip
        if result.status == "failed":
            error = " ".join(result.error.split())
            print(f"impedance-cosim {args.command}: error: {stem}: {error};"
                  f" {len(result.data)} rows kept in {kept}", file=sys.stderr)  # fmt: skip
        return result

    figures: list[Path] = []  # the figures this command wrote, for report.html
    status = None
    try:
        status = _scenarios_and_figures(args, system, overrides, stage, run, runs, figures,
                                        written)  # fmt: skip
        return status
    finally:
        done = status in (0, 3)  # completed (a diverged run is a result): replaces the earlier
        error = sys.exc_info()[1]
        suffix = "" if done else PARTIAL
        moved = settle(stage, out, done)
        figures[:] = [out / moved[f.name] for f in figures if f.name in moved]
        if done and runs:  # the folder now describes this command alone
            remove_stale(args, out, system, [*written, *figures])
        if not done and moved:
            print(f"kept as {PARTIAL} (the command did not complete; earlier results in {out}/"
                  f" are as they were): {', '.join(sorted(moved.values()))}")  # fmt: skip
        for entry in runs:  # the names the files have now
            if "results" in entry and not done:
                entry["results"]["file"] += PARTIAL
            if entry.get("csv") and not done:
                entry["csv"] += PARTIAL
        renamed(error, stage, out)
        record = provenance.record(runs, started, time.perf_counter() - t0,
                                   command=args.command_line, ssp=ssp)  # fmt: skip
        record = json.loads(json.dumps(record).replace(_json(stage), _json(out)))
        try:  # never in place of the run's own error (this is a finally)
            provenance.write(out / ("run.json" + suffix), record)
        except OSError as exc:
            print(f"impedance-cosim {args.command}: warning: {out / ('run.json' + suffix)} not"
                  f" written: {exc.strerror or exc}", file=sys.stderr)  # fmt: skip
        if not getattr(args, "no_report", False):
            from impedance_cosim.apps import report

            if page := report.write_run_report(out, record, figures, error, suffix):
                print(f"report: {page}")


PARTIAL = ".partial"  # the suffix of what a command that did not complete kept


def staging_folder(out: Path) -> Path:
    """A new, empty `.staging-<pid>` folder in out (one left by an earlier process of this pid,
    which cannot be running: out is locked, is removed)."""
    from impedance_cosim.util.atomic import write_error

    stage = out / f".staging-{os.getpid()}"
    try:
        if stage.exists():
            shutil.rmtree(stage)
        stage.mkdir()
    except OSError as exc:
        raise write_error(stage, exc) from None
    return stage


def settle(stage: Path, out: Path, done: bool) -> dict[str, str]:
    """Move what the command wrote from stage into out: under its own name when the command
    completed (replacing an earlier file), as `<name>.partial` otherwise (an earlier file of the
    name stays); the staging folder is then removed. Returns {staged name: name in out}."""
    moved = {}
    for f in sorted(stage.iterdir()):
        keep = done or f.name.endswith(PARTIAL) or f.name.startswith(".")  # .*.tmp: as named
        name = f.name if keep else f.name + PARTIAL
        try:
            os.replace(f, out / name)
        except OSError as exc:  # never in place of the command's own error: left where it is
            print(f"impedance-cosim: warning: {f} not moved to {out / name}:"
                  f" {exc.strerror or exc}", file=sys.stderr)  # fmt: skip
            continue
        moved[f.name] = name
    with contextlib.suppress(OSError):
        stage.rmdir()
    return moved


def _json(path: Path) -> str:
    """path as it appears inside a JSON string."""
    return json.dumps(str(path))[1:-1]


def renamed(error: BaseException | None, stage: Path, out: Path) -> None:
    """The error's text naming out, not the staging folder its files were moved from."""
    if error is None:
        return
    error.args = tuple(a.replace(str(stage), str(out)) if isinstance(a, str) else a
                       for a in error.args)  # fmt: skip
    for attr in ("message", "note"):
        if isinstance(getattr(error, attr, None), str):
            setattr(error, attr, getattr(error, attr).replace(str(stage), str(out)))


def _run_into(master, stream, kept: Path, progress: bool, overrides: dict, runs: list,
              written: list):  # fmt: skip
    """Run the master into the results stream and close it; its entry goes to `runs` on every
    exit path (interrupted or failed, also while the file is written at the end; kept: where
    its rows are then)."""
    from impedance_cosim.util.atomic import WriteError
    from impedance_cosim.util.interrupt import RunInterrupted, signal_name

    stderr, fmu_output, result = sys.stderr, io.StringIO(), None
    try:
        with stream, contextlib.redirect_stderr(fmu_output):
            try:
                result = master.run(progress=progress and stderr, sink=stream.write)
            except RunInterrupted as exc:
                exc.message += f"; {stream.rows} rows kept in {kept}"
                raise
            finally:
                echo_fmu_output(fmu_output.getvalue(), stderr)
    except (KeyboardInterrupt, WriteError) as exc:  # e.g. a full disk: the message says where
        if isinstance(exc, KeyboardInterrupt) and not isinstance(exc, RunInterrupted):
            signum = getattr(exc, "signum", signal.SIGINT)  # while the file was closed
            message = f"interrupted ({signal_name(signum)}); {stream.rows} rows kept in {kept}"
            exc = RunInterrupted(message, signum)
        status = "interrupted" if isinstance(exc, RunInterrupted) else "failed"
        entry = provenance.run_entry(master, result, overrides, stream.path, status)
        message = exc.message if isinstance(exc, RunInterrupted) else str(exc)
        runs.append({"rows": stream.rows, **entry, "error": message})
        written.append(stream.path)
        raise exc from None
    written.append(stream.path)
    fmt = "csv" if stream.path.suffix == ".csv" else "mat"
    csv = stream.path if fmt == "csv" else None
    runs.append(provenance.run_entry(master, result, overrides, csv))
    return result


FIG4_COMPARISON = "Fig. 4 comparison"  # the role of the runs under the paper's condition


def _scenarios_and_figures(args, system, overrides: dict, out: Path, run, runs: list,
                           figures: list, written: list) -> int:  # fmt: skip
    # out: the staging folder (settle() moves what is written there into the results folder)
    """The main scenario, its summary and figures, and its Fig. 4 pair (for `run` under
    sample-and-hold also the pair under one sample of delay, the paper's Fig. 4). Exit status
    (results.exit_status) from the runs asked for: 1 failed, 3 diverged, 0 ok."""
    from impedance_cosim.apps import analysis
    from impedance_cosim.cosim.results.result import exit_status
    from impedance_cosim.util.atomic import atomic_write

    main = run(args.scenario)
    if main.status == "failed":
        return 1
    values = analysis.summary(main) if main.ok else analysis.diverged_summary(main)
    runs[-1]["summary"] = values
    print(analysis.format_summary(values))
    if "realtime" in main.info:
        from impedance_cosim.cosim.master.realtime import format_realtime

        values["realtime"] = main.info["realtime"]
        print(format_realtime(main.info["realtime"]))
    if "events" in main.info:  # --event-exact: the switch times inside the steps
        values["events"] = main.info["events"]
        for name, times in main.info["events"].items():
            print(f"{name} events (event-exact): " + ", ".join(f"{t:.9f} s" for t in times))
    for name, ticks in main.info.get("ticks", {}).items():  # --event-exact, an input clock
        span = f", {ticks[0]:.9f} to {ticks[-1]:.9f} s" if ticks else ""
        print(f"{name} clock ticks (event-exact): {len(ticks)}{span}")
    written.append(out / f"{main.parameter_set}_summary.json")
    with atomic_write(written[-1]) as f:
        f.write(json.dumps(values, indent=2) + "\n")
    asked = [main]
    if args.no_figures:
        return exit_status([r.status for r in asked])
    if main.ok:  # a diverged run's figure is its Fig. 4 (the rows up to the divergence)
        figures.append(_figure(analysis.figure_1, out / "fig1_position_force.png", main))
        figures.append(_figure(analysis.figure_2, out / "fig2_observer.png", main))
        figures.append(_figure(analysis.figure_3, out / "fig3_velocity_tracking.png", main))
    source = str(overrides.get("controller.velocity_source", "")) or main.parameter_set
    pair = fig4_pair(system, run, {source: main} if source in FIG4_SOURCES else {})
    asked += [r for r in pair.values() if r is not main]
    if any(r.status == "failed" for r in asked):
        return 1
    if len(pair) == len(FIG4_SOURCES):
        label = analysis.condition_label(main.algorithm, overrides)
        if getattr(args, "extrapolation", "none") != "none":
            label += ", inputs extrapolated"
        rows = [(label, *pair.values())]
        if args.command == "run" and main.algorithm != "jacobi" and "realtime" not in main.info:
            delayed = fig4_pair(system, lambda s: run(s, "jacobi", FIG4_COMPARISON), {})
            if len(delayed) == len(FIG4_SOURCES):
                rows.append((analysis.condition_label("jacobi", overrides), *delayed.values()))
        fig4 = out / "fig4_observer_vs_difference.png"
        figures.append(_figure(analysis.figure_4, fig4, rows))
    print(f"figures in {out.parent}/")
    return exit_status([r.status for r in asked])


FIG4_SOURCES = ("observer", "difference")


def fig4_pair(system, run, have: dict) -> dict:
    """The observer and difference runs of Fig. 4 (those in have, the others run), in that
    order; stops at a failed run (no figure from it)."""
    pair = {}
    for name in FIG4_SOURCES:
        if name not in have and name not in system.parameter_sets:
            return pair
        pair[name] = have.get(name) or run(name)
        if pair[name].status == "failed":
            return pair
    return pair


def remove_stale(args: argparse.Namespace, out: Path, system, owned: list[Path]) -> None:
    """Remove result files of an earlier command from out (known names only: scenario CSVs and
    summaries, the figures) that this command did not write; one line on stderr says which."""
    from impedance_cosim.apps.report import CAPTIONS

    names = set(CAPTIONS)
    for ps in [*system.parameter_sets, "run"]:
        names |= {f"{ps}_summary.json"}
        for fmt in ("csv", "mat"):
            names |= {f"{ps}.{fmt}", f"{ps}-jacobi.{fmt}", f"{ps}-gauss-seidel.{fmt}"}
    names |= {n + PARTIAL for n in [*names, "run.json", "report.html"]}  # of a failed command
    keep = {p.name for p in owned}
    removed = []
    for name in sorted(names - keep):
        with contextlib.suppress(FileNotFoundError, IsADirectoryError):
            (out / name).unlink()
            removed.append(name)
    if removed:
        print(f"impedance-cosim {args.command}: removed {len(removed)} file(s) of an earlier run"
              f" from {out}/: {', '.join(removed)}", file=sys.stderr)  # fmt: skip


def results_stream(path: Path, fmt: str, every: int, master):
    """The sink that writes a run's rows (every `every`-th): a CSV as it runs, or a result file
    (.mat, cosim/results/mat.py) with the variables' descriptions and the run's parameters."""
    from impedance_cosim.cosim.results.result import CsvStream

    if fmt == "csv":
        return CsvStream(path, every=every)
    from impedance_cosim.cosim.results.mat import MatStream

    units = provenance.signal_units(master, [])
    texts = {}
    for comp, md in master.descriptions.items():
        for v in md.modelVariables:
            unit = v.unit or getattr(v.declaredType, "unit", None)
            texts[f"{comp}.{v.name}"] = (v.description or "") + (f" [{unit}]" if unit else "")
    texts["time"] = f"Time [{units['time']}]"
    numbers = {f"{c}.{k}": float(v) for c, p in master.parameters.items() for k, v in p.items()
               if isinstance(v, int | float)}  # fmt: skip
    return MatStream(path, every, texts, numbers)


def _figure(draw, path: Path, *runs) -> Path:
    """draw(*runs, path) through a temporary file renamed into place (a figure is whole or old)."""
    from impedance_cosim.util import atomic

    with atomic.atomic_path(path, suffix=".tmp" + path.suffix) as tmp:  # the suffix: the format
        draw(*runs, tmp)
    return path
