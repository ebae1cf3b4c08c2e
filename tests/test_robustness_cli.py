"""The CLI's run path under hostile input, interruption and concurrency (issue 10), each case in
a subprocess: the exit status, exactly one line on stderr (never a traceback), and the rows
kept in the CSV."""

from __future__ import annotations

import csv
import io
import os
import re
import signal
import subprocess
import sys
import time
import zipfile
from collections.abc import Callable
from pathlib import Path

import pytest

CLI = [sys.executable, "-m", "impedance_cosim.cli"]
H = 1 / 400
KEPT = re.compile(r"(\d+) rows kept in (\S+\.csv\.partial)")  # a failed run: .partial


def cli(*args: str, cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*CLI, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=300
    )


PROGRESS = re.compile(r"^\S+: +\d+% \d+/\d+ \[")  # util.progress's plain lines (not a terminal)


def one_line(stderr: str) -> str:
    """The single line on stderr besides progress lines (asserts exactly one, no traceback)."""
    lines = [ln for ln in stderr.strip().splitlines() if not PROGRESS.match(ln)]
    assert "Traceback" not in stderr and len(lines) == 1, stderr
    return lines[0]


def read_rows(path: Path) -> tuple[list[str], list[list[float]]]:
    with open(path, newline="") as f:
        reader = csv.reader(f)
        names = next(reader)
        return names, [[float(v) for v in row] for row in reader]


# --- archives with one thing wrong ------------------------------------------------------------


def _rewrite(src: Path, dst: Path, edit: Callable[[str, bytes], bytes | None]) -> Path:
    """A copy of a zip archive with each member passed through edit (None drops it)."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            data = edit(info.filename, zin.read(info.filename))
            if data is not None:
                zout.writestr(zipfile.ZipInfo(info.filename, info.date_time), data)
    return dst


def _in_plant_fmu(edit: Callable[[str, bytes], bytes | None]):
    """An SSP edit that applies edit to the members of the plant's FMU."""

    def ssp_edit(name: str, data: bytes) -> bytes | None:
        if not name.endswith("PumaPlant.fmu"):
            return data
        src, dst = io.BytesIO(data), io.BytesIO()
        with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
            for info in zin.infolist():
                member = edit(info.filename, zin.read(info.filename))
                if member is not None:
                    zout.writestr(zipfile.ZipInfo(info.filename, info.date_time), member)
        return dst.getvalue()

    return ssp_edit


def _bad_crc(name: str, data: bytes) -> bytes:
    """The plant FMU with its binary's stored bytes altered after the CRC was computed."""
    if not name.endswith("PumaPlant.fmu"):
        return data
    buf = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as zin, zipfile.ZipFile(buf, "w") as zout:
        for info in zin.infolist():  # stored, not deflated: a flipped byte still decompresses
            zout.writestr(zipfile.ZipInfo(info.filename, info.date_time), zin.read(info))
    raw = bytearray(buf.getvalue())
    with zipfile.ZipFile(io.BytesIO(bytes(raw))) as z:
        info = next(i for i in z.infolist() if i.filename.startswith("binaries/linux64/"))
    start = info.header_offset + 30 + len(info.filename)  # no extra field in what we wrote
    raw[start + 100] ^= 0xFF
    return bytes(raw)


def _nan_wall(name: str, data: bytes) -> bytes:
    if not name.endswith(".ssv"):
        return data
    return re.sub(rb'(name="wall_k">\s*<ssv:Real value=")[^"]*', rb"\1NaN", data)


def _wrong_guid(name: str, data: bytes) -> bytes:
    if name != "modelDescription.xml":
        return data
    return re.sub(rb'guid="[^"]*"', b'guid="{00000000-0000-0000-0000-000000000000}"', data)


