"""`impedance-cosim run` and `build`: a scenario of the system to CSV, summary and figures (with
its Fig. 4 pair), and the FMUs built when they are missing or out of date."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import time
from pathlib import Path

from impedance_cosim.apps.options import (
    DEFAULT_SSP,
    REPO,
    check_out,
    parse_overrides,
    prepare_out,
)
from impedance_cosim.cosim import provenance

BUILD_WAIT_S = 900.0  # how long a build waits for another one into the same folder


def cmd_build(args: argparse.Namespace) -> int:
    from impedance_cosim.packaging.build_all import build_all
    from impedance_cosim.util.atomic import FolderLock

    out = prepare_out(check_out(args.out))
    with FolderLock(out, "build folder", wait=BUILD_WAIT_S):  # one build at a time
        for path in build_all(out, args.only or None):
            print(f"built {path}")
    return 0


def stale(target: Path) -> bool:
    """True when target is missing or older than a file it is built from (the code bundled into
    the FMUs, the build itself, the SSP sources)."""
    from impedance_cosim.packaging.build import FMU_CORE, FMUS

    if not target.is_file():
        return True
    core = REPO / "impedance_cosim"
    sources = [core / "packaging" / "build.py", core / "cosim" / "system.py"]
    sources += [core / item for item in FMU_CORE]
    sources += [REPO / spec.package for spec in FMUS.values()] + [REPO / "ssp"]
    files = [f for s in sources for f in ([s] if s.is_file() else s.rglob("*"))]
    built = target.stat().st_mtime
    return any(f.suffix in (".py", ".ssd", ".ssv") and f.stat().st_mtime > built for f in files)


def ensure_built(args: argparse.Namespace, ssp: Path) -> None:
    """Build the default system archive (and its FMUs) when no --ssp was given and it is stale."""
    if not args.ssp and stale(ssp):
        from impedance_cosim.util.atomic import FolderLock

        with FolderLock(prepare_out(ssp.parent), "build folder", wait=BUILD_WAIT_S):
            if stale(ssp):  # not built meanwhile by another process
                print("building the FMUs and the system archive ...", file=sys.stderr)
                cmd_build(argparse.Namespace(out=str(ssp.parent), only=None))


def cmd_run(args: argparse.Namespace) -> int:
    """Check everything (options, archive, every scenario to run), then create --out, lock it
    and run: bad input writes nothing."""
    from impedance_cosim.cosim.ssp import read_ssp
    from impedance_cosim.util.atomic import FolderLock

    overrides = parse_overrides(args.set or [])
    out = check_out(args.out)
    ssp = Path(args.ssp) if args.ssp else DEFAULT_SSP
    ensure_built(args, ssp)
    system = args.system = read_ssp(ssp)  # closed by _dispatch()
    pair = [] if args.no_figures else ["observer", "difference"]
    for scenario in [args.scenario, *(s for s in pair if s in system.parameter_sets)]:
        _master(args, system, overrides, scenario)
    with FolderLock(prepare_out(out), "--out"):
        return _run_scenarios(args, ssp, overrides, out)


def _master(args: argparse.Namespace, system, overrides: dict, scenario: str | None):
    """The master of one run of the command (MasterError for anything it refuses)."""
    from impedance_cosim.cosim.master import Master
    from impedance_cosim.cosim.realtime import realtime_setting

    return Master(
        system,
        parameter_set=scenario,
        overrides=overrides,
        algorithm=args.algorithm,
        step_size=args.step,
        stop_time=args.stop,
        fmu_files=getattr(args, "fmu_files", None),
        realtime=realtime_setting(args),
    )


def _run_scenarios(args: argparse.Namespace, ssp: Path, overrides: dict, out: Path) -> int:
    """The chosen scenario (CSV as it runs, summary, figures) and, for Fig. 4, its pair; 1 when
    any of them failed."""
    from impedance_cosim.cosim.results import CsvStream
    from impedance_cosim.util.atomic import WriteError
    from impedance_cosim.util.interrupt import RunInterrupted

    system = args.system
    progress = not args.no_progress  # a bar on a terminal, plain periodic lines otherwise
    runs: list[dict] = []  # provenance of each run, written to run.json on every exit path
    started, t0 = provenance.now_utc(), time.perf_counter()

    def run(scenario: str | None):
        master = _master(args, system, overrides, scenario)
        path = out / f"{master.parameter_set or 'run'}.csv"
        stderr, fmu_output = sys.stderr, io.StringIO()
        with CsvStream(path) as csv, contextlib.redirect_stderr(fmu_output):
            try:
                result = master.run(progress=progress and stderr, sink=csv.write)
            except RunInterrupted as exc:
                exc.message += f"; {csv.rows} rows kept in {path}"
                entry = provenance.run_entry(master, None, overrides, path, "interrupted")
                runs.append({**entry, "rows": csv.rows, "error": exc.message})
                raise
            except WriteError as exc:  # e.g. a full disk: what it kept is in the message
                entry = provenance.run_entry(master, None, overrides, path, "failed")
                runs.append({**entry, "rows": csv.rows, "error": str(exc)})
                raise
            finally:
                echo_fmu_output(fmu_output.getvalue(), stderr)
        runs.append(provenance.run_entry(master, result, overrides, path))
        status = "ok" if result.ok else "FAILED"
        span = result.data[-1, 0] - result.data[0, 0] if len(result.data) else 0.0
        rtf = span / max(result.wall_time, 1e-9)
        print(f"{master.parameter_set}: {status}, {len(result.data)} rows -> {path} "
              f"({result.wall_time:.2f} s wall, {rtf:.1f}x real time)")  # fmt: skip
        if not result.ok:
            error = " ".join(result.error.split())
            print(f"impedance-cosim {args.command}: error: {master.parameter_set}: {error};"
                  f" {len(result.data)} rows kept in {path}", file=sys.stderr)  # fmt: skip
        return result

    figures: list[Path] = []  # the figures this command wrote, for report.html
    try:
        return _scenarios_and_figures(args, system, overrides, out, run, runs, figures)
    finally:
        record = provenance.record(runs, started, time.perf_counter() - t0,
                                   command=args.command_line, ssp=ssp)  # fmt: skip
        try:  # never in place of the run's own error (this is a finally)
            provenance.write(out / "run.json", record)
        except OSError as exc:
            print(f"impedance-cosim {args.command}: warning: {out / 'run.json'} not written:"
                  f" {exc.strerror or exc}", file=sys.stderr)  # fmt: skip
        if not getattr(args, "no_report", False):
            from impedance_cosim.apps import report

            if page := report.write_run_report(out, record, figures, sys.exc_info()[1]):
                print(f"report: {page}")


def _scenarios_and_figures(args, system, overrides: dict, out: Path, run, runs: list,
                           figures: list) -> int:  # fmt: skip
    """The main scenario, its summary and figures, and its Fig. 4 pair; 1 when any failed."""
    from impedance_cosim.apps import analysis
    from impedance_cosim.util.atomic import atomic_write

    main = run(args.scenario)
    if not main.ok:
        return 1
    values = analysis.summary(main)
    runs[-1]["summary"] = values
    print(analysis.format_summary(values))
    if "realtime" in main.info:
        from impedance_cosim.cosim.realtime import format_realtime

        values["realtime"] = main.info["realtime"]
        print(format_realtime(main.info["realtime"]))
    with atomic_write(out / f"{main.parameter_set}_summary.json") as f:
        f.write(json.dumps(values, indent=2) + "\n")
    if args.no_figures:
        return 0
    figures.append(_figure(analysis.figure_1, out / "fig1_position_force.png", main))
    figures.append(_figure(analysis.figure_2, out / "fig2_observer.png", main))
    figures.append(_figure(analysis.figure_3, out / "fig3_velocity_tracking.png", main))
    pair = {"observer": None, "difference": None}
    source = str(overrides.get("controller.velocity_source", "")) or main.parameter_set
    if source in pair:
        pair[source] = main
    for name in pair:
        if pair[name] is None and name in system.parameter_sets:
            pair[name] = run(name)
    if any(r is not None and not r.ok for r in pair.values()):
        return 1
    if all(r is not None for r in pair.values()):
        fig4 = out / "fig4_observer_vs_difference.png"
        figures.append(_figure(analysis.figure_4, fig4, pair["observer"], pair["difference"]))
    print(f"figures in {out}/")
    return 0


def _figure(draw, path: Path, *runs) -> Path:
    """draw(*runs, path) through a temporary file renamed into place (a figure is whole or old)."""
    from impedance_cosim.util import atomic

    with atomic.atomic_path(path, suffix=".tmp" + path.suffix) as tmp:  # the suffix: the format
        draw(*runs, tmp)
    return path


def echo_fmu_output(text: str, stream) -> None:
    """What Python FMUs printed to stderr during a run, less their error reports (the host gets
    those through the FMU logger and puts them in its one-line error)."""
    for line in text.splitlines():
        if line.strip() and not line.startswith("error: "):
            print(line, file=stream)
