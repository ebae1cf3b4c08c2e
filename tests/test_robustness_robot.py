"""The robot process and the bridge against hostile or broken peers (issue 10, item 5): foreign
datagrams are ignored, bad requests are refused without killing the robot or leaking its state,
bad options and a busy port give one line, and a robot that loses the session fails the run.

Every robot process listens on an ephemeral loopback port and is killed by its PID at the end."""

from __future__ import annotations

import os
import random
import socket
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import run_bridge_in_child

from bridge_model import protocol
from impedance_cosim.apps.robot import RobotServer
from impedance_cosim.apps.robot_process import ROBOT_COMMAND, start_robot, stop_robot
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp
from plant_model.model import PlantModel

TOKEN = protocol.new_token()
KEY = protocol.token_key(TOKEN)
PARAMETERS = [v for v in PlantModel.variables() if v.causality == "parameter"]
DEFAULTS = [float(v.start) for v in PARAMETERS]
SEED = [v.name for v in PARAMETERS].index("noise_seed")


@pytest.fixture(scope="module")
def system(ssp_path):
    return read_ssp(ssp_path)


class Peer:
    """A UDP socket talking to the robot the way the bridge (or an intruder) would."""

    def __init__(self, port: int, key: bytes = KEY, session: int = 12345) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.connect(("127.0.0.1", port))
        self.key, self.session = key, session

    def send(self, kind, seq, t=0.0, h=0.0, values=(), session=None) -> int:
        stamp = protocol.now_ns()
        session = self.session if session is None else session
        self.sock.send(protocol.pack(self.key, kind, seq, session, t, h, values, stamp_ns=stamp))
        return stamp

    def receive(self, timeout: float = 1.0) -> protocol.Message | None:
        self.sock.settimeout(timeout)
        try:
            return protocol.Message(self.sock.recv(65536), KEY)
        except TimeoutError:
            return None

    def ask(self, *args, **kw) -> protocol.Message | None:
        self.send(*args, **kw)
        return self.receive()

    def close(self) -> None:
        self.sock.close()


# A run that is not about timeouts must not fail because the machine is slow.
PATIENT = {"plant.timeout_s": 20.0, "plant.init_timeout_s": 60.0}


def bridged(system, bridge, port, stop, **kw):
    overrides = {"plant.robot_port": port, "plant.robot_token": TOKEN, **PATIENT}
    master = Master(
        system, RunOptions(stop_time=stop, fmu_files={"plant": bridge}, overrides=overrides, **kw)
    )
    return master.run()


# --- foreign datagrams ---------------------------------------------------------------------------


@pytest.mark.slow
def test_foreign_datagrams_mid_run_are_ignored(system, fmu_dir, robot):
    """While a lock-step bridge run goes on, another socket sends INITs and STEPs signed with
    another token, unsigned old-protocol datagrams, garbage, and STEPs signed with the right token
    for a session it made up: the run equals the in-process run bit for bit, and the robot's log
    reports the drops in at most one line a second."""
    port = robot()
    ref = Master(system, RunOptions(stop_time=2.0)).run()
    stop = threading.Event()
    sent = [0]

    def intrude() -> None:
        rng = random.Random(1)
        other = Peer(port, protocol.token_key(protocol.new_token()))
        insider = Peer(port, KEY, session=999)
        old = (
            b"ICHB\x01\x00\x01\x00"
            + bytes(40)
            + b"".join(np.float64(v).tobytes() for v in DEFAULTS)
        )
        while not stop.is_set():
            other.send(protocol.INIT, 0, 0.0, 0.0, DEFAULTS)
            other.send(protocol.STEP, rng.randrange(1, 900), 0.0, 0.0025, (500.0, 0.0, 0.0))
            other.sock.send(old)
            other.sock.send(rng.randbytes(rng.randrange(0, 700)))
            insider.send(protocol.STEP, rng.randrange(1, 900), 0.0, 0.0025, (500.0, 0.0, 0.0))
            sent[0] += 5
            time.sleep(0.001)
        other.close()
        insider.close()

    thread = threading.Thread(target=intrude)
    started = time.monotonic()
    thread.start()
    try:
        while sent[0] < 250 and time.monotonic() - started < 30:  # the flood is on before the run
            time.sleep(0.01)
        before = sent[0]
        got = bridged(system, fmu_dir / "BridgePlant.fmu", port, 2.0)
        during = sent[0] - before
    finally:
        stop.set()
        thread.join()
    seconds = time.monotonic() - started
    assert got.ok, got.error
    assert before >= 250 and during >= 50, (before, during)  # however loaded the machine is
    for name in ref.names:
        assert np.array_equal(got[name], ref[name]), name
    assert robot.proc.poll() is None
    time.sleep(1.1)  # the last counts are logged within a second
    stop_robot(robot.proc)
    lines = robot.log.read_text().splitlines()
    drops = [line for line in lines if "failed authentication" in line]
    assert drops and len(drops) <= seconds + 2, lines  # one a second, not one per datagram
    assert any("more like it" in line for line in drops)
    assert any("no such session" in line for line in lines)


