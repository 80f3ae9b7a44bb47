"""`perchd sim`'s setpoint watchdog (perchd.sim.watchdog), on injected times: it levels the
vehicle 0.5 s after the newest setpoint, cuts and locks it at 2 s, as Crazyflie firmware."""

from __future__ import annotations

import pytest

from perchd.core.errors import ConfigError
from perchd.core.types import Phase, Setpoint
from perchd.sim.watchdog import SetpointWatchdog, WatchdogParams

TILTED = Setpoint(0.0, 0.2, -0.3, 0.5, 0.35, 7, Phase.APPROACH)


def watchdog(**kw):
    got: list[Setpoint] = []
    return SetpointWatchdog(WatchdogParams(**kw), got.append), got


def test_the_defaults_are_the_crazyflie_firmwares():
    assert (WatchdogParams().level_s, WatchdogParams().cut_s) == (0.5, 2.0)


def test_a_vehicle_that_never_heard_a_setpoint_is_not_watched():
    wd, got = watchdog()
    assert wd.check(100.0) is None and got == []


def test_silence_levels_the_vehicle_at_its_last_thrust_then_cuts_and_locks_it():
    wd, got = watchdog()
    assert wd.feed(TILTED, 10.0) and got == [TILTED]
    assert wd.check(10.3) == pytest.approx(0.2)  # until the level deadline
    assert len(got) == 1
    assert wd.check(10.5) == pytest.approx(1.5)  # levelled; now until the cut
    level = got[-1]
    assert (level.roll, level.pitch, level.yaw, level.thrust) == (0.0, 0.0, 0.5, 0.35)
    assert wd.check(11.0) == pytest.approx(1.0) and len(got) == 2  # levels once
    assert wd.check(12.0) is None
    cut = got[-1]
    assert (cut.roll, cut.pitch, cut.thrust, cut.phase) == (0.0, 0.0, 0.0, Phase.ABORT)
    assert wd.locked and wd.levels == [pytest.approx(0.5)] and wd.cuts == [pytest.approx(2.0)]
    assert wd.check(20.0) is None and len(got) == 3  # cut once


def test_the_lock_refuses_thrust_until_a_zero_thrust_setpoint_unlocks_it():
    wd, got = watchdog()
    wd.feed(TILTED, 0.0)
    wd.check(2.0)
    n = len(got)
    assert not wd.feed(TILTED, 2.1) and wd.refused == 1 and len(got) == n
    unlock = Setpoint(2.2, 0.0, 0.0, 0.0, 0.0, 8, Phase.HOLD)
    assert wd.feed(unlock, 2.2) and wd.feed(TILTED, 2.3) and got[-2:] == [unlock, TILTED]
    assert not wd.locked


def test_setpoints_in_time_keep_it_quiet():
    wd, got = watchdog()
    for k in range(100):
        wd.feed(TILTED, 0.4 * k)
        assert wd.check(0.4 * k + 0.39) == pytest.approx(0.11)
    assert got == [TILTED] * 100 and wd.levels == [] and wd.cuts == []


def test_a_stop_ends_the_watch():
    wd, got = watchdog()
    wd.feed(TILTED, 0.0)
    wd.stopped()
    assert wd.check(5.0) is None and got == [TILTED] and not wd.locked


def test_the_timeouts_are_configurable():
    wd, got = watchdog(level_s=0.1, cut_s=0.3)
    wd.feed(TILTED, 0.0)
    wd.check(0.1)
    wd.check(0.3)
    assert wd.levels == [pytest.approx(0.1)] and wd.cuts == [pytest.approx(0.3)]


@pytest.mark.parametrize("level, cut", [(0.0, 2.0), (3.0, 2.0), (0.5, 61.0), (float("nan"), 2.0)])
def test_bad_timeouts_are_refused_by_name(level, cut):
    with pytest.raises(ConfigError, match="--watchdog .*need 0 < LEVEL_S <= CUT_S <= 60 s"):
        WatchdogParams(level, cut)
