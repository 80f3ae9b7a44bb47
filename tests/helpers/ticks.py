"""A real-time tick loop for driver tests: what the flight loop does to a driver, per tick."""

from __future__ import annotations

import time
from collections.abc import Callable

from perchd.core.types import EndReason, Phase, Setpoint


def wait_for(predicate: Callable[[], object], timeout: float = 2.0) -> bool:
    """Poll `predicate` until it holds or `timeout` [s] passes; returns whether it held."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.005)
    return bool(predicate())


def level(thrust: float, t: float = 0.0, seq: int = 0) -> Setpoint:
    return Setpoint(t, 0.0, 0.0, 0.0, thrust, seq, Phase.STAGE1)


def ticks_until_lost(
    driver, rate_hz: float, setpoint: Setpoint, kill: Callable[[], None], max_ticks: int = 50
) -> int | None:
    """Send `setpoint` and check health once per tick, as the supervisor does; call `kill`
    between tick 0 and tick 1. Returns how many ticks after the kill the link was reported
    lost (and the driver's failsafe called, as the supervisor would), or None."""
    period = 1.0 / rate_hz
    start = time.monotonic()
    for k in range(max_ticks + 1):
        time.sleep(max(0.0, start + k * period - time.monotonic()))
        if not driver.health().ok:
            driver.failsafe(EndReason.LOST_LINK)
            return k
        driver.send(setpoint)
        if k == 0:
            kill()
    return None
