"""The bridge and the robot process under issue 20's hostile and impatient users: a token file
that is not a regular file is refused without blocking, a signal ends any wait of the bridge at
once, timeouts have an upper bound, a foreign UDP flood at full speed leaves the results
bit-identical, a non-loopback bind needs --allow-remote, and a signal to the robot is its exit
status. Nothing here waits for a moment in time: every step syncs on an observable event (a
line printed, a datagram arriving) with a generous upper bound, and no duration is asserted.

Every process started here is stopped by its PID at the end of its test."""

from __future__ import annotations

import os
import select
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from bridge_model import protocol
from bridge_model.model import BridgeModel
from impedance_cosim.apps.robot import RobotServer
from impedance_cosim.apps.robot_process import ROBOT_COMMAND, start_robot
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.fmi.model import ModelError
from plant_model.model import PlantModel

TOKEN = protocol.new_token()
KEY = protocol.token_key(TOKEN)
CLI = [sys.executable, "-c", "from impedance_cosim.cli import entry; entry()"]
PARAMETERS = [v for v in PlantModel.variables() if v.causality == "parameter"]
DEFAULTS = [float(v.start) for v in PARAMETERS]
# A lock-step run that is not about timeouts must not fail because the machine is slow.
PATIENT = {"plant.timeout_s": 20.0, "plant.init_timeout_s": 60.0}


@pytest.fixture(scope="module")
def system(ssp_path):
    return read_ssp(ssp_path)


@pytest.fixture
def procs():
    """A list to put started processes in; each is killed (by its PID) and reaped at the end."""
    started: list[subprocess.Popen] = []
    yield started
    for proc in started:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=30)
        for stream in (proc.stdin, proc.stdout, proc.stderr):
            if stream:
                stream.close()


def env_without_token() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k != protocol.TOKEN_ENV}


def swap_bridge(ssp_path: Path, fmu_dir: Path, out: Path, stop: str, *sets: str) -> list[str]:
    """The `swap` command line that runs the system with the bridge FMU as its plant."""
    settings = [arg for item in sets for arg in ("--set", item)]
    return [*CLI, "swap", "--ssp", str(ssp_path), "--replace",
            f"plant={fmu_dir / 'BridgePlant.fmu'}", *settings, "--stop", stop, "--no-figures",
            "--out", str(out)]  # fmt: skip


def wait_for_line(stream, text: str, timeout: float = 120.0) -> str:
    """The first line of `stream` that contains `text` (AssertionError after `timeout`)."""
    lines = []
    while True:
        ready, _, _ = select.select([stream], [], [], timeout)
        line = stream.readline() if ready else ""
        assert line, f"no line with {text!r} within {timeout} s: {lines}"
        if text in line:
            return line
        lines.append(line)


# --- item 1: a token file that is not a regular file -------------------------------------------


