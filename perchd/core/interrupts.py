"""SIGINT and SIGTERM as every command meets them (docs/contracts.md §6): the command stops
what it does, says so on stderr, and exits 128 + the signal's number (130, 143)."""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Callable, Iterator

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def exit_code(signum: int) -> int:
    """The exit code of a command stopped by `signum`: 130 for SIGINT, 143 for SIGTERM."""
    return 128 + int(signum)


class Caught:
    """The first stop signal caught (None until one is)."""

    def __init__(self) -> None:
        self.signum: int | None = None

    @property
    def name(self) -> str | None:
        return None if self.signum is None else signal.Signals(self.signum).name

    def exit_code(self, otherwise: int) -> int:
        """128 + the signal's number if one was caught, else `otherwise`."""
        return otherwise if self.signum is None else exit_code(self.signum)

    def say(self, command: str, what: str) -> None:
        """One line on stderr when a signal stopped `command`: what became of its work."""
        if self.signum is not None:
            print(
                f"perchd {command}: interrupted by {self.name}; {what}", file=sys.stderr, flush=True
            )


@contextlib.contextmanager
def catching(on_signal: Callable[[], None]) -> Iterator[Caught]:
    """SIGINT and SIGTERM call `on_signal` (it must only set flags) while the block runs;
    the previous handlers come back after it. on_signal runs on a thread of its own: a
    handler runs in the main thread wherever the signal finds it, and `Event.set` there
    deadlocked `perchd sim` about one time in eight, the main thread interrupted inside
    `Event.wait` holding the lock `set` takes."""
    caught = Caught()

    def handler(signum: int, _frame: object) -> None:
        if caught.signum is None:
            caught.signum = signum
        threading.Thread(target=on_signal, name="perchd-signal", daemon=True).start()

    previous = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    try:
        yield caught
    finally:
        for s, old in previous.items():
            signal.signal(s, old)
