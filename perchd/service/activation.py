"""Socket activation (sd_listen_fds(3)): the control socket handed over by systemd.

systemd passes listening sockets from fd 3 (SD_LISTEN_FDS_START) on, with LISTEN_FDS (how
many), LISTEN_PID (the process they are meant for) and LISTEN_FDNAMES (colon-separated
FileDescriptorName= values). perchd takes exactly one: the only fd, or the one named
`control`, and only if it is what `perchd serve` would have bound itself, a listening
AF_UNIX stream socket; anything else is one ConfigError line. The LISTEN_* variables are
removed once read, so processes the service starts (the Crazyflie link keeper) do not take
the fds as theirs.
"""

from __future__ import annotations

import os
import socket
import stat
from collections.abc import MutableMapping

from perchd.core.errors import ConfigError

LISTEN_FDS_START = 3
"""The first passed fd (SD_LISTEN_FDS_START)."""
FD_NAME = "control"
"""FileDescriptorName= of the control socket when a unit passes more than one fd."""
_VARS = ("LISTEN_FDS", "LISTEN_PID", "LISTEN_FDNAMES")


def activated_socket(environ: MutableMapping[str, str] | None = None) -> socket.socket | None:
    """The control socket systemd passed to this process, or None when not activated."""
    env = os.environ if environ is None else environ
    count, pid, names = (env.get(v) for v in _VARS)
    for v in _VARS:
        env.pop(v, None)
    if count is None or pid != str(os.getpid()):
        return None  # not activated, or the variables were meant for a parent
    if not count.isdigit() or int(count) < 1:
        raise ConfigError(f"socket activation: LISTEN_FDS={count!r}: expected a count >= 1")
    return _checked(_pick(int(count), names.split(":") if names else []))


def _pick(count: int, names: list[str]) -> int:
    fds = range(LISTEN_FDS_START, LISTEN_FDS_START + count)
    if count == 1:
        return fds[0]
    named = [fd for fd, name in zip(fds, names) if name == FD_NAME]
    if len(named) != 1:
        raise ConfigError(
            f"socket activation: {count} fds passed (names {':'.join(names) or '-'}) "
            f"and not exactly one named {FD_NAME!r}; set FileDescriptorName={FD_NAME}"
        )
    return named[0]


def _checked(fd: int) -> socket.socket:
    """fd as a socket object if it is a listening AF_UNIX stream socket; else ConfigError."""
    try:
        is_sock = stat.S_ISSOCK(os.fstat(fd).st_mode)
    except OSError as err:
        raise ConfigError(f"socket activation: fd {fd}: {err.strerror}") from None
    if not is_sock:
        raise ConfigError(
            f"socket activation: fd {fd} is not a socket; the .socket unit must "
            "have ListenStream=/run/perchd/control.sock"
        )
    sock = socket.socket(fileno=fd)
    listening = sock.getsockopt(socket.SOL_SOCKET, socket.SO_ACCEPTCONN)
    if sock.family != socket.AF_UNIX or sock.type != socket.SOCK_STREAM or not listening:
        kind = f"{sock.family.name} {sock.type.name}{'' if listening else ', not listening'}"
        sock.detach()  # systemd's fd, left as it came
        raise ConfigError(
            f"socket activation: fd {fd} is {kind}, not a listening AF_UNIX "
            "stream socket; the .socket unit must have ListenStream=/run/perchd/"
            "control.sock"
        )
    sock.set_inheritable(False)
    return sock
