"""The fixed-rate loop keeps absolute deadlines and counts what it misses."""

from __future__ import annotations

import pytest

from perchd.core.clock import ManualClock
from perchd.flight.loop import FixedRateLoop


def test_ticks_fall_on_absolute_deadlines_of_the_injected_clock():
    clock = ManualClock(5.0)
    loop = FixedRateLoop(clock, 100.0)
    times = []
    loop.run(lambda k, t: times.append(t) or k < 299)
    assert len(times) == 300
    assert times[-1] == pytest.approx(5.0 + 2.99, abs=1e-9)
    assert loop.stats.summary().jitter_max_s == pytest.approx(0.0, abs=1e-9)


def test_a_slow_tick_is_an_overrun_its_missed_deadlines_are_skipped_and_the_streak_counted():
    clock = ManualClock(0.0)
    loop = FixedRateLoop(clock, 100.0)
    ks, streaks = [], []

    def tick(k, t):
        ks.append(k)
        streaks.append(loop.stats.streak)
        if 3 <= k < 8:
            clock.advance(0.025)  # 2.5 periods
        return k < 20

    stats = loop.run(tick)
    assert ks[:5] == [0, 1, 2, 3, 6]  # after tick 3 ends at 0.055, tick 6 (0.06) is next
    s = stats.summary()
    assert s.overruns == 2 and s.missed == 4 and s.max_streak == 2


def test_compute_time_is_read_on_the_wall_timer_not_the_simulated_clock():
    ticks = iter(range(100))
    fake = iter([0.0, 0.002] * 50)
    loop = FixedRateLoop(ManualClock(), 100.0, timer=lambda: next(fake))
    loop.run(lambda k, t: next(ticks) < 9)
    assert loop.stats.summary().compute_median_s == pytest.approx(0.002)


@pytest.mark.parametrize("rate", [0.5, 501.0])
def test_a_rate_outside_1_to_500_hz_is_refused(rate):
    with pytest.raises(ValueError, match="outside"):
        FixedRateLoop(ManualClock(), rate)
