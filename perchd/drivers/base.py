"""The drivers' context-manager base, the one mass rule, and the explicit registry of URI
schemes (the Driver protocol itself: core/ports.py).

A driver takes a vehicle in two steps (docs/architecture.md "Connect and engage"): connect()
opens the link and checks the vehicle, and may refuse it, before anything moves; engage()
takes control for one flight, and is called by the flight (flight/run.py) once poses flow.
A service connects at start-up and engages per flight, so an idle service leaves the
vehicle as it found it.
"""

from __future__ import annotations

from perchd.core.errors import ConfigError
from perchd.core.ports import Driver, PoseFeed, no_poses
from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.core.uri import Registry


class DriverBase:
    """Context-manager plumbing shared by the drivers: `with open_driver(...) as d:`."""

    def __enter__(self):
        """Connected and engaged: ready to fly setpoints."""
        self.connect()
        self.engage()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def engage(self, poses: PoseFeed = no_poses) -> None:
        """Links whose connect already hands the vehicle its setpoints (sim://, zmq://, the
        Crazyflie) have nothing more to take."""

    def observe_pose(self, pose: Pose) -> None:
        """Most links have no use for the pose."""

    def bind_mass(self, mass_kg: float) -> None:
        """Links that pass newtons through have no use for the mass."""

    def bind_mocap(self, uri: str) -> None:
        """Links with nothing outliving the agent have no use for the mocap's URI."""

    def thrust_ceiling_n(self) -> float | None:
        return None


MASS_REL_TOL = 0.005
"""A URI mass= within 0.5 % of the flight config's is the same mass written twice."""


def agreed_mass(uri: str, uri_mass: float | None, flight_mass_kg: float) -> float:
    """The flight's mass [kg], or ConfigError when the driver URI's mass= says another: the
    controller's newtons and the driver's thrust units would then be scaled by two masses,
    which mis-scales every thrust (ArduPilot SITL fell with ?mass=3.0 and a 30 g config)."""
    if uri_mass is not None and abs(uri_mass - flight_mass_kg) > MASS_REL_TOL * flight_mass_kg:
        raise ConfigError(
            f"{uri}: mass={uri_mass:g} kg in the driver URI disagrees with the flight config's "
            f"vehicle.mass_kg = {flight_mass_kg:g} kg; give the mass once, as [vehicle] mass_kg "
            f"in --config, and drop mass= from the URI"
        )
    return flight_mass_kg


DRIVERS: Registry[Driver] = Registry(
    "driver",
    {
        "sim": "perchd.sim.loopback:open_loopback",
        "radio": "perchd.drivers.crazyflie:open_crazyflie",
        "udp": "perchd.drivers.crazyflie:open_crazyflie",
        "mavlink": "perchd.drivers.mavlink:open_mavlink",
        "zmq": "perchd.drivers.zmq:open_zmq_driver",
    },
)


def open_driver(uri: str, runtime: Runtime) -> Driver:
    """Build the driver a URI names (not connected yet)."""
    return DRIVERS.open(uri, runtime)
