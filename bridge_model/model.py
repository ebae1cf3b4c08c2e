"""The bridge plant: the PumaPlant interface in front of an external robot process.

It simulates nothing. Initialization sends the plant parameters to the robot process (INIT) and
takes its initial outputs from the reply; each do_step sends the torques (STEP, sequence number
1, 2, ...) and returns the outputs the robot reports after the step. UDP, protocol in
bridge_model/protocol.py (docs/hil-reference.md).

Every message is signed with the session token (`robot_token_file`, or `robot_token`), and
carries a session id the bridge draws at random for its INIT. A reply counts only if its MAC
verifies, it echoes our session id, sequence number and time stamp, and it has the right kind and
count of finite values; datagrams that fail the MAC are ignored (counted in the timeout message).

A request is sent again every min(timeout / 4, 0.1 s) while it is unanswered (the robot answers
a repeated sequence number from its cache and never steps twice), so a lost datagram costs one
resend, not the run. Failures (all logged with the cause, the step is not taken):

- no reply within `timeout_s` (at most 60 s; lost packets, a stalled robot): "timeout after X ms
  waiting for the reply to STEP sequence N from HOST:PORT (sent K times)";
- the robot process is gone (ICMP port unreachable on loopback): "robot process not reachable";
- a reply with another sequence number, or that does not echo the request: "reply had sequence
  M, expected N";
- the robot no longer has our session (it restarted, or another bridge opened a session) or says
  we are out of sequence: "the robot lost this session";
- the robot refuses the step (ERROR message): "robot refused STEP N: <its message>";
- a SIGINT or SIGTERM the host recorded (the master's StopSignals) ends any wait within 0.1 s:
  "interrupted by SIGINT while waiting for the reply to ..." (impedance_cosim/fmi/host.py).

Every failure makes doStep return fmi2Discard (see BridgePlant.py). All but the refusal also
break the link: the bridge refuses every later step (the robot may or may not have taken the lost
step, so the lock-step pairing is gone). At initialization the bridge resends INIT every 0.1 s
until `init_timeout_s` (at most 600 s; the robot may still be starting).

Standard library only (it runs inside the FMU, which bundles plant_model for the interface).
"""

from __future__ import annotations

import math
import secrets
import socket
import time
from dataclasses import dataclass, field
from typing import Any

from bridge_model import protocol
from impedance_cosim.fmi.host import pending_signal, signal_text
from impedance_cosim.fmi.model import FmuModel, ModelError, build_params, check_finite_inputs
from impedance_cosim.fmi.variables import Variable, parameters_of
from impedance_cosim.physics.arm import _p, check_fields
from plant_model.model import INPUTS, PlantModel

RESEND_MAX_S = 0.1  # an unanswered request goes again after min(timeout / 4, this)


@dataclass(frozen=True)
class BridgeSetup:
    """Where the robot process is and how long to wait for it."""

    robot_host: str = field(
        default="127.0.0.1", metadata={"description": "Robot process address (IPv4)"}
    )
    robot_port: int = _p(50400, "", "Robot process UDP port", 1)
    timeout_s: float = _p(0.05, "s", "Time the robot has to answer a step (resent meanwhile)",
                          0.0, 60.0)  # fmt: skip
    init_timeout_s: float = _p(2.0, "s", "Time the robot has to answer the first INIT", 0.0,
                               600.0)  # fmt: skip
    robot_token_file: str = field(
        default="",
        metadata={"description": "File with the session token shared with the robot (mode 600)"},
    )
    robot_token: str = field(
        default="",
        metadata={"description": "The session token itself (secret; instead of the file)"},
    )


def plant_variables() -> list[Variable]:
    """PumaPlant's variable table (parameters, inputs, outputs), in its order."""
    return PlantModel.variables()


PLANT_PARAMETERS = [v for v in plant_variables() if v.causality == "parameter"]
PLANT_OUTPUTS = [v.name for v in plant_variables() if v.causality == "output"]


