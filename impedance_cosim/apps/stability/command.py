"""`impedance-cosim stability`: the stability study's tables and figures (docs/stability.md).

Parts: boundaries (bisection, docs/boundaries.csv + boundaries.png), linear (the linearised
loop's critical rates next to the simulated ones, docs/linear.csv + spectral_radius.png), fig4
(the Fig. 4 candidate conditions, docs/fig4_conditions.csv + fig4_candidates.png) and gain (the
observer discretizations at 400 Hz, docs/observer_discretization.csv).

Nothing finished is lost: every run of the part under way is in `<part>.runs.jsonl` as it
finishes (stability_log); Ctrl-C/SIGTERM stops with one line saying what was kept (exit status
128 + signal), a failure keeps the same, and `--resume` goes on without running them again.
`stability.run.json` (provenance, each part's status) and `report.html` are written on every exit.
"""

from __future__ import annotations

import argparse
import csv
import math
import signal
import sys
from pathlib import Path
from typing import Any

from impedance_cosim.apps.stability import bisection as st
from impedance_cosim.apps.stability.log import PartLog, Record
from impedance_cosim.apps.stability.parts import (
    FIG4_COLUMNS,
    GAIN_COLUMNS,
    LINEAR_COLUMNS,
    boundaries,
    fig4_part,
    gain,
    linear,
    read_csv,
    valid_record,
    write_csv,
)
from impedance_cosim.apps.sweep.command import stop_on_signals
from impedance_cosim.apps.sweep.execute import RunsLostError
from impedance_cosim.apps.sweep.plan import default_ssp, workers_problem
from impedance_cosim.apps.sweep.worker import STOP, RunInterruptedError

PARTS = ("boundaries", "linear", "fig4", "gain")
TABLES = {"boundaries": "boundaries.csv", "linear": "linear.csv", "fig4": "fig4_conditions.csv",
          "gain": "observer_discretization.csv"}  # fmt: skip
FIGURES = {"boundaries": "boundaries.png", "linear": "spectral_radius.png",
           "fig4": "fig4_candidates.png"}  # fmt: skip
__all__ = ["PARTS", "add_parser", "read_csv", "write_csv"]


def add_parser(sub) -> None:
    """Register `impedance-cosim stability`."""
    p = sub.add_parser(
        "stability",
        help="stability study: bisected boundaries, linearised loop, Fig. 4 conditions, observer"
        " discretizations (docs/stability.md)",
    )
    p.add_argument("parts", nargs="*", default=None, metavar="PART",
                   help=f"which parts ({', '.join(PARTS)}; default all)")  # fmt: skip
    p.add_argument("--out", default="results/stability",
                   help="output folder (default results/stability)")  # fmt: skip
    p.add_argument("--ssp", default=None, help="system archive (default: the native one,"
                   " PaperScenario-native.ssp: the same models in C, for many runs)")  # fmt: skip
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
    p.add_argument("--no-report", action="store_true", help="no report.html (tables, figures)")
    p.add_argument("--no-progress", action="store_true", help="no progress display")
    p.add_argument("--resume", action="store_true",
                   help="finish an interrupted study: keep the finished runs and parts in --out "
                   "(same command otherwise) and run only the others")  # fmt: skip
    p.set_defaults(func=_cmd_stability)


def _check(args: argparse.Namespace) -> Path:
    """StabilityError for a request that cannot work, before anything is written; the archive."""
    from impedance_cosim.apps import fig4

    args.parts = args.parts or list(PARTS)
    for part in args.parts:
        if part not in PARTS:
            raise st.StabilityError(f"unknown part {part!r} (have {', '.join(PARTS)})")
    for name in args.condition or []:
        if name not in [c.name for c in fig4.CONDITIONS]:
            names = ", ".join(c.name for c in fig4.CONDITIONS)
            raise st.StabilityError(f"unknown condition {name!r} (have {names})")
    if workers_problem(args.workers):
        raise st.StabilityError(workers_problem(args.workers))
    if not (math.isfinite(args.stop) and args.stop >= 1 and args.stop.is_integer()):
        raise st.StabilityError(  # so that every whole-Hz rate divides the run
            f"--stop must be a whole number of seconds >= 1 (got {args.stop})"
        )
    from impedance_cosim.apps.options import check_out

    check_out(args.out)  # empty, a file, too long a name, read-only: one line, nothing written
    ssp = Path(args.ssp) if args.ssp else default_ssp()
    if not ssp.is_file():
        raise FileNotFoundError(f"no system archive {ssp}")
    return ssp


def plans(args: argparse.Namespace, ssp: Path) -> dict[str, dict[str, Any]]:
    """What each part's results depend on (checked on --resume)."""
    from impedance_cosim.apps import fig4
    from impedance_cosim.cosim.results.provenance import file_sha256

    def selected(name: str, allowed) -> list[str]:
        return list(getattr(args, name) or allowed)

    base = {"ssp_sha256": file_sha256(ssp)}
    where = {"velocity": selected("velocity", st.SOURCES), "timing": selected("timing", st.TIMINGS)}
    return {
        "boundaries": {
            **base,
            "stop": args.stop,
            "quantity": selected("quantity", st.QUANTITIES),
            "sensor": selected("sensor", st.SENSORS),
            **where,
        },  # fmt: skip
        "linear": {**base, "stop": args.stop, **where},
        "fig4": {**base, "condition": selected("condition", [c.name for c in fig4.CONDITIONS])},
        "gain": {**base, "stop": args.stop},
    }


