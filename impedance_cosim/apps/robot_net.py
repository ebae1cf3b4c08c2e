"""The robot process's sockets: where it listens (loopback unless remote peers are allowed), and
a socket of its own for each session, so that a flood of the listening port cannot delay or drop
the session's datagrams.

The listening socket and each session socket share the port (SO_REUSEPORT). A session socket is
connected to its bridge's address, so the kernel delivers that bridge's datagrams to it and no one
else's; everything else (new INITs, foreign or forged datagrams, a flood) queues on the listening
socket, which the robot drains in batches after the session's. Another process can join the
port only with SO_REUSEPORT and the same user id (who can read the token file anyway); before
binding, a plain probe socket checks that no one holds the port, another robot included. Where
SO_REUSEPORT does not exist, everything arrives on the listening socket (no session socket).
"""

from __future__ import annotations

import ipaddress
import socket

REUSE = getattr(socket, "SO_REUSEPORT", None)


def listen(host: str, port: int, allow_remote: bool = False) -> socket.socket:
    """The robot's listening UDP socket on host:port (IPv4; port 0: a free one), non-blocking.
    ValueError (one line) when the address cannot be bound or is taken, and when it is not a
    loopback address and allow_remote is false (every machine that can reach it could send)."""
    where = f"UDP {host}:{port}"
    try:
        address = socket.gethostbyname(host) if host else "0.0.0.0"
    except (OSError, UnicodeError) as exc:
        raise ValueError(f"cannot listen on {where}: {_why(exc)}") from None
    if not allow_remote and not ipaddress.ip_address(address).is_loopback:
        which = "every interface" if address == "0.0.0.0" else f"{address}, not a loopback address"
        raise ValueError(
            f"--host {host!r} would listen on {which}: other machines could send datagrams here; "
            "give --allow-remote to accept that (docs/hil-reference.md, Trust model)"
        )
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        probe.bind((address, port))  # without SO_REUSEPORT: fails if anyone holds the port
        port = probe.getsockname()[1]
    except (OSError, OverflowError) as exc:
        probe.close()
        raise ValueError(f"cannot listen on {where}: {_why(exc)}") from None
    if REUSE is None:
        probe.setblocking(False)
        return probe
    probe.close()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, REUSE, 1)
        sock.bind((address, port))
    except OSError as exc:
        sock.close()
        raise ValueError(f"cannot listen on UDP {host}:{port}: {_why(exc)}") from None
    sock.setblocking(False)
    return sock


def session_socket(listening: socket.socket, peer: tuple) -> socket.socket | None:
    """A non-blocking socket on the listening socket's address, connected to `peer`: it gets the
    peer's datagrams and only those (see module docstring). None where the port cannot be shared
    (the caller then reads everything from the listening socket)."""
    if REUSE is None or not listening.getsockopt(socket.SOL_SOCKET, REUSE):
        return None
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, REUSE, 1)
        sock.bind(listening.getsockname())
        sock.connect(peer)
    except OSError:
        sock.close()
        return None
    sock.setblocking(False)
    return sock


def _why(exc: BaseException) -> str:
    return exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
