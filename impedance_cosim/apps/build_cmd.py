"""`impedance-cosim build`, and the build before a run: the FMUs and system archives built
when they are missing or older than what they are built from."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from impedance_cosim.apps.options import PACKAGED_FMUS, REPO, check_out, prepare_out

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
    sources = [core / "packaging" / "build.py", core / "cosim" / "system" / "paper.py"]
    sources += [
        core / "packaging" / "build_ssp2.py",
        core / "cosim" / "system" / "ssp2.py",
    ]  # SSP 2.0
    sources += [core / item for item in FMU_CORE]
    sources += [REPO / spec.package for spec in FMUS.values()] + [REPO / "ssp"]
    files = [f for s in sources for f in ([s] if s.is_file() else s.rglob("*"))]
    built = target.stat().st_mtime
    suffixes = (".py", ".ssd", ".ssv", ".html", ".txt")  # .html, .txt: a model's documentation
    return any(f.suffix in suffixes and f.stat().st_mtime > built for f in files)


def ensure_built(args: argparse.Namespace, ssp: Path) -> None:
    """Build the default system archive (and its FMUs) when no --ssp was given and it is stale;
    the ones an installed wheel carries (PACKAGED_FMUS) are used as they are."""
    if not args.ssp and ssp.parent != PACKAGED_FMUS and stale(ssp):
        from impedance_cosim.util.atomic import FolderLock

        with FolderLock(prepare_out(ssp.parent), "build folder", wait=BUILD_WAIT_S):
            if stale(ssp):  # not built meanwhile by another process
                _first_build(ssp.parent)


def _first_build(out: Path) -> None:
    """The build before a first run: one line before and one after (`build` lists each file)."""
    from impedance_cosim.packaging.build_all import build_all

    print(f"building the FMUs and system archives into {out} (once) ...", file=sys.stderr,
          flush=True)  # fmt: skip
    started = time.perf_counter()
    built = build_all(out)
    print(f"built {len(built)} FMUs and archives in {time.perf_counter() - started:.0f} s",
          file=sys.stderr)  # fmt: skip
