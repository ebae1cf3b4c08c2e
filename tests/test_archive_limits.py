"""One set of archive limits for every archive the project opens (issue 20): an FMU given to
`swap --replace`, to the API or inside an .ssp is checked by archive.check_archive before any
member is read, and extracted only by archive.unpack, which counts the bytes again. The bombs
here are small files (a few MB) that declare or inflate to 1.5 GiB; no test writes more than a
few MB."""

from __future__ import annotations

import os
import re
import struct
import subprocess
import sys
import tempfile
import zipfile
import zlib
from functools import lru_cache
from pathlib import Path

import pytest

from impedance_cosim.cosim.archive import DEFAULT_LIMITS, ArchiveError, unpack
from impedance_cosim.cosim.fmus.files import FmuArchiveError, FmuError
from impedance_cosim.cosim.fmus.fmi2 import FmuInstance
from impedance_cosim.cosim.master.master import Master, MasterError
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import SspError, read_ssp

PLANT = "PumaPlant.fmu"
GIB = 2**30
MEMBER_LIMIT, TOTAL_LIMIT = DEFAULT_LIMITS.member_bytes, DEFAULT_LIMITS.total_bytes


@lru_cache(maxsize=4)
def deflated_zeros(mib: int) -> tuple[bytes, int]:
    """A raw deflate stream of `mib` MiB of zeros (about 1 KB per MiB) and its CRC-32, made
    without compressing that much: a full flush resets the compressor, so every MiB block is
    the same bytes and the block is repeated."""
    zeros = bytes(1 << 20)
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    block = c.compress(zeros) + c.flush(zlib.Z_FULL_FLUSH)
    crc = 0
    for _ in range(mib):
        crc = zlib.crc32(zeros, crc)
    return block * mib + zlib.compressobj(9, zlib.DEFLATED, -15).flush(), crc


def with_members(src: Path, out: Path, members: dict[str, tuple[bytes, int, int]], drop=()) -> Path:
    """A copy of the archive src with members added: name -> (raw deflate stream, CRC-32, the
    uncompressed size its headers declare). Written stored, then the headers are patched to
    say deflated with the given CRC and size (zipfile cannot write a raw stream)."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            if info.filename not in drop:
                zout.writestr(info, zin.read(info))
        for name, (stream, _, _) in members.items():
            zout.writestr(zipfile.ZipInfo(name), stream, compress_type=zipfile.ZIP_STORED)
    raw = bytearray(out.read_bytes())
    for name, (_, crc, size) in members.items():
        encoded = name.encode()
        # (signature, offset of the name, of the method, of the CRC, of the uncompressed size)
        for sig, at_name, at_method, at_crc, at_size in (
            (b"PK\x03\x04", 30, 8, 14, 22),
            (b"PK\x01\x02", 46, 10, 16, 24),
        ):
            i = raw.find(sig)
            while i >= 0:
                if raw[i + at_name : i + at_name + len(encoded)] == encoded:
                    struct.pack_into("<H", raw, i + at_method, zipfile.ZIP_DEFLATED)
                    struct.pack_into("<I", raw, i + at_crc, crc)
                    struct.pack_into("<I", raw, i + at_size, size)
                i = raw.find(sig, i + 4)
    out.write_bytes(bytes(raw))
    return out


def honest_bomb(plant: Path, out: Path) -> Path:
    """The plant FMU with a member that declares and inflates to 1.5 GiB (a 1.6 MB file)."""
    stream, crc = deflated_zeros(1536)
    return with_members(plant, out, {"resources/bomb.bin": (stream, crc, 1536 << 20)})


def lying_bomb(plant: Path, out: Path) -> Path:
    """The plant FMU with a member that declares 1000 bytes and inflates to 1.5 GiB."""
    stream, crc = deflated_zeros(1536)
    return with_members(plant, out, {"resources/bomb.bin": (stream, crc, 1000)})


@pytest.fixture(autouse=True)
def private_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Temporary folders of this process and its children go under the test's folder."""
    tmp = tmp_path / "tmpdir"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    monkeypatch.setenv("TMPDIR", str(tmp))
    return tmp


