"""LAND after a failsafe, repeated until the vehicle shows it took it: a command sent into a
dead link is lost, a link back still delivers it."""

from __future__ import annotations

import time
from collections.abc import Callable

LAND_RETRY_S = 0.25
"""[s] LAND is commanded again this often until a heartbeat shows the vehicle took it."""
FAILSAFE_REPEAT_S = 10.0
"""[s] at most this long (or until close()); ArduPilot's GUIDED timeout only levels the
vehicle, so it is worth landing it well after its own watchdog has acted."""
FIRST_REPEATS = 2
"""LANDs sent at once (UDP: a lost command would leave the vehicle hovering)."""


class LandRetry:
    """command() sends one LAND; start() sends the first ones, tick(taken) the next while
    the vehicle has not `taken` it, cancel() ends the repeats (a new flight was asked for)."""

    def __init__(self, command: Callable[[], None]) -> None:
        self._command = command
        self._until_s = 0.0  # time.monotonic() until which LAND is repeated
        self._sent_s = 0.0

    def start(self) -> None:
        self._until_s = time.monotonic() + FAILSAFE_REPEAT_S
        self._send(FIRST_REPEATS)

    def cancel(self) -> None:
        self._until_s = 0.0

    def tick(self, taken: bool) -> None:
        now = time.monotonic()
        if now < self._until_s and now - self._sent_s >= LAND_RETRY_S and not taken:
            self._send(1)

    def _send(self, repeats: int) -> None:
        self._sent_s = time.monotonic()
        for _ in range(repeats):
            self._command()
