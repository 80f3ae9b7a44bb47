"""Fly a plan in simulation the way `perchd fly --driver sim:// --mocap sim://` does."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from caseplans import case1  # noqa: F401  (re-exported: the flight tests' plan)

from perchd.core.clock import ManualClock
from perchd.core.runtime import Runtime
from perchd.core.uri import parse_uri
from perchd.core.uriparams import split_sim
from perchd.drivers.base import open_driver
from perchd.flight.config import FlightConfig
from perchd.flight.run import FlightAbort, FlightResult, fly
from perchd.mocap.base import open_source

PLANS = Path(__file__).resolve().parents[2] / "plans"
NOISY = "sim://?latency=0.02&noise=0.001"
"""20 ms command latency and 1 mm mocap noise (the second acceptance case)."""


class Sim:
    """One simulated flight: its world, driver, source and result."""

    def __init__(self, uri: str = "sim://") -> None:
        self.runtime = Runtime(ManualClock(0.0))
        driver_uri, mocap_uri = split_sim(parse_uri(uri))  # one world's keys, each its side's
        self.driver = open_driver(driver_uri, self.runtime)
        self.source = open_source(mocap_uri, self.runtime)
        self.world = self.runtime.sim
        self.driver.connect()
        self.source.start()

    def fly(
        self,
        plan: Any,
        log: Path,
        cfg: FlightConfig = FlightConfig(),
        abort: FlightAbort | None = None,
        on_tick: Callable[[Any], None] | None = None,
    ) -> FlightResult:
        try:
            return fly(
                plan,
                self.driver,
                self.source,
                self.runtime.clock,
                log,
                cfg,
                abort,
                on_tick,
                world=self.world,
            )
        finally:
            self.source.close()
            self.driver.close()
