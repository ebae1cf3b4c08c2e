"""The distribution bundle's size and build time as measured (not a test: prints numbers): every
FMU and system archive built from scratch into a temporary folder and zipped, as
`impedance-cosim dist` does, a few times; the size of the bundle and of each group of members.

    python benchmarks/dist_bundle.py              # 3 builds (~1-2 min on 2 idle cores)
    python benchmarks/dist_bundle.py --repeat 1
"""

from __future__ import annotations

import argparse
import tempfile
import time
import zipfile
from pathlib import Path

from impedance_cosim.packaging.dist import NAME, build_dist


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="builds to time (default 3)")
    measure(parser.parse_args().repeat)


def measure(repeat: int) -> None:
    """Build and bundle `repeat` times from scratch; print the bundle's size and the times."""
    times = []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory(prefix="impcosim_dist_bench_") as tmp:
            start = time.perf_counter()
            path = build_dist(Path(tmp) / "dist", Path(tmp) / "fmus")
            times.append(time.perf_counter() - start)
            size = path.stat().st_size
            groups: dict[str, list[int]] = {}
            with zipfile.ZipFile(path) as z:
                for info in z.infolist():
                    parts = info.filename.removeprefix(f"{NAME}/").split("/")
                    group = "/".join(parts[:-1]) or "(top)"
                    groups.setdefault(group, []).append(info.compress_size)
    print(f"{NAME}.zip: {size / 1e6:.2f} MB ({size} bytes)")
    for group, sizes in sorted(groups.items()):
        print(f"  {group:22} {len(sizes):3} files {sum(sizes) / 1e6:7.2f} MB compressed")
    print(f"build + bundle from scratch: best {min(times):.1f} s, median "
          f"{sorted(times)[len(times) // 2]:.1f} s of {len(times)}")  # fmt: skip


if __name__ == "__main__":
    main()