@pytest.fixture(scope="module")
def bad_archives(native_ssp: Path, tmp_path_factory) -> dict[str, Path]:
    """The native system with one defect each."""
    out = tmp_path_factory.mktemp("bad")
    binary = _in_plant_fmu(lambda n, d: b"not an ELF file" * 50 if n.startswith("binaries/") else d)
    return {
        "bad CRC": _rewrite(native_ssp, out / "crc.ssp", _bad_crc),
        "no binary": _rewrite(
            native_ssp,
            out / "nobin.ssp",
            _in_plant_fmu(lambda n, d: None if "binaries/" in n else d),
        ),
        "garbage binary": _rewrite(native_ssp, out / "garbage.ssp", binary),
        "wrong GUID": _rewrite(native_ssp, out / "guid.ssp", _in_plant_fmu(_wrong_guid)),
        "NaN in parameter set": _rewrite(native_ssp, out / "nan.ssp", _nan_wall),
    }


def _read_only_folder(tmp_path: Path) -> Path:
    """A folder this process cannot write into (as root: a read-only file system)."""
    if os.geteuid() != 0:
        folder = tmp_path / "ro"
        folder.mkdir()
        folder.chmod(0o555)
        return folder
    for candidate in (Path("/sys/kernel"), Path("/proc/self")):
        try:
            (candidate / "impedance-cosim-probe").touch()
        except OSError:
            return candidate
    pytest.skip("no read-only folder to test with")


# (ssp: "python" or a bad_archives key, extra args, exit status, message, rows kept or None)
CASES = [
    ("python", ["--stop", "inf"], 2, "argument --stop: must be a finite number > 0", None),
    ("python", ["--stop", "nan"], 2, "argument --stop: must be a finite number > 0", None),
    ("python", ["--stop", "-1"], 2, "argument --stop: must be a finite number > 0", None),
    ("python", ["--step", "0"], 2, "argument --step: must be a finite number > 0", None),
    ("python", ["--step", "-1"], 2, "argument --step: must be a finite number > 0", None),
    ("python", ["--step", "nan"], 2, "argument --step: must be a finite number > 0", None),
    ("python", ["--stop", "1e9", "--step", "1e-6"], 2, "GiB of memory (limit 1 GiB)", None),
    ("python", ["--out", "{file}"], 2, "is a file, not a folder", None),
    ("python", ["--out", "{read_only}"], 2, "is not a writable folder", None),
    ("python", ["--scenario", "fast"], 2, "no parameter set 'fast'", None),
    ("python", ["--set", "controller.K=abc"], 2, "'abc' is not a valid Real", None),
    ("python", ["--set", "plant.noise_seed=4294967297"], 2, "beyond the 32-bit range", None),
    ("python", ["--set", "controller.K=nan"], 1, "parameter K1 must be finite", 0),
    ("python", ["--set", "plant.m1=-1"], 1, "parameter m1 must be >= 0.0", 0),
    ("native", ["--set", "plant.m1=-1"], 1, "parameter m1 must be >= 0", 0),
    # diverges: the plant refuses the step at its work bound (before 1000 contact switches)
    ("python", ["--set", "controller.G=1e9"], 1, "(parameter max_rhs_evaluations)", 3),
    ("NaN in parameter set", [], 1, "parameter wall_k must be finite", 0),
    ("bad CRC", [], 2, "binaries/linux64/PumaPlant.so is corrupt (CRC check failed)", None),
    ("no binary", [], 2, "PumaPlant.fmu has no binary for this platform", None),
    ("garbage binary", [], 1, "cannot load the binary of PumaPlant.fmu", 0),
    ("wrong GUID", [], 1, "GUID {00000000-0000-0000-0000-000000000000} does not match", 0),
]