def _run_parts(args: argparse.Namespace, ssp: Path, out: Path, record: Record) -> None:
    """Each part in turn: skipped when --resume finds it finished, else run with its log."""
    simulated: list[dict] = []
    for part, plan in plans(args, ssp).items():
        if part not in args.parts:
            continue
        table = out / TABLES[part]
        log_path = out / f"{part}.runs.jsonl"
        if args.resume and not log_path.exists() and record.finished(part, plan):
            rows = _kept_table(part, table)
            record.keep(part)
            print(f"kept {table} (finished earlier)")
            if part == "boundaries":
                simulated = rows
            continue
        print(f"{part} ...", flush=True)  # a part takes seconds to minutes
        with PartLog(out, part, plan, args.resume, valid_record) as log:
            record.set(part, status="running", plan=plan, table=table.name, log=log_path.name,
                       figures=[], kept_runs=len(log.kept), runs=0)  # fmt: skip
            try:
                rows, figures = _part(part, args, ssp, out, log, simulated)
            except (KeyboardInterrupt, RunInterruptedError) as exc:
                record.set(part, status="interrupted", runs=log.runs,
                           error=f"interrupted by {_signal_name(exc)}")  # fmt: skip
                raise
            except BaseException as exc:
                record.set(part, status="failed", runs=log.runs,
                           error=" ".join(str(exc).split()) or type(exc).__name__)  # fmt: skip
                raise
            if part == "boundaries":
                simulated = rows
            kept = f", {len(log.kept)} kept from an earlier run" if args.resume else ""
            print(f"wrote {table} ({log.runs} runs{kept})")
            record.set(part, status="finished", rows=len(rows), runs=log.runs, log=None,
                       figures=figures)  # fmt: skip
            record.write()
            log.remove()


def _kept_table(part: str, table: Path) -> list[dict]:
    """The rows of a part's table finished earlier (--resume), checked to be that part's."""
    columns = {"boundaries": st.COLUMNS, "linear": LINEAR_COLUMNS, "fig4": FIG4_COLUMNS,
               "gain": GAIN_COLUMNS}[part]  # fmt: skip
    try:
        with open(table, newline="") as f:
            cells = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise st.StabilityError(f"cannot resume: cannot read {table}: {exc}") from None
    if len(cells) < 2 or cells[0] != columns or any(len(r) != len(columns) for r in cells):
        raise st.StabilityError(f"cannot resume: {table} is not a table of `stability {part}` "
                                "(remove it, or run without --resume)")  # fmt: skip
    return read_csv(table)


def _part(part: str, args: argparse.Namespace, ssp: Path, out: Path, log: PartLog,
          simulated: list[dict]) -> tuple[list[dict], list[str]]:  # fmt: skip
    """Run one part into its log; write its table (and figure): its rows, the figures drawn."""
    from impedance_cosim.apps.stability import figures as figs

    table = out / TABLES[part]
    if part == "boundaries":
        rows = boundaries(args, ssp, log)
        write_csv(table, st.COLUMNS, rows)
        if not args.no_figures:
            figs.boundaries_figure(rows, out / FIGURES[part])
    elif part == "linear":
        rows = linear(args, ssp, simulated, log)
        write_csv(table, LINEAR_COLUMNS, rows)
        if not args.no_figures:
            figs.radius_curves(rows, out / FIGURES[part])
    elif part == "fig4":
        from impedance_cosim.apps import fig4

        rows, runs = fig4_part(args, ssp, log)
        write_csv(table, FIG4_COLUMNS, rows)
        if not args.no_figures and not args.condition:  # the figure shows every condition
            fig4.plot(runs, out / FIGURES[part])
    else:
        rows = gain(args, ssp, log)
        write_csv(table, GAIN_COLUMNS, rows)
    drawn = part in FIGURES and not args.no_figures and not (part == "fig4" and args.condition)
    return rows, [FIGURES[part]] if drawn else []


def _signal_name(exc: BaseException) -> str:
    """The signal that stopped the command: the handler's (STOP), or the master's own."""
    signum = getattr(exc, "signum", None)
    return STOP["signal"] or (signal.Signals(signum).name if signum else "SIGINT")


def _cmd_stability(args: argparse.Namespace) -> int:
    from impedance_cosim.apps.options import prepare_out
    from impedance_cosim.util.atomic import FolderLock

    ssp = _check(args)
    out = prepare_out(Path(args.out))
    record = Record(out, getattr(args, "command_line", None), ssp)
    outcome: BaseException | None = None
    with FolderLock(out, "--out"), stop_on_signals():
        try:
            _run_parts(args, ssp, out, record)
            return 0
        except (KeyboardInterrupt, RunInterruptedError) as exc:
            name = _signal_name(exc)
            outcome = KeyboardInterrupt(f"interrupted by {name}")
            lead = "\n" if sys.stderr.isatty() else ""
            print(f"{lead}impedance-cosim stability: interrupted by {name}: "
                  f"{record.kept()}", file=sys.stderr)  # fmt: skip
            return 128 + getattr(signal, name, signal.SIGINT)
        except RunsLostError as exc:
            outcome = exc
            print(f"impedance-cosim stability: error: {exc}; {record.kept()}",
                  file=sys.stderr)  # fmt: skip
            return 1
        except BaseException as exc:  # the dispatcher says what it was
            outcome = exc
            raise
        finally:  # on every exit path: the provenance and the page
            record.write()
            if not args.no_report:
                from impedance_cosim.apps.stability.report import write_report

                if page := write_report(out, record, outcome):
                    print(f"report: {page}")
