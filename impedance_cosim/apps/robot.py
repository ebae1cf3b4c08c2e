"""The robot process: plant_model.model.PlantModel (or MuJoCo's plant, --plant mujoco:
robot_plant.py) behind the bridge protocol (bridge_model/protocol.py), the stand-in for the
hardware behind the bridge FMU (docs/hil.md).

In lock-step mode it steps exactly as the bridge asks (the same calls as the in-process plant:
bit-identical results); in real-time mode it integrates against the wall clock in fixed ticks
with the last torque held, and answers each request with its latest outputs.

Everything that arrives is hostile until checked: a datagram must verify with the session token
(else it is dropped unanswered), then every field is checked before use (kind, count, finite
values, integer parameters, step size, start time, session, sequence). A request that fails a
check gets an ERROR reply with a fixed text (no internal state); nothing a peer sends stops the
process. Drops and refusals are counted and logged at most once a second.

A flood of foreign datagrams cannot delay or drop a session's: the session has a socket of its
own that the kernel gives only its bridge's datagrams (robot_net), served first; the listening
socket is drained in batches, and what cannot be a request (length, header) is dropped before
any MAC is computed. A repeated request (same session and sequence number: the bridge resends
an unanswered one) gets the cached reply; the plant never steps twice.
"""

from __future__ import annotations

import math
import os
import select
import socket
import sys
import time
from collections import Counter, deque
from collections.abc import Mapping
from typing import Any

from bridge_model import protocol
from impedance_cosim.apps import robot_net
from impedance_cosim.apps.robot_options import MAX_STEP_RANGE, TICK_RANGE, Fault, check_range

BATCH = 64  # datagrams handled from one socket before the other's turn
SEEN_SESSIONS = 4096  # session ids remembered (a replayed INIT of an old session is refused)


