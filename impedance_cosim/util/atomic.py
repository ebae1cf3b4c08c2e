"""Files that appear whole or not at all, and folders one process writes at a time.

- `temp_path(target)`: a unique temporary name beside target (same folder, so `os.replace` onto
  target is atomic); names not yet renamed into place are removed when the process exits.
- `atomic_write(target)`: write through a temporary file, renamed onto target only on success.
- `FolderLock(folder)`: an exclusive lock on a folder (a lock file inside it, `fcntl.flock`),
  refused at once with a clear message when another process holds it.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

try:
    import fcntl
except ImportError:  # Windows: no advisory locks here; unique temporary names still apply
    fcntl = None

LOCK_NAME = ".impedance-cosim.lock"
_pending: set[Path] = set()  # temporary files not yet renamed into place
_UMASK = os.umask(0o022)
os.umask(_UMASK)


class FolderBusyError(RuntimeError):
    """Another process holds the lock on a folder."""


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


def replace(tmp: Path, target: str | Path) -> None:
    """Rename a temporary file onto target (atomic within one file system)."""
    os.replace(tmp, target)
    _pending.discard(tmp)


@contextlib.contextmanager
def atomic_write(target: str | Path, mode: str = "w", **kwargs: Any) -> Iterator[IO]:
    """Open a temporary file beside target for writing; on success it replaces target, on an
    exception it is removed and target is left as it was."""
    tmp = temp_path(target)
    try:
        with open(tmp, mode, **kwargs) as f:
            yield f
    except BaseException:
        discard(tmp)
        raise
    replace(tmp, target)


@atexit.register
def _remove_pending() -> None:
    for path in list(_pending):
        discard(path)


_HELD_LOCKS: set[int] = set()  # descriptors of the locks held by this process


def _close_held_locks_in_child() -> None:
    """A forked child (e.g. a dask worker) must not keep this process's folders locked: its
    copies of the lock descriptors are pointed at /dev/null (the parent's keep the lock; the
    numbers stay taken, so the child's copy of a lock's file object never closes another file)."""
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


class FolderLock:
    """Exclusive use of a folder by this process while the `with` block runs (see module
    docstring). The lock file stays in the folder (removing it would race with a waiter); a
    forked child does not inherit the lock."""

    def __init__(self, folder: str | Path, what: str = "folder") -> None:
        self.folder = Path(folder)
        self.what = what
        self._file: IO | None = None

    def __enter__(self) -> FolderLock:
        path = self.folder / LOCK_NAME
        f = open(path, "a+")  # noqa: SIM115 (held open while locked)
        if fcntl is not None:
            try:
                fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                f.seek(0)
                owner = f.read().strip() or "unknown"
                f.close()
                raise FolderBusyError(
                    f"{self.what} {self.folder} is in use by another impedance-cosim process"
                    f" (pid {owner}); wait for it to finish or choose another folder"
                ) from None
        f.seek(0)
        f.truncate()
        f.write(f"{os.getpid()}\n")
        f.flush()
        self._file = f
        _HELD_LOCKS.add(f.fileno())
        return self

    def __exit__(self, *exc: object) -> None:
        if self._file is not None:
            _HELD_LOCKS.discard(self._file.fileno())
            self._file.close()  # closing releases the lock
            self._file = None