@pytest.mark.parametrize("ssp,args,status,message,rows", CASES)
@pytest.mark.slow
def test_bad_input_gives_one_line(
    ssp, args, status, message, rows, ssp_path, native_ssp, bad_archives, tmp_path
):
    archive = {"python": ssp_path, "native": native_ssp}.get(ssp) or bad_archives[ssp]
    (tmp_path / "a_file").write_text("not a folder\n")
    fill = {"{file}": str(tmp_path / "a_file")}
    if "{read_only}" in args:
        fill["{read_only}"] = str(_read_only_folder(tmp_path))
    args = [fill.get(a, a) for a in args]
    out = tmp_path / "out"
    done = cli("run", "--ssp", str(archive), "--stop", "0.5", "--out", str(out), "--no-figures",
               *args, cwd=tmp_path)  # fmt: skip
    line = one_line(done.stderr)
    assert done.returncode == status and message in line, line
    if rows is None:  # refused before simulating: nothing written
        assert not (out / "observer.csv").exists()
        return
    kept = KEPT.search(line)
    assert kept and int(kept.group(1)) == rows, line
    names, data = read_rows(Path(kept.group(2)))
    assert names[0] == "time" and len(data) == rows
    assert [r[0] for r in data] == pytest.approx([i * H for i in range(rows)])