def bytes_under(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def swap(native_ssp: Path, fmu: Path, out: Path) -> tuple[int, list[str]]:
    """`impedance-cosim swap --replace plant=FMU` in a child: (exit status, stderr lines)."""
    cmd = [sys.executable, "-m", "impedance_cosim.cli", "swap", "--ssp", str(native_ssp),
           "--replace", f"plant={fmu}", "--stop", "0.05", "--no-figures", "--no-report",
           "--out", str(out)]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=os.environ)
    assert "Traceback" not in done.stderr + done.stdout, done.stderr
    return done.returncode, done.stderr.strip().splitlines()


@pytest.mark.slow
def test_an_honest_bomb_is_refused_from_its_header_wherever_the_fmu_comes_from(
    native_dir, native_ssp, tmp_path, private_tmp
):
    """swap --replace (the case of the issue: 1.5 GiB written), the API and FmuInstance refuse
    it with the same line before anything is extracted; inside an .ssp, the same function says
    the same thing."""
    bomb = honest_bomb(native_dir / PLANT, tmp_path / "bomb.fmu")
    assert bomb.stat().st_size < 4 << 20
    expected = (f"member 'resources/bomb.bin' unpacks to {1536 << 20} bytes"
                f" (limit {MEMBER_LIMIT})")  # fmt: skip
    status, lines = swap(native_ssp, bomb, tmp_path / "out")
    assert status == 2 and lines == [f"impedance-cosim swap: error: {bomb}: {expected}"]
    assert not (tmp_path / "out").exists()
    with pytest.raises(FmuArchiveError, match=f"^bomb.fmu: {re.escape(expected)}$"):
        FmuInstance(bomb, "plant")
    with read_ssp(native_ssp) as system, pytest.raises(MasterError, match=re.escape(expected)):
        Master(system, RunOptions(stop_time=0.05, fmu_files={"plant": bomb}))
    ssp = with_members(native_ssp, tmp_path / "bomb.ssp", {}, drop=(f"resources/{PLANT}",))
    with zipfile.ZipFile(ssp, "a") as z:
        z.write(bomb, f"resources/{PLANT}")
    with pytest.raises(SspError, match=f"^bomb.ssp: resources/{PLANT}: {re.escape(expected)}$"):
        read_ssp(ssp)
    assert bytes_under(private_tmp) < 4 << 20


@pytest.mark.slow
def test_honest_members_adding_up_beyond_the_total_are_refused(native_dir, native_ssp, tmp_path):
    stream, crc = deflated_zeros(200)
    big = {f"resources/big{i}.bin": (stream, crc, 200 << 20) for i in range(6)}
    fmu = with_members(native_dir / PLANT, tmp_path / "big.fmu", big)
    status, lines = swap(native_ssp, fmu, tmp_path / "out")
    assert status == 2 and lines == [
        f"impedance-cosim swap: error: {fmu} unpacks to more than {TOTAL_LIMIT} bytes"
    ]
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_a_lying_header_is_caught_from_the_bytes_unpacked(
    native_dir, native_ssp, tmp_path, private_tmp
):
    """Declared 1000 bytes, inflating to 1.5 GiB: at most the declared bytes are unpacked, then
    the member is refused, by the extraction itself and before a run."""
    bomb = lying_bomb(native_dir / PLANT, tmp_path / "liar.fmu")
    folder = tmp_path / "unpacked"
    folder.mkdir()
    with pytest.raises(ArchiveError, match=r"^liar.fmu: member 'resources/bomb.bin' is corrupt"):
        unpack(bomb, folder, "liar.fmu")
    assert (folder / "resources" / "bomb.bin").stat().st_size <= 1000
    assert bytes_under(folder) < 4 << 20
    with pytest.raises(FmuError, match="resources/bomb.bin is corrupt"):
        FmuInstance(bomb, "plant")
    status, lines = swap(native_ssp, bomb, tmp_path / "out")
    assert status == 2 and len(lines) == 1 and "resources/bomb.bin is corrupt" in lines[0], lines
    assert not (tmp_path / "out" / "observer.csv").exists()
    assert bytes_under(private_tmp) < 4 << 20


