"""The control socket of `perchd serve` (docs/contracts.md §4): Unix stream, one JSON object per line.

ControlServer is polled from the daemon's select loop (no threads): `fds()` to wait on,
`handle(fd)` when one is readable. Each complete line is parsed with json.loads only (never
eval or unpickle) and handed to `dispatch(request) -> reply`; a malformed line, an unknown
command or a dispatch error gets {"ok": false, "error": ...} and the service carries on.

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
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from perchd.core.errors import ConfigError, LinkError

MAX_LINE = 65536
"""[bytes] a longer request line is refused and the client dropped."""
UNIX_PATH_MAX = 107
"""[bytes] longest AF_UNIX socket path Linux binds (sun_path is 108 bytes with its NUL)."""
MAX_CLIENTS = 32
"""Connections served at once; more are refused (select() and the fd table stay bounded)."""

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
    def owner(cls, uids: frozenset[int] = frozenset(), gids: frozenset[int] = frozenset()) -> "PeerPolicy":
        """The service's own user and root, plus the configured users and groups."""
        return cls(frozenset({os.geteuid(), 0}) | uids, gids)

    def refusal(self, peer: Peer) -> str | None:
        """None if `peer` may connect, else the reason it may not."""
        if peer.uid in self.uids or (self.gids and not self.gids.isdisjoint(_groups_of(peer))):
            return None
        return (f"uid {peer.uid} (gid {peer.gid}) may not use this control socket; allow it "
                "with [service] allowed_users or allowed_groups")


def _groups_of(peer: Peer) -> set[int]:

    try:
        name = pwd.getpwuid(peer.uid).pw_name
    except KeyError:  # a uid with no passwd entry has only the gid the kernel reports
        return {peer.gid}
    return {peer.gid, *os.getgrouplist(name, peer.gid)}


class ControlServer:
    """Binds `path` itself, or serves `listening`, a socket systemd bound and passed
    (perchd.service.activation): then the file is systemd's, left in place on close()."""

    def __init__(self, path: str | os.PathLike, dispatch: Dispatch, mode: int = 0o660,
                 peers: PeerPolicy | None = None,
                 on_refuse: Callable[[str], None] | None = None,
                 listening: socket.socket | None = None) -> None:
        self.dispatch = dispatch
        self.peers = peers or PeerPolicy.owner()
        self.on_refuse = on_refuse
        self.refused = 0
        self.activated = listening is not None
        if listening is None:
            self.path, self.sock = Path(path), _bind(Path(path), mode)
        else:
            self.path, self.sock = Path(listening.getsockname()), listening
        self.sock.setblocking(False)
        self.clients: dict[int, tuple[socket.socket, bytearray]] = {}

    def fds(self) -> list[int]:
        return [self.sock.fileno(), *self.clients]

    def handle(self, fd: int) -> None:
        if fd == self.sock.fileno():
            self._accept()
            return
        conn, buf = self.clients[fd]
        try:
            data = conn.recv(4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._drop(fd)
            return
        buf += data
        while b"\n" in buf:
            line, _, rest = bytes(buf).partition(b"\n")
            buf[:] = rest
            if not self._reply(conn, self.answer(line)):
                self._drop(fd)
                return
        if len(buf) > MAX_LINE:
            self._reply(conn, {"ok": False, "error": f"request line longer than {MAX_LINE} bytes"})
            self._drop(fd)

    def answer(self, line: bytes) -> dict[str, Any]:
        """The reply to one request line."""
        try:
            req = json.loads(line.decode("utf-8"))
        except (UnicodeDecodeError, ValueError) as err:
            return {"ok": False, "error": f"malformed request, not one JSON object: {err}"}
        except RecursionError:  # json.loads of "[[[[..." recurses per level
            return {"ok": False, "error": "malformed request, not one JSON object: nested too deeply"}
        if not isinstance(req, dict) or not isinstance(req.get("cmd"), str):
            return {"ok": False, "error": 'a request is a JSON object with a "cmd" string'}
        try:
            return self.dispatch(req)
        except Exception as err:  # noqa: BLE001 - one bad request must not stop the service
            return {"ok": False, "error": f"{type(err).__name__}: {err}"}

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
        refusal = self.peers.refusal(peer_of(conn))
        if refusal is None and len(self.clients) >= MAX_CLIENTS:
            refusal = f"{MAX_CLIENTS} clients connected already; try again"
        if refusal is not None:
            self.refused += 1
            if self.on_refuse is not None:
                self.on_refuse(refusal)
            self._reply(conn, {"ok": False, "error": refusal})
            conn.close()
            return
        conn.setblocking(False)
        self.clients[conn.fileno()] = (conn, bytearray())

    def _reply(self, conn: socket.socket, reply: dict[str, Any]) -> bool:
        """Send one reply line; a client that cannot take it (gone, not reading) is dropped."""
        try:
            conn.settimeout(1.0)
            conn.sendall((json.dumps(reply) + "\n").encode())
            conn.setblocking(False)
            return True
        except OSError:
            return False

    def _drop(self, fd: int) -> None:
        conn, _ = self.clients.pop(fd)
        conn.close()


def _check_length(path: Path) -> None:
    """bind() of a longer path fails with no errno text ("cannot listen: None"): say why."""
    size = len(os.fsencode(path))
    if size > UNIX_PATH_MAX:
        raise ConfigError(f"--socket {path}: path too long ({size} bytes; an AF_UNIX socket "
                          f"path has at most {UNIX_PATH_MAX}); choose a shorter one")


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


def request(path: str | os.PathLike, req: dict[str, Any], timeout: float = 5.0) -> dict[str, Any]:
    """Client side: send one request, return the one reply (used by `perchd ctl`)."""

    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(timeout)
        try:
            s.connect(str(path))
            s.sendall((json.dumps(req) + "\n").encode())
            buf = b""
            while b"\n" not in buf:
                chunk = s.recv(65536)
                if not chunk:
                    break
                buf += chunk
        except OSError as err:
            raise LinkError(f"control socket {path}: {err.strerror or err}") from None
    if not buf.strip():
        raise LinkError(f"control socket {path}: closed without a reply")
    return json.loads(buf.partition(b"\n")[0])
