"""Build everything: the Python FMUs, the native FMUs (when a C compiler is present), the system
archives per scenario, the FMI 3.0 edition and the arm's robot description files (robot/).
Above build and build_fmi3, so neither imports the other's caller."""

from __future__ import annotations

import contextlib
import os
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

from impedance_cosim.packaging import toolchains
from impedance_cosim.packaging.archive_out import ArchiveWriteError
from impedance_cosim.packaging.build import (
    DEFAULT_OUT,
    FMUS,
    NATIVE,
    build_fmu,
    build_native_fmu,
    build_ssp,
)

STAGE_PREFIX = ".impcosim-build-"  # the folder inside out_dir that a build writes first
CLOSED_LOOP = "closedloop"  # --only key: the closed-loop FMUs (packaging/closedloop.py)


def build_all(
    out_dir: Path = DEFAULT_OUT,
    only: list[str] | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[Path]:
    """Build the named FMUs (default: all, then the system archives) and return their paths.
    Everything is built into a temporary folder inside out_dir and moved into place (one
    atomic rename per file) only when all of it built: a failed or interrupted build leaves
    out_dir as it was, and concurrent builds into one folder each finish whole. progress, if
    given, is called with each file's name (relative to out_dir) as soon as it is built."""
    keys = only or list(FMUS)
    unknown = [k for k in keys if k not in FMUS and k != CLOSED_LOOP]
    if unknown:
        raise ValueError(f"unknown FMU {unknown}; choose from {sorted([*FMUS, CLOSED_LOOP])}")
    out_dir = Path(out_dir)
    created = not out_dir.exists()
    out_dir.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=STAGE_PREFIX, dir=out_dir))
    try:
        built = _build_into(stage, keys, not only, progress or (lambda name: None))
        return [_move_into_place(path, stage, out_dir) for path in built]
    except ArchiveWriteError as exc:  # name the file's final place, not the staging folder's
        shutil.rmtree(stage, ignore_errors=True)
        _remove_if_made(out_dir, created)
        target = exc.target
        if target.is_relative_to(stage):
            target = out_dir / target.relative_to(stage)
        raise exc.at(target) from None
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        _remove_if_made(out_dir, created)
        raise
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def _remove_if_made(out_dir: Path, created: bool) -> None:
    """After a failed build: remove out_dir if this build made it (it holds nothing of ours)."""
    if created:
        with contextlib.suppress(OSError):
            out_dir.rmdir()


def _move_into_place(path: Path, stage: Path, out_dir: Path) -> Path:
    """Rename a file built under stage to the same place under out_dir; its final path."""
    target = out_dir / Path(path).relative_to(stage)
    target.parent.mkdir(parents=True, exist_ok=True)
    os.replace(path, target)
    return target


def _build_into(
    out_dir: Path, keys: list[str], everything: bool, progress: Callable[[str], None]
) -> list[Path]:
    """The build itself, into out_dir (build_all's temporary folder)."""
    built: list[Path] = []

    def add(*paths: Path) -> None:
        for path in paths:
            built.append(path)
            progress(Path(path).relative_to(out_dir).as_posix())

    for k in keys:
        if k in FMUS:
            add(build_fmu(FMUS[k], out_dir))
    native = [k for k in keys if k in FMUS and (NATIVE / k / "model.c").is_file()]
    closed_loop = CLOSED_LOOP in keys
    problem = toolchains.BY_PLATFORM["linux64"].problem() if native or closed_loop else None
    if problem is not None:  # absent, or there but unable to compile: the Python FMUs still build
        linux64 = toolchains.BY_PLATFORM["linux64"]
        if linux64.available() and toolchains.require_platforms():
            raise toolchains.broken_error(linux64, problem)
        print(f"warning: no working C compiler (gcc or $CC: {problem}): the native FMUs are not"
              f" built (on Debian/Ubuntu: apt-get install {toolchains.packages(linux64)})",
              file=sys.stderr)  # fmt: skip
        if closed_loop and not everything:
            raise toolchains.CompileError(f"{problem}: the closed-loop FMUs need a C compiler")
        native = []
    for k in native:
        add(build_native_fmu(FMUS[k], Path(out_dir) / "native"))
    if everything:
        from impedance_cosim.cosim.system.paper import SCENARIOS

        flavours = [("PaperScenario", None)]
        if native:
            flavours.append(("PaperScenario-native", Path(out_dir) / "native"))
        for name, fmu_dir in flavours:
            add(build_ssp(out_dir, name, fmu_dir))
            for s in SCENARIOS:  # one archive per scenario, for engines without SSP variants
                add(build_ssp(out_dir, f"{name}-{s}", fmu_dir, scenario=s))
        if native:
            from impedance_cosim.packaging.build_fmi3 import build_fmi3  # the FMI 3.0 edition

            add(*build_fmi3(out_dir))
        from impedance_cosim.packaging.robot_files import write_robot_files  # URDF and MJCF

        add(*write_robot_files(Path(out_dir) / "robot"))
    if (everything and native) or (closed_loop and not everything):
        from impedance_cosim.packaging.closedloop import build_closed_loops  # one-FMU loops

        add(*build_closed_loops(out_dir))
    return built
