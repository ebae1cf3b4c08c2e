"""Files that appear whole or not at all, and folders one process writes at a time.

- `temp_path(target)`: a unique temporary name beside target (same folder, so `os.replace` onto
  target is atomic); names not yet renamed into place are removed when the process exits.
- `atomic_path(target)` / `atomic_write(target)`: write through a temporary file (given as a path,
  or opened), renamed onto target only on success.
- `LineFile(path)`: a file appended in whole lines; a failed write (a full disk) cuts it back to
  its last whole line, so it never ends in half a line.
- Every failure to write is a `WriteError` (an OSError) whose one line names the target file and
  its folder, never a temporary name.
- `FolderLock(folder)`: an exclusive lock on a folder (`fcntl.flock` on the folder itself, so no
  lock file is left in it), refused at once (or after `wait` seconds) with a clear message when
  another process holds it; re-entrant within a process; a forked child does not inherit it.
"""

from __future__ import annotations

import atexit
import contextlib
import errno
import os
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

try:
    import fcntl
except ImportError:  # Windows: no advisory locks here; unique temporary names still apply
    fcntl = None

LOCK_NAME = ".impedance-cosim.lock"  # the lock file of earlier versions (removed when found)
_pending: set[Path] = set()  # temporary files not yet renamed into place
_UMASK = os.umask(0o022)
os.umask(_UMASK)


class FolderBusyError(RuntimeError):
    """Another process holds the lock on a folder."""


class WriteError(OSError):
    """A file could not be written: one line naming it, its folder, the reason and (note) where
    what was already written is kept."""

    def __init__(self, target: str | Path, reason: str, note: str = "", code: int | None = None):
        self.target, self.reason, self.note = Path(target), reason, note
        folder = Path(os.path.abspath(self.target)).parent
        text = f"cannot write {self.target.name} in {folder}: {reason}"
        super().__init__(text + (f"; {note}" if note else ""))
        self.errno, self.strerror = code, reason  # as an OSError's (str() stays the line above)

    def __str__(self) -> str:
        return str(self.args[0])

    def with_note(self, note: str) -> WriteError:
        """The same error, saying where what was written is kept."""
        return WriteError(self.target, self.reason, note, self.errno)


def write_error(target: str | Path, exc: OSError, note: str = "") -> WriteError:
    """exc (raised while writing target, maybe through a temporary file) as a WriteError."""
    if isinstance(exc, WriteError):  # about our temporary file (nested writes): name target
        ours = exc.target.name.startswith(f".{Path(target).name}.")
        return WriteError(target, exc.reason, exc.note, exc.errno) if ours else exc
    reason = exc.strerror or str(exc)
    other = exc.filename and not Path(str(exc.filename)).name.startswith(f".{Path(target).name}.")
    if other:  # another file than ours (e.g. a font a figure needs): say which
        reason += f" ({exc.filename})"
    return WriteError(target, reason, note, exc.errno)


def temp_path(target: str | Path, suffix: str = ".tmp") -> Path:
    """A new, empty, uniquely named file beside target (".name.XXXXXX.tmp"), removed at exit
    unless it has been renamed into place."""
    target = Path(target)
    fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=suffix, dir=target.parent)
    os.close(fd)
    path = Path(name)
    os.chmod(path, 0o666 & ~_UMASK)  # as open() would create it (mkstemp makes it private)
    _pending.add(path)
    return path


def discard(path: Path) -> None:
    """Remove a temporary file (if it is still there)."""
    _pending.discard(path)
    with contextlib.suppress(FileNotFoundError):
        path.unlink()


def keep(path: Path) -> None:
    """A temporary file that is to stay after the process exits (it holds rows to keep)."""
    _pending.discard(path)


def replace(tmp: Path, target: str | Path) -> None:
    """Rename a temporary file onto target (atomic within one file system)."""
    os.replace(tmp, target)
    _pending.discard(tmp)


@contextlib.contextmanager
def atomic_path(target: str | Path, suffix: str = ".tmp") -> Iterator[Path]:
    """A temporary path beside target to write (e.g. savefig; keep target's suffix in `suffix`
    where it picks the format); on success it replaces target, on an exception it is removed and
    target is left as it was. An OSError becomes a WriteError naming target."""
    target = Path(target)
    try:
        tmp = temp_path(target, suffix)
    except OSError as exc:
        raise write_error(target, exc) from None
    try:
        yield tmp
        replace(tmp, target)
    except OSError as exc:
        discard(tmp)
        raise write_error(target, exc) from None
    except BaseException:
        discard(tmp)
        raise


@contextlib.contextmanager
def atomic_write(target: str | Path, mode: str = "w", **kwargs: Any) -> Iterator[IO]:
    """Open a temporary file beside target for writing; on success it replaces target, on an
    exception it is removed and target is left as it was (OSError: a WriteError naming target)."""
    with atomic_path(target) as tmp, open(tmp, mode, **kwargs) as f:
        yield f