@pytest.fixture
def odd_files(tmp_path) -> dict[str, tuple[Path, str]]:
    """Paths that are not a token file, and what the reader must say of each."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    (tmp_path / "dir").mkdir()
    real = tmp_path / "real"
    real.write_text(protocol.new_token() + "\n")
    real.chmod(0o600)
    (tmp_path / "link").symlink_to(real)
    big = tmp_path / "big"
    big.write_text("x" * 5000)
    big.chmod(0o600)
    return {
        "fifo": (fifo, "is a FIFO, not a regular file"),
        "directory": (tmp_path / "dir", "is a directory, not a regular file"),
        "device": (Path("/dev/null"), "is a character device, not a regular file"),
        "symlink": (tmp_path / "link", "is a symbolic link"),
        "oversize": (big, "5000 bytes is more than one token"),
    }


def test_the_token_file_reader_never_blocks(odd_files):
    """protocol.read_token_file (the one reader of the bridge and the robot) refuses each with
    one line, in a thread that must come back (an open() of a FIFO would wait for a writer
    forever)."""
    said = {}

    def read_all() -> None:
        for name, (path, _) in odd_files.items():
            try:
                protocol.read_token_file(path)
                said[name] = "accepted"
            except ValueError as exc:
                said[name] = str(exc)

    reader = threading.Thread(target=read_all, daemon=True)
    reader.start()
    reader.join(timeout=60)
    assert not reader.is_alive(), f"read_token_file blocked (read so far: {said})"
    for name, (path, message) in odd_files.items():
        assert said[name] == f"token file {path}: {message}" or message in said[name], said[name]


@pytest.mark.parametrize("kind", ["fifo", "directory", "device", "symlink", "oversize"])
def test_robot_refuses_an_odd_token_file_with_one_line(odd_files, procs, kind):
    path, message = odd_files[kind]
    proc = subprocess.Popen([*ROBOT_COMMAND, "--port", "0", "--token-file", str(path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env_without_token())  # fmt: skip
    procs.append(proc)
    out, err = proc.communicate(timeout=60)  # TimeoutExpired: it blocked
    assert proc.returncode == 2 and out == "", (proc.returncode, out, err)
    assert err == f"impedance-cosim robot: error: token file {path}: {message}\n" or (
        len(err.splitlines()) == 1 and message in err
    ), err


def test_swap_to_the_bridge_without_a_robot_says_how_to_start_one(ssp_path, fmu_dir, tmp_path,
                                                                   capsys):  # fmt: skip
    """No --robot and no token of a robot the user started: one line saying how to start one or
    to let swap start it (not the bridge's token error after the run began), nothing written."""
    from impedance_cosim.cli import main

    out = tmp_path / "res"
    assert main(swap_bridge(ssp_path, fmu_dir, out, "0.1")[len(CLI) :]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert "is a bridge to a robot process and none is given: use --robot lockstep" in lines[0]
    assert "--set plant.robot_token_file=PATH" in lines[0]
    assert not out.exists()


def test_swap_refuses_a_fifo_token_file_before_it_runs(ssp_path, fmu_dir, odd_files, tmp_path,
                                                        procs):  # fmt: skip
    fifo, message = odd_files["fifo"]
    out = tmp_path / "res"
    cmd = swap_bridge(ssp_path, fmu_dir, out, "0.1", f"plant.robot_token_file={fifo}")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    procs.append(proc)
    _, err = proc.communicate(timeout=120)  # TimeoutExpired: it blocked
    assert proc.returncode == 2, err
    assert err.strip().splitlines() == [
        f"impedance-cosim swap: error: --set plant.robot_token_file: token file {fifo}: {message}"
    ]
    assert not out.exists()  # bad input writes nothing


def test_the_bridge_fmu_refuses_a_fifo_token_file(system, fmu_dir, odd_files):
    """The bridge itself (an API user, no swap check before it): the run fails with the reason
    instead of waiting in open() for a writer."""
    fifo, message = odd_files["fifo"]
    result = {}

    def run() -> None:
        master = Master(
            system,
            RunOptions(
                stop_time=0.1,
                fmu_files={"plant": fmu_dir / "BridgePlant.fmu"},
                overrides={"plant.robot_token_file": str(fifo)},
            ),
        )
        result["r"] = master.run()

    runner = threading.Thread(target=run, daemon=True)
    runner.start()
    runner.join(timeout=120)
    assert not runner.is_alive(), "the bridge blocked opening the FIFO"
    assert not result["r"].ok and message in result["r"].error, result["r"].error


# --- item 2: a signal ends the bridge's waits; timeouts are bounded ----------------------------


def test_timeouts_have_an_upper_bound():
    for name, value, bound in [("timeout_s", 1e9, "60"), ("init_timeout_s", 1e9, "600")]:
        with pytest.raises(ModelError, match=f"parameter {name} must be <= {bound}"):
            BridgeModel({name: value, "robot_token": TOKEN})


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_during_the_init_wait_ends_it(ssp_path, fmu_dir, tmp_path, procs, sig):
    """A 'robot' that never answers (a bound socket, read by the test): once the first INIT
    arrives the bridge is waiting (for up to 600 s); the signal must end the command at once,
    with its one line and 128 + the signal's number."""
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    port = silent.getsockname()[1]
    cmd = swap_bridge(ssp_path, fmu_dir, tmp_path / "res", "0.1", f"plant.robot_port={port}",
                      f"plant.robot_token={TOKEN}", "plant.init_timeout_s=600")  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    procs.append(proc)
    try:
        silent.settimeout(120)
        protocol.Message(silent.recv(65536), KEY)  # the first INIT: the bridge waits now
    finally:
        silent.close()
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)  # TimeoutExpired: the wait went on (600 s)
    name = signal.Signals(sig).name
    assert proc.returncode == 128 + sig, err
    assert err.strip().splitlines() == [
        f"impedance-cosim swap: interrupted by {name} at t=0 s; 0 rows kept in"
        f" {tmp_path / 'res' / 'observer.csv.partial'}"
    ] or (len(err.strip().splitlines()) == 1 and f"interrupted by {name}" in err), err


def test_a_signal_during_a_step_wait_ends_it(ssp_path, fmu_dir, tmp_path, procs):
    """A robot that answers STEP 5 only after 60 s, a bridge that waits up to 60 s: SIGINT, sent
    once the robot has said it holds the reply back, ends the run with its rows."""
    log = tmp_path / "robot.log"
    with open(log, "w") as err:
        robot, port = start_robot(TOKEN, extra=["--fault=late@5:60"], stderr=err)
    procs.append(robot)
    cmd = swap_bridge(ssp_path, fmu_dir, tmp_path / "res", "1", f"plant.robot_port={port}",
                      f"plant.robot_token={TOKEN}", "plant.timeout_s=60")  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    procs.append(proc)
    with open(log) as lines:
        wait_for_line_in_file(lines, "reply to STEP 5 60 s late")
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)  # TimeoutExpired: the wait went on (60 s)
    assert proc.returncode == 130, err
    assert len(err.strip().splitlines()) == 1 and "interrupted by SIGINT" in err, err
    assert "5 rows kept" in err, err  # t = 0 and the 4 steps before


