"""The fixed-rate control loop: absolute deadlines on an injected clock, timing statistics.

Tick k is due at start + k * period (absolute, so errors never accumulate). A tick that
ends after the next deadline is an overrun; the missed deadlines are skipped rather than run
back to back, and `streak` counts consecutive overruns for the supervisor. Jitter (actual
start - deadline) is read on the injected clock; compute time on a separate wall timer,
because a simulated clock does not move while the tick computes.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass
from typing import Callable

from perchd.clock import Clock

RATE_MIN_HZ, RATE_MAX_HZ = 1.0, 500.0


@dataclass(frozen=True, slots=True)
class TickTiming:
    """k: tick index; deadline, start [s] on the clock; jitter_s = start - deadline;
    compute_s [s] wall time the tick took; overrun: it ended after the next deadline;
    missed: deadlines skipped after it."""

    k: int
    deadline: float
    start: float
    jitter_s: float
    compute_s: float
    overrun: bool
    missed: int


@dataclass(frozen=True, slots=True)
class LoopSummary:
    """Over a run: ticks, overruns, missed deadlines, longest overrun streak; jitter and
    compute time [s] as median, 99th percentile and maximum."""

    ticks: int
    overruns: int
    missed: int
    max_streak: int
    jitter_median_s: float
    jitter_p99_s: float
    jitter_max_s: float
    compute_median_s: float
    compute_p99_s: float
    compute_max_s: float


def _p99(values: list[float]) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))] if ordered else 0.0


class LoopStats:
    def __init__(self) -> None:
        self.jitter: list[float] = []
        self.compute: list[float] = []
        self.overruns = 0
        self.missed = 0
        self.streak = 0
        self.max_streak = 0

    def add(self, timing: TickTiming) -> None:
        self.jitter.append(timing.jitter_s)
        self.compute.append(timing.compute_s)
        self.overruns += timing.overrun
        self.missed += timing.missed
        self.streak = self.streak + 1 if timing.overrun else 0
        self.max_streak = max(self.max_streak, self.streak)

    def summary(self) -> LoopSummary:
        j, c = self.jitter or [0.0], self.compute or [0.0]
        return LoopSummary(len(self.jitter), self.overruns, self.missed, self.max_streak,
                           statistics.median(j), _p99(j), max(j),
                           statistics.median(c), _p99(c), max(c))


class FixedRateLoop:
    """Calls tick(k, t) at rate_hz until it returns False; `last` is the previous tick's
    timing (the tick being run cannot know its own compute time yet)."""

    def __init__(self, clock: Clock, rate_hz: float,
                 timer: Callable[[], float] = time.perf_counter) -> None:
        if not RATE_MIN_HZ <= rate_hz <= RATE_MAX_HZ:
            raise ValueError(f"loop rate {rate_hz:g} Hz is outside "
                             f"{RATE_MIN_HZ:g}..{RATE_MAX_HZ:g} Hz")
        self.clock = clock
        self.period = 1.0 / rate_hz
        self.timer = timer
        self.stats = LoopStats()
        self.last: TickTiming | None = None

    def run(self, tick: Callable[[int, float], bool]) -> LoopStats:
        origin = self.clock.now()
        k = 0
        while True:
            deadline = origin + k * self.period
            self.clock.sleep_until(deadline)
            start = self.clock.now()
            w0 = self.timer()
            go_on = tick(k, start)
            compute = self.timer() - w0
            end = self.clock.now()
            nxt = k + 1
            while origin + nxt * self.period < end:
                nxt += 1
            missed = nxt - k - 1
            self.last = TickTiming(k, deadline, start, start - deadline, compute,
                                   end > origin + (k + 1) * self.period, missed)
            self.stats.add(self.last)
            if not go_on:
                return self.stats
            k = nxt
