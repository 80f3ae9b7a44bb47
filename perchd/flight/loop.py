"""The control loops, on an injected clock, with their timing statistics.

FixedRateLoop: tick k is due at start + k * period (absolute, so errors never accumulate).
A tick that ends after the next deadline is an overrun; the missed deadlines are skipped
rather than run back to back, and `streak` counts consecutive overruns for the supervisor.
A pose waits up to one period for the tick that uses it.

MocapSyncLoop: a tick is released by the arrival of a new pose (PoseSource.wait), so the
setpoint follows the pose by the tick's compute time only. Its jitter is start - the pose's
arrival (latency added by the agent); it overruns when it ends more than a period
(1 / rate_hz, the expected mocap interval) after it started, i.e. when the loop cannot keep
up with the frames. Timing from the pose's claimed arrival instead would call frames that
come late off the network loop overruns, and end a flight the agent kept up with. `missed`
counts pose numbers skipped between two ticks. With no pose
for `timeout_periods` periods it ticks anyway, so the supervisor's stale-mocap rule still runs.

While a loop runs the cyclic garbage collector is off (no_collections): a collection stops
every thread of the process for as long as it scans, milliseconds for the oldest generation,
at moments no tick chooses. Reference counting still frees everything that is not a cycle;
the cycles a flight leaves are collected after it (the service does so between flights,
service/daemon.py). Collections that happen anyway (another thread calling gc.collect) are
counted in the summary.

Jitter (actual start - deadline) is read on the injected clock; compute time on a separate
wall timer, because a simulated clock does not move while the tick computes. Over the run,
the process CPU time (all threads: the pose receiver too) over the wall time is the agent's
CPU load.
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import statistics
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from perchd.core.clock import Clock

RATE_MIN_HZ, RATE_MAX_HZ = 1.0, 500.0
TIMER_SLACK_NS = 1000
"""Linux lets a sleep overrun by the thread's timer slack (50 us by default) to batch
wake-ups; the loop's thread asks for 1 us (measured here: median lateness 75 -> 30 us)."""
NO_SEQ = -(1 << 62)
"""A pose sequence number below any real one (NatNet frames may start at 0)."""