def test_token_is_not_on_the_command_line(robot):
    robot()
    pid = robot.proc.pid
    assert TOKEN.encode() not in Path(f"/proc/{pid}/cmdline").read_bytes()
    assert f"{protocol.TOKEN_ENV}={TOKEN}".encode() in Path(f"/proc/{pid}/environ").read_bytes()


# --- bad requests from a peer that has the token ----------------------------------------------


@pytest.mark.slow
def test_bad_requests_are_refused_and_the_robot_lives_on(robot):
    port = robot()
    peer = Peer(port)
    try:

        def refused(reply, code, text):
            assert reply is not None and reply.kind == protocol.ERROR, reply
            assert reply.code == code and text in reply.text, reply.text
            # nothing of the robot's own: no time stamp, no time, no values
            assert (reply.stamp_ns, reply.t, reply.h, reply.values) == (0, 0.0, 0.0, ())

        bad_ints = [(float("nan"), "not finite"), (1.5, "not a 32-bit"), (2.0**40, "not a 32-bit")]
        for value, text in bad_ints:
            values = list(DEFAULTS)
            values[SEED] = value
            refused(peer.ask(protocol.INIT, 0, 0.0, 0.0, values), 1, f"noise_seed is {text}")
        refused(peer.ask(protocol.INIT, 0, 0.0, 0.0, DEFAULTS[:5]), 1, "carries 5 values")
        refused(peer.ask(protocol.STEP, 1, 0.0, 0.0025, (0.0,) * 3), 2, "no such session")
        assert peer.ask(protocol.INIT, 0, 0.0, 0.0, DEFAULTS).kind == protocol.INIT_REPLY
        h, t = 0.0025, 0.0
        for seq in (1, 2, 3):
            reply = peer.ask(protocol.STEP, seq, t, h, (1.0, 2.0, 3.0))
            assert reply.kind == protocol.STEP_REPLY and reply.seq == seq
            t += h
        assert reply.t == t  # the robot is at t = 0.0075
        for seq, (tt, hh, values, code, text) in enumerate(
            [
                (t, h, (1.0, 2.0), 1, "STEP carries 2 values, expected 3"),
                (t, h, (1.0, float("nan"), 3.0), 1, "non-finite"),
                (t, float("inf"), (1.0, 2.0, 3.0), 1, "non-finite"),
                (t, 1e9, (1.0, 2.0, 3.0), 1, "STEP size must be > 0 and <= 1 s"),
                (t, -h, (1.0, 2.0, 3.0), 1, "STEP size must be > 0"),
                (5.0, h, (1.0, 2.0, 3.0), 1, "does not start where the previous step ended"),
            ],
            start=4,
        ):
            reply = peer.ask(protocol.STEP, seq, tt, hh, values)
            refused(reply, code, text)
            assert "0.0075" not in reply.text
        refused(peer.ask(protocol.STEP, 50, t, h, (1.0, 2.0, 3.0)), 3, "out of sequence")
        refused(peer.ask(protocol.INIT, 0, 0.0, 0.0, DEFAULTS), 3, "INIT repeated after STEP")
        # datagrams that are not requests of ours get no answer at all
        valid = protocol.pack(KEY, protocol.STEP, 10, peer.session, t, h, (1.0, 2.0, 3.0))
        for junk in [
            b"",
            b"garbage",
            os.urandom(300),
            valid[:-1],  # truncated
            valid[:30],
            valid + bytes(60000),  # oversize
            protocol.pack(KEY, protocol.STEP_REPLY, 10, peer.session, t, h, (0.0,) * 20),
        ]:
            peer.sock.send(junk)
            assert peer.receive(timeout=0.2) is None
        # and the robot still answers the next valid request, from where it was
        reply = peer.ask(protocol.STEP, 10, t, h, (1.0, 2.0, 3.0))
        assert reply.kind == protocol.STEP_REPLY and reply.t == t + h
        assert peer.ask(protocol.STEP, 10, t, h, (1.0, 2.0, 3.0)).t == t + h  # resend: cached
        assert robot.proc.poll() is None
    finally:
        peer.close()


