"""A daemon thread that calls a function at a fixed period (link keep-alives, heartbeats).

Links run in real time whatever clock the agent uses, so this waits on time.monotonic().
"""

from __future__ import annotations

import threading
from collections.abc import Callable


class Ticker:
    def __init__(self, period_s: float, fn: Callable[[], None], name: str) -> None:
        self.period_s = period_s
        self._fn = fn
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> Ticker:
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            self._fn()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=1.0)
