"""An optional cache of compiled FMU libraries, keyed by everything that decides their bytes.

With IMPCOSIM_BUILD_CACHE naming a folder, a native FMU's library for one platform is compiled
once per set of inputs and copied from the folder afterwards: the key is a SHA-256 over the
platform, the compiler (its resolved path, size, modification time and `--version` line), the
flags, the model identifier, the FMI version and every source file's name and bytes. A changed
source, flag or compiler is a new key, so a stale library is never served. Without the variable
nothing is cached (the default: a build compiles everything).

The test suite sets it (tests/conftest.py) so that each platform's library is compiled once per
pytest run and its workers, not once per fixture, test and `impedance-cosim build` subprocess;
a developer rebuilding after editing one model can set it too (docs/development.md).
Entries are written to a temporary name and renamed, so concurrent builds share it safely."""

from __future__ import annotations

import hashlib
import os
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path

ENV = "IMPCOSIM_BUILD_CACHE"
_compilers: dict[str, str] = {}  # compiler path -> identity, per process


def cache_dir() -> Path | None:
    """The cache folder named by IMPCOSIM_BUILD_CACHE, or None (no caching)."""
    folder = os.environ.get(ENV)
    return Path(folder) if folder else None


def compiler_identity(compiler: str) -> str:
    """What tells one compiler from another: resolved path, size, mtime and version line."""
    if compiler not in _compilers:
        from shutil import which

        path = Path(which(compiler) or compiler).resolve()
        try:
            st = path.stat()
            done = subprocess.run([str(path), "--version"], capture_output=True, text=True,
                                  timeout=60)  # fmt: skip
            version = (done.stdout.splitlines() or [""])[0]
        except (OSError, subprocess.SubprocessError):
            return f"{path} (unidentified)"  # not cached: identity cannot be told
        _compilers[compiler] = f"{path} {st.st_size} {st.st_mtime_ns} {version}"
    return _compilers[compiler]


def cache_key(parts: list[str], src: Path, files: list[str]) -> str:
    """SHA-256 over the parts (platform, compiler, flags, ...) and the named source files plus
    every header in src (a header change must change the key)."""
    digest = hashlib.sha256()
    for part in parts:
        digest.update(part.encode() + b"\0")
    names = sorted({*files, *(p.name for p in src.iterdir() if p.suffix == ".h")})
    for name in names:
        data = (src / name).read_bytes()
        digest.update(f"{name}\0{len(data)}\0".encode() + data)
    return digest.hexdigest()


def cached_build(key_parts: list[str], src: Path, files: list[str], out: Path,
                 build: Callable[[], None]) -> None:  # fmt: skip
    """Make out by build(), or copy it from the cache when the same inputs were built before
    (and store it there after a build). Without a cache folder, just build()."""
    folder = cache_dir()
    if folder is None or "(unidentified)" in " ".join(key_parts):
        build()
        return
    entry = folder / (cache_key(key_parts, src, files) + out.suffix)
    if entry.is_file():
        out.write_bytes(entry.read_bytes())
        return
    build()
    folder.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-")
    with os.fdopen(fd, "wb") as f:
        f.write(out.read_bytes())
    os.replace(tmp, entry)