@pytest.mark.slow
def test_an_internal_error_is_answered_and_survived():
    """A bug behind a valid request (here: the plant class raising something unexpected) gets an
    INTERNAL error reply without the exception's text, and the robot goes on serving."""
    logs = []
    server = RobotServer(KEY, log=logs.append)
    real = server.model_class
    server.model_class = lambda *a: (_ for _ in ()).throw(RuntimeError("secret detail"))
    thread = threading.Thread(target=server.serve, args=(3.0,))
    thread.start()
    peer = Peer(server.address[1])
    try:
        reply = peer.ask(protocol.INIT, 0, 0.0, 0.0, DEFAULTS)
        assert reply.kind == protocol.ERROR and reply.code == protocol.INTERNAL
        assert "secret" not in reply.text
        server.model_class = real
        assert peer.ask(protocol.INIT, 0, 0.0, 0.0, DEFAULTS).kind == protocol.INIT_REPLY
    finally:
        peer.close()
        thread.join()
        server.close()
    assert any("secret detail" in line for line in logs)  # kept in the robot's own log


# --- options ------------------------------------------------------------------------------------


def robot_cli(*args: str, env_token: str | None = TOKEN, timeout: float = 30.0):
    env = {k: v for k, v in os.environ.items() if k != protocol.TOKEN_ENV}
    if env_token is not None:
        env[protocol.TOKEN_ENV] = env_token
    cmd = [*ROBOT_COMMAND, *args]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, out, err


@pytest.mark.parametrize(
    "args,message",
    [
        (["--tick", "nan"], "--tick must be a number from 1e-05 to 0.1 (got 'nan')"),
        (["--tick", "0"], "--tick must be a number"),
        (["--tick", "-1"], "--tick must be a number"),
        (["--tick", "inf"], "--tick must be a number"),
        (["--tick", "fast"], "--tick must be a number"),
        (["--max-step", "nan"], "--max-step must be a number"),
        (["--duration", "-1"], "--duration must be a number"),
        (["--port", "70000"], "--port must be an integer from 0 to 65535"),
        (["--port", "x"], "--port must be an integer"),
        (["--fault", "late@3:nan"], "the delay must be 0-60 s"),
        (["--fault", "boom@3"], "--fault expects"),
        (["--set", "plant.m1=-1"], "the plant refuses these parameters"),
        (["--set", "plant.noise_seed=1e12"], "noise_seed"),
        (["--set", "plant.wall_k=nan"], "wall_k"),
        (["--set", "plant.nope=1"], "the robot has no parameter 'plant.nope'"),
        (["--host", "256.1.1.1"], "cannot listen on UDP 256.1.1.1:0"),
    ],
)
def test_bad_options_get_one_line(args, message):
    code, out, err = robot_cli("--port", "0", *args)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith("impedance-cosim robot: error: ") and message in err, err


