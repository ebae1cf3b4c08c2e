"""Sweeps keep their results and never hang: Ctrl-C or SIGTERM (in a subprocess, sent once the
first rows are in the table) stops the sweep with one line and exit status 128 + signal, the
table keeps every finished run (each equal to an uninterrupted sweep's row), --resume finishes
it without redoing them, a lost worker costs no row, a second sweep on the same table is
refused, a port that is not a dask scheduler fails within the connect timeout, bad input gets
one line before any work."""

from __future__ import annotations

import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import pytest

from impedance_cosim.apps import sweep
from impedance_cosim.apps.sweep.table import SweepTable, read_table
from impedance_cosim.cli import main

# A C exit handler that aborts: a process that leaves through the C library's exit(), which runs
# the loaded libraries' destructors (pythonfmu 0.7's corrupts the heap: exit -6 in some runs),
# dies with SIGABRT every time; one that leaves as fmu.exit_process does (os._exit after Python's
# own exit work, while an FMU library is loaded) exits with its status.
ABORT_AT_C_EXIT = (
    "import ctypes, runpy, sys; libc = ctypes.CDLL(None); "
    "libc.__cxa_atexit(ctypes.cast(libc.abort, ctypes.c_void_p), None, None); "
    "runpy.run_module('impedance_cosim.cli', run_name='__main__')"
)


def sweep_command(*args: str, abort_at_c_exit: bool = False) -> list[str]:
    """The sweep command in a subprocess; stderr holds only errors (no progress lines).
    abort_at_c_exit: with ABORT_AT_C_EXIT (for a process that loads FMUs itself: --serial)."""
    start = ["-c", ABORT_AT_C_EXIT] if abort_at_c_exit else ["-m", "impedance_cosim.cli"]
    return [sys.executable, *start, "sweep", "--no-plots", "--no-progress", *args]


def data_rows(table: Path) -> int:
    """Complete data lines in the table so far (0 if it is not there yet)."""
    try:
        text = table.read_text()
    except FileNotFoundError:
        return 0
    return max(text.count("\n") - 1, 0)


def wait_rows(proc: subprocess.Popen, table: Path, rows: int, timeout: float = 300) -> None:
    """Wait until the table has `rows` rows; fail if the sweep ends or the time is up first."""
    end = time.monotonic() + timeout
    while data_rows(table) < rows:
        assert proc.poll() is None, f"the sweep ended ({proc.returncode}) before {rows} rows"
        assert time.monotonic() < end, f"no {rows} rows in {table} after {timeout} s"
        time.sleep(0.02)


def finish(proc: subprocess.Popen) -> tuple[int, str, str]:
    out, err = proc.communicate(timeout=300)
    return proc.returncode, out, err


def strip(rows: list[dict]) -> dict[int, dict]:
    """Rows by run number, without the wall time (the only column that differs between runs)."""
    return {r["run"]: {k: v for k, v in r.items() if k != "wall_s"} for r in rows}


# what dask, tornado and asyncio print when a client or cluster is torn half way
DASK_OUTPUT = re.compile(r"distributed\.|tornado|asyncio|Task exception|Exception ignored|Error:")


def assert_interrupted(code: int, err: str, signum: int, total: int, table: Path,
                       least: int = 1) -> list[dict]:  # fmt: skip
    """Exit status 128 + signal, our one line on stderr (no traceback, no dask log line), the
    table's finished rows (at least `least`); returns them."""
    name = signal.Signals(signum).name
    assert code == 128 + signum, err
    lines = err.splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("impedance-cosim sweep: interrupted by"), err
    assert not DASK_OUTPUT.search(err), err
    rows = read_table(table)
    assert least <= len(rows) < total
    assert f"interrupted by {name}: {len(rows)} of {total} runs finished" in lines[0]
    assert str(table) in lines[0] and "--resume" in lines[0]
    assert not table.with_name(table.name + ".lock").exists()
    return rows


