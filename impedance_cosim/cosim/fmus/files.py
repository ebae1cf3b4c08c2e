"""FMU files: an archive checked (archive.py: the limits every archive shares) before anything
reads it, its integrity and binary checked, its model description read once per file version,
and the extraction folders shared by the instances of one FMU file (fmu.py)."""

from __future__ import annotations

import atexit
import shutil
import tempfile
import threading
import zipfile
from functools import lru_cache
from pathlib import Path
from typing import Any

from fmpy import platform, platform_tuple, read_model_description, sharedLibraryExtension

from impedance_cosim.cosim.archive import (
    DEFAULT_LIMITS,
    ArchiveError,
    check_archive,
    checked,
    unpack,
)

EXTRACT_PREFIX = "impcosim_fmu_"  # extraction folders in the temporary directory
DESCRIPTION = "modelDescription.xml"


class FmuError(RuntimeError):
    """An FMI call failed; the message carries the FMU's own log messages."""


class FmuArchiveError(FmuError, ArchiveError):
    """An FMU file is not a safe, readable archive: bad input (a ValueError too, so the commands
    exit 2), found before anything reads or extracts a member."""


def check_fmu_archive(fmu: Path, where: str | None = None) -> None:
    """FmuArchiveError naming the FMU (`where`, default its file name) and the member unless the
    archive passes the checks every archive gets (archive.check_archive: count, names, links,
    sizes) and has a modelDescription.xml of at most the XML limit (checked once per version)."""
    st = fmu.stat()
    problem = _header_problem(str(fmu), st.st_mtime_ns, st.st_size, where or fmu.name)
    if problem:
        raise FmuArchiveError(problem)


@lru_cache(maxsize=256)
def _header_problem(fmu: str, _mtime_ns: int, _size: int, where: str) -> str | None:
    try:
        files = check_archive(Path(fmu), where, DEFAULT_LIMITS, kind="an FMU archive")
    except ArchiveError as exc:
        return str(exc)
    info = next((f for f in files if f.filename == DESCRIPTION), None)
    if info is None:
        return f"{where} has no {DESCRIPTION}"
    if info.file_size > DEFAULT_LIMITS.xml_bytes:
        return (f"{where}: member {DESCRIPTION!r} unpacks to {info.file_size} bytes"
                f" (limit {DEFAULT_LIMITS.xml_bytes})")  # fmt: skip
    return None


def check_fmu(fmu: Path, description: Any) -> None:
    """FmuError naming the problem unless the archive is intact (every member's CRC) and has a
    binary for this platform (checked once per file version)."""
    # an FMI 3.0 Scheduled Execution FMU (a clocked model) runs as co-simulation (fmu3.py)
    interface = description.coSimulation or getattr(description, "scheduledExecution", None)
    if interface is None:
        raise FmuError(f"{fmu.name} is not a co-simulation FMU")
    folder = platform_tuple if str(description.fmiVersion).startswith("3") else platform
    binary = f"binaries/{folder}/{interface.modelIdentifier}"
    check_fmu_archive(fmu)
    st = fmu.stat()
    problem = _archive_problem(str(fmu), st.st_mtime_ns, st.st_size, binary)
    if problem:
        raise FmuError(problem)


@lru_cache(maxsize=256)
def _archive_problem(fmu: str, _mtime_ns: int, _size: int, binary: str) -> str | None:
    name = Path(fmu).name
    try:  # the archive passed check_fmu_archive: testzip reads at most the sizes it allows
        with checked(Path(fmu), name, DEFAULT_LIMITS, kind="an FMU archive") as (z, files):
            bad = z.testzip()
            names = {f.filename for f in files}
    except ArchiveError as exc:
        return str(exc)
    except (zipfile.BadZipFile, OSError, EOFError, RuntimeError) as exc:
        return f"{name} is not a readable FMU archive ({exc})"
    if bad is not None:
        return f"{name}: archive member {bad} is corrupt (CRC check failed)"
    if binary + sharedLibraryExtension not in names:
        have = sorted(
            {n.split("/")[1] for n in names if n.count("/") >= 2 and n[:9] == "binaries/"}
        )
        return (
            f"{name} has no binary for this platform ({binary}{sharedLibraryExtension}; "
            f"binaries for: {', '.join(have) or 'none'})"
        )
    return None