@pytest.mark.slow
def test_token_sources_are_checked(tmp_path):
    def run(*args, env_token=None):
        code, _, err = robot_cli("--port", "0", "--duration", "0.2", *args, env_token=env_token)
        assert len(err.strip().splitlines()) <= 1 and "Traceback" not in err, err
        return code, err

    code, err = run()
    assert code == 2 and "no session token: give --token-file PATH" in err
    assert "32-256 printable ASCII" in run(env_token="short")[1]
    assert "not both" in run("--token-file", str(tmp_path / "t"), env_token=TOKEN)[1]
    token_file = tmp_path / "t"
    code, err = run("--token-file", str(token_file))  # created, with a new token
    assert code == 0 and "new session token written to" in err
    assert token_file.stat().st_mode & 0o777 == 0o600
    token = token_file.read_text()
    assert run("--token-file", str(token_file)) == (0, "")  # read back, not replaced
    assert token_file.read_text() == token
    token_file.chmod(0o640)
    code, err = run("--token-file", str(token_file))
    assert code == 2 and "mode 640 lets others read it" in err


def test_a_robot_with_a_token_file_serves_a_bridge_given_the_file(system, fmu_dir, tmp_path):
    """The documented stand-alone use: `robot --token-file F` writes a new token to F, the bridge
    reads it from its robot_token_file parameter."""
    token_file = tmp_path / "robot.token"
    proc, port = start_robot(None, extra=["--token-file", str(token_file)])
    try:
        overrides = {"plant.robot_port": port, "plant.robot_token_file": str(token_file),
                     **PATIENT}  # fmt: skip
        result = Master(
            system,
            RunOptions(
                stop_time=0.5, fmu_files={"plant": fmu_dir / "BridgePlant.fmu"}, overrides=overrides
            ),
        ).run()
    finally:
        stop_robot(proc)
    assert result.ok, result.error
    assert np.array_equal(
        result["plant.q1"], Master(system, RunOptions(stop_time=0.5)).run()["plant.q1"]
    )


def test_a_port_in_use_gets_one_line():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", 0))
        port = busy.getsockname()[1]
        code, out, err = robot_cli("--port", str(port))
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert f"cannot listen on UDP 127.0.0.1:{port}: Address already in use" in err


# --- the bridge notices a lost session ---------------------------------------------------------


def test_a_robot_reset_mid_run_fails_the_run(system, fmu_dir, robot):
    result = bridged(system, fmu_dir / "BridgePlant.fmu", robot("--fault=reset@40"), 1.0)
    assert not result.ok
    assert "lost this session" in result.error and "STEP 40" in result.error, result.error
    assert len(result.data) == 40  # t = 0 and the 39 steps before


def test_a_new_session_mid_run_fails_the_old_run(system, fmu_dir, robot):
    """Another bridge with the token opens a session in the middle of a run (the plant is
    rebuilt): the first run stops with a clear message instead of going on with a reset plant."""
    port = robot()
    other = Peer(port, session=777)
    timer = threading.Timer(0.5, other.send, (protocol.INIT, 0, 0.0, 0.0, DEFAULTS))
    timer.start()
    try:
        result = bridged(system, fmu_dir / "BridgePlant.fmu", port, 4.0, realtime=True)
        assert other.receive().kind == protocol.INIT_REPLY  # the robot took the new session
    finally:
        timer.cancel()
        other.close()
    assert not result.ok
    assert "lost this session" in result.error and "no such session" in result.error
    assert 20 < len(result.data) < 1601  # stopped when the INIT came (at about t = 0.5 s)


@pytest.mark.slow
def test_a_bridge_with_another_token_fails_initialization(ssp_path, fmu_dir, robot):
    """In a child process (an initialization error corrupts pythonfmu 0.7's interpreter): the
    robot drops every datagram of a bridge with another token; the bridge says so."""
    port = robot()
    bridge = fmu_dir / "BridgePlant.fmu"
    ok, rows, error = run_bridge_in_child(ssp_path, bridge, port, protocol.new_token())
    assert ok == "False" and rows == "0"
    assert "timeout after 300 ms waiting for the reply to INIT" in error
    assert "a robot with another session token drops every message" in error
    assert robot.proc.poll() is None