def _many_members(plant: Path, out: Path) -> Path:
    raw = bytearray(plant.read_bytes())
    end = raw.rfind(b"PK\x05\x06")  # end of central directory: entry counts at +8 and +10
    raw[end + 8 : end + 12] = struct.pack("<HH", 60000, 60000)
    out.write_bytes(bytes(raw))
    return out


def _big_description(plant: Path, out: Path) -> Path:
    stream, crc = deflated_zeros(32)
    return with_members(plant, out, {"modelDescription.xml": (stream, crc, 32 << 20)},
                        drop=("modelDescription.xml",))  # fmt: skip


def _member(name: str, attr: int = 0):
    def make(plant: Path, out: Path) -> Path:
        with zipfile.ZipFile(plant) as zin, zipfile.ZipFile(out, "w") as zout:
            for info in zin.infolist():
                zout.writestr(info, zin.read(info))
            info = zipfile.ZipInfo(name)
            info.external_attr = attr << 16
            zout.writestr(info, b"/etc/passwd")
        return out

    return make


@pytest.mark.parametrize(
    "make,message",
    [
        (_many_members, r"has 60000 members \(limit 2000\)"),
        (_big_description, r"member 'modelDescription.xml' unpacks to 33554432 bytes"),
        (_member("/tmp/impcosim_evil.txt"), r"member '/tmp/impcosim_evil.txt' has an absolute"),
        (_member("../evil.txt"), r"member '../evil.txt' has a '\.\.' path component"),
        (_member("resources/link", 0o120777), r"member 'resources/link' is a symbolic link"),
    ],
    ids=["members", "description", "absolute", "dotdot", "link"],
)
@pytest.mark.slow
def test_members_names_and_links_are_checked_before_anything_runs(
    make, message, native_dir, native_ssp, tmp_path
):
    """Item 2 of the issue among them: an absolute member path in swap --replace was refused
    only after the run had started (exit 1, a CSV of 0 rows); now exit 2, one line naming the
    FMU file and the member, nothing written."""
    fmu = make(native_dir / PLANT, tmp_path / "bad.fmu")
    with pytest.raises(FmuArchiveError, match=f"^bad.fmu(:)? {message}"):
        FmuInstance(fmu, "plant")
    status, lines = swap(native_ssp, fmu, tmp_path / "out")
    assert status == 2 and len(lines) == 1, lines
    assert lines[0].startswith(f"impedance-cosim swap: error: {fmu}"), lines
    assert re.search(message, lines[0]), lines
    assert not (tmp_path / "out").exists()


def test_the_bytes_unpacked_are_counted_against_the_limits_too(native_dir, tmp_path):
    """The second count, on its own: members checked from their headers under the default
    limits, then extracted under smaller ones, stop at the limit from the bytes written (a
    header that passed cannot make extraction write more)."""
    from impedance_cosim.cosim.archive import Limits, checked, extract

    fmu = native_dir / PLANT
    small = Limits(member_bytes=1000, total_bytes=DEFAULT_LIMITS.total_bytes)
    with checked(fmu, "plant.fmu") as (archive, files):
        big = max(files, key=lambda f: f.file_size)
        assert big.file_size > 1000
        folder = tmp_path / "a"
        folder.mkdir()
        with pytest.raises(ArchiveError, match=r"unpacks to more than 1000 bytes \(the limit\)"):
            extract(archive, [big], folder, "plant.fmu", small)
        assert bytes_under(folder) <= 1000  # a chunk is counted before it is written
        folder = tmp_path / "b"
        folder.mkdir()
        total = sum(f.file_size for f in files) - 1
        with pytest.raises(ArchiveError, match=f"plant.fmu unpacks to more than {total} bytes"):
            extract(archive, files, folder, "plant.fmu", Limits(total_bytes=total))
        assert bytes_under(folder) <= total
