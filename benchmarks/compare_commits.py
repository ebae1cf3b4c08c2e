"""The 20 s paper scenario with the Python FMUs under our master (C loop): this checkout against
an earlier commit, side by side (not a test). Each side builds its own FMUs and runs in its own
processes (a Python FMU in a process that imported another version's package would otherwise
measure that one), alternating, so a VM that speeds up or slows down affects both alike. Prints
the best wall time of each side, the ratio, and whether the recorded results are bit-identical.

    python benchmarks/compare_commits.py 7f64ad6 [--rounds 3] [--repeat 3] [--stop 20]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent

RUN = """
import hashlib, sys, time
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.ssp.read import read_ssp
system = read_ssp(sys.argv[1])
best = None
try:
    from impedance_cosim.cosim.master.options import RunOptions
    options = {"options": RunOptions(stop_time=float(sys.argv[3]), loop="c")}
except ImportError:  # the other side is a commit before RunOptions (issue 36)
    options = {"stop_time": float(sys.argv[3]), "loop": "c"}
for _ in range(int(sys.argv[2])):
    start = time.perf_counter()
    result = Master(system, **options).run()
    best = min(best or 1e9, time.perf_counter() - start)
    assert result.ok, result.error
print(best, hashlib.sha256(result.data.tobytes()).hexdigest())
"""

BUILD = "from impedance_cosim.packaging.build_all import build_all; build_all()"


def run(tree: Path, args: list[str]) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run([sys.executable, *args], cwd=tree, env=env, capture_output=True,
                          text=True, check=True)  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("commit", help="the earlier commit (anything git rev-parse accepts)")
    parser.add_argument("--rounds", type=int, default=3, help="alternations of the two sides")
    parser.add_argument("--repeat", type=int, default=3, help="runs per process (best counts)")
    parser.add_argument("--stop", type=float, default=20.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="impcosim_compare_") as tmp:
        old = Path(tmp) / "old"
        subprocess.run(["git", "-C", str(HERE), "worktree", "add", "--detach", "-q", str(old),
                        args.commit], check=True)  # fmt: skip
        try:
            sides = {args.commit: old, "this checkout": HERE}
            for tree in sides.values():
                run(tree, ["-c", BUILD])
            best: dict[str, float] = {}
            digests: dict[str, str] = {}
            for _ in range(args.rounds):
                for name, tree in sides.items():
                    ssp = str(tree / "fmus" / "PaperScenario.ssp")
                    out = run(tree, ["-c", RUN, ssp, str(args.repeat), str(args.stop)])
                    seconds, digest = out.stdout.split()
                    best[name] = min(best.get(name, 1e9), float(seconds))
                    digests[name] = digest
        finally:
            subprocess.run(["git", "-C", str(HERE), "worktree", "remove", "--force", str(old)],
                           check=False)  # fmt: skip
    (a, ta), (b, tb) = best.items()
    print(f"{args.stop:g} s paper scenario, Python FMUs, our master (C loop), best of "
          f"{args.rounds} x {args.repeat}, load average {os.getloadavg()[0]:.1f}")  # fmt: skip
    for name, t in best.items():
        print(f"  {name:20} {t:7.3f} s  {args.stop / t:5.1f}x real time")
    print(f"  {b} is {ta / tb:.2f}x as fast; results bit-identical: {digests[a] == digests[b]}")


if __name__ == "__main__":
    main()
