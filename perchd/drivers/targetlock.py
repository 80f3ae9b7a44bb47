"""One vehicle, one agent: a lock per driver target on this machine, taken by each driver's
connect() and released by its close() (docs/safety.md "One vehicle, one agent").

The lock is an flock'd file in $XDG_RUNTIME_DIR/perchd-locks (else /tmp/perchd-locks) named
from the normalised driver URI (scheme, host, port, path; no query), holding the holder's pid
and command line. The kernel drops an flock when its holder dies however it dies, so a lock
left by a dead process is simply taken over; the file is only the holder's name tag. Within
one process the lock is counted, not refused: a service that replaces its links connects the
new driver before it closes the old one (service/daemon.py), and one process is one agent.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import re
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from perchd.core.errors import PerchdError
from perchd.core.uri import parse_uri

COMMAND_CHARS = 200
"""The holder's command line is kept (and named in a refusal) up to this length."""


class TargetBusy(PerchdError):
    """Another process holds the vehicle: bad input, nothing done (exit 2, as a taken port)."""


@dataclass(frozen=True)
class Holder:
    pid: int | None  # None: the holder has not written its name yet
    command: str

    def describe(self) -> str:
        return f"pid {self.pid if self.pid is not None else '?'} ({self.command or 'unknown'})"


def target_of(uri: str) -> str:
    """The vehicle a driver URI reaches, as one string: its options (the query) left out,
    the host's case and the loopback name folded."""
    u = parse_uri(uri)
    if not u.host and u.port is None:  # mavlink:udpin:HOST:PORT keeps its device as the path
        return f"{u.scheme}:{u.path.partition('?')[0]}"
    host = "127.0.0.1" if u.host.lower() == "localhost" else u.host.lower()
    port = "" if u.port is None else f":{u.port}"
    return f"{u.scheme}://{host}{port}{u.path}"


def lock_dir() -> Path:
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    return Path(runtime) / "perchd-locks" if runtime else Path("/tmp/perchd-locks")


def lock_path(uri: str) -> Path:
    target = target_of(uri)
    readable = re.sub(r"[^A-Za-z0-9.]+", "_", target).strip("_")[:80]
    return lock_dir() / f"{readable}-{hashlib.sha1(target.encode()).hexdigest()[:10]}.lock"


class TargetLock:
    """A driver's hold on its vehicle: take() at connect, release() at close (and when the
    connect fails); both may be called again and do nothing then."""

    def __init__(self, uri: str) -> None:
        self.uri = uri
        self.path: Path | None = None  # where, once taken
        self.shared = False  # taken while this process held it already

    @property
    def held(self) -> bool:
        return self.path is not None

    def take(self) -> None:
        """TargetBusy naming the process that holds the vehicle, if another does."""
        if self.path is None:
            path = lock_path(self.uri)
            self.shared = _HELD.take(path, self.uri) > 1
            self.path = path

    def release(self) -> None:
        path, self.path = self.path, None
        if path is not None:
            _HELD.drop(path)


def connect_holding(
    lock: TargetLock, open_link: Callable[[], None], close_link: Callable[[], None]
) -> None:
    """A driver's connect(): the lock taken first (refused: nothing opened), then the link;
    a link that fails to open is closed and the lock released, so a failed connect holds
    nothing."""
    lock.take()
    try:
        open_link()
    except BaseException:
        close_link()
        lock.release()
        raise


def hold_target(uri: str) -> TargetLock:
    """The lock for `uri`'s vehicle, taken."""
    lock = TargetLock(uri)
    lock.take()
    return lock


class _Held:
    """This process's locks: path -> [fd, count]."""

    def __init__(self) -> None:
        self._mutex = threading.Lock()
        self._locks: dict[Path, list[int]] = {}

    def take(self, path: Path, uri: str) -> int:
        """How many times this process holds it now."""
        with self._mutex:
            if path not in self._locks:
                self._locks[path] = [_flock(path, uri), 0]
            self._locks[path][1] += 1
            return self._locks[path][1]

    def drop(self, path: Path) -> None:
        with self._mutex:
            entry = self._locks[path]
            entry[1] -= 1
            if entry[1] == 0:
                del self._locks[path]
                os.close(entry[0])  # closing the only fd drops the flock


_HELD = _Held()


def _flock(path: Path, uri: str) -> int:
    """An fd holding the flock on `path`, our name written in it; TargetBusy if taken."""
    _make_dir(path.parent)
    flags, named = os.O_NOFOLLOW | os.O_CLOEXEC, True
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | flags, 0o644)
    except PermissionError:  # another user's tag in the shared directory: lock it unnamed
        fd, named = os.open(path, os.O_RDONLY | flags), False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = read_holder(path)
        os.close(fd)
        raise TargetBusy(
            f"{uri}: the vehicle is in use by another perchd, {holder.describe()}; "
            f"stop that one first (lock {path})"
        ) from None
    if named:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n{_command()}\n".encode())
    return fd


def _make_dir(path: Path) -> None:
    """Private under $XDG_RUNTIME_DIR; under /tmp one directory all users share, sticky."""
    shared = not os.environ.get("XDG_RUNTIME_DIR")
    try:
        path.mkdir(mode=0o700, parents=True)
    except FileExistsError:
        return
    if shared:
        path.chmod(0o1777)


def read_holder(path: Path) -> Holder:
    try:
        text = path.read_text(errors="replace")
    except OSError:
        return Holder(None, "")
    pid, _, command = text.partition("\n")
    return Holder(int(pid) if pid.isdigit() else None, command.strip())


def _command() -> str:
    try:
        argv = Path("/proc/self/cmdline").read_bytes().split(b"\0")
        text = " ".join(a.decode(errors="replace") for a in argv if a)
    except OSError:
        text = " ".join(sys.argv)
    return text[:COMMAND_CHARS]
