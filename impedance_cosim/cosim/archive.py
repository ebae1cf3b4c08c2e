"""Safe handling of a zip archive from outside: an .ssp, an .fmu given to `swap --replace` or to
the API, an FMU inside an .ssp. Every archive the project opens goes through `checked` (before
anything reads a member: check_archive, unpack and the SSP reader use it) and is extracted only
by `extract` (through unpack or the SSP reader), with one set of limits.

An archive is hostile until checked: no absolute names, `..`, backslashes, drive letters,
symbolic links, duplicates or encrypted members; member count, member size and total size are
capped (from the headers and again from the bytes actually read, so a lying header cannot fill
the disk). Extraction creates regular files only, never follows or creates links.
"""

from __future__ import annotations

import os
import stat
import unicodedata
import zipfile
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path


class ArchiveError(ValueError):
    """An archive is unsafe or unreadable; the message names the archive and the member."""


@dataclass(frozen=True)
class Limits:
    """Caps on what one archive may unpack to (bytes are uncompressed sizes)."""

    members: int = 2000
    member_bytes: int = 256 * 2**20
    total_bytes: int = 1024 * 2**20
    xml_bytes: int = 16 * 2**20  # an XML member read into memory (.ssd, .ssv, modelDescription.xml)


DEFAULT_LIMITS = Limits()
_CHUNK = 1 << 20
_RESERVED = {"CON", "PRN", "AUX", "NUL"} | {f"{d}{i}" for d in ("COM", "LPT") for i in range(1, 10)}
_STORED_OR_DEFLATED = (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED)  # SSP 1.0 3; FMI 2.0 2.3


def name_problem(name: str) -> str | None:
    """Why a member name is unsafe or unportable, or None if it is a plain relative path."""
    if not name or name == "/":
        return "an empty name"
    if any(ord(ch) < 32 or ord(ch) == 127 for ch in name):
        return "a control character in its name"
    if "\\" in name:
        return "a backslash in its name (zip names use /)"
    if ":" in name:
        return "a drive letter or ':' in its name"
    if name.startswith("/"):
        return "an absolute name"
    if len(name) > 1024:
        return "a name longer than 1024 characters"
    for part in name.rstrip("/").split("/"):
        if part in ("", ".", ".."):
            return f"a {part!r} path component" if part else "an empty path component"
        if len(part.encode("utf-8", "surrogatepass")) > 255:
            return "a path component longer than 255 bytes"
        if part.split(".")[0].upper() in _RESERVED or part[-1] in ". ":
            return f"the name {part!r}, which Windows cannot store"
    return None


def _key(name: str) -> str:
    """Two names that would land on one file on some file system (case, Unicode form)."""
    return unicodedata.normalize("NFC", name.rstrip("/")).casefold()


def declared_members(path: Path) -> int | None:
    """The member count the end-of-central-directory record declares (zip64 included), read
    before zipfile loads the whole directory into memory; None if it cannot be read."""
    end_record = getattr(zipfile, "_EndRecData", None)  # private, guarded: only a pre-check
    try:
        with open(path, "rb") as f:
            record = end_record(f) if end_record else None
        return int(record[zipfile._ECD_ENTRIES_TOTAL]) if record else None
    except (OSError, ValueError, TypeError, IndexError, AttributeError, zipfile.BadZipFile):
        return None


def open_zip(
    path: Path, where: str, limits: Limits, kind: str = "a zip archive"
) -> zipfile.ZipFile:
    """Open a zip archive after checking its declared member count (a huge central directory
    would otherwise fill memory before any check)."""
    count = declared_members(path)
    if count is not None and count > limits.members:
        raise ArchiveError(f"{where} has {count} members (limit {limits.members})")
    try:
        return zipfile.ZipFile(path)
    except Exception as exc:  # zipfile raises several types for a damaged central directory
        raise ArchiveError(f"{where} is not {kind} (not a readable zip file: {exc})") from None


def check_members(archive: zipfile.ZipFile, where: str, limits: Limits = DEFAULT_LIMITS) -> list:
    """Every member's name, type, method and declared size is safe; returns the file members."""
    infos = archive.infolist()
    if len(infos) > limits.members:
        raise ArchiveError(f"{where} has {len(infos)} members (limit {limits.members})")
    files, seen, dirs, total = [], {}, set(), 0
    for info in infos:
        name = info.filename
        if "\0" in info.orig_filename:
            raise ArchiveError(f"{where}: member {name!r} has a NUL byte in its name")
        problem = name_problem(name)
        if problem:
            raise ArchiveError(f"{where}: member {name!r} has {problem}")
        key = _key(name)
        if key in seen:
            raise ArchiveError(f"{where}: member {name!r} appears twice (also as {seen[key]!r})")
        seen[key] = name
        kind = stat.S_IFMT(info.external_attr >> 16)
        if kind == stat.S_IFLNK:
            raise ArchiveError(f"{where}: member {name!r} is a symbolic link")
        if kind not in (0, stat.S_IFREG, stat.S_IFDIR):
            raise ArchiveError(f"{where}: member {name!r} is not a regular file or folder")
        if info.flag_bits & 0x1:
            raise ArchiveError(f"{where}: member {name!r} is encrypted (not allowed)")
        if info.compress_type not in _STORED_OR_DEFLATED:
            raise ArchiveError(
                f"{where}: member {name!r} uses compression method {info.compress_type}"
                " (SSP and FMI allow only stored or deflated)"
            )
        parts = key.split("/")
        dirs.update("/".join(parts[:i]) for i in range(1, len(parts)))
        if info.is_dir() or kind == stat.S_IFDIR:
            dirs.add(key)
            continue
        if info.file_size > limits.member_bytes:
            raise ArchiveError(
                f"{where}: member {name!r} unpacks to {info.file_size} bytes"
                f" (limit {limits.member_bytes})"
            )
        total += info.file_size
        if total > limits.total_bytes:
            raise ArchiveError(f"{where} unpacks to more than {limits.total_bytes} bytes")
        files.append(info)
    clash = [f.filename for f in files if _key(f.filename) in dirs]
    if clash:
        raise ArchiveError(f"{where}: member {clash[0]!r} is both a file and a folder")
    return files


