"""The SSP fuzz targets' common part (ssp1.py, ssp2.py): one member of a built system archive
(an .ssd or .ssv, chosen by byte 0) replaced by the fuzz bytes, the archive read with read_ssp.
Only SspError, with a one-line message, may come out. Byte 0's bit 7 set turns schema
validation off for that input, so that the reader's own checks are fuzzed alone."""

from __future__ import annotations

import io
import sys
import tempfile
import zipfile
from pathlib import Path

import _common

from impedance_cosim.cosim.ssp import ssp1 as ssd
from impedance_cosim.cosim.ssp import ssp2 as ssd2
from impedance_cosim.cosim.ssp.read import SspError, read_ssp


class _AnythingGoes:
    error_log = ()

    def validate(self, doc) -> bool:
        return True


class Target:
    """The fuzz target on the built system archive ARCHIVE (an ssp*.py's TARGET)."""

    def __init__(self, archive: str) -> None:
        self.archive = archive
        self.members: list[tuple[str, bytes]] | None = None
        self.tmp = Path(tempfile.mkdtemp(prefix="impcosim-fuzz-ssp-"))

    def _load(self) -> list[tuple[str, bytes]]:
        if self.members is None:
            with zipfile.ZipFile(_common.fmus_dir() / self.archive) as z:
                self.members = [(n, z.read(n)) for n in z.namelist()]
        return self.members

    def xml_members(self) -> list[str]:
        return [n for n, _ in self._load() if n.endswith((".ssd", ".ssv"))]

    def entry(self, data: bytes) -> None:
        if not data:
            return
        members = self._load()
        xml = self.xml_members()
        target = xml[(data[0] & 0x7F) % len(xml)]
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as z:
            for name, content in members:
                z.writestr(name, data[1:] if name == target else content)
        path = self.tmp / "fuzz.ssp"
        path.write_bytes(buf.getvalue())
        saved = ssd._schema, ssd2.schema
        if data[0] & 0x80:
            ssd._schema = ssd2.schema = lambda name: _AnythingGoes()
        try:
            read_ssp(path).close()
        except SspError as exc:
            assert str(exc) and "\n" not in str(exc), repr(exc)
        finally:
            ssd._schema, ssd2.schema = saved

    def seeds(self) -> dict[str, bytes]:
        """One seed per XML member: its own bytes (schema on and off)."""
        out = {}
        xml = self.xml_members()
        for k, name in enumerate(xml):
            content = dict(self._load())[name]
            out[Path(name).stem] = bytes([k]) + content
            out[Path(name).stem + "-noschema"] = bytes([k | 0x80]) + content
        return out

    def fuzz_if_run(self, module: str) -> None:
        """Fuzz entry under atheris (_common.main) where MODULE, the target's __name__, is the
        script run (benchmarks/fuzz.py runs fuzz/py/ssp1.py, ssp2.py)."""
        if module == "__main__":
            _common.main(self.entry)
            sys.exit(0)
