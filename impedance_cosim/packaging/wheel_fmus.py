"""The built FMUs and system archives that the wheel carries as package data
(impedance_cosim/_fmus): which files of a build folder they are, the check that the folder is a
complete and current build, and the copy. Standard library only: setup.py loads this file by its
path while building the wheel, in an environment that has none of the package's dependencies."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

SUFFIXES = (".fmu", ".ssp")
ROBOT = "robot"  # the arm's URDF and MJCF (small text files)
# What a complete build has (build_all with a C compiler): without them the wheel is refused.
REQUIRED = ("PaperScenario.ssp", "PaperScenario-native.ssp", "native/PumaPlant.fmu", "fmi3")
# What the archives are built from (a superset of what build_cmd.stale checks: also the C sources
# and the whole build code); the commands (apps) are not in the FMUs.
SOURCES = (
    *(f"impedance_cosim/{name}" for name in ("__init__.py", "version.py", "physics", "fmi")),
    "impedance_cosim/cosim/system",
    "impedance_cosim/packaging",
    *("plant_model", "controller_model", "bridge_model", "native", "ssp"),
)
SOURCE_SUFFIXES = (".py", ".c", ".h", ".ssd", ".ssv", ".html", ".txt")  # .html, .txt: model docs
THIS = Path(__file__).name  # this file decides what goes into the wheel, not what is built


class NotBuiltError(Exception):
    """The build folder is missing, incomplete or older than its sources."""


def archive_files(folder: Path) -> list[str]:
    """The FMUs, system archives and robot files under folder, as sorted relative POSIX paths;
    hidden files and folders (a build's staging folder, locks) are left out."""
    folder = Path(folder)
    found = []
    for path in folder.rglob("*"):
        rel = path.relative_to(folder)
        if not path.is_file() or any(part.startswith(".") for part in rel.parts):
            continue
        if path.suffix in SUFFIXES or rel.parts[0] == ROBOT:
            found.append(rel.as_posix())
    return sorted(found)


def check_built(folder: Path, repo: Path) -> list[str]:
    """archive_files(folder), after checking it holds a complete build that is newer than every
    source file in repo (NotBuiltError otherwise, saying what to run)."""
    folder = Path(folder)
    hint = f"run `impedance-cosim build --out {folder}` first"
    missing = [name for name in REQUIRED if not (folder / name).exists()]
    if missing:
        raise NotBuiltError(f"{folder} is not a complete build (no {', '.join(missing)}): {hint}")
    files = archive_files(folder)
    oldest = min((folder / name).stat().st_mtime for name in files)
    for source in SOURCES:
        top = Path(repo) / source
        for path in [top] if top.is_file() else top.rglob("*"):
            if path.name == THIS or path.suffix not in SOURCE_SUFFIXES:
                continue
            if path.stat().st_mtime > oldest:
                raise NotBuiltError(f"{folder} is older than {path}: {hint}")
    return files


def copy_files(src: Path, dst: Path, names: list[str]) -> None:
    """Copy src/name to dst/name for each name (folders made as needed), bytes unchanged; each
    file is written beside its target and renamed into place."""
    for name in names:
        target = Path(dst) / name
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
        try:
            shutil.copyfile(Path(src) / name, tmp)
            os.replace(tmp, target)
        finally:
            tmp.unlink(missing_ok=True)