@pytest.mark.slow
def test_swap_shares_the_checks(ssp_path, bad_archives, tmp_path):
    with zipfile.ZipFile(bad_archives["bad CRC"]) as z:
        bad = tmp_path / "PumaPlant.fmu"
        bad.write_bytes(z.read("resources/PumaPlant.fmu"))
    done = cli("swap", "--ssp", str(ssp_path), "--replace", f"plant={bad}", "--stop", "0.5",
               "--out", str(tmp_path / "out"), "--no-figures", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 2 and "is corrupt (CRC check failed)" in one_line(done.stderr)


# --- interruption -----------------------------------------------------------------------------


def _interrupt(args: list[str], out: Path, sig: int, cwd: Path, env: dict) -> tuple[int, str]:
    """Start a run, send sig once it has run about a second and written rows (real time: rows
    are written when it stops, so wait longer to be past initialization on a loaded machine);
    (status, line)."""
    realtime = "--realtime" in args
    written, wait = (0, 3.0) if realtime else (1e4, 1.0)
    proc = subprocess.Popen([*CLI, *args, "--out", str(out)], cwd=cwd, env=env, text=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)  # fmt: skip
    try:
        started = time.monotonic()
        while time.monotonic() - started < 60 and proc.poll() is None:
            partial = list(out.glob(".staging-*/.observer.csv.*.tmp"))
            if (
                time.monotonic() - started > wait
                and partial
                and partial[0].stat().st_size > written
            ):
                break
            time.sleep(0.05)
        assert proc.poll() is None, "the run ended before it could be interrupted"
        proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    return proc.returncode, one_line(stderr)


def _check_interrupted(status, line, sig, out, ssp, cwd, extra=()) -> None:
    """Exit 128 + sig, one line saying when it stopped, and a CSV (observer.csv.partial: the
    command did not complete) whose rows are exactly those of an uninterrupted run to that
    time; no staging folder left."""
    name = signal.Signals(sig).name
    assert status == 128 + sig, line
    m = re.search(rf"interrupted by {name} at t=(\S+) s; (\d+) rows kept in (\S+)", line)
    assert m, line
    stop, rows = float(m.group(1)), int(m.group(2))
    kept = out / "observer.csv.partial"  # the run did not complete: not under the result's name
    assert Path(m.group(3)) == kept and rows == round(stop / H) + 1
    names, data = read_rows(kept)
    assert len(data) == rows and data[-1][0] == pytest.approx(stop, rel=1e-12)
    ref = cwd / "reference"
    done = cli("run", "--ssp", str(ssp), "--stop", repr(stop), "--out", str(ref), "--no-figures",
               cwd=cwd)  # fmt: skip
    assert done.returncode == 0, done.stderr
    ref_names, ref_data = read_rows(ref / "observer.csv")
    common = [k for k, n in enumerate(names) if n in ref_names]
    assert len(common) == len(ref_names)
    assert [[row[k] for k in common] for row in data] == ref_data
    assert list(out.glob(".*.tmp")) == [] and list(out.glob(".staging-*")) == []


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.slow
def test_interrupted_native_run_keeps_every_row(sig, native_ssp, tmp_path):
    env = {**os.environ, "TMPDIR": str(tmp_path / "tmp")}
    (tmp_path / "tmp").mkdir()
    out = tmp_path / "out"
    args = ["run", "--ssp", str(native_ssp), "--stop", "400", "--no-figures"]
    status, line = _interrupt(args, out, sig, tmp_path, env)
    _check_interrupted(status, line, sig, out, native_ssp, tmp_path)
    assert os.listdir(tmp_path / "tmp") == []  # extraction folders removed, also when stopped


@pytest.mark.slow
def test_interrupted_python_fmu_run_keeps_every_row(ssp_path, tmp_path):
    out = tmp_path / "out"
    args = ["run", "--ssp", str(ssp_path), "--stop", "400", "--no-figures"]
    status, line = _interrupt(args, out, signal.SIGINT, tmp_path, None)
    _check_interrupted(status, line, signal.SIGINT, out, ssp_path, tmp_path)


@pytest.mark.slow
def test_interrupted_realtime_run_keeps_every_row(native_ssp, tmp_path):
    out = tmp_path / "out"
    args = ["run", "--ssp", str(native_ssp), "--stop", "60", "--realtime", "--no-figures"]
    status, line = _interrupt(args, out, signal.SIGINT, tmp_path, None)
    _check_interrupted(status, line, signal.SIGINT, out, native_ssp, tmp_path)
    names, _ = read_rows(out / "observer.csv.partial")
    assert names[-3:] == ["rt.start_late_s", "rt.compute_s", "rt.lateness_s"]


# --- temporary folders and concurrency --------------------------------------------------------


def test_a_run_leaves_no_temporary_folders(ssp_path, native_ssp, tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {**os.environ, "TMPDIR": str(tmp)}
    for archive in (ssp_path, native_ssp):
        done = cli("run", "--ssp", str(archive), "--stop", "0.5", "--out", str(tmp_path / "out"),
                   "--no-figures", cwd=tmp_path, env=env)  # fmt: skip
        assert done.returncode == 0, done.stderr
        assert os.listdir(tmp) == []


@pytest.mark.slow
def test_a_second_run_into_a_busy_folder_is_refused(native_ssp, tmp_path):
    """Run B starts while run A (paced to the wall clock: 5 s whatever the load) is writing into
    the same --out: B is refused with one line before it simulates anything; A's CSV is whole
    and equal to an undisturbed run's."""
    args = ["run", "--ssp", str(native_ssp), "--stop", "5", "--no-figures", "--out"]
    expected = cli(*args, str(tmp_path / "ref"), cwd=tmp_path)
    assert expected.returncode == 0, expected.stderr
    out = tmp_path / "out"
    first = subprocess.Popen([*CLI, *args, str(out), "--realtime"], cwd=tmp_path, text=True,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)  # fmt: skip
    try:
        started = time.monotonic()
        while (
            not list(out.glob(".staging-*/.observer.csv.*.tmp")) and time.monotonic() - started < 60
        ):
            time.sleep(0.02)
        second = cli(*args, str(out), cwd=tmp_path)
        assert first.poll() is None, "the first run ended before the second started"
        assert first.wait(timeout=120) == 0, first.stderr.read()
    finally:
        first.kill()
    line = one_line(second.stderr)
    assert second.returncode == 2 and "is in use by another impedance-cosim process" in line
    names, data = read_rows(out / "observer.csv")
    ref_names, ref_data = read_rows(tmp_path / "ref" / "observer.csv")
    assert names[: len(ref_names)] == ref_names and len(data) == len(ref_data) == 2001
    assert [row[: len(ref_names)] for row in data] == ref_data
    assert list(out.glob(".*.tmp")) == []


@pytest.mark.slow
def test_two_builds_into_one_folder_at_once(tmp_path):
    from impedance_cosim.cosim.ssp.read import read_ssp

    out = tmp_path / "fmus"
    for _ in range(2):
        procs = [
            subprocess.Popen(
                [*CLI, "build", "--out", str(out)],
                cwd=tmp_path,
                text=True,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
            )  # fmt: skip
            for _ in range(2)
        ]
        for p in procs:
            assert p.wait(timeout=300) == 0, p.stderr.read()
    archives = sorted(out.rglob("*.fmu")) + sorted(out.glob("*.ssp"))
    assert len(archives) >= 7 and not list(out.rglob("*.tmp"))
    for path in archives:
        with zipfile.ZipFile(path) as z:
            assert z.testzip() is None, path
    assert read_ssp(out / "PaperScenario.ssp").parameter_sets


@pytest.mark.parametrize("loop", ["c", "python"])
def test_sink_gets_every_row_and_a_signal_stops_the_run(native_ssp, loop):
    """In process: the sink's blocks are the result's rows; SIGINT (sent from the sink, so
    mid-run) stops the run after the block under way with RunInterrupted and every row kept."""
    import numpy as np

    from impedance_cosim.cosim.master.master import Master
    from impedance_cosim.cosim.master.options import RunOptions
    from impedance_cosim.cosim.ssp.read import read_ssp
    from impedance_cosim.util.interrupt import RunInterrupted

    system = read_ssp(native_ssp)
    blocks: list = []
    done = Master(system, RunOptions(stop_time=2.0, loop=loop)).run(
        sink=lambda n, b: blocks.append(b.copy())
    )
    assert len(blocks[0]) == 0 and np.array_equal(np.vstack(blocks), done.data)

    blocks.clear()

    def sink(names, block):
        blocks.append(block.copy())
        if sum(map(len, blocks)) > 1000 and not sent:
            sent.append(signal.SIGINT)
            os.kill(os.getpid(), signal.SIGINT)

    sent: list = []
    before = signal.getsignal(signal.SIGINT)  # SIG_IGN when the tests run in a background job
    with pytest.raises(RunInterrupted) as caught:
        Master(system, RunOptions(stop_time=400.0, loop=loop)).run(sink=sink)
    kept = caught.value.result.data
    assert np.array_equal(np.vstack(blocks), kept) and 1000 < len(kept) < 2000
    assert np.array_equal(kept[:801], done.data)
    assert caught.value.message == f"interrupted by SIGINT at t={kept[-1, 0]:.9g} s"
    assert signal.getsignal(signal.SIGINT) is before  # handlers restored


@pytest.mark.parametrize(
    "kwargs,message",
    [
        ({"step_size": 0.0}, "step size must be a finite number > 0 (got 0.0)"),
        ({"step_size": -1.0}, "step size must be a finite number > 0"),
        ({"step_size": float("nan")}, "step size must be a finite number > 0"),
        ({"stop_time": float("inf")}, "stop time must be finite"),
        ({"stop_time": float("nan")}, "stop time must be finite"),
        ({"stop_time": 1e300}, "GiB of memory"),
        ({"stop_time": 1e-300}, "the run length 1e-300 s is shorter than one 0.0025 s step"),
        ({"stop_time": 1.2e-12}, "is shorter than one 0.0025 s step"),
    ],
)
def test_master_refuses_bad_times(native_ssp, kwargs, message):
    """The API too: a zero step is refused, not replaced by the default."""
    from impedance_cosim.cosim.master.master import Master, MasterError
    from impedance_cosim.cosim.master.options import RunOptions
    from impedance_cosim.cosim.ssp.read import read_ssp

    with pytest.raises(MasterError, match=re.escape(message)):
        Master(read_ssp(native_ssp), RunOptions(**kwargs))
