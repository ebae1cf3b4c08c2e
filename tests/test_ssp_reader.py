"""The SSP reader treats an archive as hostile: sources stay inside the archive, members are
checked and capped before extraction, every problem is one SspError naming it, and nothing it
extracted is left behind. Ends with a fuzz test over mutated archives."""

from __future__ import annotations

import os
import random
import re
import signal
import struct
import subprocess
import sys
import tempfile
import time
import traceback
import warnings
import zipfile
from pathlib import Path

import pytest

from impedance_cosim.cosim.master.master import Master, MasterError
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp import ssp1 as ssd
from impedance_cosim.cosim.ssp.read import Limits, SspError, SystemDescription, read_ssp

SSD = "SystemStructure.ssd"
PLANT = "resources/PumaPlant.fmu"


@pytest.fixture(scope="module")
def archive(native_dir: Path) -> Path:
    """The small (native FMUs) system archive."""
    return native_dir.parent / "PaperScenario-native.ssp"  # built beside the Python one


@pytest.fixture(autouse=True)
def private_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The reader's temporary folders go under this test's folder, so leftovers can be counted."""
    tmp = tmp_path / "tmpdir"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    return tmp


def leftovers(tmp: Path) -> list[str]:
    return sorted(p.name for p in tmp.iterdir() if p.name.startswith("impcosim_ssp_"))


def members(path: Path) -> list[tuple[zipfile.ZipInfo, bytes]]:
    with zipfile.ZipFile(path) as z:
        return [(i, z.read(i)) for i in z.infolist()]


def repack(src: Path, out: Path, edits: dict | None = None, drop=(), add=()) -> Path:
    """A copy of an archive with members rewritten (bytes or function of bytes), dropped, added
    ((name or ZipInfo, bytes) pairs, written as given, duplicates included)."""
    edits = edits or {}
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for info, data in members(src):
            if info.filename in drop:
                continue
            edit = edits.get(info.filename)
            z.writestr(info.filename, edit(data) if callable(edit) else (edit or data))
        for name, data in add:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # "Duplicate name": wanted here
                z.writestr(name, data)
    return out


def ssd_edit(old: bytes, new: bytes, count: int = 1):
    def edit(data: bytes) -> bytes:
        assert old in data, old
        return data.replace(old, new, count)

    return edit


def refused(path: Path, match: str, **kw) -> str:
    with pytest.raises(SspError, match=match) as err:
        read_ssp(path, **kw)
    message = str(err.value)
    assert "\n" not in message
    return message


# --- sources stay inside the archive -------------------------------------------------------------


def test_the_archive_reads_and_close_removes_the_folder(archive, private_tmp):
    desc = read_ssp(archive)
    assert [c.name for c in desc.components] == ["plant", "controller"]  # as the SSD lists them
    assert desc.order == ["controller", "plant"]  # our master's Gauss-Seidel order (annotation)
    assert desc.component("plant").fmu == desc.folder / PLANT
    assert desc.component("plant").fmu.is_file()
    assert list(desc.parameter_sets) == ["observer", "difference", "measured"]
    assert leftovers(private_tmp) == [desc.folder.name]
    desc.close()
    desc.close()  # idempotent
    assert leftovers(private_tmp) == []
    with read_ssp(archive) as desc:
        assert desc.folder.is_dir()
    assert not desc.folder.exists()


def test_dropping_the_description_removes_the_folder(archive, private_tmp):
    desc = read_ssp(archive)
    assert leftovers(private_tmp)
    del desc
    assert leftovers(private_tmp) == []


def test_absolute_member_and_source_pointing_outside_is_refused(archive, tmp_path, private_tmp):
    """On the old reader a member named like an absolute path plus a source naming it loaded the
    FMU from that path on disk (pathlib joins an absolute name as is)."""
    outside = tmp_path / "elsewhere" / "Evil.fmu"
    outside.parent.mkdir()
    outside.write_bytes(b"not from the archive")
    source = str(outside).encode()
    edit = ssd_edit(b'source="resources/PumaPlant.fmu"', b'source="' + source + b'"')
    bad = repack(archive, tmp_path / "abs.ssp", {SSD: edit}, add=[(str(outside), b"x")])
    refused(bad, "absolute name")
    # the member alone (a legal archive otherwise) is refused too, before anything is written
    bad = repack(archive, tmp_path / "abs2.ssp", add=[("/tmp/x.fmu", b"x")])
    refused(bad, r"member '/tmp/x.fmu' has an absolute name")
    assert leftovers(private_tmp) == []


@pytest.mark.parametrize(
    "source,message",
    [
        ("/etc/hostname", "absolute path"),
        ("file:///etc/hostname", "absolute URI"),
        ("http://example.org/PumaPlant.fmu", "absolute URI"),
        ("//host/share/PumaPlant.fmu", "absolute URI"),
        ("../PumaPlant.fmu", r"'\.\.' path component"),
        ("resources/../../PumaPlant.fmu", r"'\.\.' path component"),
        ("%2e%2e/PumaPlant.fmu", r"'\.\.' path component"),
        ("resources/%2Fetc/hostname", "empty path component"),
        ("resources\\..\\PumaPlant.fmu", "backslash"),
        ("C:/PumaPlant.fmu", "absolute URI"),
        ("C:\\PumaPlant.fmu", "absolute URI"),
        ("resources/PumaPlant.fmu#x", "fragment"),
        ("resources/Puma%00Plant.fmu", "control character"),
        ("resources/Other.fmu", "resources/Other.fmu is missing from the archive"),
        ("resources", "resources is missing from the archive"),
    ],
)
def test_component_sources_must_name_a_file_inside_the_archive(archive, tmp_path, source, message):
    edit = ssd_edit(b'source="resources/PumaPlant.fmu"', f'source="{source}"'.encode())
    text = refused(repack(archive, tmp_path / "bad.ssp", {SSD: edit}), message)
    assert "component 'plant'" in text


def test_relative_source_with_dot_segments_and_escapes_is_read(archive, tmp_path):
    edit = ssd_edit(b'source="resources/PumaPlant.fmu"', b'source="./resources/Puma%50lant.fmu"')
    with read_ssp(repack(archive, tmp_path / "ok.ssp", {SSD: edit})) as desc:
        assert desc.component("plant").fmu == desc.folder / PLANT


def test_parameter_set_sources_are_resolved_the_same_way(archive, tmp_path):
    edit = ssd_edit(b'source="resources/observer_plant.ssv"', b'source="/etc/passwd"')
    text = refused(repack(archive, tmp_path / "bad.ssp", {SSD: edit}), "absolute path")
    assert "parameter binding" in text


def test_missing_parameter_set_names_the_member(archive, tmp_path):
    bad = repack(archive, tmp_path / "bad.ssp", drop=("resources/difference_plant.ssv",))
    text = refused(bad, "resources/difference_plant.ssv is missing from the archive")
    assert "SystemStructure.ssd" not in text.split(":")[-1]


# --- members are checked and capped before extraction ------------------------------------------


def test_symlink_member_is_refused(archive, tmp_path, private_tmp):
    link = zipfile.ZipInfo("resources/link.fmu")
    link.external_attr = (0o120777 << 16) | 0  # a symbolic link, as zip -y stores it
    link.create_system = 3
    bad = repack(archive, tmp_path / "link.ssp", add=[(link, b"/etc/passwd")])
    refused(bad, "member 'resources/link.fmu' is a symbolic link")
    assert leftovers(private_tmp) == []


@pytest.mark.parametrize(
    "name,message",
    [
        ("../evil.txt", r"'\.\.' path component"),
        ("resources/../../evil.txt", r"'\.\.' path component"),
        ("resources\\evil.txt", "backslash"),
        ("C:/evil.txt", "drive letter"),
        ("./SystemStructure.ssd", r"'\.' path component"),
        ("resources//evil.txt", "empty path component"),
        ("RESOURCES/PumaPlant.fmu", "appears twice"),
        ("resources/aux.txt", "Windows cannot store"),
        ("resources/trailing. ", "Windows cannot store"),
        ("resources/PumaPlant.fmu/inner", "both a file and a folder"),
    ],
)
def test_unsafe_member_names_are_refused(archive, tmp_path, name, message):
    refused(repack(archive, tmp_path / "bad.ssp", add=[(name, b"x")]), message)


def test_fmu_inside_is_checked_like_the_archive(archive, tmp_path):
    """fmpy extracts each FMU later: its members get the same name, link and size checks."""

    def with_member(name: str, data: bytes, attr: int = 0):
        def edit(fmu: bytes) -> bytes:
            out = tmp_path / "inner.fmu"
            out.write_bytes(fmu)
            with zipfile.ZipFile(out, "a") as z:
                info = zipfile.ZipInfo(name)
                info.external_attr = attr << 16
                z.writestr(info, data, compress_type=zipfile.ZIP_DEFLATED)
            return out.read_bytes()

        return edit

    for name, attr, message in [
        ("../../evil.so", 0, r"resources/PumaPlant.fmu: member '../../evil.so' has a '\.\.'"),
        ("binaries/link.so", 0o120777, "resources/PumaPlant.fmu: member .* symbolic link"),
    ]:
        bad = repack(archive, tmp_path / "inner.ssp", {PLANT: with_member(name, b"x", attr)})
        refused(bad, message)
    bomb = repack(archive, tmp_path / "bomb.ssp", {PLANT: with_member("big.bin", bytes(3 << 20))})
    refused(bomb, "PumaPlant.fmu: member 'big.bin' unpacks to", limits=Limits(member_bytes=2 << 20))


def test_extract_to_must_be_empty(archive, tmp_path):
    folder = tmp_path / "given"
    folder.mkdir()
    (folder / "something").write_text("mine")
    refused(archive, "the folder is not empty", extract_to=folder)
    assert (folder / "something").read_text() == "mine"
    with read_ssp(archive, extract_to=tmp_path / "new") as desc:
        assert desc.component("plant").fmu == tmp_path / "new" / PLANT
    assert (tmp_path / "new" / PLANT).is_file()  # a given folder belongs to the caller


def test_duplicate_member_is_refused(archive, tmp_path):
    bad = repack(archive, tmp_path / "dup.ssp", add=[(PLANT, b"a second plant")])
    refused(bad, "member 'resources/PumaPlant.fmu' appears twice")


def test_member_count_and_sizes_are_capped(archive, tmp_path):
    big = repack(archive, tmp_path / "big.ssp", add=[("extra/big.bin", bytes(3 << 20))])
    refused(big, r"'extra/big.bin' unpacks to 3145728 bytes \(limit 1048576\)",
            limits=Limits(member_bytes=1 << 20))  # fmt: skip
    refused(big, "unpacks to more than 2000000 bytes", limits=Limits(total_bytes=2_000_000))
    refused(archive, r"has 11 members \(limit 5\)", limits=Limits(members=5))
    refused(archive, "SystemStructure.ssd' is 16", limits=Limits(xml_bytes=1000))


def test_parameter_set_reading_is_bounded(archive, tmp_path):
    """One .ssv bound many times cannot make the reader parse without end."""
    many = b'<ssd:ParameterBinding source="resources/observer_controller.ssv" />' * 30
    edit = ssd_edit(b"<ssd:ParameterBindings>", b"<ssd:ParameterBindings>" + many)
    bad = repack(archive, tmp_path / "many.ssp", {SSD: edit})
    refused(bad, "parameter sets bound add up to more than 80000 bytes",
            limits=Limits(xml_bytes=20000))  # fmt: skip


def test_member_count_is_checked_before_the_directory_is_loaded(archive, tmp_path):
    raw = bytearray(archive.read_bytes())
    end = raw.rfind(b"PK\x05\x06")  # end of central directory: entry counts at +8 and +10
    raw[end + 8 : end + 12] = struct.pack("<HH", 60000, 60000)
    (tmp_path / "many.ssp").write_bytes(bytes(raw))
    refused(tmp_path / "many.ssp", r"many.ssp has 60000 members \(limit 2000\)")


def _set_sizes(data: bytes, name: bytes, size: int) -> bytes:
    """Rewrite a member's uncompressed size in its local header and central directory entry."""
    out = bytearray(data)
    for sig, off in ((b"PK\x03\x04", 22), (b"PK\x01\x02", 24)):
        i = out.find(sig)
        while i >= 0:
            name_at = i + (30 if sig == b"PK\x03\x04" else 46)
            if out[name_at : name_at + len(name)] == name:
                out[i + off : i + off + 4] = struct.pack("<I", size)
            i = out.find(sig, i + 4)
    return bytes(out)


