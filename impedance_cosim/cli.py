"""Command-line interface: `impedance-cosim <subcommand>`."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DEFAULT_SSP = REPO / "fmus" / "PaperScenario.ssp"


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


def _cmd_build(args: argparse.Namespace) -> int:
    from impedance_cosim.build import build_all

    for path in build_all(Path(args.out), args.only or None):
        print(f"built {path}")
    return 0


def _stale(target: Path) -> bool:
    """True when target is missing or older than a file it is built from (the code bundled into
    the FMUs, the build itself, the SSP sources)."""
    from impedance_cosim.build import FMU_CORE, FMUS

    if not target.is_file():
        return True
    core = REPO / "impedance_cosim"
    sources = [core / "build.py", core / "system.py", *(core / item for item in FMU_CORE)]
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


def _cmd_run(args: argparse.Namespace) -> int:
    from impedance_cosim import analysis
    from impedance_cosim.master import Master
    from impedance_cosim.ssp import read_ssp

    ssp = Path(args.ssp) if args.ssp else DEFAULT_SSP
    if not args.ssp and _stale(ssp):
        print("building the FMUs and the system archive ...", file=sys.stderr)
        _cmd_build(argparse.Namespace(out=str(ssp.parent), only=None))
    overrides = parse_overrides(args.set or [])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    system = read_ssp(ssp)
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
            realtime=getattr(args, "realtime", False),
        )
        result = master.run(progress=progress)
        path = out / f"{master.parameter_set or 'run'}.csv"
        analysis.write_csv(path, result.names, result.data)
        status = "ok" if result.ok else "FAILED"
        rtf = (result.data[-1, 0] - result.data[0, 0]) / max(result.wall_time, 1e-9)
        print(f"{master.parameter_set}: {status}, {len(result.data)} rows -> {path} "
              f"({result.wall_time:.2f} s wall, {rtf:.1f}x real time)")  # fmt: skip
        if not result.ok:
            print(f"  {result.error}")
        return result

    main = run(args.scenario)
    if not main.ok:
        print(f"impedance-cosim run: error: {main.error}", file=sys.stderr)
        print(f"partial results kept in {out / (main.parameter_set + '.csv')}", file=sys.stderr)
        return 1
    values = analysis.summary(main)
    print(analysis.format_summary(values))
    if "realtime" in main.info:
        from impedance_cosim.master import format_realtime

        values["realtime"] = main.info["realtime"]
        print(format_realtime(main.info["realtime"]))
    (out / f"{main.parameter_set}_summary.json").write_text(json.dumps(values, indent=2) + "\n")
    if args.no_figures:
        return 0
    analysis.figure_1(main, out / "fig1_position_force.png")
    analysis.figure_2(main, out / "fig2_observer.png")
    analysis.figure_3(main, out / "fig3_velocity_tracking.png")
    pair = {"observer": None, "difference": None}
    source = str(overrides.get("controller.velocity_source", "")) or main.parameter_set
    if source in pair:
        pair[source] = main
    for name in pair:
        if pair[name] is None and name in system.parameter_sets:
            pair[name] = run(name)
    if all(r is not None for r in pair.values()):
        analysis.figure_4(
            pair["observer"], pair["difference"], out / "fig4_observer_vs_difference.png"
        )
    print(f"figures in {out}/")
    return 0


def add_run_options(p: argparse.ArgumentParser, out: str = "results") -> None:
    """The options of `run` (shared with the commands that run the system the same way)."""
    p.add_argument("--scenario", default=None,
                   help="parameter set of the SSD: observer (default, the paper), difference, "
                        "measured")  # fmt: skip
    p.add_argument("--ssp", default=None, help=f"system archive (default: {DEFAULT_SSP}, "
                   "built if missing or out of date)")  # fmt: skip
    p.add_argument("--stop", type=float, default=None, help="stop time [s] (default 20)")
    p.add_argument("--step", type=float, default=None, help="communication step [s] (1/400)")
    p.add_argument("--algorithm", choices=["gauss-seidel", "jacobi"], default=None,
                   help="master algorithm (default gauss-seidel, controller first)")  # fmt: skip
    p.add_argument("--set", action="append", metavar="COMPONENT.VARIABLE=VALUE",
                   help="override a parameter, e.g. controller.K=80 (K1..K3) or "
                        "plant.q_noise=1e-4 (repeatable)")  # fmt: skip
    p.add_argument("--realtime", action="store_true",
                   help="pace the steps to the wall clock; per-step timing recorded")  # fmt: skip
    p.add_argument("--out", default=out, help=f"output folder (default {out}/)")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def main(argv: list[str] | None = None) -> int:
    """Entry point of the impedance-cosim command."""
    parser = argparse.ArgumentParser(
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
    from impedance_cosim import dist

    dist.add_parser(sub)

    p = sub.add_parser("run", help="run a scenario of the system: CSV, summary, figures")
    add_run_options(p)
    p.set_defaults(func=_cmd_run)
    from impedance_cosim import sweep

    sweep.add_parser(sub)
    from impedance_cosim.hil import add_parsers as add_hil_parsers

    add_hil_parsers(sub)

    args = parser.parse_args(argv)
    from impedance_cosim.master import MasterError
    from impedance_cosim.ssp import SspError

    try:
        return args.func(args)
    except (CliError, MasterError, SspError, ValueError, FileNotFoundError) as exc:
        print(f"impedance-cosim {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
