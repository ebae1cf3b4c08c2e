"""Results files under a full disk, folders two commands want at once, and input that must write
nothing (issue 20), each case through the CLI in a subprocess: the exit status, one line naming
the file and its folder, and what is on disk afterwards (whole files or none, rows kept)."""

from __future__ import annotations

import contextlib
import os
import re
import resource
import subprocess
import sys
import time
from pathlib import Path

import pytest

CLI = [sys.executable, "-m", "impedance_cosim.cli"]
PARTIAL = re.compile(r"the (\d+) whole rows that fit \(to t=(\S+) s\) are in (\S+\.partial)$")


def cli(*args: str, cwd: Path, limit: int | None = None) -> subprocess.CompletedProcess:
    """The CLI in a subprocess; limit: RLIMIT_FSIZE in bytes (a write beyond it fails, EFBIG)."""

    def file_size_limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return subprocess.run([*CLI, *args], cwd=cwd, capture_output=True, text=True, timeout=300,
                          preexec_fn=file_size_limit if limit else None)  # fmt: skip


def lines(stderr: str) -> list[str]:
    """stderr's lines (no traceback, ever)."""
    assert "Traceback" not in stderr, stderr
    return stderr.strip().splitlines()


def whole_csv(path: Path) -> int:
    """Rows of a CSV that must be whole: ends with a newline, every row as wide as the header."""
    text = path.read_text()
    assert text.endswith("\n"), text[-200:]
    header, *rows = text.splitlines()
    width = header.count(",")
    assert all(row.count(",") == width for row in rows)
    [float(v) for v in rows[-1].split(",")]
    return len(rows)


@contextlib.contextmanager
def tmpfs(folder: Path, options: str):
    """A tmpfs mounted at folder (root only), unmounted afterwards; skip when it cannot be."""
    folder.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)],
                          capture_output=True, text=True)  # fmt: skip
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.strip() or 'not root'})")
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)


# --- a full disk ------------------------------------------------------------------------------


def _check_partial(out: Path, line: str) -> None:
    """observer.csv not there, its rows whole in observer.csv.partial as the line says."""
    assert f"cannot write observer.csv in {out}: " in line, line
    found = PARTIAL.search(line)
    assert found, line
    partial = Path(found[3])
    assert partial == out / "observer.csv.partial" and not (out / "observer.csv").exists()
    assert whole_csv(partial) == int(found[1]) > 0
    last = partial.read_text().splitlines()[-1].split(",")[0]
    assert float(last) == pytest.approx(float(found[2]))
    assert not list(out.glob(".*.tmp*")), os.listdir(out)


def test_a_full_disk_keeps_the_rows_that_fit_and_names_the_file(native_ssp, tmp_path):
    """A 2 MB tmpfs: the CSV at its final name never holds half a row; the rows that fit are in
    observer.csv.partial, cut back to the last whole row; the error line names the file, its
    folder and where the rows are; exit status 1 (a failed run)."""
    with tmpfs(tmp_path / "full", "size=2m") as full:
        out = full / "a"
        done = cli("run", "--ssp", str(native_ssp), "--stop", "20", "--out", str(out),
                   "--no-figures", "--no-report", cwd=tmp_path)  # fmt: skip
        assert done.returncode == 1, done.stderr
        error = [ln for ln in lines(done.stderr) if ": error: " in ln]
        assert len(error) == 1 and "No space left on device" in error[0], done.stderr
        _check_partial(out, error[0])
        warnings = [ln for ln in lines(done.stderr) if ": warning: " in ln]
        assert all(str(out / "run.json.partial") in w for w in warnings), warnings  # named
        assert set(os.listdir(out)) == {"observer.csv.partial"}


