"""The bridge protocol: one UDP datagram per message, little-endian, version 1.

Every message is a fixed 48-byte header, then `count` float64 values, then (ERROR only) a UTF-8
text:

    offset size type     field
    0      4    char[4]  magic  b"ICHB"
    4      2    uint16   version  (1)
    6      2    uint16   type     (INIT=1, INIT_REPLY=2, STEP=3, STEP_REPLY=4, ERROR=5)
    8      4    uint32   seq      request: the sender's sequence number; reply: the request's
    12     2    uint16   count    number of float64 values after the header
    14     2    uint16   flags    reserved, 0
    16     8    int64    stamp_ns sender's CLOCK_MONOTONIC at sending (ns)
    24     8    int64    echo_ns  reply: the request's stamp_ns (round-trip time); request: 0
    32     8    float64  t        request: simulation time at the step's start; reply: the robot's
                                  time after the step (lock-step: t + h; real time: its own clock)
    40     8    float64  h        request: communication step size; reply: as requested
    48     8*count float64 payload

Payloads:

- INIT (bridge -> robot): the plant's parameter values as float64, in the order of
  PlantModel.variables() (Booleans as 0/1, Integers exactly); count = number of parameters.
  The robot (re)builds its plant from them, answers INIT_REPLY with the initial outputs.
- STEP (bridge -> robot): the joint torques tau1..tau3 over [t, t + h]; seq = 1, 2, ...
  (INIT uses seq 0).
- INIT_REPLY / STEP_REPLY (robot -> bridge): the plant's outputs (q1..q3, fx, fy, n, q1_true..,
  qd1.., x, y, phi, xd, yd, phid, contact_force, penetration: the PumaPlant outputs in order).
- ERROR (robot -> bridge): count = 0, then a UTF-8 message (the robot refused the request).

A receiver drops datagrams with a wrong magic, version or length (counted, never answered).
A repeated request (same seq) gets the cached reply again; it never steps the robot twice.
"""

from __future__ import annotations

import struct
import time

MAGIC = b"ICHB"
VERSION = 1
INIT, INIT_REPLY, STEP, STEP_REPLY, ERROR = 1, 2, 3, 4, 5
TYPE_NAMES = {INIT: "INIT", INIT_REPLY: "INIT_REPLY", STEP: "STEP", STEP_REPLY: "STEP_REPLY",
              ERROR: "ERROR"}  # fmt: skip
HEADER = struct.Struct("<4sHHIHHqqdd")
assert HEADER.size == 48
MAX_VALUES = 128


class ProtocolError(ValueError):
    """A datagram that is not a valid message of this protocol version."""


def now_ns() -> int:
    """The protocol's time stamps: CLOCK_MONOTONIC (shared by all processes of the machine)."""
    return time.monotonic_ns()


def pack(kind: int, seq: int, t: float, h: float, values=(), text: str = "", echo_ns: int = 0):
    """One message as bytes."""
    values = tuple(values)
    head = HEADER.pack(MAGIC, VERSION, kind, seq & 0xFFFFFFFF, len(values), 0, now_ns(), echo_ns,
                       t, h)  # fmt: skip
    return head + struct.pack(f"<{len(values)}d", *values) + text.encode("utf-8")


class Message:
    """A decoded message."""

    __slots__ = ("kind", "seq", "stamp_ns", "echo_ns", "t", "h", "values", "text")

    def __init__(self, data: bytes) -> None:
        if len(data) < HEADER.size:
            raise ProtocolError(f"datagram of {len(data)} bytes is shorter than the header")
        magic, version, kind, seq, count, _flags, stamp, echo, t, h = HEADER.unpack_from(data)
        if magic != MAGIC:
            raise ProtocolError(f"bad magic {magic!r}")
        if version != VERSION:
            raise ProtocolError(f"protocol version {version}, expected {VERSION}")
        if kind not in TYPE_NAMES:
            raise ProtocolError(f"unknown message type {kind}")
        end = HEADER.size + 8 * count
        if count > MAX_VALUES or len(data) < end or (kind != ERROR and len(data) != end):
            raise ProtocolError(f"{TYPE_NAMES[kind]} of {len(data)} bytes with count {count}")
        self.kind, self.seq, self.stamp_ns, self.echo_ns = kind, seq, stamp, echo
        self.t, self.h = t, h
        self.values = struct.unpack_from(f"<{count}d", data, HEADER.size)
        self.text = data[end:].decode("utf-8", "replace")

    @property
    def name(self) -> str:
        return TYPE_NAMES[self.kind]
