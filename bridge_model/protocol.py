"""The bridge protocol: one UDP datagram per message, little-endian, version 2, authenticated.

Every message is a fixed 56-byte header, then `count` float64 values, then (ERROR only) a UTF-8
text, then a 16-byte MAC:

    offset size type     field
    0      4    char[4]  magic  b"ICHB"
    4      2    uint16   version  (2)
    6      2    uint16   type     (INIT=1, INIT_REPLY=2, STEP=3, STEP_REPLY=4, ERROR=5)
    8      4    uint32   seq      request: the sender's sequence number; reply: the request's
    12     2    uint16   count    number of float64 values after the header
    14     2    uint16   code     ERROR: why (BAD_REQUEST, NO_SESSION, SEQUENCE, REFUSED,
                                  INTERNAL); otherwise 0
    16     8    uint64   session  the session id the bridge drew (at random) for its INIT; every
                                  request carries it, every reply echoes it
    24     8    int64    stamp_ns sender's CLOCK_MONOTONIC at sending (ns); 0 in ERROR replies
    32     8    int64    echo_ns  reply: the request's stamp_ns (round-trip time); request: 0
    40     8    float64  t        request: simulation time at the step's start; reply: the robot's
                                  time after the step (lock-step: t + h; real time: its own
                                  clock); 0 in ERROR replies
    48     8    float64  h        request: communication step size (INIT: 0); reply: as
                                  requested; 0 in ERROR replies
    56     8*count float64 payload
    ...    n    UTF-8    ERROR only: a fixed text saying which check failed
    end-16 16   bytes    MAC: HMAC-SHA256 over every byte before it, keyed with the session
                         token, first 16 bytes

Payloads:

- INIT (bridge -> robot): the plant's parameter values as float64, in the order of
  PlantModel.variables() (Booleans as 0/1, Integers exactly); count = number of parameters;
  seq 0. The robot builds a plant from them, makes the request's session the current one (bound
  to the sender's address) and answers INIT_REPLY with the initial outputs.
- STEP (bridge -> robot): the joint torques tau1..tau3 over [t, t + h]; seq = 1, 2, ...
- INIT_REPLY / STEP_REPLY (robot -> bridge): the plant's outputs (q1..q3, fx, fy, n, q1_true..,
  qd1.., x, y, phi, xd, yd, phid, contact_force, penetration: the PumaPlant outputs in order).
- ERROR (robot -> bridge): count = 0, a code and a fixed text (never the robot's state).

The session token is a secret both ends get at start-up (never on a command line: an environment
variable or a file only its owner can read, see read_token_file). A receiver drops, without any
answer, datagrams that are too short or too long, whose MAC does not verify, or whose header is
not this protocol version. A repeated request (same session and seq) gets the cached reply again;
it never steps the robot twice. See docs/hil-reference.md for the checks on each side and the
trust model.
"""

from __future__ import annotations

import errno
import hmac
import math
import os
import secrets
import stat
import struct
import time
from pathlib import Path

MAGIC = b"ICHB"
VERSION = 2
INIT, INIT_REPLY, STEP, STEP_REPLY, ERROR = 1, 2, 3, 4, 5
TYPE_NAMES = {INIT: "INIT", INIT_REPLY: "INIT_REPLY", STEP: "STEP", STEP_REPLY: "STEP_REPLY",
              ERROR: "ERROR"}  # fmt: skip
# ERROR codes. NO_SESSION and SEQUENCE mean the pairing of bridge and robot is gone.
BAD_REQUEST, NO_SESSION, SEQUENCE, REFUSED, INTERNAL = 1, 2, 3, 4, 5
HEADER = struct.Struct("<4sHHIHHQqqdd")
assert HEADER.size == 56
MAC_SIZE = 16
MAX_VALUES = 64
MAX_TEXT = 256
MAX_DATAGRAM = HEADER.size + 8 * MAX_VALUES + MAX_TEXT + MAC_SIZE

