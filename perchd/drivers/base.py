"""The Driver protocol, its context-manager base, and the explicit registry of URI schemes.

A driver takes a vehicle in two steps (docs/architecture.md "Connect and engage"): connect()
opens the link and checks the vehicle, and may refuse it, before anything moves; engage()
takes control for one flight, and is called by the flight (flight/run.py) once poses flow.
A service connects at start-up and engages per flight, so an idle service leaves the
vehicle as it found it.
"""

from __future__ import annotations

from typing import Callable, Protocol

from perchd.core.errors import ConfigError
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, LinkHealth, Pose, Setpoint
from perchd.core.uri import Registry

PoseFeed = Callable[[], "Pose | None"]
"""The flight's newest pose (PoseSource.latest), read by a driver while engage() waits."""


def no_poses() -> None:
    """A PoseFeed with nothing to give (a driver engaged outside a flight)."""


class Driver(Protocol):
    uri: str

    def connect(self) -> None:
        """Open the link, identify the vehicle and check its set-up; raises LinkError, or
        ConfigError for a vehicle set up unsafely. Changes nothing on the vehicle: no mode,
        no arming, no setpoint."""

    def engage(self, poses: PoseFeed = no_poses) -> None:
        """Take control for one flight: whatever the vehicle needs before the loop's first
        setpoint (an autopilot's offboard mode, arming, spool-up). While it waits it forwards
        each new pose from `poses` through observe_pose (an autopilot's EKF may need mocap
        before it arms). Called once per flight, so a flight after a failsafe takes the
        vehicle anew; raises LinkError when the vehicle will not be taken."""

    def send(self, setpoint: Setpoint) -> None:
        """Hand one SI setpoint to the vehicle (never blocks for long)."""

    def failsafe(self, reason: EndReason) -> None:
        """Make the vehicle safe (stop setpoint, land, disarm) and say why; idempotent."""

    def health(self) -> LinkHealth:
        """The link's state now; never blocks."""

    def observe_pose(self, pose: Pose) -> None:
        """Every pose the flight uses, before the setpoint computed from it: drivers that
        feed the vehicle's own estimator (Crazyflie extpose) or steer yaw use it."""

    def close(self, hand_over: bool = True) -> None:
        """Release the link; a vehicle left flying gets the failsafe first. hand_over=False:
        new links to the same vehicle take over at once, so nothing of this driver's
        outlives it (the MAVLink sentinel is released, not handed the landing)."""

    def bind_mass(self, mass_kg: float) -> None:
        """The flight's vehicle mass [kg], FlightConfig.vehicle.mass_kg: the one mass.
        A thrust model calibrated by weight scales to it. Called before connect() by
        the session and again by flight.run.fly(); raises ConfigError, one line naming both
        values, when the URI's own mass= disagrees (nothing has been armed or flown yet)."""

    def bind_mocap(self, uri: str) -> None:
        """The flight's mocap URI, before connect(): a driver whose helper outlives the
        agent (the MAVLink sentinel) opens it there to keep the vehicle's own estimator fed
        after the agent dies."""

    def thrust_ceiling_n(self) -> float | None:
        """[N] the most collective thrust the vehicle flies, in this driver's newtons (None:
        no ceiling known); the flight's saturation uses min(config, this)."""


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
            f"in --config, and drop mass= from the URI")
    return flight_mass_kg


DRIVERS: Registry[Driver] = Registry("driver", {
    "sim": "perchd.drivers.loopback:open_loopback",
    "radio": "perchd.drivers.crazyflie:open_crazyflie",
    "udp": "perchd.drivers.crazyflie:open_crazyflie",
    "mavlink": "perchd.drivers.mavlink:open_mavlink",
    "zmq": "perchd.drivers.zmq:open_zmq_driver",
})


def open_driver(uri: str, runtime: Runtime) -> Driver:
    """Build the driver a URI names (not connected yet)."""
    return DRIVERS.open(uri, runtime)