class LineFile:
    """A file appended to in whole lines, each written out at once (no buffer). A write that
    fails part-way (a full disk, a file size limit) is cut back to its last whole line, so the
    file never ends in half a line, and raises a WriteError naming `name` (the target)."""

    def __init__(self, path: str | Path, name: str | Path | None = None) -> None:
        self.path, self.name = Path(path), Path(name or path)
        try:
            self._fd: int | None = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_APPEND,
                                           0o666)  # fmt: skip
            self.size = os.fstat(self._fd).st_size
        except OSError as exc:
            raise write_error(self.name, exc) from None
        self.failed = False

    def append(self, text: str, sync: bool = False) -> None:
        """Write text (whole lines), then fsync if sync. On a failure the file is cut back to its
        last whole line (`kept_text`: the part of text it holds) and WriteError is raised."""
        data, done = text.encode(), 0
        try:
            while done < len(data):
                done += os.write(self._fd, data[done:])  # type: ignore[arg-type]
            if sync:
                os.fsync(self._fd)  # type: ignore[arg-type]
        except OSError as exc:
            self.failed = True
            whole = data.rfind(b"\n", 0, done) + 1
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, self.size + whole)  # type: ignore[arg-type]
            self.size += whole
            self.kept_text = data[:whole].decode()
            raise write_error(self.name, exc) from None
        self.size += done

    def close(self) -> None:
        """Close the file (what was appended is already written)."""
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None


@atexit.register
def _remove_pending() -> None:
    for path in list(_pending):
        discard(path)


_HELD_LOCKS: set[int] = set()  # descriptors of the locks held by this process
_HELD_FOLDERS: dict[tuple[int, int], list[int]] = {}  # (device, inode) -> [descriptor, uses]


def _close_held_locks_in_child() -> None:
    """A forked child (e.g. a dask worker) must not keep this process's folders locked: its
    copies of the lock descriptors are pointed at /dev/null (the parent's keep the lock; the
    numbers stay taken, so the child's copy of a lock's file object never closes another file)."""
    _HELD_FOLDERS.clear()
    if not _HELD_LOCKS:
        return
    with contextlib.suppress(OSError):
        null = os.open(os.devnull, os.O_RDWR)
        for fd in _HELD_LOCKS:
            os.dup2(null, fd)
        os.close(null)
    _HELD_LOCKS.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_close_held_locks_in_child)


@contextlib.contextmanager
def lock_not_inherited(fd: int) -> Iterator[None]:
    """While the block runs, a forked child (a dask worker) does not share the lock held on fd."""
    _HELD_LOCKS.add(fd)
    try:
        yield
    finally:
        _HELD_LOCKS.discard(fd)


def _lock_owner(st: os.stat_result) -> str:
    """The pid holding a flock on the file st describes, from /proc/locks (Linux), or "unknown"."""
    want = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    try:
        with open("/proc/locks") as f:
            for line in f:
                parts = line.split()
                if "->" not in parts and parts[1:2] == ["FLOCK"] and parts[5:6] == [want]:
                    return parts[4]
    except (OSError, IndexError):
        pass
    return "unknown"


class FolderLock:
    """Exclusive use of a folder by this process while the `with` block runs (see module
    docstring): `wait` seconds to wait for another process to finish (0: refuse at once). The
    lock is the folder's own (nothing is written into it); a forked child does not inherit it."""

    def __init__(self, folder: str | Path, what: str = "folder", wait: float = 0.0) -> None:
        self.folder = Path(folder)
        self.what, self.wait = what, wait
        self._key: tuple[int, int] | None = None

    def __enter__(self) -> FolderLock:
        if fcntl is None:
            return self
        fd = os.open(self.folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        st = os.fstat(fd)
        key = (st.st_dev, st.st_ino)
        if key in _HELD_FOLDERS:  # this process holds it already (e.g. swap runs as run)
            os.close(fd)
            _HELD_FOLDERS[key][1] += 1
            self._key = key
            return self
        deadline, said = time.monotonic() + self.wait, False
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except OSError as exc:
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    os.close(fd)  # a file system without locks: go on unlocked
                    return self
            if time.monotonic() >= deadline:
                os.close(fd)
                raise FolderBusyError(
                    f"{self.what} {self.folder} is in use by another impedance-cosim process"
                    f" (pid {_lock_owner(st)}); wait for it to finish or choose another folder"
                )
            if not said:
                print(f"impedance-cosim: waiting for another impedance-cosim process (pid"
                      f" {_lock_owner(st)}) to finish with {self.folder} ...",
                      file=sys.stderr)  # fmt: skip
                said = True
            time.sleep(0.2)
        _HELD_FOLDERS[key] = [fd, 1]
        _HELD_LOCKS.add(fd)
        self._key = key
        with contextlib.suppress(OSError):  # an earlier version's lock file: not needed now
            (self.folder / LOCK_NAME).unlink()
        return self

    def __exit__(self, *exc: object) -> None:
        key, self._key = self._key, None
        held = _HELD_FOLDERS.get(key) if key else None
        if held is None:
            return
        held[1] -= 1
        if held[1] == 0:
            del _HELD_FOLDERS[key]
            _HELD_LOCKS.discard(held[0])
            os.close(held[0])  # closing releases the lock