def test_lying_header_cannot_fill_the_disk(archive, tmp_path):
    """A member whose header claims 1000 bytes but inflates to 50 MB: at most the claimed bytes
    are written, then the member is refused (its CRC covers the real data)."""
    honest = repack(archive, tmp_path / "bomb.ssp", add=[("extra/bomb.bin", bytes(50 << 20))])
    liar = tmp_path / "liar.ssp"
    liar.write_bytes(_set_sizes(honest.read_bytes(), b"extra/bomb.bin", 1000))
    with zipfile.ZipFile(liar) as z:
        assert z.getinfo("extra/bomb.bin").file_size == 1000
    folder = tmp_path / "out"
    refused(liar, r"member 'extra/bomb.bin' is corrupt \(bad CRC\)", extract_to=folder)
    written = sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())
    assert (folder / "extra" / "bomb.bin").stat().st_size <= 1000
    assert written < 1 << 20


def bad_crc(archive: Path, out: Path) -> Path:
    """The archive stored (not deflated) with one bit of a parameter set flipped."""
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as z:
        for info, data in members(archive):
            z.writestr(info.filename, data)
    raw = bytearray(out.read_bytes())
    at = raw.find(b'<ssv:Parameter name="wall_k"') + 16  # inside the first plant .ssv
    assert at > 16
    raw[at + 6] ^= 0x01
    out.write_bytes(bytes(raw))
    return out


