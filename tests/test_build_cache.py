"""The compiled-library cache (IMPCOSIM_BUILD_CACHE): a hit gives the same bytes without running
a compiler; a changed source, header or compiler is a miss; without the variable nothing is
cached."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from impedance_cosim.packaging import build_cache, toolchains

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

SOURCE = '#include "lib.h"\ndouble impcosim_cached(double x) { return x * SCALE; }\n'


def sources(folder: Path, scale: str = "2.0") -> Path:
    folder.mkdir(parents=True)
    (folder / "lib.c").write_text(SOURCE)
    (folder / "lib.h").write_text(f"#define SCALE {scale}\n")
    return folder


def linux64_only(monkeypatch) -> list[str]:
    """Build for linux64 alone, counting the compiler runs."""
    calls = []
    real = toolchains.compile_library

    def counting(toolchain, src, files, out, *args, **kwargs):
        if out.name != f"probe{toolchain.suffix}":  # the once-per-process compiler probe
            calls.append(out.name)
        return real(toolchain, src, files, out, *args, **kwargs)

    monkeypatch.setattr(toolchains, "TOOLCHAINS", (toolchains.BY_PLATFORM["linux64"],))
    monkeypatch.setattr(toolchains, "compile_library", counting)
    return calls


def test_hit_gives_same_bytes_without_compiling(tmp_path, monkeypatch):
    calls = linux64_only(monkeypatch)
    monkeypatch.setenv(build_cache.ENV, str(tmp_path / "cache"))
    first = toolchains.build_binaries(sources(tmp_path / "a" / "src"), "Lib", ["lib.c"])
    second = toolchains.build_binaries(sources(tmp_path / "b" / "src"), "Lib", ["lib.c"])
    assert first == second and len(first) == 1
    assert calls == ["Lib.so"]  # compiled once
    assert len(list((tmp_path / "cache").glob("*.so"))) == 1


def test_changed_header_or_compiler_is_a_miss(tmp_path, monkeypatch):
    calls = linux64_only(monkeypatch)
    monkeypatch.setenv(build_cache.ENV, str(tmp_path / "cache"))
    two = toolchains.build_binaries(sources(tmp_path / "a" / "src"), "Lib", ["lib.c"])
    three = toolchains.build_binaries(sources(tmp_path / "b" / "src", "3.0"), "Lib", ["lib.c"])
    assert two != three and len(calls) == 2
    monkeypatch.setitem(build_cache._compilers, "gcc", "another gcc")
    toolchains.build_binaries(sources(tmp_path / "c" / "src"), "Lib", ["lib.c"])
    assert len(calls) == 3


def test_no_cache_without_the_variable(tmp_path, monkeypatch):
    calls = linux64_only(monkeypatch)
    monkeypatch.delenv(build_cache.ENV, raising=False)
    toolchains.build_binaries(sources(tmp_path / "a" / "src"), "Lib", ["lib.c"])
    toolchains.build_binaries(sources(tmp_path / "b" / "src"), "Lib", ["lib.c"])
    assert len(calls) == 2