def test_a_file_size_limit_is_a_full_disk_without_a_mount(native_ssp, tmp_path):
    """The same mechanism without root: RLIMIT_FSIZE (1 MB) makes the CSV's writes fail (EFBIG);
    the small files still get written, run.json saying how the run failed."""
    import json

    out = tmp_path / "out"
    done = cli("run", "--ssp", str(native_ssp), "--stop", "20", "--out", str(out),
               "--no-figures", cwd=tmp_path, limit=2**20)  # fmt: skip
    assert done.returncode == 1, done.stderr
    (line,) = [ln for ln in lines(done.stderr) if ": error: " in ln]
    assert "File too large" in line
    _check_partial(out, line)
    run = json.loads((out / "run.json.partial").read_text())["runs"][0]  # a failed command's
    assert run["status"] == "failed" and "observer.csv.partial" in run["error"]
    assert (out / "report.html.partial").is_file()


def test_a_mat_file_that_does_not_fit_keeps_the_rows_that_fit_and_says_where(native_ssp, tmp_path):
    """--result-format mat under a 1 MB file size limit: the whole file (8001 rows) does not fit;
    the first rows that do are a result file of their own, observer.mat.partial, and the line
    and run.json say so (on main: no rows kept, nothing said)."""
    import json

    from scipy.io import loadmat

    out = tmp_path / "out"
    done = cli("run", "--ssp", str(native_ssp), "--stop", "20", "--out", str(out),
               "--result-format", "mat", "--no-figures", "--no-report", "--no-progress",
               cwd=tmp_path, limit=2**20)  # fmt: skip
    assert done.returncode == 1, done.stderr
    (line,) = [ln for ln in lines(done.stderr) if ": error: " in ln]
    partial = out / "observer.mat.partial"
    match = re.search(r"the first (\d+) of the 8001 rows \(to t=([\d.]+) s\) are in (\S+)$", line)
    assert f"cannot write observer.mat in {out}: File too large" in line and match, line
    assert match.group(3) == str(partial) and not (out / "observer.mat").exists()
    kept = loadmat(partial)["data_2"]
    assert kept.shape[1] == int(match.group(1)) > 1000
    assert f"{kept[0, -1]:.9g}" == match.group(2) and kept[0, 0] == 0.0
    run = json.loads((out / "run.json.partial").read_text())["runs"][0]
    assert run["status"] == "failed" and str(partial) in run["error"] and run["rows"] == 8001


@pytest.mark.slow
def test_a_figure_that_does_not_fit_is_named_and_not_left_half_written(native_ssp, tmp_path):
    """The CSV fits on a 64 kB tmpfs, Fig. 1 does not: the line names the figure (not its
    temporary name, even through nested temporary files) and its folder; no half figure."""
    with tmpfs(tmp_path / "full", "size=64k") as full:
        out = full / "a"
        done = cli("run", "--ssp", str(native_ssp), "--stop", "0.1", "--out", str(out),
                   "--no-progress", cwd=tmp_path)  # fmt: skip
        assert done.returncode == 1, done.stderr
        (line,) = [ln for ln in lines(done.stderr) if ": error: " in ln]
        assert line.endswith(f"cannot write fig1_position_force.png in {out}: No space left on"
                             " device"), line  # fmt: skip
        assert whole_csv(out / "observer.csv.partial") == 41  # the command failed
        assert not list(out.glob("*.png")) and not list(out.glob(".*"))


_TO_CSV = """
import sys
import numpy as np
from impedance_cosim.api import Result
from impedance_cosim.cosim.results.result import RunResult
data = np.random.default_rng(1).random((20000, 12))
run = RunResult(["time", *[f"s{i}" for i in range(11)]], data, 0.0025, "jacobi", "observer")
try:
    Result(run, {"runs": [{}]}).to_csv(sys.argv[1])
except OSError as exc:
    print(exc, file=sys.stderr)
    sys.exit(1)
"""


@pytest.mark.parametrize("where", ["full", "missing folder"])
def test_to_csv_is_whole_or_not_there_and_names_its_target(tmp_path, where):
    """Result.to_csv: a failed write names the target and its folder (never a temporary name)
    and leaves nothing (the rows are still in the Result)."""
    target = tmp_path / ("nosuch" if where == "missing folder" else "") / "r.csv"
    done = subprocess.run([sys.executable, "-c", _TO_CSV, str(target)], capture_output=True,
                          text=True, timeout=120,
                          preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE,
                                                                (2**20, 2**20)))  # fmt: skip
    assert done.returncode == 1, done.stderr
    (line,) = lines(done.stderr)
    assert line.startswith(f"cannot write r.csv in {target.parent}: "), line
    assert ".tmp" not in line and "the rows are still in this Result" in line
    assert os.listdir(tmp_path) == []


