"""Progress of long work on stderr: a bar rewritten in place on a terminal; elsewhere a line
at every tenth of the work (`lines`, e.g. a campaign's log) or nothing at all."""

from __future__ import annotations

import sys
import time
from collections import Counter
from typing import TextIO


class Progress:
    """`total` steps of `unit` (flights, nodes, generations) done by `command`."""

    WIDTH = 30

    def __init__(
        self,
        total: int,
        unit: str,
        command: str,
        stream: TextIO | None = None,
        lines: bool = True,
        rates: bool = False,
        done: int = 0,
    ) -> None:
        """rates: the line also gives failures, steps per second and the time left;
        done: steps done before this run (a resumed campaign's), not counted in its rate."""
        self.stream = sys.stderr if stream is None else stream
        self.tty = self.stream.isatty()
        self.quiet = not (self.tty or lines)
        self.total, self.unit, self.command = max(1, total), unit, command
        self.done = self.start = min(done, self.total)
        self.failed = 0
        self.rates = rates
        self.outcomes: Counter[str] = Counter()
        self.t0 = time.monotonic()
        self._step = max(1, self.total // 10)

    def __call__(
        self, outcome: str | None = None, done: int | None = None, failed: bool = False
    ) -> None:
        """One step more (or `done` steps in all), with its outcome if steps have one;
        failed: the step counts as a failure."""
        before, self.done = self.done, self.done + 1 if done is None else min(done, self.total)
        self.failed += failed
        if outcome is not None:
            self.outcomes[outcome] += 1
        if self.quiet:
            return
        if self.tty:
            fill = self.WIDTH * self.done // self.total
            self.stream.write(f"\r[{'#' * fill}{'.' * (self.WIDTH - fill)}] {self.line()}\x1b[K")
        elif self.done // self._step > before // self._step or self.done == self.total:
            self.stream.write(f"perchd {self.command}: {self.line()}\n")
        self.stream.flush()

    def at(self, done: int, _total: int) -> None:
        """The `progress(done, total)` callback form the planners call."""
        self(done=done)

    def line(self) -> str:
        counts = ", ".join(f"{k} {v}" for k, v in self.outcomes.most_common())
        elapsed = time.monotonic() - self.t0
        return (
            f"{self.done}/{self.total} {self.unit}{f' ({counts})' if counts else ''} "
            f"{elapsed:.1f} s{self._rates(elapsed) if self.rates else ''}"
        )

    def _rates(self, elapsed: float) -> str:
        """', F failed, R unit/s, ETA S s' (no rate before a step ends)."""
        rate = (self.done - self.start) / elapsed if elapsed > 0 else 0.0
        eta = f"{(self.total - self.done) / rate:.0f} s" if rate > 0 else "--"
        return f", {self.failed} failed, {rate:.1f} {self.unit}/s, ETA {eta}"

    def close(self) -> None:
        if self.tty and self.done:
            self.stream.write("\n")
            self.stream.flush()
