"""What a run does before its first step, done once and only as much as needed: an FMU's
extraction writes what running it needs (not its sources, documentation or other platforms'
binaries), and the FMU instances still load and step from it."""

from __future__ import annotations

import zipfile
from pathlib import Path

from fmpy import platform

from impedance_cosim.cosim.fmus.files import extractions


def test_an_fmu_is_extracted_with_only_what_running_it_needs(native_dir: Path) -> None:
    fmu = native_dir / "PumaPlant.fmu"
    members = zipfile.ZipFile(fmu).namelist()
    assert any(m.startswith("sources/") for m in members)  # there to be left out
    key, _, folder = extractions.acquire(fmu)
    try:
        written = sorted(str(p.relative_to(folder)) for p in Path(folder).rglob("*") if p.is_file())
    finally:
        extractions.release(key)
    assert "modelDescription.xml" in written
    assert any(w.startswith(f"binaries/{platform}/") for w in written), written
    assert not [w for w in written if w.startswith(("sources/", "documentation/"))], written
    assert all(w == "modelDescription.xml" or w.startswith(f"binaries/{platform}/")
               or w.startswith("resources/") for w in written), written  # fmt: skip
