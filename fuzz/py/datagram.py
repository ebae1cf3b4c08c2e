#!/usr/bin/env python3
"""Fuzz target: the bridge protocol's datagram decoder (bridge_model/protocol.py), as the robot
and the bridge run it on every datagram they receive: header_problem, then Message (MAC,
fields). Only ProtocolError (AuthenticationError is one) may come out.

Byte 0 is a mode: bit 0 set re-signs the rest with the fuzz key (its last 16 bytes become the
right MAC), so that mutations get past the MAC to the field decoding."""

from __future__ import annotations

import sys

import _common  # noqa: F401 - sys.path

from bridge_model import protocol

KEY = b"k" * 32


def entry(data: bytes) -> None:
    if not data:
        return
    body = data[1:]
    if data[0] & 1 and len(body) >= protocol.MAC_SIZE:
        body = body[: -protocol.MAC_SIZE]
        body += protocol._mac(KEY, body)
    protocol.header_problem(body)
    try:
        msg = protocol.Message(body, KEY)
    except protocol.ProtocolError as exc:
        assert str(exc) and "\n" not in str(exc), repr(exc)
        return
    assert msg.name in protocol.TYPE_NAMES.values()
    assert len(msg.values) <= protocol.MAX_VALUES
    msg.finite()


if __name__ == "__main__":
    _common.main(entry)
    sys.exit(0)
