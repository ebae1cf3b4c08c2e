"""How long the test tiers take and how much of the full suite's coverage the fast tier keeps
(docs/development.md's table).

    python benchmarks/test_tiers.py [--tiers fast,full,coverage] [--workers 2] [--busy 0]

- fast: `python -m pytest -m "not slow" -n W`, wall time and test count;
- full: `python -m pytest -n W`, the same (IMPCOSIM_REQUIRE_PLATFORMS as set by the caller);
- coverage: both tiers again under coverage.py (every Python process they start, the CLI
  subprocesses included: coverage's subprocess patch), and the share of the lines the full
  suite executes that the fast tier executes too, over impedance_cosim and the model packages.
--busy N starts N processes that each keep a core busy for the whole measurement (the "under
load" rows). The build cache (.cache/build) is warmed by one build first, so the fast tier is
timed as a developer meets it; a cold cache adds one compile of every library (about a minute,
`time impedance-cosim build` on an empty cache)."""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SOURCES = ["impedance_cosim", "plant_model", "controller_model", "bridge_model"]
BUSY = "while True: pass"


def pytest(args: list[str], env: dict[str, str] | None = None) -> tuple[float, str]:
    """Run pytest with args in the checkout; wall seconds and its summary line."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args],
                          cwd=REPO, capture_output=True, text=True, env=env)  # fmt: skip
    seconds = time.perf_counter() - start
    summary = done.stdout.strip().splitlines()[-1] if done.stdout.strip() else done.stderr[-300:]
    if done.returncode != 0:
        print(done.stdout[-3000:], file=sys.stderr)
    return seconds, re.sub(r"=+", "", summary).strip()


def covered(args: list[str], data: Path) -> dict[str, set[int]]:
    """Lines executed (per file) by pytest args under coverage, every subprocess included."""
    rc = data.parent / f"{data.name}.rc"
    rc.write_text(
        "[run]\nparallel = true\npatch = subprocess\n"
        f"data_file = {data}\nsource = {','.join(str(REPO / s) for s in SOURCES)}\n"
    )
    env = {**os.environ, "COVERAGE_RCFILE": str(rc)}
    cmd = [sys.executable, "-m", "coverage", "run", f"--rcfile={rc}", "-m", "pytest", "-q",
           "-p", "no:cacheprovider", *args]  # fmt: skip
    done = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True)
    if done.returncode != 0:  # the share would be of a broken run: say so
        print(f"coverage run {' '.join(args)} failed:\n{done.stdout[-3000:]}{done.stderr[-3000:]}",
              file=sys.stderr)  # fmt: skip
    subprocess.run([sys.executable, "-m", "coverage", "combine", f"--rcfile={rc}"], cwd=REPO,
                   env=env, capture_output=True, text=True)  # fmt: skip
    return lines_of(data)


def lines_of(data: Path) -> dict[str, set[int]]:
    """The executed lines per file of a combined coverage data file."""
    import coverage

    cov = coverage.Coverage(data_file=str(data))
    cov.load()
    lines = cov.get_data()
    return {f: set(lines.lines(f) or ()) for f in lines.measured_files()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tiers", default="fast,full,coverage")
    parser.add_argument("--workers", default="2", help="pytest-xdist -n (0: one process)")
    parser.add_argument("--busy", type=int, default=0, help="busy processes beside the tests")
    parser.add_argument("--data", default=None, help="keep the coverage data in this folder and"
                        " reuse a full-suite measurement found there")  # fmt: skip
    args = parser.parse_args()
    tiers = args.tiers.split(",")
    xdist = ["-n", args.workers] if args.workers != "0" else []
    cache = {**os.environ, "IMPCOSIM_BUILD_CACHE": str(REPO / ".cache" / "build")}
    build = [sys.executable, "-m", "impedance_cosim", "build", "--out", tempfile.mkdtemp()]
    subprocess.run(build, cwd=REPO, capture_output=True, env=cache)
    busy = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(args.busy)]
    try:
        print(f"workers {args.workers}, busy processes {args.busy}, {os.cpu_count()} cores")
        if "fast" in tiers:
            seconds, summary = pytest(["-m", "not slow", *xdist])
            print(f"fast tier: {seconds:.0f} s ({summary})")
        if "full" in tiers:
            seconds, summary = pytest(xdist)
            print(f"full suite: {seconds:.0f} s ({summary})")
        if "coverage" in tiers:
            with tempfile.TemporaryDirectory() as tmp:
                folder = Path(args.data or tmp)
                folder.mkdir(parents=True, exist_ok=True)
                fast = covered(["-m", "not slow", *xdist], folder / "fast")
                reuse = args.data is not None and (folder / "full").is_file()
                full = lines_of(folder / "full") if reuse else covered(xdist, folder / "full")
            total = sum(len(v) for v in full.values())
            kept = sum(len(v & fast.get(f, set())) for f, v in full.items())
            unseen = sorted(Path(f).relative_to(REPO).as_posix() for f in full
                            if full[f] and not fast.get(f))  # fmt: skip
            print(
                f"fast tier covers {kept} of the {total} lines the full suite covers:"
                f" {100 * kept / total:.1f} %"
            )
            print(f"modules the full suite runs and the fast tier does not: {unseen or 'none'}")
    finally:
        for p in busy:
            p.kill()


if __name__ == "__main__":
    main()