@dataclass(frozen=True, slots=True)
class TickTiming:
    """k: tick index; deadline, start [s] on the clock; jitter_s = start - deadline;
    compute_s [s] wall time the tick took; overrun: it ended after the next deadline;
    missed: deadlines (fixed rate) or poses (mocap-synchronous) skipped after it."""

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
        compute time [s] (the whole tick) as min, median, 99th percentile and maximum; agent_* [s]:
        the estimator + supervisor + controller part of the tick; latency_* [s]: from a pose's
        arrival to the setpoint computed from it handed to the driver (each pose's first; the
    flight records it);
        cpu_fraction: process CPU time / wall time over the run (1.0 = one core);
        wall_s [s]; sync: "fixed" or "mocap"; gc_collections: garbage collections that ran
        during the run (0 unless some thread forced one: the loop turns the collector off)."""

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
    jitter_min_s: float = 0.0
    compute_min_s: float = 0.0
    agent_min_s: float = 0.0
    agent_median_s: float = 0.0
    agent_p99_s: float = 0.0
    agent_max_s: float = 0.0
    latency_min_s: float = 0.0
    latency_median_s: float = 0.0
    latency_p99_s: float = 0.0
    latency_max_s: float = 0.0
    cpu_fraction: float = 0.0
    wall_s: float = 0.0
    sync: str = "fixed"
    gc_collections: int = 0


def p99(values: list[float]) -> float:
    """99th percentile by nearest rank (0.0 for no values)."""
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))] if ordered else 0.0


def spread(values: list[float]) -> tuple[float, float, float, float]:
    """(min, median, p99, max), zeros for no values."""
    if not values:
        return 0.0, 0.0, 0.0, 0.0
    return min(values), statistics.median(values), p99(values), max(values)


class LoopStats:
    def __init__(self) -> None:
        self.jitter: list[float] = []
        self.compute: list[float] = []
        self.agent: list[float] = []
        self.latency: list[float] = []
        self.overruns = 0
        self.missed = 0
        self.streak = 0
        self.max_streak = 0
        self.cpu_s = 0.0
        self.wall_s = 0.0
        self.gc_collections = 0

    def add(self, timing: TickTiming) -> None:
        self.jitter.append(timing.jitter_s)
        self.compute.append(timing.compute_s)
        self.overruns += timing.overrun
        self.missed += timing.missed
        self.streak = self.streak + 1 if timing.overrun else 0
        self.max_streak = max(self.max_streak, self.streak)

    def summary(self, sync: str = "fixed") -> LoopSummary:
        (j0, *jitter), (c0, *compute) = spread(self.jitter), spread(self.compute)
        return LoopSummary(
            len(self.jitter),
            self.overruns,
            self.missed,
            self.max_streak,
            *jitter,
            *compute,
            j0,
            c0,
            *spread(self.agent),
            *spread(self.latency),
            self.cpu_s / self.wall_s if self.wall_s > 0 else 0.0,
            self.wall_s,
            sync,
            self.gc_collections,
        )


@contextlib.contextmanager
def timer_slack(ns: int) -> Iterator[None]:
    """The calling thread's timer slack set to `ns` [ns] inside the block (Linux only;
    elsewhere, or if prctl refuses, nothing changes)."""
    prctl = None
    if sys.platform.startswith("linux"):
        prctl = getattr(ctypes.CDLL(None), "prctl", None)
    if prctl is None:
        yield
        return
    PR_SET_TIMERSLACK, PR_GET_TIMERSLACK = 29, 30
    before = prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0)
    prctl(PR_SET_TIMERSLACK, ns, 0, 0, 0)
    try:
        yield
    finally:
        if before > 0:
            prctl(PR_SET_TIMERSLACK, before, 0, 0, 0)


_gc_lock = threading.Lock()
_gc_holders = [0, False]
"""Loops running now (threads of one process may each run one), and whether the collector
was on when the first of them started: it comes back on when the last one ends."""


@contextlib.contextmanager
def no_collections(stats: LoopStats) -> Iterator[None]:
    """The cyclic garbage collector off inside the block (and back as it was once no loop
    runs); every collection that runs anyway is counted in stats.gc_collections."""

    def count(phase: str, info: dict) -> None:
        if phase == "start":
            stats.gc_collections += 1

    with _gc_lock:
        if _gc_holders[0] == 0:
            _gc_holders[1] = gc.isenabled()
            gc.disable()
        _gc_holders[0] += 1
        gc.callbacks.append(count)
    try:
        yield
    finally:
        with _gc_lock:
            gc.callbacks.remove(count)
            _gc_holders[0] -= 1
            if _gc_holders[0] == 0 and _gc_holders[1]:
                gc.enable()


class _Loop:
    """What both loops share: the rate, the timed tick, the statistics and the CPU meter."""

    sync = "fixed"

    def __init__(self, clock: Clock, rate_hz: float, timer: Callable[[], float]) -> None:
        if not RATE_MIN_HZ <= rate_hz <= RATE_MAX_HZ:
            raise ValueError(
                f"loop rate {rate_hz:g} Hz is outside {RATE_MIN_HZ:g}..{RATE_MAX_HZ:g} Hz"
            )
        self.clock = clock
        self.period = 1.0 / rate_hz
        self.timer = timer
        self.stats = LoopStats()
        self.last: TickTiming | None = None

    def run(self, tick: Callable[[int, float], bool]) -> LoopStats:
        """Call tick(k, t) until it returns False; `last` is the previous tick's timing (the
        tick being run cannot know its own compute time yet)."""
        cpu0, wall0 = time.process_time(), time.perf_counter()
        try:
            with timer_slack(TIMER_SLACK_NS), no_collections(self.stats):
                self._run(tick)
        finally:
            self.stats.cpu_s += time.process_time() - cpu0
            self.stats.wall_s += time.perf_counter() - wall0
        return self.stats

    def summary(self) -> LoopSummary:
        return self.stats.summary(self.sync)

    def _run(self, tick: Callable[[int, float], bool]) -> None:
        raise NotImplementedError

    def _timed(
        self, tick: Callable[[int, float], bool], k: int, start: float
    ) -> tuple[bool, float, float]:
        """Run tick k at clock time `start`: (go on, its end on the clock, compute time [s])."""
        w0 = self.timer()
        go_on = tick(k, start)
        compute = self.timer() - w0
        return go_on, self.clock.now(), compute

    def _record(
        self, k: int, deadline: float, start: float, compute: float, overrun: bool, missed: int
    ) -> None:
        self.last = TickTiming(k, deadline, start, start - deadline, compute, overrun, missed)
        self.stats.add(self.last)


class FixedRateLoop(_Loop):
    """Calls tick(k, t) at rate_hz on absolute deadlines."""

    def __init__(
        self, clock: Clock, rate_hz: float, timer: Callable[[], float] = time.perf_counter
    ) -> None:
        super().__init__(clock, rate_hz, timer)

    def _run(self, tick: Callable[[int, float], bool]) -> None:
        origin = self.clock.now()
        k = 0
        while True:
            deadline = origin + k * self.period
            self.clock.sleep_until(deadline)
            start = self.clock.now()
            go_on, end, compute = self._timed(tick, k, start)
            nxt = k + 1
            while origin + nxt * self.period < end:
                nxt += 1
            self._record(
                k, deadline, start, compute, end > origin + (k + 1) * self.period, nxt - k - 1
            )
            if not go_on:
                return
            k = nxt


class MocapSyncLoop(_Loop):
    """Calls tick(k, t) as soon as `source` has a pose newer than the last one ticked on.

    rate_hz: the expected mocap rate (it sets the overrun deadline and the timeout);
    timeout_periods: periods without a pose after which a tick runs anyway."""

    sync = "mocap"

    def __init__(
        self,
        clock: Clock,
        rate_hz: float,
        source: Any,
        timer: Callable[[], float] = time.perf_counter,
        timeout_periods: float = 1.5,
    ) -> None:
        super().__init__(clock, rate_hz, timer)
        if timeout_periods <= 0:
            raise ValueError(f"timeout_periods {timeout_periods:g} must be positive")
        self.source = source
        self.timeout = timeout_periods * self.period

    def _run(self, tick: Callable[[int, float], bool]) -> None:
        seq, k = NO_SEQ, 0
        while True:
            pose = self.source.wait(seq, self.timeout)
            start = self.clock.now()
            missed = 0
            if pose is None:  # no frame in time: tick anyway (the stale-mocap rule runs)
                release = start
                pose = self.source.latest()  # what the tick will read, if anything
            else:
                release = pose.t + pose.latency  # its arrival on the agent's clock
            if pose is not None:  # frames that came while the wait was held count too
                missed = max(0, pose.seq - seq - 1) if seq != NO_SEQ else 0
                seq = pose.seq  # follows a restarted sender
            go_on, end, compute = self._timed(tick, k, start)
            self._record(k, release, start, compute, end > start + self.period, missed)
            if not go_on:
                return
            k += 1


def make_loop(sync: str, clock: Clock, rate_hz: float, source: Any) -> _Loop:
    """The loop a flight configuration asks for: "fixed" or "mocap"."""
    if sync == "mocap":
        return MocapSyncLoop(clock, rate_hz, source)
    if sync == "fixed":
        return FixedRateLoop(clock, rate_hz)
    raise ValueError(f"loop sync {sync!r} is neither 'fixed' nor 'mocap'")
