"""Client side of the control socket (docs/contracts.md §4), as `perchd ctl` uses it: one
request, one reply, and when there is none the true reason in one line."""

from __future__ import annotations

import errno
import json
import os
import socket
import stat
import time
from dataclasses import dataclass
from typing import Any

from perchd.core.errors import LinkError
from perchd.core.safefile import kind
from perchd.service.control_socket import peer_of

TIMEOUT_S = 5.0
"""[s] longest wait for the whole exchange: connecting, sending, the reply."""
MAX_REPLY_BYTES = 1 << 20
"""[bytes] the longest reply read (a status is under 2 kB)."""


class Unreachable(LinkError):
    """No reply came; str() says why. `server_pid`: the pid that listens on the socket, when
    the connection got that far (SO_PEERCRED of the listener), else None."""

    def __init__(self, why: str, server_pid: int | None = None) -> None:
        super().__init__(why)
        self.server_pid = server_pid


@dataclass(frozen=True)
class Answer:
    reply: dict[str, Any]
    server_pid: int | None  # as for Unreachable


def exchange(path: str | os.PathLike, req: dict[str, Any], timeout_s: float = TIMEOUT_S) -> Answer:
    """Send one request and read its one reply, all within timeout_s; Unreachable with the
    reason otherwise (a server that trickles bytes, or sends more than MAX_REPLY_BYTES or
    anything but one JSON object, included)."""
    pid = None
    deadline = time.monotonic() + timeout_s
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        try:
            s.settimeout(timeout_s)
            s.connect(str(path))
            pid = peer_of(s).pid or None  # 0: the listener is in another pid namespace
            _send(s, req, deadline)
            buf = _read_line(s, deadline)
        except OSError as err:
            raise Unreachable(
                why_unreachable(path, err, timeout_s, connected=pid is not None), pid
            ) from None
    if len(buf) > MAX_REPLY_BYTES:
        raise Unreachable(
            f"perchd serve at {path} sent over {MAX_REPLY_BYTES} bytes without ending its reply",
            pid,
        )
    if not buf.endswith(b"\n"):
        raise Unreachable(f"perchd serve at {path} closed the connection without a reply", pid)
    return Answer(_reply(path, buf, pid), pid)


def _reply(path: str | os.PathLike[str], line: bytes, pid: int | None) -> dict[str, Any]:
    try:
        reply = json.loads(line)
    except ValueError:
        reply = None
    if not isinstance(reply, dict):
        raise Unreachable(
            f"{path} answered {line[:40]!r}, not a reply of perchd serve (one JSON object)", pid
        )
    return reply


def _remaining(s: socket.socket, deadline: float) -> None:
    """The socket's timeout set to what is left of the exchange's; TimeoutError if none."""
    left = deadline - time.monotonic()
    if left <= 0:
        raise TimeoutError("timed out")
    s.settimeout(left)


def request(
    path: str | os.PathLike, req: dict[str, Any], timeout_s: float = TIMEOUT_S
) -> dict[str, Any]:
    """The reply alone."""
    return exchange(path, req, timeout_s).reply


def _send(s: socket.socket, req: dict[str, Any], deadline: float) -> None:
    """A server that refused us at once (the peer check, the bound) may have closed before
    our request went out; its reply is still there to read."""
    _remaining(s, deadline)
    try:
        s.sendall((json.dumps(req) + "\n").encode())
    except (BrokenPipeError, ConnectionResetError):
        pass


def _read_line(s: socket.socket, deadline: float) -> bytes:
    buf = b""
    while b"\n" not in buf:
        if len(buf) > MAX_REPLY_BYTES:
            break
        _remaining(s, deadline)
        chunk = s.recv(65536)
        if not chunk:
            break
        buf += chunk
    return buf.partition(b"\n")[0] + (b"\n" if b"\n" in buf else b"")


def not_a_socket(path: str | os.PathLike[str]) -> str | None:
    """What is at `path` when it is there and not a socket (a FIFO, a directory, ...)."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    return None if stat.S_ISSOCK(mode) else kind(mode)


def why_unreachable(
    path: str | os.PathLike, err: OSError, timeout_s: float, connected: bool
) -> str:
    """One line naming the cause of a failed exchange."""
    if isinstance(err, socket.timeout):
        step = "for its reply" if connected else "to connect (its queue is full: busy or stuck)"
        return f"perchd serve at {path} did not answer: waited {timeout_s:g} s {step}"
    code = err.errno
    if code == errno.ENOENT:
        return f"no control socket at {path}: is perchd serve running, and is --socket its path?"
    if code in (errno.ECONNREFUSED, errno.ENOTSOCK) and (other := not_a_socket(path)):
        return f"{path} is not a socket ({other}): is --socket perchd serve's control socket?"
    if code == errno.ECONNREFUSED:
        return (
            f"nothing listens on {path}: a socket left by a perchd serve that stopped; "
            "is perchd serve running?"
        )
    if code in (errno.EACCES, errno.EPERM):
        return (
            f"permission denied on {path} for uid {os.geteuid()}: the socket is for its "
            "owner and group (join the group, or [service] allowed_users)"
        )
    if code in (errno.EPIPE, errno.ECONNRESET):
        return f"perchd serve at {path} closed the connection before replying"
    return f"control socket {path}: {err.strerror or err}"