TOKEN_ENV = "IMPEDANCE_COSIM_ROBOT_TOKEN"
TOKEN_MIN, TOKEN_MAX = 32, 256  # characters


class ProtocolError(ValueError):
    """A datagram that is not a valid message of this protocol version."""


class AuthenticationError(ProtocolError):
    """A datagram whose MAC does not verify with our session token."""


def now_ns() -> int:
    """The protocol's time stamps: CLOCK_MONOTONIC (shared by all processes of the machine)."""
    return time.monotonic_ns()


def _mac(key: bytes, data: bytes) -> bytes:
    return hmac.digest(key, data, "sha256")[:MAC_SIZE]


def pack(
    key: bytes,
    kind: int,
    seq: int,
    session: int,
    t: float,
    h: float,
    values=(),
    *,
    text: str = "",
    code: int = 0,
    echo_ns: int = 0,
    stamp_ns: int | None = None,
) -> bytes:
    """One message as bytes, signed with `key` (stamp_ns: now unless given)."""
    values = tuple(values)
    stamp = now_ns() if stamp_ns is None else stamp_ns
    head = HEADER.pack(MAGIC, VERSION, kind, seq & 0xFFFFFFFF, len(values), code,
                       session & 0xFFFFFFFFFFFFFFFF, stamp, echo_ns, t, h)  # fmt: skip
    body = head + struct.pack(f"<{len(values)}d", *values) + text.encode("utf-8")[:MAX_TEXT]
    return body + _mac(key, body)


_PREFIX = MAGIC + VERSION.to_bytes(2, "little")


def header_problem(data: bytes | bytearray | memoryview) -> str:
    """Why `data` cannot be a message of this protocol version, from its length and header alone
    ("" when it may be one). No MAC is computed: a receiver drops most foreign datagrams (garbage,
    other protocols, a flood) at the cost of a few comparisons."""
    n = len(data)
    if n < HEADER.size + MAC_SIZE:
        return f"datagram of {n} bytes is shorter than header and MAC"
    if n > MAX_DATAGRAM:
        return f"datagram of {n} bytes is longer than {MAX_DATAGRAM}"
    if data[:6] != _PREFIX:
        if data[:4] != MAGIC:
            return f"bad magic {bytes(data[:4])!r}"
        return f"protocol version {int.from_bytes(data[4:6], 'little')}, expected {VERSION}"
    kind = int.from_bytes(data[6:8], "little")
    if kind not in TYPE_NAMES:
        return f"unknown message type {kind}"
    count = int.from_bytes(data[12:14], "little")
    end = HEADER.size + 8 * count + MAC_SIZE
    if count > MAX_VALUES or n < end or (kind != ERROR and n != end):
        return f"{TYPE_NAMES[kind]} of {n} bytes with count {count}"
    return ""


class Message:
    """A decoded, authenticated message (ProtocolError / AuthenticationError otherwise)."""

    __slots__ = ("kind", "seq", "code", "session", "stamp_ns", "echo_ns", "t", "h", "values",
                 "text")  # fmt: skip

    def __init__(self, data: bytes, key: bytes) -> None:
        problem = header_problem(data)
        if problem:
            raise ProtocolError(problem)
        body, mac = data[:-MAC_SIZE], data[-MAC_SIZE:]
        if not hmac.compare_digest(mac, _mac(key, body)):
            raise AuthenticationError("MAC does not verify (not signed with our session token)")
        _, _, kind, seq, count, code, session, stamp, echo, t, h = HEADER.unpack_from(body)
        end = HEADER.size + 8 * count
        self.kind, self.seq, self.code, self.session = kind, seq, code, session
        self.stamp_ns, self.echo_ns, self.t, self.h = stamp, echo, t, h
        self.values = struct.unpack_from(f"<{count}d", body, HEADER.size)
        self.text = body[end:].decode("utf-8", "replace")

    @property
    def name(self) -> str:
        return TYPE_NAMES[self.kind]

    def finite(self) -> bool:
        """True when t, h and every value are finite."""
        return all(math.isfinite(x) for x in (self.t, self.h, *self.values))


