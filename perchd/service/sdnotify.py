"""sd_notify(3) written by hand: one non-blocking datagram per message to $NOTIFY_SOCKET.

A no-op when NOTIFY_SOCKET is unset (not started by systemd). Abstract socket names start
with '@' (sent as a leading NUL). A full or vanished socket drops the message rather than
stall the control loop: a missed WATCHDOG=1 is what the watchdog exists to notice.
"""

from __future__ import annotations

import os
import socket
import time


class Notifier:
    """ready(), reloading(), status(text), stopping(), watchdog() (rate-limited to a
    quarter of the period)."""

    def __init__(self, environ: dict[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        addr = env.get("NOTIFY_SOCKET", "")
        self._addr = "\0" + addr[1:] if addr.startswith("@") else addr
        self._sock: socket.socket | None = None
        if self._addr:
            self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.setblocking(False)
        self.watchdog_s = _watchdog_period(env)
        self._next_ping = 0.0

    @property
    def enabled(self) -> bool:
        return self._sock is not None

    def send(self, *fields: str) -> bool:
        """Send 'KEY=VALUE' fields as one message; False if not sent."""
        if self._sock is None:
            return False
        try:
            self._sock.sendto("\n".join(fields).encode(), self._addr)
            return True
        except OSError:  # full (EAGAIN), gone (ENOENT/ECONNREFUSED): never block or crash
            return False

    def ready(self, status: str = "") -> bool:
        return self.send("READY=1", *([f"STATUS={status}"] if status else []))

    def status(self, text: str) -> bool:
        return self.send(f"STATUS={text}")

    def reloading(self, status: str = "") -> bool:
        """RELOADING=1 with MONOTONIC_USEC (CLOCK_MONOTONIC in microseconds) in one datagram:
        Type=notify-reload matches it against the SIGHUP it sent (sd_notify(3)). ready()
        ends the reload."""
        usec = time.clock_gettime_ns(time.CLOCK_MONOTONIC) // 1000
        return self.send(
            "RELOADING=1", f"MONOTONIC_USEC={usec}", *([f"STATUS={status}"] if status else [])
        )

    def stopping(self) -> bool:
        return self.send("STOPPING=1")

    def watchdog(self, now: float | None = None) -> bool:
        """WATCHDOG=1 at most every watchdog_s / 4 [s] (every call when no period is set,
        at most every 0.5 s)."""
        now = time.monotonic() if now is None else now
        if now < self._next_ping:
            return False
        self._next_ping = now + (self.watchdog_s / 4 if self.watchdog_s else 0.5)
        return self.send("WATCHDOG=1")

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None


def _watchdog_period(env) -> float | None:
    """[s] WATCHDOG_USEC, when it is meant for this process (WATCHDOG_PID unset or ours)."""
    usec, pid = env.get("WATCHDOG_USEC"), env.get("WATCHDOG_PID")
    if not usec or (pid and pid != str(os.getpid())):
        return None
    try:
        return int(usec) / 1e6 or None
    except ValueError:
        return None
