"""Coverage-guided fuzzing of the inputs that come from outside (fuzz/, docs/failures.md).

    python benchmarks/fuzz.py --minutes N [--targets a,b] [--update-corpus]

Runs every target (or those named) for N minutes EACH (N may be a fraction: 0.25 is 15 s), one
after the other, nice'd (--nice), starting from its committed corpus fuzz/corpus/<target>/
(seeded with a few valid inputs when empty). C targets are libFuzzer binaries (clang
-fsanitize=fuzzer,address,undefined) built from the native FMUs' shipped sources; Python targets
run under atheris. Prints per target: executions, edges (libFuzzer's cov:) and features (ft:),
and findings (crash, leak, timeout and out-of-memory files, kept in the work folder, default
/tmp/impcosim-fuzz; see IMPCOSIM_FUZZ_WORK). --update-corpus merges what was found into the
committed corpus, minimized with libFuzzer's -merge=1 (by edges: -use_counters=0). Exits 1 when
there are findings."""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fuzz"))
import targets  # noqa: E402

FLAGS = ["-timeout=30", "-rss_limit_mb=2048", "-print_final_stats=1", "-max_len=16384"]


_BUILT: dict[str, Path] = {}


def command(name: str, work: Path) -> list[str]:
    if name in targets.C_TARGETS:
        if name not in _BUILT:  # once per invocation (a few seconds each)
            fmus = targets.build_fmus(work / "fmus")
            _BUILT[name] = targets.build_c(name, fmus, work / "build", libfuzzer=True)
        return [str(_BUILT[name])]
    return [sys.executable, str(targets.FUZZ / "py" / f"{name}.py")]


def stats(log: str) -> dict[str, str]:
    found = {"execs": "?", "cov": "?", "ft": "?"}
    for m in re.finditer(r"cov: (\d+) ft: (\d+)", log):
        found["cov"], found["ft"] = m.groups()
    m = re.search(r"stat::number_of_executed_units: (\d+)", log)
    if m:
        found["execs"] = m.group(1)
    return found


def run(
    name: str, seconds: int, work: Path, update: bool, niceness: int = 10
) -> tuple[dict[str, str], list[Path]]:
    committed = targets.CORPUS / name
    if not targets.corpus(name):
        targets.write_seeds(name, committed, work)
    live = work / "corpus" / name
    findings = work / "findings" / name
    live.mkdir(parents=True, exist_ok=True)
    findings.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, IMPCOSIM_FUZZ_FMUS=str(targets.build_fmus(work / "fmus")))
    earlier = set(findings.iterdir())  # findings of earlier runs stay, and are not counted
    cmd = ["nice", "-n", str(niceness), *command(name, work), str(live), str(committed), *FLAGS]
    cmd += [f"-max_total_time={seconds}", f"-artifact_prefix={findings}/"]
    done = subprocess.run(cmd, capture_output=True, text=True, env=env)
    (work / f"{name}.log").write_text(done.stdout + done.stderr)
    crashes = sorted(p for p in findings.iterdir() if p.is_file() and p not in earlier)
    if update and not crashes:  # a merge would drop the inputs that crash: fix them first
        merged = work / "merged" / name
        shutil.rmtree(merged, ignore_errors=True)
        merged.mkdir(parents=True)
        merge = ["-merge=1", "-use_counters=0"]  # by edges alone: a few dozen files a target
        subprocess.run([*command(name, work), *merge, str(merged), str(committed), str(live)],
                       capture_output=True, env=env, check=True, cwd=work)  # fmt: skip
        if any(merged.iterdir()):  # an empty merge (a failed child) never wipes the corpus
            shutil.rmtree(committed)
            shutil.copytree(merged, committed)
    return stats(done.stdout + done.stderr), crashes


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, required=True, help="per target")
    parser.add_argument("--targets", help="comma-separated (default: all)")
    parser.add_argument("--update-corpus", action="store_true")
    parser.add_argument("--nice", type=int, default=10, help="niceness of the fuzzers (default"
                        " 10: beside other work; 0: as busy as anything else)")  # fmt: skip
    args = parser.parse_args()
    every = [*targets.C_TARGETS, *targets.PY_TARGETS]
    names = args.targets.split(",") if args.targets else every
    unknown = [n for n in names if n not in every]
    if unknown:
        parser.error(f"unknown targets {unknown} (have {every})")
    if any(n in targets.C_TARGETS for n in names) and not targets.clang():
        parser.error("the C targets need clang (apt-get install clang libclang-rt-14-dev)")
    work = targets.work_dir()
    seconds = max(1, round(args.minutes * 60))
    print(f"{'target':24} {'executions':>11} {'edges':>6} {'features':>8}  findings")
    total = 0
    for name in names:
        found, crashes = run(name, seconds, work, args.update_corpus, args.nice)
        total += len(crashes)
        print(f"{name:24} {found['execs']:>11} {found['cov']:>6} {found['ft']:>8}  "
              f"{len(crashes)} {' '.join(str(p) for p in crashes)}", flush=True)  # fmt: skip
    return 1 if total else 0


if __name__ == "__main__":
    sys.exit(main())