def model_description(fmu: Path) -> Any:
    """fmpy's model description of an FMU file, read once per file version after the archive
    checks (parsing costs ~5 ms: a sweep's runs share it; treat it as read-only)."""
    check_fmu_archive(fmu)
    st = fmu.stat()
    return _description(str(fmu), st.st_mtime_ns, st.st_size)


@lru_cache(maxsize=64)
def _description(fmu: str, _mtime_ns: int, _size: int) -> Any:
    return read_model_description(fmu)


def needed_to_run(member: str) -> bool:
    """Whether an FMU's member is extracted to run it: its modelDescription.xml, resources/ and
    this platform's binaries (not the sources, documentation or other platforms' binaries:
    writing those cost ~40 ms per run on the native FMUs)."""
    return member == DESCRIPTION or member.startswith(
        ("resources/", f"binaries/{platform}/", f"binaries/{platform_tuple}/")
    )


class Extractions:
    """fmpy's extraction folders, one per FMU file version, shared by its instances for the life
    of the process (extracting again for every run cost ~0.1 s per run). A folder is removed at
    exit, or earlier once no instance uses it and its FMU file has gone or changed (e.g. the
    temporary folder of a system archive was removed)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._entries: dict[tuple, list] = {}  # (path, mtime_ns, size) -> [description, dir, users]

    def acquire(self, fmu: Path) -> tuple[tuple, Any, str]:
        """(key for release, model description, extraction folder) of an FMU file, checked and
        extracted on first use (FmuArchiveError for an unsafe archive, FmuError otherwise)."""
        st = fmu.stat()
        key = (fmu, st.st_mtime_ns, st.st_size)
        with self._lock:
            self._prune()
            entry = self._entries.get(key)
            if entry is None:
                check_fmu_archive(fmu)
                try:  # parsed once per file version (shared with the master's checks)
                    description = _description(str(fmu), st.st_mtime_ns, st.st_size)
                except Exception as exc:  # fmpy raises bare Exceptions
                    raise FmuError(f"{fmu.name}: invalid modelDescription.xml ({exc})") from None
                check_fmu(fmu, description)
                folder = tempfile.mkdtemp(prefix=EXTRACT_PREFIX)
                try:  # the bytes unpacked are counted against the limits again
                    unpack(fmu, Path(folder), fmu.name, DEFAULT_LIMITS, kind="an FMU archive",
                           wanted=needed_to_run)  # fmt: skip
                except ArchiveError as exc:
                    shutil.rmtree(folder, ignore_errors=True)
                    raise FmuArchiveError(str(exc)) from None
                except BaseException:
                    shutil.rmtree(folder, ignore_errors=True)
                    raise
                entry = self._entries[key] = [description, folder, 0]
            entry[2] += 1
            return key, entry[0], entry[1]

    def release(self, key: tuple) -> None:
        with self._lock:
            if key in self._entries:
                self._entries[key][2] -= 1

    def _prune(self) -> None:
        for key, (_, folder, users) in list(self._entries.items()):
            try:
                st = key[0].stat()
                current = (st.st_mtime_ns, st.st_size) == key[1:]
            except OSError:
                current = False
            if users <= 0 and not current:
                del self._entries[key]
                shutil.rmtree(folder, ignore_errors=True)

    def clear(self) -> None:
        with self._lock:
            for _, folder, _ in self._entries.values():
                shutil.rmtree(folder, ignore_errors=True)
            self._entries.clear()


extractions = Extractions()
atexit.register(extractions.clear)
