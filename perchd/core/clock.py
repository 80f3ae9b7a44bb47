"""Clocks are injected: the agent reads time and sleeps only through a Clock."""

from __future__ import annotations

import time
from typing import Protocol


class Clock(Protocol):
    def now(self) -> float:
        """[s] monotonic time."""

    def sleep_until(self, deadline: float) -> None:
        """Block until now() >= deadline [s] (returns at once if already past)."""


class MonotonicClock:
    """Real time from time.monotonic(); wall-clock changes do not move it."""

    def now(self) -> float:
        return time.monotonic()

    def sleep_until(self, deadline: float) -> None:
        delay = deadline - time.monotonic()
        if delay > 0:
            time.sleep(delay)


class ManualClock:
    """Simulated time: sleeping advances it at once, so simulated flights run fast."""

    def __init__(self, start: float = 0.0) -> None:
        self._t = start

    def now(self) -> float:
        return self._t

    def sleep_until(self, deadline: float) -> None:
        self._t = max(self._t, deadline)

    def advance(self, dt: float) -> None:
        if dt < 0:
            raise ValueError(f"cannot move a clock backwards by {dt} s")
        self._t += dt