def wait_for_line_in_file(f, text: str, timeout: float = 120.0) -> None:
    """Wait until the open file `f` (being written by another process) has a line with `text`."""
    seen = threading.Event()
    done = threading.Event()

    def watch() -> None:
        buffer = ""
        while not done.is_set():
            buffer += f.read()
            if text in buffer:
                seen.set()
                return
            done.wait(0.05)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    ok = seen.wait(timeout)
    done.set()
    watcher.join()
    assert ok, f"no line with {text!r} within {timeout} s"


# --- item 3: a foreign flood at full speed -----------------------------------------------------

FLOODER = r"""
import os, select, socket, struct, sys
port, limit = int(sys.argv[1]), int(sys.argv[2])
head = struct.Struct("<4sHHIHHQqqdd")
forged = [  # well-formed headers with a MAC made up (they pass every check but the MAC),
    head.pack(b"ICHB", 2, 3, 1, 3, 0, 12345, 0, 0, 0.0, 0.0025) + bytes(24) + os.urandom(16),
    head.pack(b"ICHB", 2, 1, 0, 30, 0, 999, 0, 0, 0.0, 0.0) + bytes(240) + os.urandom(16),
    os.urandom(120),  # and garbage
]
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.connect(("127.0.0.1", port))
sent = 0
while sent < limit:
    for data in forged:
        for _ in range(2000):
            try:
                s.send(data)
            except OSError:
                pass
        sent += 2000
    if sent == 6000:
        print("flooding", flush=True)
    if select.select([sys.stdin], [], [], 0)[0]:  # stdin closed: stop
        break
print(sent, flush=True)
"""


