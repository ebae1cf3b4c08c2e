"""End-to-end speed of the command line (issue 24): whole processes, alternating, medians of N.

Measured side by side in one sitting, each command once per round, rounds alternating:
- `impedance-cosim run --ssp <native per-scenario archive> --no-figures --no-report
  --no-progress` (every output of both components to CSV, shortest round-trip text), also with
  `--result-format mat` and `--output-interval 0.01` where this checkout has them;
- ecospy 0.7.2 running the same archive from a Python script, the same outputs recorded by its
  own CSV writer (its 6 decimals);
- `impedance-cosim --version`, `impedance-cosim --help`, and the floor: `python -c pass`,
  `import numpy`, `import fmpy.fmi2` (what our run imports before it does anything);
- with --before REV: the same `impedance-cosim` commands of that commit (a git worktree in a
  temporary folder, run with this venv's Python), so before and after appear side by side.
The CSV of each side is checked byte-identical to the other's. One round before the measured
ones is not counted (it writes the bytecode caches and the compiled C loop).

    python benchmarks/speed_end_to_end.py [--runs 5] [--before main] [--stop 20]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ARCHIVE = REPO / "fmus" / "PaperScenario-native-observer.ssp"
CLI = "import sys; from impedance_cosim.cli import entry; sys.argv[0] = 'impedance-cosim'; entry()"

ECOSPY = """
import json, sys
import ecospy
ssp, out, h, stop, names = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), \\
    json.loads(sys.argv[5])
sim = ecospy.EcosSimulation(step_size=h, ssp_path=ssp)
sim.add_csv_writer(out, identifiers=[n.replace(".", "::") for n in names])
assert sim.init(parameter_set="observer"), "ecospy could not initialize"
sim.step(round(stop / h))
sim.terminate()
sim.free()
"""


def output_names(archive: Path) -> tuple[list[str], float]:
    """Every Real output of the archive's components ("component.variable"), and its step."""
    from fmpy import read_model_description

    from impedance_cosim.cosim.master.setup import real_outputs
    from impedance_cosim.cosim.ssp.read import read_ssp

    system = read_ssp(archive)
    try:
        names = [
            f"{c.name}.{o}" for c in system.components
            for o in real_outputs(read_model_description(c.fmu))
        ]  # fmt: skip
        return names, system.step_size
    finally:
        system.close()


def environment(**extra: str) -> dict[str, str]:
    """The children's environment: this one, but writing bytecode caches as a user's Python
    does (PYTHONDONTWRITEBYTECODE, set in some sandboxes, makes every start compile every
    module: ~50 ms more per process here)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    return {**env, **extra}


def timed(cmd: list[str], env: dict[str, str], cwd: Path) -> float:
    """Wall time of one whole process (which must exit 0)."""
    start = time.perf_counter()
    done = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True, timeout=600)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)[:200]}: exit {done.returncode}: {done.stderr[-500:]}")
    return wall


def side(tree: Path, label: str, work: Path, stop: float) -> dict[str, tuple[list[str], dict]]:
    """The commands of one checkout (tree): name -> (command, environment)."""
    env = environment(PYTHONPATH=str(tree))
    cli = [sys.executable, "-c", CLI]
    run = [*cli, "run", "--ssp", str(ARCHIVE), "--no-figures", "--no-report", "--no-progress",
           "--stop", f"{stop:g}"]  # fmt: skip
    help_text = subprocess.run([*cli, "run", "--help"], env=env, cwd=work, capture_output=True,
                               text=True)  # fmt: skip
    commands = {
        f"{label}: --version": ([*cli, "--version"], env),
        f"{label}: --help": ([*cli, "--help"], env),
        f"{label}: run (CSV)": ([*run, "--out", str(work / f"{label}-csv")], env),
    }
    if "--result-format" in help_text.stdout:
        out = str(work / f"{label}-mat")
        commands[f"{label}: run (mat)"] = ([*run, "--result-format", "mat", "--out", out], env)
    if "--output-interval" in help_text.stdout:
        out = str(work / f"{label}-every4")
        commands[f"{label}: run (CSV, 100 Hz)"] = ([*run, "--output-interval", "0.01", "--out",
                                                     out], env)  # fmt: skip
    return commands


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5, help="rounds (default 5)")
    parser.add_argument("--before", help="a git revision to measure side by side")
    parser.add_argument("--stop", type=float, default=20.0, help="stop time [s] (default 20)")
    args = parser.parse_args()
    if not ARCHIVE.is_file():
        raise SystemExit(f"{ARCHIVE} missing: run `impedance-cosim build` first")
    names, step = output_names(ARCHIVE)
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="speed-e2e-") as tmp:
        work = Path(tmp)
        floor = {"python -c pass": ([sys.executable, "-c", "pass"], environment()),
                 "python -c 'import numpy'": ([sys.executable, "-c", "import numpy"],
                                              environment()),
                 "python -c 'import fmpy.fmi2'": ([sys.executable, "-c", "import fmpy.fmi2"],
                                                  environment())}  # fmt: skip
        ecos = [sys.executable, "-c", ECOSPY, str(ARCHIVE), str(work / "ecospy.csv"), repr(step),
                repr(args.stop), json.dumps(names)]  # fmt: skip
        commands = {**floor, "ecospy 0.7.2 (CSV)": (ecos, environment())}
        commands.update(side(REPO, "after", work, args.stop))
        if args.before:
            before = work / "before"
            subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(before),
                            args.before], check=True, capture_output=True)  # fmt: skip
        try:
            if args.before:
                commands.update(side(before, "before", work, args.stop))
            for cmd, env in commands.values():  # a round not counted: caches, bytecode
                timed(cmd, env, work)
            times: dict[str, list[float]] = {name: [] for name in commands}
            for _ in range(args.runs):
                for name, (cmd, env) in commands.items():
                    times[name].append(timed(cmd, env, work))
        finally:
            if args.before:
                subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force",
                                str(before)], check=False, capture_output=True)  # fmt: skip
        report(times, args, names, work, (load, os.getloadavg()[0]))


def report(times: dict[str, list[float]], args, names: list[str], work: Path,
           load: tuple[float, float]) -> None:  # fmt: skip
    """The table: median, range, and the runs' ratio to ecospy's."""
    ecospy = statistics.median(times["ecospy 0.7.2 (CSV)"])
    print(f"{ARCHIVE.name}, {args.stop:g} s, {len(names)} outputs, medians of {args.runs} "
          f"(alternating rounds), whole processes; load average {load[0]:.1f} at the start,"
          f" {load[1]:.1f} at the end")  # fmt: skip
    print(f"{'command':32} {'median s':>9} {'range s':>15} {'/ ecospy':>9}")
    for name, values in times.items():
        med = statistics.median(values)
        ratio = f"{med / ecospy:.2f}x"
        print(f"{name:32} {med:9.3f} {min(values):7.3f}-{max(values):<7.3f} {ratio:>9}")
    after = work / "after-csv" / "observer.csv"
    if args.before:
        same = after.read_bytes() == (work / "before-csv" / "observer.csv").read_bytes()
        print(f"CSV before and after byte-identical: {same}")
    rows = sum(1 for _ in open(work / "ecospy.csv")) - 1
    print(f"rows: ours {sum(1 for _ in open(after)) - 1}, ecospy {rows}")


if __name__ == "__main__":
    main()
