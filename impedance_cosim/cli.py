"""Command-line interface: `impedance-cosim <subcommand>`."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import signal
import sys
import tempfile
from pathlib import Path

from impedance_cosim.util.interrupt import signal_name, sigterm_raises

REPO = Path(__file__).resolve().parent.parent
DEFAULT_SSP = REPO / "fmus" / "PaperScenario.ssp"


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage block), exit status 2."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def _cmd_build(args: argparse.Namespace) -> int:
    from impedance_cosim.packaging.build import build_all

    for path in build_all(prepare_out(Path(args.out)), args.only or None):
        print(f"built {path}")
    return 0


def _stale(target: Path) -> bool:
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


def parse_overrides(items: list[str]) -> dict[str, str]:
    """["controller.K=80", ...] -> {"controller.K": "80"}; one-line error for a bad item."""
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise CliError(f"--set expects component.variable=value (got {item!r})")
        out[name.strip()] = value.strip()
    return out


def finite_positive(text: str) -> float:
    """argparse type of --stop and --step: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0 (got {text})")
    return value


def prepare_out(folder: Path) -> Path:
    """The output folder, created if needed and checked writable (before any simulation)."""
    if folder.exists() and not folder.is_dir():
        raise CliError(f"--out {folder} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise CliError(f"--out {folder} is not a writable folder ({exc.strerror or exc})") from None
    return folder


def _cmd_run(args: argparse.Namespace) -> int:
    from impedance_cosim.util.atomic import FolderLock

    overrides = parse_overrides(args.set or [])
    out = prepare_out(Path(args.out))
    ssp = Path(args.ssp) if args.ssp else DEFAULT_SSP
    with FolderLock(out, "--out"):
        if not args.ssp and _stale(ssp):
            print("building the FMUs and the system archive ...", file=sys.stderr)
            _cmd_build(argparse.Namespace(out=str(ssp.parent), only=None))
        return _run_scenarios(args, ssp, overrides, out)


def _run_scenarios(args: argparse.Namespace, ssp: Path, overrides: dict, out: Path) -> int:
    """The chosen scenario (CSV as it runs, summary, figures) and, for Fig. 4, its pair; 1 when
    any of them failed."""
    from impedance_cosim.apps import analysis
    from impedance_cosim.cosim.master import Master
    from impedance_cosim.cosim.realtime import realtime_setting
    from impedance_cosim.cosim.results import CsvStream
    from impedance_cosim.cosim.ssp import read_ssp
    from impedance_cosim.util.atomic import atomic_write
    from impedance_cosim.util.interrupt import RunInterrupted

    system = args.system = read_ssp(ssp)  # closed by _dispatch()
    progress = sys.stderr.isatty() and not args.no_progress

    def run(scenario: str | None):
        master = Master(
            system,
            parameter_set=scenario,
            overrides=overrides,
            algorithm=args.algorithm,
            step_size=args.step,
            stop_time=args.stop,
            fmu_files=getattr(args, "fmu_files", None),
            realtime=realtime_setting(args),
        )
        path = out / f"{master.parameter_set or 'run'}.csv"
        stderr, fmu_output = sys.stderr, io.StringIO()
        with CsvStream(path) as csv, contextlib.redirect_stderr(fmu_output):
            try:
                result = master.run(progress=progress and stderr, sink=csv.write)
            except RunInterrupted as exc:
                exc.message += f"; {csv.rows} rows kept in {path}"
                raise
            finally:
                _echo_fmu_output(fmu_output.getvalue(), stderr)
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

    main = run(args.scenario)
    if not main.ok:
        return 1
    values = analysis.summary(main)
    print(analysis.format_summary(values))
    if "realtime" in main.info:
        from impedance_cosim.cosim.master import format_realtime

        values["realtime"] = main.info["realtime"]
        print(format_realtime(main.info["realtime"]))
    with atomic_write(out / f"{main.parameter_set}_summary.json") as f:
        f.write(json.dumps(values, indent=2) + "\n")
    if args.no_figures:
        return 0
    _figure(analysis.figure_1, out / "fig1_position_force.png", main)
    _figure(analysis.figure_2, out / "fig2_observer.png", main)
    _figure(analysis.figure_3, out / "fig3_velocity_tracking.png", main)
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
        _figure(analysis.figure_4, fig4, pair["observer"], pair["difference"])
    print(f"figures in {out}/")
    return 0


def _figure(draw, path: Path, *runs) -> None:
    """draw(*runs, path) through a temporary file renamed into place (a figure is whole or old)."""
    from impedance_cosim.util import atomic

    tmp = atomic.temp_path(path, suffix=".tmp" + path.suffix)  # the suffix picks the format
    try:
        draw(*runs, tmp)
    except BaseException:
        atomic.discard(tmp)
        raise
    atomic.replace(tmp, path)


def _echo_fmu_output(text: str, stream) -> None:
    """What Python FMUs printed to stderr during a run, less their error reports (the host gets
    those through the FMU logger and puts them in its one-line error)."""
    for line in text.splitlines():
        if line.strip() and not line.startswith("error: "):
            print(line, file=stream)


def add_run_options(p: argparse.ArgumentParser, out: str = "results") -> None:
    """The options of `run` (shared with the commands that run the system the same way)."""
    p.add_argument("--scenario", default=None,
                   help="parameter set of the SSD: observer (default, the paper), difference, "
                        "measured")  # fmt: skip
    p.add_argument("--ssp", default=None, help=f"system archive (default: {DEFAULT_SSP}, "
                   "built if missing or out of date)")  # fmt: skip
    p.add_argument("--stop", type=finite_positive, default=None, help="stop time [s] (default 20)")
    p.add_argument("--step", type=finite_positive, default=None,
                   help="communication step [s] (1/400)")  # fmt: skip
    p.add_argument("--algorithm", choices=["gauss-seidel", "jacobi"], default=None,
                   help="master algorithm (default gauss-seidel, controller first)")  # fmt: skip
    p.add_argument("--set", action="append", metavar="COMPONENT.VARIABLE=VALUE",
                   help="override a parameter, e.g. controller.K=80 (K1..K3) or "
                        "plant.q_noise=1e-4 (repeatable)")  # fmt: skip
    p.add_argument("--realtime", action="store_true",
                   help="pace the steps to the wall clock; per-step timing recorded")  # fmt: skip
    from impedance_cosim.cosim.realtime import add_options

    add_options(p)
    p.add_argument("--out", default=out, help=f"output folder (default {out}/)")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def main(argv: list[str] | None = None) -> int:
    """Entry point of the impedance-cosim command."""
    parser = _Parser(
        prog="impedance-cosim",
        description="Impedance control without velocity measurements, as FMI co-simulation.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("build", help="build the FMUs and the system archive into fmus/")
    p.add_argument("--out", default=str(REPO / "fmus"),
                   help="output folder (default: the repository's fmus/)")  # fmt: skip
    p.add_argument("--only", action="append", choices=["plant", "controller", "bridge"],
                   help="build only this FMU (repeatable; skips the .ssp)")  # fmt: skip
    p.set_defaults(func=_cmd_build)
    from impedance_cosim.packaging import dist

    dist.add_parser(sub)

    p = sub.add_parser("run", help="run a scenario of the system: CSV, summary, figures")
    add_run_options(p)
    p.set_defaults(func=_cmd_run)
    from impedance_cosim.apps import sweep

    sweep.add_parser(sub)
    from impedance_cosim.apps import stability_study

    stability_study.add_parser(sub)
    from impedance_cosim.apps.hil import add_parsers as add_hil_parsers

    add_hil_parsers(sub)

    args = parser.parse_args(argv)
    with sigterm_raises():
        return _dispatch(args)


def entry() -> None:
    """The console script: main(), then leave the process safely (see fmu.exit_process)."""
    from impedance_cosim.cosim.fmu import exit_process

    exit_process(main())


def _dispatch(args: argparse.Namespace) -> int:
    """Run a subcommand; every failure becomes one line on stderr and an exit status:
    2 bad input, 1 a failed run or other error, 128 + signal number when interrupted."""
    from impedance_cosim.cosim.fmu import FmuError
    from impedance_cosim.cosim.master import MasterError
    from impedance_cosim.cosim.ssp import SspError
    from impedance_cosim.packaging.toolchains import CompileError
    from impedance_cosim.util.atomic import FolderBusyError
    from impedance_cosim.util.interrupt import RunInterrupted

    prefix = f"impedance-cosim {args.command}:"
    try:
        return args.func(args)
    except CliError as exc:  # our own wording (may list several problems, one per line)
        print(f"{prefix} error: {exc}", file=sys.stderr)
        return 2
    except (MasterError, SspError, ValueError, FileNotFoundError) as exc:
        print(f"{prefix} error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except FolderBusyError as exc:
        print(f"{prefix} refused: {exc}", file=sys.stderr)
        return 2
    except RunInterrupted as exc:
        print(f"{prefix} {exc.message}", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt as exc:
        signum = getattr(exc, "signum", signal.SIGINT)
        print(f"{prefix} interrupted ({signal_name(signum)})", file=sys.stderr)
        return 128 + signum
    except (FmuError, OSError, CompileError) as exc:
        print(f"{prefix} error: {_one_line(exc)}", file=sys.stderr)
        return 1
    except Exception as exc:  # a bug: still one line; the traceback on request
        if os.environ.get("IMPEDANCE_COSIM_DEBUG"):
            raise
        print(f"{prefix} internal error: {type(exc).__name__}: {_one_line(exc)} (set"
              " IMPEDANCE_COSIM_DEBUG=1 for the traceback)", file=sys.stderr)  # fmt: skip
        return 1
    finally:  # remove what read_ssp extracted, on every exit path
        if getattr(args, "system", None) is not None:
            args.system.close()


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


if __name__ == "__main__":
    # Run the imported module's main, not this __main__ copy: otherwise CliError raised by other
    # modules (impedance_cosim.cli.CliError) would be another class than the one caught here.
    from impedance_cosim.cli import entry as _entry

    _entry()