@pytest.mark.slow
def test_a_foreign_flood_at_full_speed_leaves_the_run_bit_identical(system, fmu_dir, tmp_path,
                                                                     procs):  # fmt: skip
    """One local socket sends the robot's port forged and garbage datagrams as fast as it can
    (bounded: at most 10^9, or until its stdin closes), from before the INIT to after the last
    step: the lock-step run equals the in-process run bit for bit, and the robot, still serving,
    logs the drops."""
    log = tmp_path / "robot.log"
    with open(log, "w") as err:
        robot, port = start_robot(TOKEN, stderr=err)
    procs.append(robot)
    flooder = subprocess.Popen(
        [sys.executable, "-c", FLOODER, str(port), str(10**9)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    procs.append(flooder)
    wait_for_line(flooder.stdout, "flooding")
    overrides = {"plant.robot_port": port, "plant.robot_token": TOKEN, **PATIENT}
    got = Master(
        system,
        RunOptions(
            stop_time=2.0, fmu_files={"plant": fmu_dir / "BridgePlant.fmu"}, overrides=overrides
        ),
    ).run()
    assert flooder.poll() is None  # the flood went on until the last step
    flooder.stdin.close()
    sent = int(wait_for_line(flooder.stdout, ""))
    assert got.ok, got.error
    ref = Master(system, RunOptions(stop_time=2.0)).run()
    for name in ref.names:
        assert np.array_equal(got[name], ref[name]), name
    assert robot.poll() is None  # still serving
    robot.terminate()  # SIGTERM: it writes the counts it has not logged yet
    assert robot.wait(timeout=60) == 143
    text = log.read_text()
    assert "failed authentication" in text and "malformed" in text, text
    assert sent > 6000


def test_a_lost_request_is_resent_and_answered_from_the_cache(tmp_path):
    """A robot that never sees the first copy of any request (a lossy link): the bridge sends it
    again within the step's timeout, each step is taken once, and the outputs are the plant's."""
    server = RobotServer(KEY, log=lambda text: None)
    seen: set[tuple[int, int]] = set()
    handle = server._handle

    def lossy(raw: bytes, client) -> None:
        msg = protocol.Message(raw, KEY)
        if (msg.kind, msg.seq) not in seen:
            seen.add((msg.kind, msg.seq))
            return  # lost
        handle(raw, client)

    server._handle = lossy
    thread = threading.Thread(target=server.serve)
    thread.start()
    try:
        bridge = BridgeModel({"robot_port": server.address[1], "robot_token": TOKEN,
                              "timeout_s": 20.0, "init_timeout_s": 60.0})  # fmt: skip
        plant = PlantModel({}, 0.0, None)
        h = 0.0025
        for i in range(5):
            tau = (10.0 + i, -3.0, 0.5)
            bridge.do_step(i * h, h, tau)
            plant.do_step(i * h, h, tau)
            assert tuple(bridge.values) == tuple(plant.outputs())
        bridge.sock.close()
    finally:
        server.stop()
        thread.join(timeout=60)
        server.close()
    assert server.steps == 5  # each step taken once, however many copies came
    assert len(seen) == 6  # INIT and 5 STEPs, each lost once


def test_foreign_datagrams_are_dropped_before_any_mac(monkeypatch):
    """Garbage, other protocol versions, replies and misfit lengths never reach the MAC: a flood
    of them costs a few comparisons each."""
    macs = []
    real_mac = protocol._mac
    monkeypatch.setattr(protocol, "_mac", lambda key, data: macs.append(1) or real_mac(key, data))
    server = RobotServer(KEY, log=lambda text: None)
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.connect(server.address)
    valid = protocol.pack(KEY, protocol.STEP, 1, 5, 0.0, 0.0025, (1.0, 2.0, 3.0))
    init = protocol.pack(KEY, protocol.INIT, 0, 7, 0.0, 0.0, DEFAULTS)
    junk = [os.urandom(100), b"ICHB\x01\x00" + valid[6:], valid[:-8], valid + bytes(8),
            valid[:6] + b"\x04\x00" + valid[8:], b"", valid[:71]]  # fmt: skip
    thread = threading.Thread(target=server.serve)
    thread.start()
    try:
        macs.clear()
        for data in junk * 20:
            peer.send(data)
        peer.send(init)  # after every junk datagram: its reply says they were all handled
        peer.settimeout(60)
        reply = protocol.Message(peer.recv(65536), KEY)
    finally:
        peer.close()
        server.stop()
        thread.join(timeout=60)
        server.close()
    assert reply.kind == protocol.INIT_REPLY
    assert server.dropped["malformed"] + server.dropped["not a request"] == len(junk) * 20
    assert len(macs) == 3  # the INIT's check, its reply's signature and this test's check


# --- item 4: a non-loopback bind needs --allow-remote -------------------------------------------


def robot_cli(*args: str) -> tuple[int, str, str]:
    """`impedance-cosim robot ARGS` with the token in its environment; (status, stdout, stderr)."""
    env = {**env_without_token(), protocol.TOKEN_ENV: TOKEN}
    done = subprocess.run([*ROBOT_COMMAND, *args], capture_output=True, text=True, env=env,
                          timeout=60)  # fmt: skip
    return done.returncode, done.stdout, done.stderr


@pytest.mark.parametrize("host", ["", "0.0.0.0"])
def test_a_non_loopback_bind_needs_allow_remote(host):
    code, out, err = robot_cli("--host", host, "--port", "0", "--duration", "0.2")
    assert code == 2 and out == "", (code, out, err)
    assert err.strip().splitlines() == [
        f"impedance-cosim robot: error: --host {host!r} would listen on every interface: other "
        "machines could send datagrams here; give --allow-remote to accept that "
        "(docs/hil-reference.md, Trust model)"
    ]
    with pytest.raises(ValueError, match="--allow-remote"):
        RobotServer(KEY, host=host)  # the server itself refuses (an API user)


def test_allow_remote_binds_every_interface_with_a_warning():
    code, out, err = robot_cli("--host", "", "--allow-remote", "--port", "0", "--duration", "0.2")
    assert code == 0 and out.startswith("robot: listening on 0.0.0.0:"), (code, out, err)
    assert "0.0.0.0 is not a loopback address" in err


def test_a_second_robot_on_the_same_port_is_refused(procs):
    """The robot's port is shared with its session sockets (SO_REUSEPORT): another robot (same
    user) must still find it taken, not share it."""
    robot, port = start_robot(TOKEN)
    procs.append(robot)
    code, _, err = robot_cli("--port", str(port))
    assert code == 2 and f"cannot listen on UDP 127.0.0.1:{port}: Address already in use" in err


# --- item 5: a signal to the robot is its exit status ------------------------------------------


@pytest.mark.parametrize("ignored", [False, True], ids=["", "started with SIGINT ignored"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_stops_the_robot_with_its_status(tmp_path, procs, sig, ignored):
    """Also when the robot inherits SIGINT ignored, as a script's background job does (Python
    then installs no handler of its own: the command must)."""
    log = tmp_path / "robot.log"
    inherited = signal.SIG_IGN if ignored else signal.getsignal(signal.SIGINT)
    previous = signal.signal(signal.SIGINT, inherited)
    try:
        with open(log, "w") as err:
            robot, _ = start_robot(TOKEN, stderr=err)  # it has printed its first line: serving
    finally:
        signal.signal(signal.SIGINT, previous)
    procs.append(robot)
    robot.send_signal(sig)
    assert robot.wait(timeout=60) == 128 + sig
    name = signal.Signals(sig).name
    assert log.read_text().splitlines() == [f"impedance-cosim robot: interrupted ({name})"]
