"""The control socket of `perchd serve` (docs/contracts.md §4): Unix stream, one JSON object per line.

ControlServer is polled from the daemon's select loop (no threads): `fds()` to wait on,
`handle(fd)` when one is readable. Each complete line is parsed (service/request_line.py) and
handed to `dispatch(request) -> reply`; a malformed line, an unknown command or a dispatch
error gets {"ok": false, "error": ...} and the service carries on.

Access is checked twice: the socket file is mode 0660 (owner and group may connect), and each
connection's peer credentials (SO_PEERCRED) must pass a PeerPolicy: by default the service's
own user and root only; other users and groups are let in only when configured
([service] allowed_users / allowed_groups). A refused peer gets one error line and is closed.
"""

from __future__ import annotations

import json
import os
import pwd
import socket
import stat
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from perchd.core.clock import Clock, MonotonicClock
from perchd.core.errors import ConfigError
from perchd.service.request_line import BadRequest, parse_request

MAX_LINE = 65536
"""[bytes] a longer request line is refused and the client dropped."""
UNIX_PATH_MAX = 107
"""[bytes] longest AF_UNIX socket path Linux binds (sun_path is 108 bytes with its NUL)."""
MAX_CLIENTS = 32
"""Connections served at once (select() and the fd table stay bounded); over it, abort only."""
RESERVED_SLOTS = 4
"""Connections taken over MAX_CLIENTS, each for one abort."""
IDLE_TIMEOUT_S = 30.0
"""[s] a client that sends nothing this long is closed, so idle ones cannot hold the bound."""
RESERVED_WAIT_S = 2.0
"""[s] how long a connection over the bound may take to send its abort."""

Dispatch = Callable[[dict[str, Any]], dict[str, Any]]
_UCRED = struct.Struct("3i")  # struct ucred {pid_t pid; uid_t uid; gid_t gid;}


@dataclass(frozen=True)
class Peer:
    """The credentials the kernel reports for a connected client (SO_PEERCRED)."""

    pid: int
    uid: int
    gid: int


def peer_of(conn: socket.socket) -> Peer:
    return Peer(*_UCRED.unpack(conn.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, _UCRED.size)))


@dataclass(frozen=True)
class PeerPolicy:
    """Who may talk to the control socket: these uids, or members (primary group, or
    supplementary per the user database) of these gids. `owner()` is the default."""

    uids: frozenset[int]
    gids: frozenset[int] = frozenset()

    @classmethod
    def owner(
        cls, uids: frozenset[int] = frozenset(), gids: frozenset[int] = frozenset()
    ) -> PeerPolicy:
        """The service's own user and root, plus the configured users and groups."""
        return cls(frozenset({os.geteuid(), 0}) | uids, gids)

    def refusal(self, peer: Peer) -> str | None:
        """None if `peer` may connect, else the reason it may not."""
        if peer.uid in self.uids or (self.gids and not self.gids.isdisjoint(_groups_of(peer))):
            return None
        return (
            f"uid {peer.uid} (gid {peer.gid}) may not use this control socket; allow it "
            "with [service] allowed_users or allowed_groups"
        )


def _groups_of(peer: Peer) -> set[int]:

    try:
        name = pwd.getpwuid(peer.uid).pw_name
    except KeyError:  # a uid with no passwd entry has only the gid the kernel reports
        return {peer.gid}
    return {peer.gid, *os.getgrouplist(name, peer.gid)}


@dataclass
class Client:
    """One accepted connection: its unread bytes and when it last sent any [s, server clock].
    A reserved client came in over the bound: it is served one abort, then closed."""

    conn: socket.socket
    buf: bytearray
    last_s: float
    reserved: bool = False


