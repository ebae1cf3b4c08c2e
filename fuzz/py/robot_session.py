#!/usr/bin/env python3
"""Fuzz target: the robot's side of the bridge protocol (impedance_cosim/apps/robot.py
RobotServer._handle): a sequence of datagrams from two peers through the session handshake
(INIT, STEP, resends, other sessions). _handle never raises, and no datagram may reach its
catch-all (an "internal error" note is a finding); replies are kept, not sent.

Input: records of [flags, length low, length high, bytes...]; flags bit 0 re-signs the bytes with
the session key (the last 16 become the right MAC), bit 1 picks the peer."""

from __future__ import annotations

import sys

import _common  # noqa: F401 - sys.path

from bridge_model import protocol
from impedance_cosim.apps.robot import RobotServer

KEY = b"r" * 32
PEERS = [("127.0.0.1", 40001), ("127.0.0.1", 40002)]


class _Sink:
    """The listening socket's stand-in: replies are counted; the port is not shared, so the
    server keeps no per-session socket."""

    def __init__(self, real) -> None:
        self.real, self.replies = real, 0

    def sendto(self, data: bytes, peer) -> int:
        self.replies += 1
        return len(data)

    def getsockopt(self, *args) -> int:
        return 0

    def __getattr__(self, name):
        return getattr(self.real, name)


_SERVER: list[RobotServer] = []
_NOTES: list[str] = []


def server() -> RobotServer:
    if not _SERVER:
        s = RobotServer(KEY, log=_NOTES.append)
        s.sock = _Sink(s.sock)
        _SERVER.append(s)
    return _SERVER[0]


def reset(s: RobotServer) -> None:
    """A fresh session table per input (the server's state is part of what is fuzzed)."""
    s._forget_session()
    s.seen.clear()
    s.seen_order.clear()
    s.last_seq, s.last_reply = -1, b""
    s._pending.clear()
    _NOTES.clear()


def entry(data: bytes) -> None:
    s = server()
    reset(s)
    k = 0
    while k + 3 <= len(data) and k < 64 * 1024:
        flags, n = data[k], min(data[k + 1] | data[k + 2] << 8, protocol.MAX_DATAGRAM + 1)
        raw = data[k + 3 : k + 3 + n]
        k += 3 + n
        if flags & 1 and len(raw) >= protocol.MAC_SIZE:
            raw = raw[: -protocol.MAC_SIZE] + protocol._mac(KEY, raw[: -protocol.MAC_SIZE])
        s._handle(raw, PEERS[(flags >> 1) & 1])
        internal = [t for t in [*_NOTES, *map(str, s._pending)] if "internal error" in t]
        assert not internal, internal


def record(raw: bytes, flags: int = 0) -> bytes:
    return bytes([flags, len(raw) & 0xFF, len(raw) >> 8]) + raw


def seeds() -> dict[str, bytes]:
    s = server()
    start = [float(v.start) for v in s.parameters]
    init = protocol.pack(KEY, protocol.INIT, 0, 11, 0.0, 0.0, start, stamp_ns=1)
    steps = b"".join(
        record(protocol.pack(KEY, protocol.STEP, q, 11, (q - 1) / 400, 1 / 400, [1.0, 0.5, 0.1]))
        for q in (1, 2, 2, 3)
    )
    other = protocol.pack(KEY, protocol.STEP, 4, 11, 3 / 400, 1 / 400, [0.0] * 3)
    return {
        "handshake": record(init) + steps,
        "resent_init": record(init) + record(init) + steps,
        "other_peer": record(init) + steps + record(other, 2),
        "new_session": record(init) + record(init.replace(b"\x0b", b"\x0c", 1), 1),
    }


if __name__ == "__main__":
    _common.main(entry)
    sys.exit(0)
