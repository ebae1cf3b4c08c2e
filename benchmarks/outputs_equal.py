"""Proves that a refactoring changed no output, bit for bit: two commits' FMUs, system archives and
CLI commands run side by side, their output files compared (not a test).

python benchmarks/outputs_equal.py OLD [NEW] [--stop 2]

Each side gets a detached git worktree in a temporary folder (NEW omitted: this checkout's working
tree), builds its FMUs there and runs everything in child processes with that tree on PYTHONPATH and
as cwd, as benchmarks/compare_commits.py does, so each side's own package runs. Compared: every FMU
the build wrote, simulated alone by `fmpy simulate` (co-simulation); every system archive under our
master (`impedance-cosim run --ssp`); `run`, a 2-point `sweep` and `stability linear`; with
IMPCOSIM_FMUSIM set, the native FMUs under the Reference FMUs' fmusim. Fields that hold times,
dates, paths and the inputs' hashes and GUIDs (changed sources give other ones; the outputs are what
must stay) are left out of the JSON and CSV files compared. One line per item: equal, DIFFERENT
(where), failed (why), skipped (why) or new (built on the new side only: an added FMU or archive has
no old output); exit status 0 when every compared item is equal and none of the old side's is gone,
1 otherwise, 2 for bad arguments, 130/143 on SIGINT/SIGTERM (the worktrees are removed).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import Any, NoReturn

HERE = Path(__file__).resolve().parent.parent
FMU_DIRS = ("", "native", "fmi3", "fmi3/python")
# JSON keys and CSV columns that differ from run to run (times, dates, paths; found by running
# the same commit twice) or name the inputs (hashes of the archive and FMUs, and the GUID, a hash
# of an FMU's sources: another commit's sources give another one even if the outputs are equal).
VARYING = frozenset(
    {"command", "ssp", "started", "wall_time_s", "wall_s", "real_time_factor", "sha256",
     "ssp_sha256", "guid"}
)  # fmt: skip
NEEDS_PACKAGE = {"MujocoPlant.fmu": "mujoco", "PinocchioPlant.fmu": "pinocchio"}
FMPY = "import sys; from fmpy.cli import main; sys.argv[0] = 'fmpy'; sys.exit(main())"
TIMEOUT = 900.0


class ArgumentError(Exception):
    """A bad command-line argument: one line on stderr, exit status 2."""


class Parser(argparse.ArgumentParser):
    """argparse raising ArgumentError instead of printing usage and exiting."""

    def error(self, message: str) -> NoReturn:  # type: ignore[override]
        """Raises ArgumentError(message)."""
        raise ArgumentError(message)


def drop_varying(value: Any) -> Any:
    """The JSON value without the VARYING keys, at any depth."""
    if isinstance(value, dict):
        return {k: drop_varying(v) for k, v in value.items() if k not in VARYING}
    if isinstance(value, list):
        return [drop_varying(v) for v in value]
    return value


def csv_lines(text: str) -> list[str]:
    """The CSV text's lines without the VARYING columns (named in the first line)."""
    lines = text.splitlines()
    if not lines:
        return lines
    header = [name.strip('"') for name in lines[0].split(",")]
    keep = [i for i, name in enumerate(header) if name not in VARYING]
    if len(keep) == len(header):
        return lines
    return [",".join(row[i] for i in keep if i < len(row)) for row in (x.split(",") for x in lines)]


def first_field(x: str, y: str, header: str) -> str:
    """The first differing comma-separated field of two lines, named by the CSV header if any."""
    fx, fy, names = x.split(","), y.split(","), header.split(",")
    i = next((i for i, (u, v) in enumerate(zip(fx, fy)) if u != v), min(len(fx), len(fy)))
    name = names[i].strip('"') if header and i < len(names) else f"field {i + 1}"
    u, v = (f[i][:60] if i < len(f) else "(none)" for f in (fx, fy))
    return f"{name}: {u!r} != {v!r}"