# --- the session token ------------------------------------------------------------------------


def new_token() -> str:
    """A fresh random session token (64 hex digits, 256 bits)."""
    return secrets.token_hex(32)


def token_key(token: str, where: str = "session token") -> bytes:
    """The MAC key of a token; ValueError unless it is 32-256 printable ASCII characters without
    spaces."""
    token = token.strip()
    if not TOKEN_MIN <= len(token) <= TOKEN_MAX or not all(33 <= ord(c) < 127 for c in token):
        raise ValueError(
            f"{where}: a session token must be {TOKEN_MIN}-{TOKEN_MAX} printable ASCII "
            "characters without spaces"
        )
    return token.encode("ascii")


_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"))  # fmt: skip
_NONBLOCK = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOFOLLOW", 0)
_NONBLOCK |= getattr(os, "O_NOCTTY", 0)


def read_token_file(path: str | os.PathLike) -> bytes:
    """The MAC key from a token file; ValueError unless it is a regular file of ours, at most one
    token long, that no one else can read or write (like ssh's private keys). Never blocks: it is
    opened without following a symbolic link and without waiting (a FIFO or a device is refused
    from fstat before any read)."""
    key = _token_file_key(path)
    if key is None:
        raise ValueError(f"token file {Path(path).expanduser()}: No such file or directory")
    return key


def token_file_key(path: str | os.PathLike) -> tuple[bytes, bool]:
    """The MAC key from a token file, creating the file with a new token if it does not exist
    (write_token_file); and whether it was created. ValueError as read_token_file."""
    key = _token_file_key(path)
    return (key, False) if key is not None else (write_token_file(path), True)


def _token_file_key(path: str | os.PathLike) -> bytes | None:
    """read_token_file, but None when the file does not exist."""
    path = Path(path).expanduser()
    try:
        fd = os.open(path, _NONBLOCK)
    except FileNotFoundError:
        return None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise ValueError(
                f"token file {path}: is a symbolic link (give the file itself)"
            ) from None
        raise ValueError(f"token file {path}: {exc.strerror}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            kind = next((name for test, name in _KINDS if test(info.st_mode)), "not a file")
            raise ValueError(f"token file {path}: is {kind}, not a regular file")
        if os.name == "posix":
            if info.st_uid != os.getuid():
                raise ValueError(f"token file {path}: owned by another user")
            if info.st_mode & 0o077:
                mode = stat.S_IMODE(info.st_mode)
                raise ValueError(f"token file {path}: mode {mode:o} lets others read it (want 600)")
        if info.st_size > TOKEN_MAX + 2:
            raise ValueError(f"token file {path}: {info.st_size} bytes is more than one token "
                             f"({TOKEN_MIN}-{TOKEN_MAX} characters)")  # fmt: skip
        data = os.read(fd, TOKEN_MAX + 3)
    except OSError as exc:
        raise ValueError(f"token file {path}: {exc.strerror}") from None
    finally:
        os.close(fd)
    try:
        return token_key(data.decode("ascii"), f"token file {path}")
    except UnicodeDecodeError:
        raise ValueError(f"token file {path}: not ASCII text") from None


def write_token_file(path: str | os.PathLike) -> bytes:
    """Create `path` (mode 600, refusing an existing file) with a new token; its MAC key."""
    path = Path(path).expanduser()
    token = new_token()
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
    try:
        fd = os.open(path, flags, 0o600)
    except OSError as exc:
        raise ValueError(f"token file {path}: {exc.strerror}") from None
    with os.fdopen(fd, "w") as f:
        f.write(token + "\n")
    return token_key(token)
