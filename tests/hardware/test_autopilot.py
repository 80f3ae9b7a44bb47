"""Opt-in: a real ArduPilot or PX4 autopilot over MAVLink (python -m pytest -m hardware tests/hardware).

PERCHD_MAVLINK_URI names it, e.g. mavlink:udpout:192.168.1.10:14550?mass=1.2 (or a SITL).
Without PERCHD_HW_ARM=1 nothing is armed: the tests switch modes and stream level,
zero-thrust attitude targets only. With it, the vehicle is armed (propellers OFF).
"""

from __future__ import annotations

import os
import time

import pytest

from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, Phase, Setpoint
from perchd.drivers.base import open_driver

pytestmark = pytest.mark.hardware
pytest.importorskip("pymavlink")

URI = os.environ.get("PERCHD_MAVLINK_URI", "")
needs_uri = pytest.mark.skipif(not URI, reason="set PERCHD_MAVLINK_URI to the autopilot")


@needs_uri
def test_the_autopilot_takes_the_offboard_mode_and_stays_healthy():
    with open_driver(URI, Runtime.real()) as drv:
        start = time.monotonic()
        for k in range(200):  # 4 s at 50 Hz, level, no thrust
            time.sleep(max(0.0, start + k / 50 - time.monotonic()))
            drv.send(Setpoint(0.0, 0.0, 0.0, 0.0, 0.0, k, Phase.IDLE))
            assert drv.health().ok, drv.health().detail
        drv.failsafe(EndReason.OPERATOR_ABORT)


@needs_uri
@pytest.mark.skipif(
    os.environ.get("PERCHD_HW_ARM") != "1",
    reason="arms the vehicle: set PERCHD_HW_ARM=1 with the propellers off",
)
def test_the_autopilot_arms_on_request_and_lands_on_failsafe():
    sep = "&" if "?" in URI else "?"
    with open_driver(URI + sep + "arm=1", Runtime.real()) as drv:
        assert drv.health().ok
        drv.failsafe(EndReason.OPERATOR_ABORT)