def first_difference(a: bytes, b: bytes, suffix: str) -> str | None:
    """None if the two files' contents are equal for comparison, else where they first differ."""
    if a == b:
        return None
    if suffix == ".json":
        try:
            ja, jb = drop_varying(json.loads(a)), drop_varying(json.loads(b))
        except ValueError:
            ja = jb = None
        if ja is not None and ja == jb:
            return None
        a = json.dumps(ja, indent=1, sort_keys=True).encode() if ja is not None else a
        b = json.dumps(jb, indent=1, sort_keys=True).encode() if jb is not None else b
    if suffix in (".csv", ".json"):
        la, lb = csv_lines(a.decode(errors="replace")), csv_lines(b.decode(errors="replace"))
        for n, (x, y) in enumerate(zip(la, lb), start=1):
            if x != y:
                return f"line {n}: " + first_field(x, y, la[0] if suffix == ".csv" else "")
        if len(la) == len(lb):
            return None
        return f"line {min(len(la), len(lb)) + 1}: one file ends ({len(la)} vs {len(lb)} lines)"
    offset = next((i for i, (x, y) in enumerate(zip(a, b)) if x != y), min(len(a), len(b)))
    return f"byte offset {offset}"


def compare_dirs(old: Path, new: Path) -> str | None:
    """None if both folders hold the same files with equal contents, else the first difference."""
    files_old = {p.relative_to(old) for p in old.rglob("*") if p.is_file()}
    files_new = {p.relative_to(new) for p in new.rglob("*") if p.is_file()}
    for rel in sorted(files_old ^ files_new):
        return f"{rel} only on the {'old' if rel in files_old else 'new'} side"
    for rel in sorted(files_old):
        where = first_difference((old / rel).read_bytes(), (new / rel).read_bytes(), rel.suffix)
        if where:
            return f"{rel}: {where}"
    return None


def run(tree: Path, args: list[str], cwd: Path | None = None) -> str | None:
    """Runs python ARGS with TREE's package first on the path; None if it succeeded, else why."""
    env = {**os.environ, "PYTHONPATH": str(tree), "MPLBACKEND": "Agg"}
    try:
        done = subprocess.run([sys.executable, *args], cwd=cwd or tree, env=env, text=True,
                              capture_output=True, timeout=TIMEOUT)  # fmt: skip
    except subprocess.TimeoutExpired:
        return f"timed out after {TIMEOUT:g} s"
    if done.returncode == 0:
        return None
    last = (done.stderr.strip() or done.stdout.strip() or "no output").splitlines()[-1]
    return f"exit status {done.returncode}: {last[:120]}"


def output_complete(csv: Path, stop: float) -> bool:
    """Whether an fmpy result file exists and its last row is at the stop time."""
    try:
        last = csv.read_text().rstrip().splitlines()[-1]
        return abs(float(last.split(",")[0]) - stop) <= 1e-9 * max(1.0, stop)
    except (OSError, IndexError, ValueError):
        return False


def has_cosimulation(fmu: Path) -> bool:
    """Whether the FMU's modelDescription.xml declares the co-simulation interface."""
    with zipfile.ZipFile(fmu) as archive:
        return b"<CoSimulation" in archive.read("modelDescription.xml")


def skip_reason(rel: str, fmu: Path) -> str | None:
    """Why this FMU is not simulated alone, or None."""
    name = Path(rel).name
    if name.startswith("Bridge"):
        return "needs a robot process (impedance-cosim robot) behind the bridge"
    package = NEEDS_PACKAGE.get(name)
    if package and importlib.util.find_spec(package) is None:
        return f"the {package} package is not installed"
    if not has_cosimulation(fmu):
        return "no co-simulation interface (scheduled execution only)"
    return None


def collect(fmus: Path) -> tuple[list[str], list[str]]:
    """The FMUs (in FMU_DIRS) and system archives a build wrote, relative to its folder."""
    found = [p for d in FMU_DIRS for p in sorted((fmus / d).glob("*.fmu"))]
    return [p.relative_to(fmus).as_posix() for p in found], sorted(
        p.relative_to(fmus).as_posix() for p in fmus.rglob("*.ssp")
    )


