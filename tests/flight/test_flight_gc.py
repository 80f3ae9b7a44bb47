"""No garbage collection runs while a flight's loop runs (a collection stops every thread of
the agent at a moment no tick chose); the collector is back as it was once the loop ends,
and a collection forced by another thread is counted, not hidden."""

from __future__ import annotations

import gc
import threading

from simflight import Sim, case1

from perchd.core.clock import ManualClock
from perchd.core.types import EndReason
from perchd.flight.loop import FixedRateLoop


class Collections:
    """Counts every collection of the process through gc.callbacks."""

    def __init__(self) -> None:
        self.n = 0
        gc.callbacks.append(self._count)

    def _count(self, phase: str, info: dict) -> None:
        self.n += phase == "start"

    def close(self) -> None:
        gc.callbacks.remove(self._count)


def test_a_simulated_flight_sees_no_collection_between_its_first_and_last_tick(tmp_path):
    counter, seen = Collections(), []

    def on_tick(st):
        seen.append(counter.n)  # collections so far, at each tick
        for _ in range(50):
            a, b = [], []
            a.append(b), b.append(a)  # cycles: what the collector would chase

    try:
        assert gc.isenabled()
        res = Sim().fly(case1("ipts"), tmp_path / "f.jsonl", on_tick=on_tick)
    finally:
        counter.close()
    assert res.outcome is EndReason.CONTACT and len(seen) > 300
    assert seen[-1] - seen[0] == 0 and res.loop.gc_collections == 0
    assert gc.isenabled()


def test_the_collector_stays_off_until_the_last_of_two_loops_ends():
    inner_done = threading.Event()

    def inner():
        FixedRateLoop(ManualClock(0.0), 100.0).run(lambda k, t: k < 10)
        inner_done.set()

    def outer_tick(k, t):
        if k == 0:
            threading.Thread(target=inner).start()
            inner_done.wait(5.0)
            assert not gc.isenabled()  # the other loop ended; this one still runs
        return k < 3

    FixedRateLoop(ManualClock(0.0), 100.0).run(outer_tick)
    assert gc.isenabled()


def test_a_collection_forced_during_the_loop_is_counted():
    loop = FixedRateLoop(ManualClock(0.0), 100.0)
    loop.run(lambda k, t: (k == 2 and gc.collect(0)) or k < 5)
    assert loop.summary().gc_collections == 1
