"""After a failsafe the MAVLink driver hands the vehicle to its LAND and repeats it until the
heartbeat shows it taken (drivers/mavlink/landing.py); real pymavlink over loopback UDP
against a vehicle double."""

from __future__ import annotations

import pytest

pytest.importorskip("pymavlink")

from mavlink_double import connected
from ticks import level

from perchd.core.runtime import Runtime
from perchd.core.types import EndReason
from perchd.drivers.base import open_driver

MASS = 0.5
WEIGHT = MASS * 9.81


def test_failsafe_hands_ardupilot_to_land_and_stops_streaming(ardupilot):
    drv = connected(ardupilot)
    drv.send(level(WEIGHT))
    drv.failsafe(EndReason.TAU_DIVERGENCE)
    assert ardupilot.wait_for(lambda: ardupilot.custom_mode == 9)
    count = len(ardupilot.targets)
    drv.send(level(WEIGHT))
    ardupilot.wait_for(lambda: False, timeout=0.3)
    assert len(ardupilot.targets) == count
    drv.close()


def lands(vehicle) -> int:
    return sum(1 for _, c, p in vehicle.commands if (c, p[1]) == (176, 9))


def test_land_is_repeated_until_the_vehicles_heartbeat_shows_it_taken(ardupilot):
    drv = connected(ardupilot)
    try:
        drv.send(level(WEIGHT))
        ardupilot.mute()  # it obeys but cannot say so: LAND must go out again
        drv.failsafe(EndReason.LOST_LINK)
        ardupilot.wait_for(lambda: False, timeout=0.9)
        assert lands(ardupilot) >= 2 + 2  # the failsafe's two, then one per LAND_RETRY_S
        ardupilot.unmute()  # the next LAND's heartbeat shows custom mode 9
        assert ardupilot.wait_for(lambda: drv.vehicle.mode == 9)
        taken = lands(ardupilot)
        ardupilot.wait_for(lambda: False, timeout=0.6)
        assert lands(ardupilot) == taken  # and then no more
    finally:
        drv.close()


def test_closing_the_driver_ends_the_land_repeats(ardupilot):
    drv = connected(ardupilot)
    ardupilot.mute()
    drv.failsafe(EndReason.LOST_LINK)
    drv.close()
    ardupilot.wait_for(lambda: False, timeout=0.6)  # open, it would have sent 2 more
    assert lands(ardupilot) == 2


def test_closing_a_flying_px4_lands_it(px4):
    with open_driver(f"{px4.uri}?mass={MASS}", Runtime.real()) as drv:
        drv.send(level(WEIGHT))
    assert px4.wait_for(lambda: px4.custom_mode == (4 << 16) | (6 << 24))
