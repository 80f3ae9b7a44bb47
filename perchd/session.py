"""A flight's links, put together in one place: clock, driver, mocap and, when simulated,
the world.

`perchd fly`, `perchd serve`, campaigns, benchmarks and tests all open their links here, so
a simulated vehicle is built one way only. Driver and pose source are opened through the
URI registries whether they are real or simulated.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from perchd.core.clock import Clock, ManualClock
from perchd.core.errors import UriError
from perchd.core.ports import Driver, PoseSource
from perchd.core.runtime import Runtime
from perchd.core.uri import parse_uri
from perchd.drivers.base import open_driver
from perchd.flight.config import FlightConfig, SurfaceConfig
from perchd.flight.planner_worker import Planner
from perchd.flight.run import FlightAbort, FlightResult, TickStatus, fly
from perchd.mocap.base import open_source
from perchd.sim.world import SimWorld, WorldParams, world_params_from_uri
from perchd.tau.plan import Plan


@dataclass
class Session:
    """A connected driver and a started pose source on one runtime; `world` is the
    simulated truth (None for a real vehicle). Connected, not engaged: each flight engages
    the driver (flight.run.fly, docs/architecture.md "Connect and engage")."""

    runtime: Runtime
    world: SimWorld | None
    driver: Driver
    source: PoseSource

    @property
    def clock(self) -> Clock:
        return self.runtime.clock

    def fly(self, plan: Plan, log_path: str | Path, cfg: FlightConfig = FlightConfig(),
            abort: FlightAbort | None = None,
            on_tick: Callable[[TickStatus], None] | None = None,
            header: dict | None = None, planner: Planner | None = None) -> FlightResult:
        """One flight on this vehicle, then its links closed (planner: see flight.run.fly)."""
        try:
            return fly(plan, self.driver, self.source, self.clock, log_path, cfg, abort,
                       on_tick, world=self.world, header=header, planner=planner)
        finally:
            self.close()

    def close(self, hand_over: bool = True) -> None:
        """Driver, then source; hand_over: Driver.close's."""
        try:
            self.driver.close(hand_over)
        finally:
            self.source.close()


def open_links(driver_uri: str, mocap_uri: str, surface: SurfaceConfig | None = None,
               simulated_clock: Clock | None = None, mass_kg: float | None = None) -> Session:
    """The flight's links from the user's URIs. mass_kg: the flight config's vehicle mass,
    given to the driver before it connects (Driver.bind_mass refuses a URI mass= that
    disagrees before anything is armed). sim:// on both flies a fresh simulated world
    on `simulated_clock` (default a ManualClock: faster than real time); sim:// on only one
    side is refused, since the simulated vehicle would be steered on real poses or the
    reverse."""
    sims = parse_uri(driver_uri).scheme == "sim", parse_uri(mocap_uri).scheme == "sim"
    if sims[0] != sims[1]:
        raise UriError("sim:// flies only with sim:// on both driver and mocap "
                       f"(got {driver_uri} and {mocap_uri})")
    if sims[0]:
        return open_session(driver_uri, surface=surface, clock=simulated_clock)
    return _connect(Runtime.real(), None, driver_uri, mocap_uri, mass_kg)


def _connect(runtime: Runtime, world: SimWorld | None, driver_uri: str,
             mocap_uri: str, mass_kg: float | None = None) -> Session:
    """Open and connect: the vehicle is checked (a refusal comes here), not taken."""
    driver = open_driver(driver_uri, runtime)
    if mass_kg is not None:
        driver.bind_mass(mass_kg)
    driver.bind_mocap(mocap_uri)
    source = open_source(mocap_uri, runtime)
    source.start()
    try:
        driver.connect()
    except BaseException:
        source.close()
        raise
    return Session(runtime, world, driver, source)


def open_session(uri: str = "sim://", *, surface: SurfaceConfig | None = None,
                 params: WorldParams | None = None, clock: Clock | None = None) -> Session:
    """A connected simulated vehicle.

    uri: the sim:// URI whose options (latency, noise, start, ...) apply over `params`.
    surface: where the wall is (default: params' surface). clock: a ManualClock at 0 unless
    given (a MonotonicClock runs the world in real time, as `perchd serve` does).
    """
    wp = world_params_from_uri(parse_uri(uri), params)
    if surface is not None:
        wp = dataclasses.replace(wp, surface_point=surface.point, surface_normal=surface.normal)
    runtime = Runtime(clock or ManualClock(0.0))
    runtime.sim = SimWorld(wp, runtime.clock)
    return _connect(runtime, runtime.sim, uri, uri)
