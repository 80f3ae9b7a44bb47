"""Echo clock sync: the echo with the shortest round trip sets the server-to-agent mapping."""

from __future__ import annotations

import pytest

from perchd.mocap.natnet.clock import ClockSync

HZ = 3312787
OFFSET = 1234.5  # [s] server clock minus agent clock


def echo(sync: ClockSync, sent: float, out_s: float, back_s: float) -> None:
    """An echo leaving at agent time `sent`, reaching the server after out_s, back after back_s."""
    stamp = sync.request(sent)
    server_ticks = round((sent + out_s + OFFSET) * HZ)
    assert sync.response(stamp, server_ticks, sent + out_s + back_s)


def test_a_symmetric_echo_recovers_the_offset():
    sync = ClockSync(HZ)
    assert not sync.synced
    echo(sync, 10.0, 0.0002, 0.0002)
    assert sync.to_agent(round((20.0 + OFFSET) * HZ)) == pytest.approx(20.0, abs=1e-6)


def test_the_shortest_round_trip_wins_over_delayed_ones():
    sync = ClockSync(HZ)
    echo(sync, 1.0, 0.030, 0.001)  # queued on the way out: 15 ms wrong on its own
    echo(sync, 2.0, 0.0001, 0.0001)
    echo(sync, 3.0, 0.001, 0.040)
    assert sync.round_trip_s == pytest.approx(0.0002)
    assert sync.to_agent(round((5.0 + OFFSET) * HZ)) == pytest.approx(5.0, abs=2e-6)


def test_an_unknown_or_repeated_stamp_is_ignored():
    sync = ClockSync(HZ)
    stamp = sync.request(1.0)
    assert not sync.response(stamp + 99, 0, 1.1)
    assert sync.response(stamp, round(OFFSET * HZ), 1.001)
    assert not sync.response(stamp, round(OFFSET * HZ), 1.002)


def test_a_zero_clock_frequency_is_refused():
    with pytest.raises(ValueError, match="must be > 0 Hz"):
        ClockSync(0)
