"""Writing the archives the build makes (FMUs, .ssp system archives, the dist bundle): whole under
their final name or not there. Each is written to a temporary file beside its target
(util/atomic.py's temp_path), checked, and renamed onto the target only when complete; on a full
disk (or a file size limit) the temporary file is removed and the error names the file and its
folder in one line."""

from __future__ import annotations

import contextlib
import errno
import zipfile
from collections.abc import Callable, Iterator
from pathlib import Path

from impedance_cosim.util import atomic

# the errors of a write that found no room: the archive is incomplete, never renamed into place
NO_ROOM = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})


class ArchiveWriteError(OSError):
    """An archive could not be written for lack of room; nothing was left under its name."""

    def __init__(self, target: str | Path, reason: str, code: int | None = None) -> None:
        super().__init__(code, reason)
        self.target = Path(target)
        self.reason = reason

    def __str__(self) -> str:
        return (
            f"cannot write {self.target.name} in {self.target.parent}: {self.reason}"
            " (nothing was written under that name)"
        )

    def at(self, target: str | Path) -> ArchiveWriteError:
        """The same error naming another target (a staged file's final place)."""
        return ArchiveWriteError(target, self.reason, self.errno)


@contextlib.contextmanager
def write_zip(
    target: str | Path, check: Callable[[Path], None] | None = None
) -> Iterator[zipfile.ZipFile]:
    """A zip archive open for writing whose bytes go to a temporary file beside target; when the
    block ends without error (and check(temporary path) passes, if given) it is renamed onto
    target. On any error the temporary file is removed and target is left as it was; a write
    without room raises ArchiveWriteError naming target and its folder."""
    target = Path(target)
    try:
        tmp = atomic.temp_path(target)
    except OSError as exc:  # no room for even an empty file
        if exc.errno in NO_ROOM:
            raise ArchiveWriteError(target, exc.strerror or str(exc), exc.errno) from None
        raise
    try:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            yield z
        if check is not None:
            check(tmp)
    except OSError as exc:
        atomic.discard(tmp)
        if exc.errno in NO_ROOM and not isinstance(exc, ArchiveWriteError):
            raise ArchiveWriteError(target, exc.strerror or str(exc), exc.errno) from None
        raise
    except BaseException:
        atomic.discard(tmp)
        raise
    atomic.replace(tmp, target)