def items(fmus: Path, stop: float, fmusim: str | None) -> list[tuple[str, str, list[str]]]:
    """The items to run on each side: (name, kind, arguments), kind 'fmpy', 'fmusim',
    'cli' or 'skip' (arguments then hold the reason)."""
    t = f"{stop:g}"
    fmu_list, ssp_list = collect(fmus)
    plan: list[tuple[str, str, list[str]]] = []
    for rel in fmu_list:
        reason = skip_reason(rel, fmus / rel)
        plan.append((f"fmpy {rel}", "skip", [reason]) if reason else (f"fmpy {rel}", "fmpy", [rel]))
    quiet = ["--no-report", "--no-progress"]
    for rel in ssp_list:
        args = ["run", "--ssp", rel, "--stop", t, "--no-figures", *quiet]
        plan.append((f"run --ssp {rel}", "cli", args))
    plan.append(
        (
            "run (default scenario)",
            "cli",
            ["run", "--ssp", "PaperScenario.ssp", "--stop", t, "--no-figures", *quiet],
        )
    )
    plan.append(
        (
            "sweep --grid controller.K=25,50",
            "cli",
            [
                "sweep",
                "--ssp",
                "PaperScenario-native.ssp",
                "--stop",
                t,
                "--grid",
                "controller.K=25,50",
                "--serial",
                "--no-plots",
                *quiet,
            ],
        )
    )
    whole = f"{max(1, math.ceil(stop))}"  # stability takes whole seconds only
    plan.append((f"stability linear --sensor ideal --stop {whole}", "cli",
                 ["stability", "linear", "--ssp", "PaperScenario-native.ssp", "--sensor", "ideal",
                  "--stop", whole, "--serial", "--no-figures", *quiet]))  # fmt: skip
    native = [r for r in fmu_list if r.startswith(("native/", "fmi3/")) and "python" not in r]
    if not fmusim:
        plan.append(("fmusim", "skip", ["not found; set IMPCOSIM_FMUSIM=/path/to/fmusim"]))
    for rel in native if fmusim else []:
        if has_cosimulation(fmus / rel):
            plan.append((f"fmusim {rel}", "fmusim", [rel]))
        else:
            plan.append((f"fmusim {rel}", "skip", ["no co-simulation interface"]))
    return plan


def produce(tree: Path, fmus: Path, out: Path, kind: str, args: list[str], stop: float,
            fmusim: str | None) -> str | None:  # fmt: skip
    """Runs one item on one side into OUT; None if it succeeded, else why not."""
    out.mkdir(parents=True)
    if kind == "cli":
        args = [str(fmus / a) if a.endswith(".ssp") else a for a in args]
        return run(tree, ["-m", "impedance_cosim", *args, "--out", str(out)])
    csv = out / "out.csv"
    t = f"{stop:g}"
    if kind == "fmpy":
        command = ["-c", FMPY, "simulate", str(fmus / args[0]), "--stop-time", t,
                   "--interface-type", "CoSimulation", "--output-file", str(csv)]  # fmt: skip
        error = run(tree, command, cwd=out)
    else:
        command = [str(fmusim), "--stop-time", t, "--output-file", str(csv), str(fmus / args[0])]
        done = subprocess.run(command, cwd=out, capture_output=True, text=True, timeout=TIMEOUT)
        error = None if done.returncode == 0 else f"exit status {done.returncode}"
    # pythonfmu's library may abort at exit after a complete run: the file is what counts
    return None if output_complete(csv, stop) else error or "incomplete output file"


def verdict(old_error: str | None, new_error: str | None, old: Path, new: Path) -> str:
    """The item's line: equal, DIFFERENT (where) or failed (why)."""
    if old_error or new_error:
        sides = [f"{s}: {e}" for s, e in (("old", old_error), ("new", new_error)) if e]
        return "failed (" + "; ".join(sides) + ")"
    where = compare_dirs(old, new)
    return "equal" if where is None else f"DIFFERENT ({where})"


def git(*args: str) -> subprocess.CompletedProcess[str]:
    """git in this checkout, its output captured."""
    return subprocess.run(["git", "-C", str(HERE), *args], capture_output=True, text=True)


def resolve(commit: str) -> str:
    """The commit's full hash; ArgumentError if git does not know it."""
    done = git("rev-parse", "--verify", "--quiet", f"{commit}^{{commit}}")
    if done.returncode != 0 or not done.stdout.strip():
        raise ArgumentError(f"unknown commit: {commit}")
    return done.stdout.strip()


