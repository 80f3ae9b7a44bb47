"""Opt-in: a real Crazyflie 2.x over a real Crazyradio (python -m pytest -m hardware tests/hardware).

PERCHD_CF_URI picks the vehicle (default radio://0/80/2M/E7E7E7E7E7). The motor test also
needs PERCHD_HW_MOTORS=1 and the propellers OFF: it spins the motors at low thrust.
"""

from __future__ import annotations

import os
import time

import pytest

from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, Phase, Setpoint
from perchd.drivers.base import open_driver

pytestmark = pytest.mark.hardware
pytest.importorskip("cflib")

URI = os.environ.get("PERCHD_CF_URI", "radio://0/80/2M/E7E7E7E7E7")


def stream(driver, setpoint: Setpoint, seconds: float, rate_hz: float = 100.0) -> list[bool]:
    """Send at the loop rate; returns health per tick."""
    healthy, start = [], time.monotonic()
    for k in range(int(seconds * rate_hz)):
        time.sleep(max(0.0, start + k / rate_hz - time.monotonic()))
        driver.send(setpoint)
        healthy.append(driver.health().ok)
    return healthy


def test_the_radio_link_connects_and_stays_healthy_at_100_hz():
    with open_driver(URI, Runtime.real()) as cf:
        healthy = stream(cf, Setpoint(0.0, 0.0, 0.0, 0.0, 0.0, 0, Phase.IDLE), 2.0)
        assert all(healthy), f"{healthy.count(False)} unhealthy ticks of {len(healthy)}"
        assert cf.health().age < 0.1


@pytest.mark.skipif(
    os.environ.get("PERCHD_HW_MOTORS") != "1",
    reason="spins the motors: set PERCHD_HW_MOTORS=1 with the propellers off",
)
def test_the_motors_spin_at_low_thrust_and_stop_on_failsafe():
    with open_driver(URI, Runtime.real()) as cf:
        assert all(stream(cf, Setpoint(0.0, 0.0, 0.0, 0.0, 0.03, 0, Phase.HOLD), 1.0))
        cf.failsafe(EndReason.OPERATOR_ABORT)
        assert cf.health().ok  # the link outlives the stop