def test_bad_crc_names_the_member(archive, tmp_path):
    refused(
        bad_crc(archive, tmp_path / "crc.ssp"),
        r"member 'resources/\w+\.ssv' is corrupt \(bad CRC\)",
    )


def test_no_place_to_extract_is_one_error(archive, tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "missing" / "tmp"))
    refused(archive, "cannot make a folder to extract PaperScenario-native.ssp into")
    refused(tmp_path, "is not a file")


def test_not_a_zip_and_truncated_zip(archive, tmp_path):
    (tmp_path / "text.ssp").write_text("hello")
    refused(tmp_path / "text.ssp", "not an SSP archive")
    data = archive.read_bytes()
    (tmp_path / "cut.ssp").write_bytes(data[: len(data) // 2])
    refused(tmp_path / "cut.ssp", "not an SSP archive")
    refused(tmp_path / "nothing.ssp", "does not exist")


# --- the SSD's content ---------------------------------------------------------------------------

COMPONENT = b'<ssd:Component name="plant" source="resources/PumaPlant.fmu"'
CONNECTION = b'<ssd:Connection startElement="controller"'
EXPERIMENT = b'<ssd:DefaultExperiment startTime="0.0" stopTime="20.0">'


@pytest.mark.parametrize(
    "old,new,message",
    [
        (COMPONENT, b'<ssd:Component source="resources/PumaPlant.fmu"', "malformed SSD.*'name'"),
        (COMPONENT, b'<ssd:Component name="plant"', "attribute 'source' is required"),
        (
            COMPONENT,
            b'<ssd:Component name="controller" source="resources/PumaPlant.fmu"',
            "component 'controller' is declared twice",
        ),
        (CONNECTION, b"<ssd:Connection", "connections to the system's own connectors"),
        (b'startConnector="', b'startConnectorX="', "malformed SSD"),
        (EXPERIMENT, b'<ssd:DefaultExperiment startTime="0.0" stopTime="soon">', "malformed SSD"),
        (
            EXPERIMENT,
            b'<ssd:DefaultExperiment startTime="0.0" stopTime="INF">',
            "stopTime: 'INF' is not a finite number",
        ),
        (
            EXPERIMENT,
            b'<ssd:DefaultExperiment startTime="NaN" stopTime="20">',
            "startTime: 'NaN' is not a finite number",
        ),
        (EXPERIMENT, b'<ssd:DefaultExperiment startTime="5" stopTime="1">', "not after startTime"),
        (b'stepSize="0.0025"', b'stepSize="fast"', "stepSize: 'fast' is not a number"),
        (b'stepSize="0.0025"', b'stepSize="-1e-3"', "stepSize: -0.001 is not positive"),
        (b'stepSize="0.0025"', b'stepSize="1e999"', "stepSize: '1e999' is not a finite number"),
        (b'<ssc:BaseUnit s="-1" />', b'<ssc:BaseUnit s="x" />', "malformed SSD"),
        (
            b"<?xml version='1.0' encoding='UTF-8'?>",
            b'<?xml version="1.0"?><!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>',
            "DOCTYPE",
        ),
        (b'name="plant"', 'name="pl\xe4nt"'.encode("latin-1"), "not UTF-8"),
        (b"<ssd:Elements>", b"<ssd:Elements", "malformed SSD"),
    ],
)
def test_malformed_ssd_gives_one_ssp_error(archive, tmp_path, old, new, message):
    refused(repack(archive, tmp_path / "bad.ssp", {SSD: ssd_edit(old, new)}), message)


def test_malformed_parameter_set_names_the_file(archive, tmp_path):
    edit = ssd_edit(b'<ssv:Real value="0.65"', b'<ssv:Real value="lots"')
    bad = repack(archive, tmp_path / "bad.ssv.ssp", {"resources/observer_plant.ssv": edit})
    refused(bad, "malformed parameter set in .*resources/observer_plant.ssv")


@pytest.mark.parametrize(
    "old,new,message",
    [
        (
            b'<ssv:Real value="0.65"',
            b'<ssv:Real value="1e400"',
            "variable plant.wall_x: '1e400' is out of range",
        ),
        (
            b'<ssv:Parameter name="wall_k"',
            b'<ssv:Parameter name="wall_kk"',
            "unknown parameter plant.wall_kk in parameter set 'observer'; did you mean"
            " plant.wall_k, plant.wall_x, plant.wall_d?",
        ),
    ],
)
def test_a_bad_parameter_value_names_the_archive_and_the_ssv(archive, tmp_path, old, new, message):
    """Read fine, refused by the master: the line still says which archive and which .ssv."""
    edits = {"resources/observer_plant.ssv": ssd_edit(old, new)}
    bad = repack(archive, tmp_path / "values.ssp", edits)
    with read_ssp(bad) as system, pytest.raises(MasterError) as err:
        Master(system, RunOptions(parameter_set="observer"))
    assert str(err.value) == f"{bad}: resources/observer_plant.ssv: {message}" + (
        " (a 64-bit float is at most 1.798e+308 in magnitude)" if "1e400" in message else ""
    )


@pytest.mark.slow
def test_cli_gives_one_line_for_each_bad_archive(archive, tmp_path):
    """End to end: the CLI on hostile archives prints one line naming the problem, no traceback,
    and exits non-zero."""
    link = zipfile.ZipInfo("resources/link.fmu")
    link.external_attr = 0o120777 << 16
    plant = b'source="resources/PumaPlant.fmu"'
    cases = {
        "absolute member": (repack(archive, tmp_path / "a.ssp", add=[("/tmp/x.fmu", b"x")]),
                            "member '/tmp/x.fmu' has an absolute name"),
        "absolute source": (repack(archive, tmp_path / "b.ssp",
                                   {SSD: ssd_edit(plant, b'source="/etc/hostname"')}),
                            "source '/etc/hostname' has an absolute path"),
        "escaping source": (repack(archive, tmp_path / "c.ssp",
                                   {SSD: ssd_edit(plant, b'source="../PumaPlant.fmu"')}),
                            "source '../PumaPlant.fmu' has a '..' path component"),
        "symlink": (repack(archive, tmp_path / "d.ssp", add=[(link, b"/etc/passwd")]),
                    "member 'resources/link.fmu' is a symbolic link"),
        "bad CRC": (bad_crc(archive, tmp_path / "e.ssp"), "is corrupt (bad CRC)"),
        "missing ssv": (repack(archive, tmp_path / "f.ssp", drop=("resources/measured_plant.ssv",)),
                        "resources/measured_plant.ssv is missing from the archive"),
        "duplicate component": (
            repack(archive, tmp_path / "g.ssp", {SSD: ssd_edit(
                b'<ssd:Component name="plant"', b'<ssd:Component name="controller"')}),
            "component 'controller' is declared twice"),
        "not a zip": (tmp_path / "h.ssp", "is not an SSP archive"),
    }  # fmt: skip
    (tmp_path / "h.ssp").write_bytes(b"PK\x03\x04" + bytes(100))
    for case, (path, message) in cases.items():
        cmd = [sys.executable, "-m", "impedance_cosim.cli", "run", "--ssp", str(path), "--stop",
               "0.05", "--no-figures", "--out", str(tmp_path / "out")]  # fmt: skip
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        lines = done.stderr.strip().splitlines()
        assert done.returncode != 0, case
        assert len(lines) == 1 and message in lines[0], (case, done.stderr)
        assert "Traceback" not in done.stderr + done.stdout, case


@pytest.mark.slow
def test_cli_run_leaves_no_extraction_folder(archive, tmp_path):
    """A CLI run leaves no folder of the reader's: a successful one, one refused at load and
    one interrupted by Ctrl-C."""
    tmp = tmp_path / "cli_tmp"
    tmp.mkdir()
    env = dict(os.environ, TMPDIR=str(tmp))
    bad = repack(
        archive, tmp_path / "bad.ssp", {SSD: ssd_edit(b'stepSize="0.0025"', b'stepSize="x"')}
    )
    for path, code in ((archive, 0), (bad, 2)):
        cmd = [sys.executable, "-m", "impedance_cosim.cli", "run", "--ssp", str(path), "--stop",
               "0.05", "--no-figures", "--out", str(tmp_path / "out")]  # fmt: skip
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
        assert done.returncode == code, done.stderr
        assert leftovers(tmp) == []
    assert "stepSize: 'x' is not a number" in done.stderr
    cmd[cmd.index(str(bad))] = str(archive)
    cmd[cmd.index("0.05")] = "400"
    run = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while not leftovers(tmp) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert leftovers(tmp), "the run never extracted the archive"
        time.sleep(0.5)
        run.send_signal(signal.SIGINT)  # Ctrl-C in the middle of the run
        run.wait(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert leftovers(tmp) == []


# --- fuzz ----------------------------------------------------------------------------------------

ATTR = re.compile(rb'\s[A-Za-z]+="[^"]*"')
VALUE = re.compile(rb'="([^"]*)"')
NUMBER = re.compile(rb"-?\d+(\.\d+)?([eE]-?\d+)?")
ODD = ["../", "/", "\\", "%2e%2e/", "\u202e", "\U0001f600", "\x00", "&amp;", "<", "\ufeff", "é"]
HUGE = [b"1e999", b"-1e308", b"NaN", b"INF", b"0", b"-0", b"99999999999999999999", b"1e-320"]


def _mutate_text(rng: random.Random, data: bytes) -> bytes:
    for _ in range(rng.randint(1, 3)):
        op = rng.randrange(6)
        if op == 0:  # delete an attribute
            found = list(ATTR.finditer(data))
            if found:
                m = rng.choice(found)
                data = data[: m.start()] + data[m.end() :]
        elif op == 1:  # swap two attribute values
            found = list(VALUE.finditer(data))
            if len(found) > 1:
                a, b = sorted(rng.sample(found, 2), key=lambda m: m.start())
                va, vb = a.group(1), b.group(1)
                data = (data[: a.start(1)] + vb + data[a.end(1) : b.start(1)] + va
                        + data[b.end(1) :])  # fmt: skip
        elif op == 2:  # insert something odd into a value
            found = list(VALUE.finditer(data))
            if found:
                m = rng.choice(found)
                odd = rng.choice(ODD).encode("utf-8", "surrogatepass")
                data = data[: m.start(1)] + odd + data[m.start(1) :]
        elif op == 3:  # a number becomes huge, tiny or not finite
            found = list(NUMBER.finditer(data))
            if found:
                m = rng.choice(found)
                data = data[: m.start()] + rng.choice(HUGE) + data[m.end() :]
        elif op == 4:  # random unicode anywhere
            at = rng.randrange(len(data) + 1)
            text = "".join(chr(rng.randrange(1, 0x2FFFF)) for _ in range(rng.randint(1, 4)))
            data = data[:at] + text.encode("utf-8", "surrogatepass") + data[at:]
        else:  # duplicate or drop a line
            lines = data.split(b"\n")
            i = rng.randrange(len(lines))
            lines[i : i + 1] = [] if rng.random() < 0.5 else [lines[i], lines[i]]
            data = b"\n".join(lines)
    return data


def _mutant(rng: random.Random, base: bytes, entries, path: Path) -> None:
    kind = rng.randrange(4)
    if kind == 0:  # flip bytes of the archive
        raw = bytearray(base)
        for _ in range(rng.randint(1, 8)):
            raw[rng.randrange(len(raw))] ^= 1 << rng.randrange(8)
        path.write_bytes(bytes(raw))
        return
    if kind == 1:  # truncate it
        path.write_bytes(base[: rng.randrange(len(base))])
        return
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for info, data in entries:
            name = info.filename
            odds = 0.9 if name == SSD else 0.15 if name.endswith(".ssv") else 0.0
            if kind == 2 and rng.random() < odds:
                data = _mutate_text(rng, data)
            if kind == 3 and rng.random() < 0.3:  # rename, drop or turn into a link
                choice = rng.randrange(4)
                if choice == 0:
                    name = rng.choice(["../", "/tmp/", "a\\", "C:", "./", "x/../"]) + name
                elif choice == 1:
                    continue
                elif choice == 2:
                    info = zipfile.ZipInfo(name)
                    info.external_attr = 0o120777 << 16
                    z.writestr(info, b"/etc/passwd")
                    continue
                else:
                    name = name.upper()
            z.writestr(name, data)


class _AnythingGoes:
    """A stand-in schema that accepts every document: the reader's own checks must hold alone."""

    error_log = ()

    def validate(self, doc) -> bool:
        return True


def mutant_outcomes(archive: Path, seed: int, tmp_path: Path, n: int = 400) -> dict[str, int]:
    """read_ssp on n mutants of archive (_mutant, from seed): how many gave a SystemDescription
    ("ok") and how many a one-line SspError; anything else fails the calling test."""
    rng = random.Random(seed)
    base, entries = archive.read_bytes(), members(archive)
    failures, outcomes = [], {"ok": 0, "SspError": 0}
    for case in range(n):
        path = tmp_path / f"mutant{case % 4}.ssp"
        _mutant(rng, base, entries, path)
        try:
            desc = read_ssp(path)
        except SspError as exc:
            outcomes["SspError"] += 1
            if "\n" in str(exc) or not str(exc):
                failures.append((case, f"message not one line: {exc!r}"))
        except Exception:  # noqa: BLE001 - the point of the test
            failures.append((case, traceback.format_exc(limit=3)))
        else:
            assert isinstance(desc, SystemDescription)
            outcomes["ok"] += 1
            desc.close()
    assert not failures, failures[:3]
    return outcomes


@pytest.mark.parametrize("schema", ["with schema", "without schema"])
@pytest.mark.slow
def test_fuzz_mutated_archives_end_in_a_description_or_an_ssp_error(
    archive, tmp_path, private_tmp, monkeypatch, schema
):
    """400 mutants from a fixed seed (bytes flipped, truncated, SSD/SSV text mutated, members
    renamed/dropped/turned into links): each gives a SystemDescription or a one-line SspError.
    Run a second time with schema validation disabled, so the reader's own checks are fuzzed."""
    if schema == "without schema":
        monkeypatch.setattr(ssd, "_schema", lambda name: _AnythingGoes())
    outcomes = mutant_outcomes(archive, 20261201, tmp_path)
    assert outcomes["ok"] >= 5 and outcomes["SspError"] > 100, outcomes  # both paths exercised
    assert leftovers(private_tmp) == []


# --- SSP variants: one system description per scenario -------------------------------------------


def test_variant_ssds_are_the_scenarios(archive, tmp_path):
    with read_ssp(archive) as desc:
        assert desc.variants == {"observer": SSD, "difference": "difference.ssd",
                                 "measured": "measured.ssd"}  # fmt: skip
        difference = {p.name: p.value for p in desc.parameter_sets["difference"]}
        assert difference["controller.velocity_source"] == "2"
        assert difference["plant.wall_k"] == "10000.0"  # each component's binding, merged
    with read_ssp(archive, ssd="difference.ssd") as desc:  # one named variant alone
        assert list(desc.parameter_sets) == ["difference"]
    refused(archive, r"has no system description 'nope.ssd' \(have \['SystemStructure.ssd', "
            "'difference.ssd', 'measured.ssd'\\]\\)", ssd="nope.ssd")  # fmt: skip


def test_a_variant_of_another_system_is_refused(archive, tmp_path):
    def drop_tau3(data: bytes) -> bytes:  # a valid system alone, but not the default's
        return re.sub(rb'<ssd:Connection startElement="controller" startConnector="tau3"[^>]*/>',
                      b"", data)  # fmt: skip

    bad = repack(archive, tmp_path / "variant.ssp", {"measured.ssd": drop_tau3})
    refused(bad, "variant measured.ssd describes another system than SystemStructure.ssd")
