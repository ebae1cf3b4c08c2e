"""Shared by the Python fuzz targets: where the built FMUs and archives are, and the atheris main.

A target module defines ``entry(data: bytes)``: it feeds the bytes to one reader and lets through
nothing but that reader's documented error class (anything else, or a hang, is a finding)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

FUZZ = Path(__file__).resolve().parents[1]
if str(FUZZ) not in sys.path:
    sys.path.insert(0, str(FUZZ))


def fmus_dir() -> Path:
    """The output of `impedance-cosim build` (IMPCOSIM_FUZZ_FMUS, else built once into a cache)."""
    given = os.environ.get("IMPCOSIM_FUZZ_FMUS")
    if given:
        return Path(given)
    import targets

    return targets.build_fmus(targets.work_dir() / "fmus")


def main(entry) -> None:
    """Run ENTRY under atheris (libFuzzer's options in sys.argv), every loaded function
    instrumented (the target imported its reader before calling this)."""
    import atheris

    atheris.instrument_all()
    atheris.Setup(sys.argv, entry)
    atheris.Fuzz()