class ControlServer:
    """Binds `path` itself, or serves `listening`, a socket systemd bound and passed
    (perchd.service.activation): then the file is systemd's, left in place on close().

    The operator always gets an abort through: at most `max_clients` connections are served
    and each is closed after `idle_s` without a byte (expire(), called from the service
    loop), and over that bound up to RESERVED_SLOTS more are taken, each served only an
    abort within RESERVED_WAIT_S (a full reserve drops its oldest: the newest connection is
    the one whose request is still to come)."""

    def __init__(
        self,
        path: str | os.PathLike,
        dispatch: Dispatch,
        mode: int = 0o660,
        peers: PeerPolicy | None = None,
        on_refuse: Callable[[str], None] | None = None,
        listening: socket.socket | None = None,
        clock: Clock | None = None,
        max_clients: int = MAX_CLIENTS,
        idle_s: float = IDLE_TIMEOUT_S,
    ) -> None:
        self.dispatch = dispatch
        self.peers = peers or PeerPolicy.owner()
        self.on_refuse = on_refuse
        self.clock = clock or MonotonicClock()
        self.max_clients, self.idle_s = max_clients, idle_s
        self.refused = 0
        self.activated = listening is not None
        if listening is None:
            self.path, self.sock = Path(path), _bind(Path(path), mode)
        else:
            self.path, self.sock = Path(listening.getsockname()), listening
        self.sock.setblocking(False)
        self.clients: dict[int, Client] = {}

    def fds(self) -> list[int]:
        return [self.sock.fileno(), *self.clients]

    def handle(self, fd: int) -> None:
        if fd == self.sock.fileno():
            self._accept()
            return
        client = self.clients[fd]
        try:
            data = client.conn.recv(4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._drop(fd)
            return
        client.last_s = self.clock.now()
        client.buf += data
        while b"\n" in client.buf:
            line, _, rest = bytes(client.buf).partition(b"\n")
            client.buf[:] = rest
            if not self._reply(client.conn, self.answer(line, client.reserved)) or client.reserved:
                self._drop(fd)
                return
        if len(client.buf) > MAX_LINE:
            self._refuse(fd, f"request line longer than {MAX_LINE} bytes")

    def answer(self, line: bytes, reserved: bool = False) -> dict[str, Any]:
        """The reply to one request line; over the bound (`reserved`) only abort is served."""
        try:
            req = parse_request(line)
        except BadRequest as err:
            return {"ok": False, "error": str(err)}
        if reserved and req["cmd"] != "abort":
            return {"ok": False, "error": self._bound_text()}
        try:
            return self.dispatch(req)
        except Exception as err:  # noqa: BLE001 - one bad request must not stop the service
            return {"ok": False, "error": f"{type(err).__name__}: {err}"}

    def expire(self) -> None:
        """Close every client silent for longer than its allowance."""
        now = self.clock.now()
        for fd, client in list(self.clients.items()):
            allowed = RESERVED_WAIT_S if client.reserved else self.idle_s
            if now - client.last_s > allowed:
                self._refuse(fd, f"closed: nothing received for {allowed:g} s")

    def close(self) -> None:
        for fd in list(self.clients):
            self._drop(fd)
        self.sock.close()
        if self.activated:
            return  # systemd's socket: it keeps listening for the next start
        try:
            self.path.unlink()
        except FileNotFoundError:
            pass

    def _accept(self) -> None:
        try:
            conn, _ = self.sock.accept()
        except OSError:  # nothing to accept after all, or out of fds: the service carries on
            return
        conn.setblocking(False)
        refusal = self.peers.refusal(peer_of(conn))
        if refusal is not None:
            self.refused += 1
            if self.on_refuse is not None:
                self.on_refuse(refusal)
            self._reply(conn, {"ok": False, "error": refusal})
            conn.close()
            return
        reserved = sum(not c.reserved for c in self.clients.values()) >= self.max_clients
        if reserved:
            self._make_room()
        self.clients[conn.fileno()] = Client(conn, bytearray(), self.clock.now(), reserved)

    def _make_room(self) -> None:
        """Over the bound: drop the oldest reserved client if the reserve is full."""
        reserve = [fd for fd, c in self.clients.items() if c.reserved]
        if len(reserve) >= RESERVED_SLOTS:
            self._refuse(min(reserve, key=lambda fd: self.clients[fd].last_s), self._bound_text())

    def _bound_text(self) -> str:
        return (
            f"{self.max_clients} clients connected already (the bound); over it only abort "
            "is served: try again once one closes"
        )

    def _refuse(self, fd: int, why: str) -> None:
        self._reply(self.clients[fd].conn, {"ok": False, "error": why})
        self._drop(fd)

    def _reply(self, conn: socket.socket, reply: dict[str, Any]) -> bool:
        """Send one reply line without waiting: a client that has not read its earlier replies
        (its buffer full) or is gone is dropped rather than stalling the service loop."""
        try:
            conn.sendall((json.dumps(reply) + "\n").encode())
            return True
        except OSError:
            return False

    def _drop(self, fd: int) -> None:
        self.clients.pop(fd).conn.close()


def _check_length(path: Path) -> None:
    """bind() of a longer path fails with no errno text ("cannot listen: None"): say why."""
    size = len(os.fsencode(path))
    if size > UNIX_PATH_MAX:
        raise ConfigError(
            f"--socket {path}: path too long ({size} bytes; an AF_UNIX socket "
            f"path has at most {UNIX_PATH_MAX}); choose a shorter one"
        )


def _bind(path: Path, mode: int) -> socket.socket:
    """A listening AF_UNIX stream socket at `path`, created with `mode`."""
    _check_length(path)
    _remove_stale(path)
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
    old = os.umask(0o777 & ~mode)  # never world-accessible, not even between bind and chmod
    try:
        sock.bind(str(path))
    except OSError as err:
        sock.close()
        raise ConfigError(f"--socket {path}: cannot listen: {err.strerror}") from None
    finally:
        os.umask(old)
    os.chmod(path, mode)
    sock.listen(8)
    return sock


def _remove_stale(path: Path) -> None:
    """Remove a socket left by a dead server; refuse to steal a live one or a non-socket."""

    try:
        st = path.lstat()
    except FileNotFoundError:
        return
    if not stat.S_ISSOCK(st.st_mode):
        raise ConfigError(f"--socket {path}: exists and is not a socket")
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        probe.connect(str(path))
    except OSError:
        path.unlink()
        return
    finally:
        probe.close()
    raise ConfigError(f"--socket {path}: another perchd serve is listening there")