_LINES = """
import sys
from impedance_cosim.util.atomic import LineFile
f = LineFile(sys.argv[1])
try:
    for i in range(100000):
        f.append("".join(f"{i},{k},{'x' * 50}\\n" for k in range(30)))
except OSError as exc:
    print(exc, file=sys.stderr)
    sys.exit(1)
"""


def test_an_appended_table_is_cut_back_to_its_last_whole_line(tmp_path):
    """The mechanism of the sweep table and the stability logs: an append that fails part-way
    leaves the file ending in a whole line."""
    path = tmp_path / "sweep.csv"
    done = subprocess.run([sys.executable, "-c", _LINES, str(path)], capture_output=True,
                          text=True, timeout=120,
                          preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE,
                                                                (100_001, 100_001)))  # fmt: skip
    assert done.returncode == 1
    assert lines(done.stderr) == [f"cannot write sweep.csv in {tmp_path}: File too large"]
    text = path.read_text()
    assert 90_000 < len(text) <= 100_001 and text.endswith("\n")
    assert all(len(ln.split(",")) == 3 for ln in text.splitlines())


def test_a_sweep_table_on_a_full_disk_holds_whole_rows_and_says_so(native_ssp, tmp_path):
    """sweep.csv is appended as runs finish: on a full disk (16 kB tmpfs) it ends in a whole
    row, the line names it, its folder and how many rows it holds; exit status 1."""
    import csv

    with tmpfs(tmp_path / "full", "size=16k") as full:
        out = full / "s"
        done = cli("sweep", "--ssp", str(native_ssp), "--serial", "--no-progress", "--grid",
                   "controller.K=lin:50:100:200", "--stop", "0.01", "--out", str(out),
                   cwd=tmp_path)  # fmt: skip
        assert done.returncode == 1, done.stderr
        (line,) = [ln for ln in lines(done.stderr) if ": error: " in ln]
        found = re.search(rf"cannot write sweep.csv in {out}: No space left on device; it holds"
                          r" the (\d+) rows before this one, whole$", line)  # fmt: skip
        assert found, line
        text = (out / "sweep.csv").read_text()
        rows = list(csv.reader(text.splitlines()))
        assert text.endswith("\n") and len({len(r) for r in rows}) == 1
        assert len(rows) - 1 == int(found[1]) > 0
        assert not list(out.glob(".*.tmp*"))