def read_member(archive: zipfile.ZipFile, info: zipfile.ZipInfo, where: str, cap: int) -> bytes:
    """A member's bytes, read with a cap (never more than `cap` or its declared size)."""
    if info.file_size > cap:
        raise ArchiveError(
            f"{where}: member {info.filename!r} is {info.file_size} bytes (limit {cap})"
        )
    chunks, size = [], 0
    for chunk in _chunks(archive, info, where):
        size += len(chunk)
        if size > info.file_size:
            raise ArchiveError(f"{where}: member {info.filename!r} is larger than its header says")
        chunks.append(chunk)
    return b"".join(chunks)


def _chunks(archive: zipfile.ZipFile, info: zipfile.ZipInfo, where: str):
    try:
        with archive.open(info) as src:
            while chunk := src.read(_CHUNK):
                yield chunk
    except zipfile.BadZipFile as exc:
        what = "bad CRC" if "CRC" in str(exc) else str(exc)
        raise ArchiveError(f"{where}: member {info.filename!r} is corrupt ({what})") from None
    except (zlib.error, EOFError, OSError, ValueError, NotImplementedError, RuntimeError) as exc:
        raise ArchiveError(f"{where}: member {info.filename!r} is corrupt ({exc})") from None


def extract(
    archive: zipfile.ZipFile, files: list, folder: Path, where: str, limits: Limits
) -> None:
    """Write the checked members under `folder` (regular files only, no links followed, no file
    overwritten), counting the bytes actually unpacked against the caps."""
    root = folder.resolve()
    total = 0
    for info in files:
        try:
            total += _write(archive, info, root, where, limits, total)
        except OSError as exc:  # disk full, permissions, a name the file system refuses
            raise ArchiveError(
                f"{where}: cannot extract {info.filename!r}: {exc.strerror or exc}"
            ) from None


def _write(
    archive: zipfile.ZipFile, info: zipfile.ZipInfo, root: Path, where: str, limits: Limits,
    total: int,
) -> int:  # fmt: skip
    """Write one member below root; returns its size."""
    parts = info.filename.split("/")
    parent = root
    for part in parts[:-1]:
        parent = parent / part
        try:
            os.mkdir(parent, 0o700)
        except FileExistsError:
            pass
        if not stat.S_ISDIR(os.lstat(parent).st_mode):  # never walk through a link
            raise ArchiveError(f"{where}: cannot extract {info.filename!r}: {part} is not a folder")
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
    flags |= getattr(os, "O_BINARY", 0)
    size = 0
    with os.fdopen(os.open(parent / parts[-1], flags, 0o600), "wb") as out:
        for chunk in _chunks(archive, info, where):
            size += len(chunk)
            if size > info.file_size:
                raise ArchiveError(
                    f"{where}: member {info.filename!r} unpacks to more than its header says"
                    f" ({info.file_size} bytes)"
                )
            if size > limits.member_bytes:
                raise ArchiveError(
                    f"{where}: member {info.filename!r} unpacks to more than"
                    f" {limits.member_bytes} bytes (the limit)"
                )
            if total + size > limits.total_bytes:
                raise ArchiveError(f"{where} unpacks to more than {limits.total_bytes} bytes")
            out.write(chunk)
    return size


@contextmanager
def checked(
    path: Path, where: str, limits: Limits = DEFAULT_LIMITS, kind: str = "a zip archive"
) -> Iterator[tuple[zipfile.ZipFile, list[zipfile.ZipInfo]]]:
    """The one way the project opens an archive: (the open archive, its file members) after
    every check that needs no member's bytes (count, names, types, methods, declared sizes);
    ArchiveError naming `where` and the member otherwise."""
    with open_zip(path, where, limits, kind) as archive:
        yield archive, check_members(archive, where, limits)


def check_archive(
    path: Path, where: str, limits: Limits = DEFAULT_LIMITS, kind: str = "a zip archive"
) -> list[zipfile.ZipInfo]:
    """The file members of an archive that passes `checked`."""
    with checked(path, where, limits, kind) as (_, files):
        return files


def unpack(
    path: Path,
    folder: Path,
    where: str,
    limits: Limits = DEFAULT_LIMITS,
    kind: str = "a zip archive",
    wanted: Callable[[str], bool] | None = None,
) -> list[zipfile.ZipInfo]:
    """Check the archive (`checked`: every member) and extract its files (those whose name is
    `wanted`, default all) into the existing folder, counting the bytes unpacked against the
    same limits; returns the file members."""
    with checked(path, where, limits, kind) as (archive, files):
        chosen = files if wanted is None else [f for f in files if wanted(f.filename)]
        extract(archive, chosen, folder, where, limits)
    return files
