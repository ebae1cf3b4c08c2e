"""The robot process as a child: start `impedance-cosim robot` on a free loopback port with the
session token in its environment, wait for its first line (the address it listens on), and stop
it by its PID. Used by `impedance-cosim hil` and the tests."""

from __future__ import annotations

import os
import select
import subprocess
import sys

from bridge_model import protocol

LISTENING = "robot: listening on"  # the robot's first line: LISTENING HOST:PORT (mode)
# `impedance-cosim robot` in a child (not `-m impedance_cosim.cli`: that imports cli twice, and
# an exception class of the second copy escapes main's handler as a traceback); entry() makes a
# signal while it starts one line and 128 + its number too
ROBOT_COMMAND = [sys.executable, "-c", "from impedance_cosim.cli import entry; entry()",
                 "robot"]  # fmt: skip


def start_robot(
    token: str | None,
    realtime: bool = False,
    extra: list[str] | None = None,
    timeout: float = 20.0,
    stderr=None,
) -> tuple[subprocess.Popen, int]:
    """Start `impedance-cosim robot` on a free loopback port as a child process, with the session
    token in its environment (not on its command line, which every user can read; None: give
    --token-file in `extra`); returns it and its port (read from its first line). The caller must
    stop it (stop_robot)."""
    cmd = [*ROBOT_COMMAND, "--port", "0"]
    cmd += ["--realtime" if realtime else "--lockstep", *(extra or [])]
    env = {k: v for k, v in os.environ.items() if k != protocol.TOKEN_ENV}
    if token is not None:
        env[protocol.TOKEN_ENV] = token
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=stderr, text=True, env=env)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], timeout)
        line = proc.stdout.readline() if ready else ""
    except BaseException:  # e.g. Ctrl-C while it starts: no robot is left behind
        stop_robot(proc)
        raise
    if LISTENING not in line:
        stop_robot(proc)
        raise RobotStartError(
            f"the robot process did not start (exit status {proc.returncode}; its message is above)"
        )
    return proc, int(line.split()[3].rsplit(":", 1)[1])


class RobotStartError(ValueError):
    """The robot process did not start (its own message went to its stderr)."""


def stop_robot(proc: subprocess.Popen) -> None:
    """Kill a robot process started by start_robot (by its PID) and reap it."""
    if proc.poll() is None:
        proc.kill()
    proc.wait(timeout=10)
    if proc.stdout:
        proc.stdout.close()