class RobotServer:
    """The plant behind the bridge protocol (see module docstring)."""

    def __init__(
        self,
        key: bytes,
        host: str = "127.0.0.1",
        port: int = 0,
        realtime: bool = False,
        overrides: Mapping[str, Any] | None = None,
        faults: list[Fault] | None = None,
        tick: float = 0.001,
        max_step: float = 1.0,
        log=None,
        allow_remote: bool = False,
        plant: str = "ours",
    ) -> None:
        from impedance_cosim.apps.robot_plant import plant_class
        from impedance_cosim.fmi.model import ModelError
        from plant_model.model import PlantModel

        self.key = key
        self.tick = check_range("--tick", tick, *TICK_RANGE)
        self.max_step = check_range("--max-step", max_step, *MAX_STEP_RANGE)
        if not (isinstance(port, int) and 0 <= port <= 65535):
            raise ValueError(f"--port must be 0-65535 (got {port!r})")
        self.model_class = plant_class(plant)  # ours or MuJoCo's (apps/robot_plant.py)
        self.parameters = [
            v for v in PlantModel.variables() if v.causality == "parameter"
        ]  # INIT's
        names = {v.name: v for v in self.model_class.variables() if v.causality == "parameter"}
        self.overrides = {}
        for key_, value in (overrides or {}).items():
            comp, _, var = key_.partition(".")
            if comp != "plant" or var not in names:
                raise ValueError(f"the robot has no parameter {key_!r} (write plant.<parameter>)")
            self.overrides[var] = _convert(names[var].type, value, key_)
        try:  # a bad override is found now, not at the first INIT
            self.model_class({**{v.name: v.start for v in names.values()}, **self.overrides}, 0.0)
        except ModelError as exc:
            raise ValueError(f"--set: the plant refuses these parameters: {exc}") from None
        self.realtime = realtime
        self.faults = {f.seq: f for f in faults or []}
        self.log = log or _log_to_stderr
        self.sock = robot_net.listen(host, port, allow_remote)  # ValueError: one line
        self.address = self.sock.getsockname()
        self.session_sock: socket.socket | None = None  # the current session's own (robot_net)
        self._buf = bytearray(protocol.MAX_DATAGRAM + 1)  # one more: an oversize one shows
        self._view = memoryview(self._buf)
        self.plant = None
        self.session: int | None = None  # the current session, bound to self.peer
        self.peer = None
        self.last_seq = -1
        self.last_reply = b""
        self.seen: set[int] = set()
        self.seen_order: deque[int] = deque()
        self.tau = (0.0, 0.0, 0.0)
        self.steps = 0
        self.dropped: Counter[str] = Counter()  # totals, by reason
        self.refused: Counter[str] = Counter()
        self._pending: dict[str, list] = {}  # since the last log line: key -> [count, text]
        self._last_log = 0.0
        self._stopping = False

    @property
    def mode(self) -> str:
        return "real time" if self.realtime else "lock-step"

    def close(self) -> None:
        self._flush_log(force=True)
        self._close_session_socket()
        self.sock.close()

    def stop(self) -> None:
        """Make serve return within its next 0.2 s (from another thread)."""
        self._stopping = True

    def serve(self, duration: float | None = None) -> None:
        """Answer requests (for `duration` seconds, default forever, or until stop)."""
        end = None if duration is None else time.perf_counter() + duration
        while (end is None or time.perf_counter() < end) and not self._stopping:
            timeout = 0.2 if end is None else max(0.0, min(0.2, end - time.perf_counter()))
            if self.realtime and self.plant is not None:
                self._advance()
                timeout = min(timeout, max(0.0, self._next_tick() - time.perf_counter()))
            session = self.session_sock
            ready, _, _ = select.select([self.sock] if session is None else [session, self.sock],
                                        [], [], timeout)  # fmt: skip
            for sock in ready:  # the session's own socket first, then a batch of the others
                if sock is self.session_sock or sock is self.sock:
                    self._drain(sock)
            self._flush_log()

    # --- requests -------------------------------------------------------------------------------

    def _drain(self, sock: socket.socket) -> None:
        """Handle what `sock` holds, at most BATCH datagrams; those that cannot be a request of
        this protocol (length, header: protocol.header_problem) are dropped before any MAC."""
        buf, view = self._buf, self._view
        for _ in range(BATCH):
            try:
                n, client = sock.recvfrom_into(buf)
            except BlockingIOError:
                return
            except OSError:
                if sock.fileno() == -1:
                    return  # a new INIT on it replaced the session (and closed its socket)
                continue  # e.g. an ICMP error queued for the socket
            if protocol.header_problem(view[:n]):
                self._drop("malformed", client)
            elif buf[6] not in (protocol.INIT, protocol.STEP):
                self._drop("not a request", client)  # never answer a reply (no loops)
            else:
                self._handle(bytes(view[:n]), client)

    def _handle(self, raw: bytes, client) -> None:
        """Check one datagram and answer it (or drop it); never raises."""
        try:
            msg = protocol.Message(raw, self.key)
        except protocol.AuthenticationError:
            return self._drop("failed authentication", client)
        except protocol.ProtocolError:
            return self._drop("malformed", client)
        if msg.kind not in (protocol.INIT, protocol.STEP):
            return self._drop("not a request", client)
        try:
            handler = self._init if msg.kind == protocol.INIT else self._step
            reply = handler(msg, client)
        except Exception as exc:  # a bug must not stop the robot: refuse, log the cause
            self._note(f"internal error ({type(exc).__name__}: {exc})")
            reply = self._error(msg, protocol.INTERNAL, "internal error")
        if reply:
            try:
                self.sock.sendto(reply, client)
            except OSError as exc:
                self._note(f"cannot answer {client[0]}:{client[1]} ({exc.strerror})")

    def _init(self, msg: protocol.Message, client) -> bytes:
        from impedance_cosim.fmi.model import ModelError

        if msg.session == self.session and client == self.peer and msg.seq == 0:
            if self.last_seq == 0:
                return self.last_reply  # a resent INIT: the same answer
            return self._refuse(msg, protocol.SEQUENCE, "INIT repeated after STEP")
        if msg.session in self.seen:
            return self._refuse(msg, protocol.SEQUENCE, "INIT of a session that was used before")
        n = len(self.parameters)
        if msg.seq != 0 or msg.h != 0.0 or not math.isfinite(msg.t):
            return self._refuse(msg, protocol.BAD_REQUEST, "INIT needs seq 0, h 0 and a finite t")
        if len(msg.values) != n:
            text = f"INIT carries {len(msg.values)} values, expected {n}"
            return self._refuse(msg, protocol.BAD_REQUEST, text)
        params = {}
        for v, x in zip(self.parameters, msg.values, strict=True):
            problem = _parameter_problem(v.type, x)
            if problem:
                return self._refuse(msg, protocol.BAD_REQUEST, f"INIT: {v.name} {problem}")
            params[v.name] = {"Boolean": bool, "Integer": int}.get(v.type, float)(x)
        params.update(self.overrides)
        try:
            plant = self.model_class(params, msg.t, None)
        except ModelError as exc:
            self._note(f"INIT refused: {exc}")
            return self._refuse(msg, protocol.REFUSED, "the plant refused the parameters")
        self._forget_session()
        self.session, self.peer, self.plant = msg.session, client, plant
        self.session_sock = robot_net.session_socket(self.sock, client)
        self.seen.add(msg.session)
        self.seen_order.append(msg.session)
        if len(self.seen_order) > SEEN_SESSIONS:
            self.seen.discard(self.seen_order.popleft())
        self.tau = (0.0, 0.0, 0.0)
        self.t_sim0, self.k = msg.t, 0
        self.t_wall0 = time.perf_counter()
        self.steps = 0
        self.log(f"INIT ({self.mode}) at t={msg.t:g}: new session from {client[0]}:{client[1]}")
        return self._answer(msg, protocol.INIT_REPLY, 0)

    def _step(self, msg: protocol.Message, client) -> bytes:
        from impedance_cosim.fmi.model import ModelError

        seq = msg.seq
        fault = self.faults.get(seq) if msg.session == self.session else None
        if fault and fault.kind == "reset" and self.last_seq == seq - 1:
            self.log(f"fault injected: session forgotten at STEP {seq}")
            self._forget_session()
        if self.session is None or msg.session != self.session:
            return self._refuse(msg, protocol.NO_SESSION, "no such session")
        if client != self.peer:
            self._drop("from an address other than the session's", client)
            return b""
        if seq == self.last_seq:
            return self.last_reply  # a resent request: the same answer, no new step
        if seq != self.last_seq + 1:
            return self._refuse(msg, protocol.SEQUENCE, "STEP out of sequence")
        self.last_seq = seq  # from here on, a resend gets this answer
        if fault and fault.kind == "exit":
            self.log(f"fault injected: exiting at STEP {seq}")
            os._exit(3)
        if fault and fault.kind == "drop":
            self.log(f"fault injected: no reply to STEP {seq}")
            self.last_reply = b""
            return b""
        problem = self._step_problem(msg)
        if problem:
            return self._refuse(msg, protocol.BAD_REQUEST, problem, cache=True)
        if self.plant is None:
            return self._refuse(msg, protocol.REFUSED, "the plant failed earlier", cache=True)
        if self.realtime:
            self._advance()  # up to now, with the torque held so far
            if self.plant is None:
                return self._refuse(msg, protocol.REFUSED, "the plant failed earlier", cache=True)
        try:
            if self.realtime:
                self.tau = tuple(msg.values)
            else:
                self.plant.do_step(msg.t, msg.h, tuple(msg.values))
        except ModelError as exc:
            self._note(f"STEP {seq} refused: {exc}")
            return self._refuse(msg, protocol.REFUSED, "the plant refused the step", cache=True)
        self.steps += 1
        if fault and fault.kind == "late":
            self.log(f"fault injected: reply to STEP {seq} {fault.arg:g} s late")
            time.sleep(fault.arg)
        shift = 1000 if fault and fault.kind == "seq" else 0
        if shift:
            self.log(f"fault injected: reply to STEP {seq} with sequence {seq + shift}")
        return self._answer(msg, protocol.STEP_REPLY, shift)

    def _step_problem(self, msg: protocol.Message) -> str:
        """Why a STEP of the current session cannot be taken ("" when it can)."""
        if len(msg.values) != 3:
            return f"STEP carries {len(msg.values)} values, expected 3"
        if not msg.finite():
            return "STEP with a non-finite t, h or torque"
        if not 0.0 < msg.h <= self.max_step:
            return f"STEP size must be > 0 and <= {self.max_step:g} s"
        if not self.realtime and self.plant is not None:
            if abs(msg.t - self.plant.t) > 1e-9 * max(1.0, abs(msg.t)):
                return "STEP does not start where the previous step ended"
        return ""

    def _forget_session(self) -> None:
        self.session, self.peer, self.plant = None, None, None
        self.last_seq, self.last_reply = 0, b""
        self._close_session_socket()

    def _close_session_socket(self) -> None:
        if self.session_sock is not None:
            self.session_sock.close()
            self.session_sock = None

    # --- replies --------------------------------------------------------------------------------

    def _answer(self, msg: protocol.Message, kind: int, shift: int) -> bytes:
        reply = protocol.pack(self.key, kind, msg.seq + shift, msg.session, self.plant.t, msg.h,
                              self.plant.outputs(), echo_ns=msg.stamp_ns)  # fmt: skip
        self.last_seq, self.last_reply = msg.seq, reply
        return reply

    def _error(self, msg: protocol.Message, code: int, text: str) -> bytes:
        """An ERROR reply: the request's seq, session and stamp, a code and a fixed text; no time
        or value of the robot's."""
        return protocol.pack(self.key, protocol.ERROR, msg.seq, msg.session, 0.0, 0.0, (),
                             text=text, code=code, echo_ns=msg.stamp_ns, stamp_ns=0)  # fmt: skip

    def _refuse(self, msg: protocol.Message, code: int, text: str, cache: bool = False) -> bytes:
        self.refused[text] += 1
        self._note(f"refused {msg.name} {msg.seq}: {text}", text)
        reply = self._error(msg, code, text)
        if cache:
            self.last_reply = reply
        return reply

    # --- counting and logging (at most one line a second) ---------------------------------------

    def _drop(self, reason: str, client) -> None:
        """Count a dropped datagram; its line is written with the next log line (cheap enough
        to be called for every datagram of a flood)."""
        self.dropped[reason] += 1
        entry = self._pending.get(reason)
        if entry is None:
            self._pending[reason] = [1, (reason, client)]
        else:
            entry[0] += 1
            entry[1] = (reason, client)

    def _note(self, text: str, key: str | None = None) -> None:
        """Log `text` now, or with its count in the next line if one went out < 1 s ago."""
        entry = self._pending.setdefault(key or text, [0, text])
        entry[0] += 1
        entry[1] = text
        self._flush_log()

    def _flush_log(self, force: bool = False) -> None:
        now = time.monotonic()
        if not self._pending or (now - self._last_log < 1.0 and not force):
            return
        texts = [(n, t if isinstance(t, str) else f"dropped a datagram ({t[0]}) from "
                  f"{t[1][0]}:{t[1][1]}") for n, t in self._pending.values()]  # fmt: skip
        self.log("; ".join(t if n == 1 else f"{t} (and {n - 1} more like it)" for n, t in texts))
        self._pending.clear()
        self._last_log = now

    # --- real time: the plant advances in ticks of `tick` seconds of wall-clock time ------------

    def _next_tick(self) -> float:
        return self.t_wall0 + (self.k + 1) * self.tick

    def _advance(self) -> None:
        from impedance_cosim.fmi.model import ModelError

        while self.plant is not None and time.perf_counter() >= self._next_tick():
            try:
                self.plant.do_step(self.t_sim0 + self.k * self.tick, self.tick, self.tau)
            except ModelError as exc:
                self._note(f"the plant failed in real time: {exc}; stopped")
                self.plant = None
                return
            self.k += 1


def _log_to_stderr(text: str) -> None:
    """The robot's log line on stderr; a closed or full stderr must not stop the robot."""
    try:
        print(f"robot: {text}", file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


def _parameter_problem(kind: str, x: float) -> str:
    """Why the float64 x cannot be a parameter of FMI type `kind` ("" when it can)."""
    if not math.isfinite(x):
        return "is not finite"
    if kind == "Integer" and not (x.is_integer() and -(2**31) <= x < 2**31):
        return "is not a 32-bit integer"
    if kind == "Boolean" and x not in (0.0, 1.0):
        return "is not 0 or 1"
    return ""


def _convert(kind: str, value: Any, name: str) -> Any:
    from impedance_cosim.cosim.fmus.fmi2 import fmi_value

    if kind in ("Integer", "Boolean") and isinstance(value, float):
        value = int(value)
    value = fmi_value(kind, value, name)
    if kind == "Real" and not math.isfinite(value):
        raise ValueError(f"variable {name}: {value!r} is not finite")
    if kind == "Integer" and not -(2**31) <= value < 2**31:
        raise ValueError(f"variable {name}: {value} is not a 32-bit integer")
    return value