def _token_key(setup: BridgeSetup) -> bytes:
    """The MAC key from robot_token_file or robot_token (exactly one of them); ModelError."""
    try:
        if setup.robot_token_file and setup.robot_token:
            raise ValueError("set robot_token_file or robot_token, not both")
        if setup.robot_token_file:
            return protocol.read_token_file(setup.robot_token_file)
        if setup.robot_token:
            return protocol.token_key(setup.robot_token, "robot_token")
    except ValueError as exc:
        raise ModelError(str(exc)) from None
    raise ModelError(
        "no session token: set robot_token_file to the robot's token file (or robot_token)"
    )


class LinkError(ModelError):
    """The link to the robot failed (timeout, robot gone, out of sequence): the bridge is done."""


class BridgeModel(FmuModel):
    """PumaPlant's interface, answered by an external robot process (see module docstring)."""

    MODEL_NAME = "BridgePlant"
    DESCRIPTION = (
        "Hardware-in-the-loop bridge with PumaPlant's interface: sends the joint torques to an"
        " external robot process over UDP each step and returns the outputs it reports"
    )
    OUTPUT_DEPENDENCIES = ""

    @classmethod
    def variables(cls) -> list[Variable]:
        return [
            *plant_variables(),
            *parameters_of(BridgeSetup()),
            Variable("link_rtt", "output", 0.0, "Round-trip time of the last exchange", "s"),
            Variable("robot_t", "output", 0.0, "The robot's time in its last reply", "s"),
        ]

    def __init__(self, parameters: dict[str, Any], start_time: float = 0.0, inputs=None) -> None:
        try:
            self.setup = build_params(BridgeSetup, parameters)
            check_fields(self.setup)
            plant = [float(parameters.get(v.name, v.start)) for v in PLANT_PARAMETERS]
        except (TypeError, ValueError) as exc:
            raise ModelError(str(exc)) from None
        self.where = f"{self.setup.robot_host}:{self.setup.robot_port}"
        self.key = _token_key(self.setup)
        self.session = secrets.randbits(64) | 1  # never 0
        self.rejected = 0  # datagrams that failed the MAC or the checks
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.connect((self.setup.robot_host, self.setup.robot_port))
        except OSError as exc:
            self.sock.close()
            raise ModelError(f"cannot reach the robot process at {self.where}: {exc}") from None
        self.t = float(start_time)
        self.seq = 0
        self.answered = -1
        self.failed: str | None = None
        reply = self._request(protocol.INIT, self.t, 0.0, plant, self.setup.init_timeout_s)
        self._take(reply)
        self.rtt = 0.0  # outputs at initialization do not depend on the exchange's timing

    def __del__(self) -> None:
        sock = getattr(self, "sock", None)
        if sock is not None:
            sock.close()

    # --- the exchange ---------------------------------------------------------------------------

    def _request(self, kind: int, t: float, h: float, values, timeout: float):
        """Send one request (seq = self.seq), again every min(timeout / 4, RESEND_MAX_S) while it
        is unanswered (the robot answers a repeat from its cache), and return its reply within
        `timeout`; LinkError on failure, or as soon as the host has recorded a stop signal."""
        seq = self.seq
        stamp = protocol.now_ns()
        data = protocol.pack(self.key, kind, seq, self.session, t, h, values, stamp_ns=stamp)
        what = f"the reply to {protocol.TYPE_NAMES[kind]} sequence {seq} from {self.where}"
        start = time.perf_counter()
        deadline, interval = start + timeout, max(min(timeout / 4, RESEND_MAX_S), 1e-3)
        next_send, sends, refused = start, 0, False
        while True:
            signum = pending_signal()
            if signum is not None:
                raise LinkError(f"interrupted by {signal_text(signum)} while waiting for {what}")
            now = time.perf_counter()
            if sends and now >= deadline:
                raise LinkError(self._timeout_cause(kind, timeout, what, sends, refused))
            if now >= next_send:
                self._send(data)
                sends, next_send = sends + 1, now + interval
            self.sock.settimeout(max(min(deadline, next_send) - now, 1e-4))
            try:
                raw = self.sock.recv(65536)
            except TimeoutError:
                continue
            except ConnectionRefusedError:
                # Loopback: the robot's port is closed (process not started, or gone).
                if kind != protocol.INIT:
                    raise LinkError(
                        f"robot process not reachable at {self.where} (connection refused)"
                        f" while waiting for sequence {seq}"
                    ) from None
                refused = True  # it may still be starting: the next INIT goes at next_send
                continue
            try:
                msg = protocol.Message(raw, self.key)
            except protocol.ProtocolError:
                self.rejected += 1
                continue  # not signed with our token, or not this protocol: ignored
            if msg.session != self.session:
                self.rejected += 1
                continue  # not a reply to this session
            if msg.seq <= self.answered:
                continue  # a duplicate reply to a resent request
            if msg.seq != seq or msg.echo_ns != stamp:
                stale = ", but not our request's time stamp" if msg.seq == seq else ""
                raise LinkError(
                    f"reply had sequence {msg.seq}, expected {seq}{stale} (from {self.where})"
                )
            if msg.kind == protocol.ERROR:
                self.answered = seq
                text = f"robot refused {protocol.TYPE_NAMES[kind]} {seq}: {msg.text}"
                if msg.code in (protocol.NO_SESSION, protocol.SEQUENCE):
                    raise LinkError(
                        f"the robot at {self.where} lost this session (it restarted, or another"
                        f" bridge opened a session there): {text}"
                    )
                raise ModelError(text)
            if msg.kind != kind + 1 or len(msg.values) != len(PLANT_OUTPUTS):
                raise LinkError(
                    f"reply to sequence {seq} is a {msg.name} with {len(msg.values)} values,"
                    f" expected a {protocol.TYPE_NAMES[kind + 1]} with {len(PLANT_OUTPUTS)}"
                )
            if not msg.finite():
                raise LinkError(f"reply to sequence {seq} has a non-finite value")
            self.answered = seq
            self.rtt = time.perf_counter() - start
            return msg

    def _timeout_cause(self, kind: int, timeout: float, what: str, sends: int, refused: bool):
        """Why a request went unanswered, for LinkError."""
        if refused:
            cause = f"robot process not reachable at {self.where} (connection refused)"
        else:
            times = "once" if sends == 1 else f"{sends} times"
            cause = f"timeout after {1e3 * timeout:g} ms waiting for {what} (sent {times})"
        if self.rejected:
            cause += f" ({self.rejected} datagrams that failed the checks were ignored)"
        if kind == protocol.INIT and not refused:
            cause += " (a robot with another session token drops every message)"
        return cause

    def _send(self, data: bytes) -> None:
        try:
            self.sock.send(data)
        except ConnectionRefusedError:
            pass  # reported by the receive (or its timeout)
        except OSError as exc:
            raise LinkError(f"cannot send to the robot process at {self.where}: {exc}") from None

    def _take(self, msg: protocol.Message) -> None:
        self.values = msg.values
        self.robot_t = msg.t

    # --- FmuModel -------------------------------------------------------------------------------

    def do_step(self, t: float, h: float, inputs: tuple) -> None:
        if self.failed:
            raise LinkError(f"the link to the robot failed earlier ({self.failed})")
        check_finite_inputs(INPUTS, inputs)
        if not (h > 0.0 and math.isfinite(h)):
            raise ModelError(f"communication step must be > 0 and finite (got {h})")
        self.seq += 1
        try:
            msg = self._request(protocol.STEP, t, h, inputs, self.setup.timeout_s)
        except LinkError as exc:
            self.failed = str(exc)
            raise
        self._take(msg)
        self.t = t + h

    def outputs(self) -> tuple:
        return (*self.values, self.rtt, self.robot_t)

    def get_state(self) -> dict[str, Any]:
        return {"t": self.t, "seq": self.seq, "values": list(self.values)}

    def set_state(self, state: dict[str, Any]) -> None:
        raise ModelError("the bridge cannot restore the robot's state (no rollback of hardware)")
