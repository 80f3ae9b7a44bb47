"""A flight's links, put together in one place: clock, driver, mocap and, when simulated,
the world.

`perchd fly`, `perchd serve`, campaigns, benchmarks and tests all open their links here, so
a simulated vehicle is built one way only. Driver and pose source are opened through the
URI registries whether they are real or simulated.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from perchd.core.clock import Clock, ManualClock
from perchd.core.errors import UriError
from perchd.core.ports import Driver, PoseSource
from perchd.core.runtime import Runtime
from perchd.core.uri import parse_uri
from perchd.core.uriparams import query_of, split_sim
from perchd.drivers.base import open_driver
from perchd.flight.config import FlightConfig, SurfaceConfig
from perchd.flight.planner_worker import Planner
from perchd.flight.run import FlightAbort, FlightResult, TickStatus, fly
from perchd.logs.flightlog import jsonable
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
    applied: dict = field(default_factory=dict)
    """The URI parameters each link applied (every other key was refused), and the
    simulated world's resolved parameters: the flight log's header records them."""

    @property
    def clock(self) -> Clock:
        return self.runtime.clock

    def fly(
        self,
        plan: Plan,
        log_path: str | Path,
        cfg: FlightConfig = FlightConfig(),
        abort: FlightAbort | None = None,
        on_tick: Callable[[TickStatus], None] | None = None,
        header: dict | None = None,
        planner: Planner | None = None,
        log_force: bool = False,
    ) -> FlightResult:
        """One flight on this vehicle, then its links closed (planner, log_force: see
        flight.run.fly)."""
        try:
            return fly(
                plan,
                self.driver,
                self.source,
                self.clock,
                log_path,
                cfg,
                abort,
                on_tick,
                world=self.world,
                header={"uri_params": self.applied, **(header or {})},
                planner=planner,
                log_force=log_force,
            )
        finally:
            self.close()

    def close(self, hand_over: bool = True) -> None:
        """Driver, then source; hand_over: Driver.close's."""
        try:
            self.driver.close(hand_over)
        finally:
            self.source.close()


def open_links(
    driver_uri: str,
    mocap_uri: str,
    surface: SurfaceConfig | None = None,
    simulated_clock: Clock | None = None,
    mass_kg: float | None = None,
) -> Session:
    """The flight's links from the user's URIs. mass_kg: the flight config's vehicle mass,
    given to the driver before it connects (Driver.bind_mass refuses a URI mass= that
    disagrees before anything is armed). sim:// on both flies a fresh simulated world
    on `simulated_clock` (default a ManualClock: faster than real time); sim:// on only one
    side is refused, since the simulated vehicle would be steered on real poses or the
    reverse."""
    sims = parse_uri(driver_uri).scheme == "sim", parse_uri(mocap_uri).scheme == "sim"
    if sims[0] != sims[1]:
        raise UriError(
            "sim:// flies only with sim:// on both driver and mocap "
            f"(got {driver_uri} and {mocap_uri})"
        )
    if sims[0]:  # one world: the vehicle's options from --driver, the mocap's from --mocap
        wp = world_params_from_uri(parse_uri(driver_uri), kind="driver")
        wp = world_params_from_uri(parse_uri(mocap_uri), wp, kind="mocap")
        return _simulate(wp, driver_uri, mocap_uri, surface, simulated_clock)
    return _connect(Runtime.real(), None, driver_uri, mocap_uri, mass_kg)


def _connect(
    runtime: Runtime,
    world: SimWorld | None,
    driver_uri: str,
    mocap_uri: str,
    mass_kg: float | None = None,
) -> Session:
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
    applied = {"driver": query_of(parse_uri(driver_uri)), "mocap": query_of(parse_uri(mocap_uri))}
    if world is not None:
        applied["sim_world"] = jsonable(world.params)
    return Session(runtime, world, driver, source, applied)


def open_session(
    uri: str = "sim://",
    *,
    surface: SurfaceConfig | None = None,
    params: WorldParams | None = None,
    clock: Clock | None = None,
) -> Session:
    """A connected simulated vehicle.

    uri: the sim:// URI whose options (latency, noise, start, ...) apply over `params`:
    a whole world's, the vehicle's and the mocap's options in one (split between the links).
    surface: where the wall is (default: params' surface). clock: a ManualClock at 0 unless
    given (a MonotonicClock runs the world in real time, as `perchd serve` does).
    """
    parsed = parse_uri(uri)
    return _simulate(world_params_from_uri(parsed, params), *split_sim(parsed), surface, clock)


def _simulate(
    wp: WorldParams,
    driver_uri: str,
    mocap_uri: str,
    surface: SurfaceConfig | None,
    clock: Clock | None,
) -> Session:
    """A fresh world of `wp` on `clock`, its two links connected."""
    if surface is not None:
        wp = dataclasses.replace(wp, surface_point=surface.point, surface_normal=surface.normal)
    runtime = Runtime(clock or ManualClock(0.0))
    runtime.sim = SimWorld(wp, runtime.clock)
    return _connect(runtime, runtime.sim, driver_uri, mocap_uri)