@pytest.mark.slow
def test_a_stability_log_on_a_full_disk_keeps_its_runs_for_resume(native_ssp, tmp_path):
    """The stability study's run log on a full disk (8 kB tmpfs): one line naming it and how
    many finished runs it holds, each line whole; with space again, --resume uses them."""
    args = ["stability", "boundaries", "--quantity", "rate", "--serial", "--no-progress", "--stop",
            "1", "--no-figures", "--ssp", str(native_ssp), "--out"]  # fmt: skip
    with tmpfs(tmp_path / "full", "size=8k") as full:
        out = full / "s"
        done = cli(*args, str(out), cwd=tmp_path)
        assert done.returncode == 1, done.stderr
        (line,) = [ln for ln in lines(done.stderr) if ": error: " in ln]
        found = re.search(rf"cannot write boundaries.runs.jsonl in {out}: No space left on"
                          r" device; it holds the (\d+) finished runs before", line)  # fmt: skip
        assert found and int(found[1]) > 0, line
        text = (out / "boundaries.runs.jsonl").read_text()
        assert text.endswith("\n") and len(text.splitlines()) == int(found[1]) + 1  # + its plan
        subprocess.run(["mount", "-o", "remount,size=8m", str(full)], check=True)
        done = cli(*args, str(out), "--resume", cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        assert f"{found[1]} kept from an earlier run" in done.stdout, done.stdout


# --- one folder, one command at a time ----------------------------------------------------------


def _commands(ssp: Path, out: Path) -> dict[str, list[str]]:
    o = str(out)
    return {
        "run": ["run", "--ssp", str(ssp), "--stop", "0.5", "--no-figures", "--out", o],
        "sweep": [
            "sweep",
            "--ssp",
            str(ssp),
            "--serial",
            "--grid",
            "controller.K=50,60",
            "--stop",
            "0.5",
            "--out",
            o,
        ],  # fmt: skip
        "stability": ["stability", "--ssp", str(ssp), "boundaries", "--stop", "1", "--out", o],
    }


@pytest.mark.parametrize("command", ["run", "sweep", "stability"])
def test_every_command_writing_a_folder_takes_the_one_folder_lock(native_ssp, tmp_path, command):
    """While this process holds the folder's lock (util.atomic.FolderLock, the lock of every
    command), each command is refused with one line naming the holder, and writes nothing."""
    from impedance_cosim.util.atomic import FolderLock

    out = tmp_path / "out"
    out.mkdir()
    with FolderLock(out):
        done = cli(*_commands(native_ssp, out)[command], cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    (line,) = lines(done.stderr)
    assert f"is in use by another impedance-cosim process (pid {os.getpid()})" in line
    assert os.listdir(out) == []


@pytest.mark.slow
def test_a_build_waits_for_the_folder_and_leaves_no_lock_file(tmp_path):
    """build into a folder another command holds: it says it waits, then builds once the folder
    is free; no lock file is left in the folder."""
    from impedance_cosim.util.atomic import LOCK_NAME, FolderLock

    out = tmp_path / "fmus"
    out.mkdir()
    with FolderLock(out):
        build = subprocess.Popen([*CLI, "build", "--only", "controller", "--out", str(out)],
                                 cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                 text=True)  # fmt: skip
        try:
            said = build.stderr.readline()  # blocks until the line is there
            assert "waiting for another impedance-cosim process" in said, said
            assert build.poll() is None and not list(out.glob("*.fmu"))
        except BaseException:
            build.kill()
            raise
    stdout, stderr = build.communicate(timeout=300)
    assert build.returncode == 0, stderr
    assert (out / "ImpedanceController.fmu").is_file() and LOCK_NAME not in os.listdir(out)


def test_a_sweep_into_the_folder_of_a_running_run_is_refused(native_ssp, tmp_path):
    """run (paced to the wall clock: 30 s whatever the load) writes into W; a sweep into W is
    refused (they used to take different locks); the run finishes and no lock file is left."""
    from impedance_cosim.util.atomic import LOCK_NAME

    out = tmp_path / "W"
    commands = _commands(native_ssp, out)
    run = subprocess.Popen([*CLI, *commands["run"][:4], "30", *commands["run"][5:], "--realtime"],
                           cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                           text=True)  # fmt: skip
    try:
        started = time.monotonic()
        while (
            not list(out.glob(".staging-*/.observer.csv.*.tmp"))
            and time.monotonic() - started < 120
        ):
            time.sleep(0.05)
        assert run.poll() is None, run.stderr.read()
        sweep = cli(*commands["sweep"], cwd=tmp_path)
        assert run.poll() is None, "the run ended before the sweep was refused"
    finally:
        run.terminate()
        run.wait(timeout=120)
    assert sweep.returncode == 2, sweep.stderr
    (line,) = lines(sweep.stderr)
    assert f"--out {out} is in use by another impedance-cosim process (pid {run.pid})" in line
    assert not (out / "sweep.csv").exists() and LOCK_NAME not in os.listdir(out)


# --- bad input writes nothing -------------------------------------------------------------------

DIGITS = "9" * 5000
BAD_INPUT = [
    (["run", "--scenario", "nosuch"], "no parameter set 'nosuch'"),
    (["run", "--stop", "0.001"], "is not a whole number of 0.0025 s steps"),
    (["run", "--stop", "1e-300"], "the run length 1e-300 s is shorter than one 0.0025 s step"),
    (["run", "--stop", "1e-12"], "the run length 1e-12 s is shorter than one 0.0025 s step"),
    (
        ["sweep", "--serial", "--grid", "controller.K=10,20", "--stop", "1e-300"],
        "the run length 1e-300 s is shorter than one 0.0025 s step",
    ),
    (["run", "--set", "controller.nosuch=1"], "unknown parameter controller.nosuch"),
    (["run", "--set", f"plant.m3={DIGITS}"], "(5000 characters) is out of range"),
    (["run", "--rt-cpu", "1"], "--rt-cpu only apply with --realtime"),
    (["sweep", "--serial", "--grid", "controller.nosuch=1,2"], "controller.nosuch"),
    (["stability", "nosuch"], "unknown part 'nosuch'"),
]


@pytest.mark.parametrize("args,message", BAD_INPUT, ids=[" ".join(a)[:32] for a, _ in BAD_INPUT])
@pytest.mark.slow
def test_bad_input_writes_nothing(native_ssp, tmp_path, args, message):
    """Every check comes before --out is created: exit 2, one line, no folder at all."""
    out = tmp_path / "NEW"
    done = cli(*args, "--ssp", str(native_ssp), "--out", str(out), cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    (line,) = lines(done.stderr)
    assert message in line and "inf" not in line, line
    assert len(line) < 400 and not out.exists()


def _read_only(tmp_path: Path):
    """A read-only folder: a read-only tmpfs (root), else a folder without write permission."""
    if os.geteuid() != 0:
        folder = tmp_path / "ro"
        folder.mkdir(mode=0o555)
        return contextlib.nullcontext(folder)
    return tmpfs(tmp_path / "ro", "size=1m,ro")


@pytest.mark.parametrize(
    "command,out,message",
    [
        ("run", "", "--out is empty: give the folder to write into"),
        ("run", "x" * 300, "a name of 300 bytes, longer than the file system allows (255)"),
        ("sweep", "x" * 300, "a name of 300 bytes, longer than the file system allows (255)"),
        ("stability", "{ro}", "is not a writable folder"),
        ("stability", "{ro}/sub", "is not a writable folder"),
        ("run", "{ro}", "is not a writable folder"),
    ],
)
def test_an_unusable_out_is_one_line_and_exit_2(native_ssp, tmp_path, command, out, message):
    """--out '' used to write into the current folder; a too long name and a read-only folder
    were raw OS errors (exit 1)."""
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    with _read_only(tmp_path) as ro:
        args = _commands(native_ssp, Path("OUT"))[command]
        args[args.index("OUT")] = out.replace("{ro}", str(ro))
        done = cli(*args, cwd=cwd)
        assert done.returncode == 2, done.stderr
        (line,) = lines(done.stderr)
        assert message in line and "Errno" not in line, line
        assert os.listdir(ro) == []
    assert os.listdir(cwd) == []


def test_a_csv_whose_rename_fails_is_kept_as_partial(tmp_path, monkeypatch):
    """The rows are whole when the CSV is renamed into place: a failed rename keeps them under
    <name>.partial and says so (on main the temporary file was removed: every row lost)."""
    import errno

    import numpy as np

    from impedance_cosim.cosim.results.result import CsvStream
    from impedance_cosim.util import atomic

    real = atomic.replace

    def refuse_the_target(tmp, target):
        if Path(target).name == "r.csv":
            raise OSError(errno.EIO, "Input/output error")
        real(tmp, target)

    monkeypatch.setattr(atomic, "replace", refuse_the_target)
    stream = CsvStream(tmp_path / "r.csv")
    stream.write(["time", "x"], np.array([[0.0, 1.0], [0.5, 2.0]]))
    with pytest.raises(atomic.WriteError) as err:
        stream.close()
    partial = tmp_path / "r.csv.partial"
    assert str(err.value) == (f"cannot write r.csv in {tmp_path}: Input/output error; the 2 rows"
                              f" are in {partial}")  # fmt: skip
    assert partial.read_text().splitlines() == ["time,x", "0.0,1.0", "0.5,2.0"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv.partial"]