def parse(argv: list[str] | None) -> argparse.Namespace:
    """The command line; ArgumentError (one line) for a bad one."""
    parser = Parser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("old", help="the commit before the refactoring")
    parser.add_argument("new", nargs="?", help="the commit after it (default: the working tree)")
    parser.add_argument("--stop", type=float, default=2.0, help="stop time [s] (default 2)")
    args = parser.parse_args(argv)
    if not args.stop > 0:
        raise ArgumentError(f"--stop must be positive, not {args.stop:g}")
    return args


def build_side(tree: Path, fmus: Path) -> str | None:
    """Builds the side's FMUs and archives into FMUS; None if it worked, else why not."""
    return run(tree, ["-m", "impedance_cosim", "build", "--out", str(fmus)])


def compare(trees: dict[str, Path], tmp: Path, stop: float, fmusim: str | None) -> list[str]:
    """Builds both sides, runs every item on each and prints one line per item; the verdicts."""
    for side, tree in trees.items():
        error = build_side(tree, tmp / side / "fmus")
        if error:
            print(f"build ({side}): failed ({error})", flush=True)
            return ["failed"]
    plan = items(tmp / "new" / "fmus", stop, fmusim)
    names = {name for name, _, _ in items(tmp / "old" / "fmus", stop, fmusim)}
    verdicts = []
    for number, (name, kind, args) in enumerate(plan):
        if kind == "skip":
            line = f"skipped: {args[0]}"
        elif name not in names:
            line = "new: only built on the new side, nothing to compare"
        else:
            out = {s: tmp / s / "out" / str(number) for s in trees}
            errors = {s: produce(trees[s], tmp / s / "fmus", out[s], kind, args, stop, fmusim)
                      for s in trees}  # fmt: skip
            line = verdict(errors["old"], errors["new"], out["old"], out["new"])
        print(f"{name}: {line}", flush=True)
        verdicts.append(line.split(" ")[0].rstrip(":"))
    for name in sorted(names - {name for name, _, _ in plan}):
        print(f"{name}: DIFFERENT (only built on the old side)", flush=True)
        verdicts.append("DIFFERENT")
    return verdicts


class Terminated(KeyboardInterrupt):
    """SIGTERM, handled as Ctrl-C (the worktrees are removed) but with exit status 143."""


def interrupted(signum: int, frame: object) -> None:
    """The SIGTERM handler: raises Terminated."""
    raise Terminated


def main(argv: list[str] | None = None) -> int:
    """The command: 0 all compared items equal, 1 otherwise, 2 bad arguments."""
    try:
        args = parse(argv)
        old = resolve(args.old)
        new = resolve(args.new) if args.new else None
    except ArgumentError as error:
        print(f"outputs_equal: {error}", file=sys.stderr)
        return 2
    fmusim = os.environ.get("IMPCOSIM_FMUSIM") or shutil.which("fmusim")
    signal.signal(signal.SIGTERM, interrupted)
    added: list[Path] = []
    with tempfile.TemporaryDirectory(prefix="impcosim_outputs_") as name:
        tmp = Path(name)
        try:
            trees = {"old": tmp / "old" / "tree", "new": tmp / "new" / "tree"}
            for side, commit in (("old", old), ("new", new)):
                if commit is None:
                    trees[side] = HERE
                    continue
                done = git("worktree", "add", "--detach", "-q", str(trees[side]), commit)
                added.append(trees[side])
                if done.returncode != 0:
                    raise RuntimeError(f"git worktree add {commit}: {done.stderr.strip()}")
            new_name = f"{args.new} ({new[:9]})" if new else "the working tree"
            print(f"old {args.old} ({old[:9]}), new {new_name}, stop {args.stop:g} s", flush=True)
            verdicts = compare(trees, tmp, args.stop, fmusim)
        except KeyboardInterrupt as stop:
            print("interrupted", file=sys.stderr)
            return 143 if isinstance(stop, Terminated) else 130
        except RuntimeError as error:
            print(f"outputs_equal: {error}", file=sys.stderr)
            return 1
        finally:
            for tree in added:
                git("worktree", "remove", "--force", str(tree))
    counts = {v: verdicts.count(v) for v in ("equal", "DIFFERENT", "failed", "skipped", "new")}
    print(", ".join(f"{n} {v.lower()}" for v, n in counts.items()))
    return 0 if counts["DIFFERENT"] == counts["failed"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