# --- Ctrl-C / SIGTERM and --resume ----------------------------------------------------------

PY_GRID = ["--grid", "controller.K=" + ",".join(str(k) for k in range(10, 130, 10))]  # 12 runs


@pytest.fixture(scope="module")
def python_reference(ssp_path, tmp_path_factory) -> dict[int, dict]:
    """The uninterrupted serial sweep on the Python FMUs."""
    out = tmp_path_factory.mktemp("reference")
    args = ["sweep", "--serial", "--no-plots", "--no-progress", "--ssp", str(ssp_path)]
    assert main([*args, "--stop", "3", "--out", str(out), *PY_GRID]) == 0
    rows = read_table(out / "sweep.csv")
    assert len(rows) == 12 and all(r["status"] == "ok" for r in rows)
    return strip(rows)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.slow
def test_signal_stops_a_serial_sweep_keeps_rows_and_resume_finishes_it(
    ssp_path, tmp_path, python_reference, signum
):
    """Python FMUs: on main a Ctrl-C inside an FMU became a failed row and the sweep went on.
    Both processes load Python FMUs and must leave without the C destructors (ABORT_AT_C_EXIT):
    before, they ran pythonfmu's at exit, which corrupted the heap (exit -6) in some runs."""
    out = tmp_path / "o"
    args = ["--serial", "--ssp", str(ssp_path), "--stop", "3", "--out", str(out), *PY_GRID]
    proc = subprocess.Popen(sweep_command(*args, abort_at_c_exit=True), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)  # fmt: skip
    wait_rows(proc, out / "sweep.csv", 1)
    proc.send_signal(signum)
    code, _out, err = finish(proc)
    kept = assert_interrupted(code, err, signum, 12, out / "sweep.csv")
    for row in kept:  # every kept row is a finished run, equal to the uninterrupted one
        assert strip([row]) == {row["run"]: python_reference[row["run"]]}

    resume = sweep_command(*args, "--resume", abort_at_c_exit=True)
    resumed = subprocess.run(resume, capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert f"({len(kept)} kept from the table)" in resumed.stdout
    rows = read_table(out / "sweep.csv")
    assert strip(rows) == python_reference  # same rows as the uninterrupted sweep
    wall = {r["run"]: r["wall_s"] for r in rows}
    assert all(wall[r["run"]] == r["wall_s"] for r in kept)  # kept runs were not run again


@pytest.fixture(scope="module")
def native_grid(native_ssp) -> list[str]:
    return ["--grid", "controller.K=lin:10:100:40", "--stop", "30", "--ssp", str(native_ssp)]


@pytest.fixture(scope="module")
def native_reference(native_grid, tmp_path_factory) -> dict[int, dict]:
    """The uninterrupted serial sweep of native_grid."""
    out = tmp_path_factory.mktemp("native_reference")
    args = ["sweep", "--serial", "--no-plots", "--no-progress", "--out", str(out)]
    assert main([*args, *native_grid]) == 0
    return strip(read_table(out / "sweep.csv"))


def worker_processes(proc: subprocess.Popen) -> list[psutil.Process]:
    """The sweep's child processes that are its LocalCluster's workers (living ones): Python
    like the sweep, not multiprocessing's resource tracker (nor e.g. the ldconfig that ctypes
    runs while fmpy is imported)."""
    parent = psutil.Process(proc.pid)
    found = []
    for child in parent.children():
        try:
            if child.exe() == parent.exe() and "resource_tracker" not in " ".join(child.cmdline()):
                found.append(child)
        except psutil.Error:  # e.g. a child that just ended (a zombie until reaped)
            pass
    return found


def wait_line(proc: subprocess.Popen, text: str, timeout: float = 300) -> None:
    """Wait until the command has printed a line starting with `text` on stdout (the event it
    reports itself); fail if it ends or the time is up first. Reads the pipe's descriptor only,
    so proc.communicate() still gets the rest."""
    import os
    import select

    buffer, end = b"", time.monotonic() + timeout
    fd = proc.stdout.fileno()
    while not any(line.startswith(text.encode()) for line in buffer.split(b"\n")[:-1]):
        assert time.monotonic() < end, f"no line {text!r} after {timeout} s: {buffer!r}"
        if select.select([fd], [], [], 0.1)[0]:
            chunk = os.read(fd, 4096)
            assert chunk, f"the command ended ({proc.wait()}) before {text!r}: {buffer!r}"
            buffer += chunk


@pytest.mark.slow
def test_dask_sweep_survives_a_lost_worker_and_ctrl_c(native_grid, native_reference, tmp_path):
    """2 workers: one is killed after the first rows (its run goes to another worker), then
    Ctrl-C; the table keeps every finished run; --resume (serial) equals a serial sweep."""
    out = tmp_path / "o"
    proc = subprocess.Popen(sweep_command("--workers", "2", "--out", str(out), *native_grid),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    table = out / "sweep.csv"
    wait_rows(proc, table, 2)
    workers = worker_processes(proc)
    assert len(workers) == 2
    workers[0].kill()
    wait_rows(proc, table, data_rows(table) + 3)
    proc.send_signal(signal.SIGINT)
    code, _out, err = finish(proc)
    kept = assert_interrupted(code, err, signal.SIGINT, 40, table)
    for row in kept:
        assert strip([row]) == {row["run"]: native_reference[row["run"]]}
    resume = sweep_command("--serial", "--resume", "--out", str(out), *native_grid)
    resumed = subprocess.run(resume, capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert strip(read_table(table)) == native_reference


def running_worker(proc: subprocess.Popen, timeout: float = 300) -> psutil.Process:
    """A worker of the sweep that has started running: an FMU's library is loaded in it (a
    task's first run reads the archive and loads the FMUs), read from /proc/<pid>/maps."""
    end = time.monotonic() + timeout
    while True:
        assert proc.poll() is None, f"the sweep ended ({proc.returncode}) before a worker ran"
        assert time.monotonic() < end, f"no worker ran an FMU after {timeout} s"
        for worker in worker_processes(proc):
            try:
                if "/binaries/" in Path(f"/proc/{worker.pid}/maps").read_text():
                    return worker
            except OSError:  # it just ended
                pass
        time.sleep(0.002)


@pytest.mark.skipif(not Path("/proc/self/maps").is_file(), reason="needs /proc")
@pytest.mark.slow
def test_a_worker_killed_in_its_first_run_costs_no_row(native_grid, native_reference, tmp_path):
    """SIGKILL to a worker as soon as it runs: its runs go to the other worker, every row is the
    serial sweep's, exit 0. On main the archive was broadcast to every worker and each prepared
    there (client.run): a worker killed then failed the sweep (`Stream is closed`, no row)."""
    out = tmp_path / "o"
    proc = subprocess.Popen(sweep_command("--workers", "2", "--out", str(out), *native_grid),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    running_worker(proc).kill()
    code, _out, err = finish(proc)
    assert code == 0 and err == "", err
    assert strip(read_table(out / "sweep.csv")) == native_reference


@pytest.mark.slow
def test_a_worker_killed_while_the_cluster_starts_costs_nothing(native_grid, native_reference,
                                                               tmp_path):  # fmt: skip
    """SIGKILL to the first worker process as soon as it exists (the cluster is still starting,
    or has just started): the sweep finishes with every row. Before, a worker killed while the
    LocalCluster started failed the sweep (`Nanny failed to start`, exit 1)."""
    out = tmp_path / "o"
    proc = subprocess.Popen(sweep_command("--workers", "2", "--out", str(out), *native_grid),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    wait_line(proc, "dask: starting a LocalCluster of 2 worker processes")
    end = time.monotonic() + 300
    while not (workers := worker_processes(proc)):
        assert proc.poll() is None and time.monotonic() < end, "no worker process"
        time.sleep(0.001)
    workers[0].kill()
    code, _out, err = finish(proc)
    assert code == 0 and err == "", err
    assert strip(read_table(out / "sweep.csv")) == native_reference


@pytest.mark.parametrize("signum", [None, signal.SIGINT])
@pytest.mark.slow
def test_a_dask_sweep_leaves_nothing_in_tmpdir(native_grid, tmp_path, signum):
    """The workers' extractions (impcosim_fmu_*, impcosim_ssp_*) and dask's scratch folder are
    in a folder of the sweep's, removed once the cluster is closed, also after Ctrl-C; on main
    every dask sweep left them in TMPDIR."""
    import os

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    out = tmp_path / "o"
    env = {**os.environ, "TMPDIR": str(tmp)}
    proc = subprocess.Popen(sweep_command("--workers", "2", "--out", str(out), *native_grid),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)  # fmt: skip
    if signum is not None:
        wait_rows(proc, out / "sweep.csv", 3)
        proc.send_signal(signum)
    code, _out, err = finish(proc)
    assert code == (0 if signum is None else 128 + signum), err
    assert sorted(p.name for p in tmp.iterdir()) == []


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize("when", ["cluster starting", "runs under way"])
@pytest.mark.slow
def test_a_signal_during_a_dask_sweep_is_our_one_line(
    native_grid, native_reference, tmp_path, signum, when
):
    """Whether it lands while the LocalCluster starts (it is closed whole once up) or while the
    main thread waits for results (fetched by dask's own thread): our one line, exit 128 +
    signal, every finished row kept and equal to the serial sweep's. Before, a signal landing
    inside a dask call left dask's tracebacks or a worker's log lines on stderr."""
    out = tmp_path / "o"
    proc = subprocess.Popen(sweep_command("--workers", "2", "--out", str(out), *native_grid),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    table = out / "sweep.csv"
    if when == "cluster starting":  # reported once our handlers are in place, then it starts
        wait_line(proc, "dask: starting a LocalCluster of 2 worker processes")
    else:
        wait_rows(proc, table, 3)
    proc.send_signal(signum)
    code, _out, err = finish(proc)
    kept = assert_interrupted(code, err, signum, 40, table, least=0)
    for row in kept:
        assert strip([row]) == {row["run"]: native_reference[row["run"]]}


@pytest.mark.slow
def test_a_lost_scheduler_keeps_the_rows_and_says_so(native_grid, native_reference, tmp_path):
    """A scheduler that goes away mid-sweep: on main its cancelled runs became `failed` rows
    (skipped by a resume) with dask's tracebacks and exit 0; now one line, exit 1, no row."""
    scheduler = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
         "--port", "0", "--no-dashboard"], stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    worker = None
    try:
        address = None
        while address is None:
            line = scheduler.stderr.readline()
            assert line, "the scheduler did not start"
            if "Scheduler at:" in line:
                address = line.split()[-1]
        worker = subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
             "--no-nanny", "--no-dashboard"], stderr=subprocess.DEVNULL,
        )  # fmt: skip
        out = tmp_path / "o"
        args = ["--scheduler", address, "--out", str(out), *native_grid]
        proc = subprocess.Popen(sweep_command(*args), stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)  # fmt: skip
        table = out / "sweep.csv"
        wait_rows(proc, table, 3)
        scheduler.kill()
        code, _out, err = finish(proc)
    finally:
        for p in (scheduler, worker):
            if p is not None:
                p.kill()
                p.wait()
    assert code == 1 and err.count("\n") == 1 and "Traceback" not in err, err
    rows = read_table(table)
    assert f"dask lost {40 - len(rows)} of 40 runs" in err
    assert f"{len(rows)} of 40 runs finished, kept in {table}" in err and "--resume" in err
    assert all(strip([r]) == {r["run"]: native_reference[r["run"]]} for r in rows)
    resume = sweep_command("--serial", "--resume", "--out", str(out), *native_grid)
    resumed = subprocess.run(resume, capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert strip(read_table(table)) == native_reference


# --- the table: resume checks, torn rows, a second sweep ------------------------------------


def small_sweep(native_ssp, out: Path, *extra: str) -> int:
    args = ["sweep", "--serial", "--no-plots", "--no-progress", "--ssp", str(native_ssp)]
    return main([*args, "--stop", "0.5", "--out", str(out), "--grid", "controller.K=10,20,30",
                 *extra])  # fmt: skip


def test_resume_refuses_another_sweep_and_reruns_torn_rows(native_ssp, tmp_path, capsys):
    out = tmp_path / "o"
    assert small_sweep(native_ssp, out) == 0
    table = out / "sweep.csv"
    complete = table.read_text()
    lines = complete.splitlines(keepends=True)
    interrupted = "".join(lines[:2]) + lines[3][:25]  # run 1 kept, run 3 torn mid-line
    table.write_text(interrupted)
    capsys.readouterr()

    assert small_sweep(native_ssp, out) == 2  # no --resume: the finished run is not thrown away
    assert "holds 2 of 3 runs of an unfinished sweep: add --resume" in capsys.readouterr().err
    for extra, why in [
        (["--stop", "0.6"], "its option stop is 0.5, this command's 0.6"),
        (["--grid", "plant.q_noise=0,1e-4"], "it sweeps controller.K, this command sweeps"),
        (["--set", "plant.q_noise=1e-4"], "its option fixed is {}"),
    ]:
        args = ["sweep", "--serial", "--no-plots", "--ssp", str(native_ssp), "--out", str(out)]
        stop = [] if "--stop" in extra else ["--stop", "0.5"]
        grid = [] if "--grid" in extra else ["--grid", "controller.K=10,20,30"]
        assert main([*args, *stop, *grid, *extra, "--resume"]) == 2
        err = capsys.readouterr().err
        assert f"cannot resume {table}: it is another sweep: {why}" in err and err.count("\n") == 1
        assert table.read_text() == interrupted  # refused: nothing touched

    assert small_sweep(native_ssp, out, "--resume") == 0
    assert "(1 kept from the table)" in capsys.readouterr().out
    (tmp_path / "complete.csv").write_text(complete)
    assert strip(read_table(table)) == strip(read_table(tmp_path / "complete.csv"))
    assert table.read_text().splitlines()[1] == lines[1].rstrip("\n")  # run 1 kept as it was


def test_a_second_sweep_on_the_same_table_is_refused(native_ssp, tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\n"
         "from impedance_cosim.apps.sweep.table import _lock\n"
         "from pathlib import Path\nwith _lock(Path(sys.argv[1])): print('locked', flush=True); "
         "time.sleep(60)", str(out / "sweep.csv.lock")],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout.readline() == "locked\n"
        assert small_sweep(native_ssp, out) == 2
        err = capsys.readouterr().err
        assert f"{out / 'sweep.csv'} is being written by another sweep (pid {holder.pid})" in err
        assert err.count("\n") == 1 and not (out / "sweep.csv").exists()
    finally:
        holder.kill()  # killed, not cleaned up: the OS releases its lock
        holder.wait()
    assert small_sweep(native_ssp, out) == 0
    assert len(read_table(out / "sweep.csv")) == 3 and not (out / "sweep.csv.lock").exists()


def test_table_writes_go_through_a_temporary_name(tmp_path, monkeypatch):
    """A failure while the table is rewritten leaves the previous table whole."""
    import os

    table = tmp_path / "sweep.csv"
    names = ["run", "x", "status", "error"]
    points = [{"x": 1}, {"x": 2}]
    plan = {"format": 1, "axes": {"x": [1, 2]}, "runs": 2}
    with SweepTable(table, names, plan, points) as t:
        t.add(1, {"x": 2, "status": "ok", "error": ""})
        assert table.read_bytes() == b"run,x,status,error\r\n2,2,ok,\r\n"  # appended, flushed
        t.add(0, {"x": 1, "status": "ok", "error": ""})
        before = table.read_text()

        def fail(*_a):
            raise OSError("disk full")

        monkeypatch.setattr(os, "replace", fail)
        with pytest.raises(OSError):
            t._rewrite()
        assert table.read_text() == before and list(tmp_path.glob(".*.tmp")) == []
        monkeypatch.undo()
    assert table.read_bytes() == b"run,x,status,error\r\n1,1,ok,\r\n2,2,ok,\r\n"  # sorted


# --- bounded waits --------------------------------------------------------------------------


@pytest.fixture(params=["silent", "garbage"])
def not_a_scheduler(request):
    """A TCP server on 127.0.0.1 (port 0) that accepts and says nothing, or garbage."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    conns = []

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            conns.append(conn)
            if request.param == "garbage":
                conn.sendall(b"HTTP/1.0 200 OK\r\n\r\n" + bytes(range(256)) * 4)

    threading.Thread(target=serve, daemon=True).start()
    yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    server.close()
    for c in conns:
        c.close()


@pytest.mark.slow
def test_a_port_that_is_not_a_scheduler_fails_within_the_timeout(
    native_ssp, tmp_path, not_a_scheduler
):
    """In a subprocess with a generous time limit (a hang fails it; no duration is asserted: the
    start-up alone took more than 5 s under load): on main this hung with no output."""
    args = ["--ssp", str(native_ssp), "--grid", "controller.K=10,50", "--out", str(tmp_path / "o")]
    done = subprocess.run(sweep_command(*args, "--scheduler", not_a_scheduler, "--connect-timeout",
                          "1"), capture_output=True, text=True, timeout=300)  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert f"{not_a_scheduler} accepts connections but is not a dask scheduler" in done.stderr
    assert done.stderr.count("\n") == 1 and not (tmp_path / "o").exists()


def test_a_real_scheduler_passes_the_check():
    from distributed import LocalCluster

    with LocalCluster(n_workers=0, processes=False, protocol="tcp", host="127.0.0.1",
                      dashboard_address=":0") as cluster:  # fmt: skip
        sweep.check_scheduler(cluster.scheduler_address, timeout=2.0)


@pytest.mark.parametrize(
    "address, message",
    [
        ("tcp://127.0.0.1:1", "cannot reach the dask scheduler at tcp://127.0.0.1:1"),
        ("tcp://no-such-host.invalid:8786", "cannot reach the dask scheduler"),
        ("tcp://127.0.0.1:x", "bad scheduler address"),
        ("udp://127.0.0.1:9", "only tcp:// and tls://"),
    ],
)
def test_an_unreachable_scheduler_is_one_line(tmp_path, capsys, address, message):
    code = main(["sweep", "--grid", "controller.K=10", "--scheduler", address,
                 "--connect-timeout", "1", "--out", str(tmp_path / "o")])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1


# --- bad input: one line, no traceback, before any work --------------------------------------

BAD = [
    (["--stop", "inf"], "--stop must be a finite number > 0"),
    (["--stop", "nan"], "--stop must be a finite number > 0"),
    (["--step", "0"], "--step must be a finite number > 0"),
    (["--stop", "1e12"], "run 1 of 1 (controller.K=10): stop time 1e+12 s at step 0.0025 s"),
    (["--step", "1e-12"], "GiB of memory (limit 1 GiB)"),
    (["--grid", "plant.m3=lin:1:2:1e9"], "needs a count 1..100000"),
    (["--grid", "plant.m3=lin:1:inf:3"], "needs finite numbers"),
    (["--grid", "plant.m3=lin:1:2"], "needs a count"),
    (["--grid", "plant.m3=log:0:1:3"], "log spacing needs positive bounds"),
    (["--grid", "plant.m3=1,inf"], "plant.m3: inf is not a finite number"),
    (["--grid", "plant.m3=lin:1:2:1000", "--grid", "plant.m2=lin:1:2:1000"], "more than 100000"),
    (["--grid", "=1,2"], "--grid expects component.variable=values"),
    (["--grid", "plant.m3"], "--grid expects component.variable=values"),
    (["--grid", "plant.m3=,,"], "empty grid for plant.m3"),
    (["--grid", "controller.K=1,,2"], "--grid controller.K=1,,2: value 2 of 3 is empty"),
    (["--grid", "controller.K=1,2,"], "--grid controller.K=1,2,: value 3 of 3 is empty"),
    (["--grid", "nope.x=1"], "unknown parameter 'nope.x'"),
    (["--set", "plant.m3=nan"], "plant.m3: nan is not a finite number"),
    (["--set", "controller.K=1e400"], "controller.K: inf is not a finite number"),
    (["--set", "controller.K=5"], "--set controller.K=5: controller.K is swept by --grid"),
    (["--set", "controller.K2=5"], "--set controller.K2=5: controller.K2 is swept by --grid"),
    (["--set", "controller.K=abc"], "--set: variable controller.K1: 'abc' is not a valid Real"),
    (
        ["--grid", "system.friction_scale=1,2", "--set", "plant.f2=3"],
        "plant.f2 is swept by --grid system.friction_scale",
    ),
    (["--random", "0"], "--random must be 1..100000"),
    (["--random", "1000000000"], "--random must be 1..100000"),
    (["--workers", "0"], "--workers must be >= 1"),
    (["--workers", "100000"], "--workers 100000 is more than 4 per core of this machine"),
    (["--connect-timeout", "0"], "--connect-timeout must be"),
    (["--connect-timeout", "nan"], "--connect-timeout must be"),
    (["--plot", "bogus"], "unknown metric 'bogus'"),
    (["--ssp", "/nonexistent/x.ssp"], "does not exist"),
    (["--study", "delay", "--grid", "controller.K=1"], "--study runs its own grids"),
]


@pytest.fixture
def time_limit():
    """Fail (instead of hanging) a test that takes more than 30 s: on main some of these inputs
    planned 10**6 runs or sampled 10**9 points."""

    def expire(*_a):
        raise TimeoutError("more than 30 s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, 30)
    yield
    signal.setitimer(signal.ITIMER_REAL, 0)
    signal.signal(signal.SIGALRM, previous)


@pytest.mark.parametrize("extra, message", BAD)
def test_bad_sweep_input_is_one_line(
    native_ssp, tmp_path, capsys, monkeypatch, time_limit, extra, message
):
    import distributed

    def refuse(*_a, **_k):
        raise AssertionError("a cluster was started for bad input")

    monkeypatch.setattr(distributed, "LocalCluster", refuse)
    args = ["sweep", "--out", str(tmp_path / "o")]
    if "--ssp" not in extra:
        args += ["--ssp", str(native_ssp)]
    if "--grid" not in extra:
        args += ["--grid", "controller.K=10"]
    assert main([*args, *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
    assert not (tmp_path / "o").exists()


def test_a_local_cluster_is_no_bigger_than_the_runs(native_ssp, tmp_path, capsys):
    """--workers 4 for 2 runs starts 2 worker processes (said on stdout)."""
    args = ["sweep", "--no-plots", "--no-progress", "--no-report", "--ssp", str(native_ssp)]
    grid = ["--stop", "0.5", "--grid", "controller.K=10,20", "--out", str(tmp_path / "o")]
    assert main([*args, "--workers", "4", *grid]) == 0
    assert "dask: starting a LocalCluster of 2 worker processes" in capsys.readouterr().out


def test_out_naming_a_file_is_one_line(native_ssp, tmp_path, capsys):
    (tmp_path / "f").write_text("x")
    args = ["sweep", "--ssp", str(native_ssp), "--grid", "controller.K=1", "--stop", "0.5", "--out"]
    assert main([*args, str(tmp_path / "f")]) == 2
    err = capsys.readouterr().err
    assert "is a file, not a folder" in err and err.count("\n") == 1
    assert main([*args, str(tmp_path / "f" / "sub")]) == 2  # a folder that cannot be made
    err = capsys.readouterr().err
    assert f"is a file, not a folder ({tmp_path / 'f'})" in err and err.count("\n") == 1


def _worker_view() -> tuple[list[str], str, str]:
    """(open files, SIGINT handler, SIGTERM handler) as a worker process sees them."""
    import os

    files = []
    for fd in os.listdir("/proc/self/fd"):
        try:
            files.append(os.readlink(f"/proc/self/fd/{fd}"))
        except OSError:
            pass
    return files, str(signal.getsignal(signal.SIGINT)), str(signal.getsignal(signal.SIGTERM))


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="needs /proc")
def test_local_workers_hold_no_lock_of_ours_and_leave_signals_to_us(tmp_path):
    """LocalCluster workers are forked from the sweep's process on Linux (fast start): they must
    not keep its folder or table lock (a re-run would be refused while they live) nor its signal
    handlers (Ctrl-C is the main process's; SIGTERM ends a worker)."""
    from impedance_cosim.apps.sweep.cluster import dask_client
    from impedance_cosim.apps.sweep.table import _lock as table_lock
    from impedance_cosim.util.atomic import LOCK_NAME, FolderLock

    def handler(*_):
        raise AssertionError("a worker ran the sweep's handler")

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        with (
            FolderLock(tmp_path),
            table_lock(tmp_path / "sweep.csv.lock"),
            dask_client(workers=1) as client,
        ):
            ((files, sigint, sigterm),) = client.run(_worker_view).values()
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert not [f for f in files if f.endswith((LOCK_NAME, "sweep.csv.lock"))], files
    assert str(tmp_path) not in files, files  # the folder lock is the folder's own descriptor
    assert sigint == str(signal.SIG_IGN) and sigterm == str(signal.SIG_DFL)


@pytest.mark.parametrize("outcome", ["passed", "failed"])
def test_the_test_session_leaves_without_the_fmu_destructors(tmp_path, outcome):
    """A pytest session with an FMU library loaded (simulated: one left after fmi2Fatal) leaves
    with its own status and without the C destructors (tests/conftest.py: pytest_unconfigure),
    as the command does: before, a suite that passed could die at exit with SIGABRT."""
    test = tmp_path / "test_one.py"
    test.write_text(
        "from impedance_cosim.cosim.fmus import fmi2 as fmu\n\n\ndef test_one():\n"
        f"    fmu._leaked_libraries.append('x')\n    assert {outcome == 'passed'}\n"
    )
    tests = Path(__file__).parent
    code = ABORT_AT_C_EXIT.replace(
        "runpy.run_module('impedance_cosim.cli', run_name='__main__')",
        f"sys.path.insert(0, {str(tests)!r}); import pytest; "
        f"sys.exit(pytest.main(['-q', '-p', 'no:cacheprovider', '-p', 'conftest', {str(test)!r}]))",
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=tmp_path, timeout=300)  # fmt: skip
    assert done.returncode == (0 if outcome == "passed" else 1), done.stdout + done.stderr
    assert f"1 {outcome}" in done.stdout


def test_set_may_give_what_the_grid_does_not_sweep(native_ssp):
    """controller.K1 swept, controller.K2 fixed: different parameters, both applied."""
    from impedance_cosim.apps.sweep.plan import plan_sweep, run_options

    plan = plan_sweep(["controller.K1=10,20"], ssp=native_ssp, fixed=["controller.K2=7"])
    overrides = run_options(plan.points[1], plan.options).overrides
    assert overrides == {"controller.K1": 20, "controller.K2": 7}
