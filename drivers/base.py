"""The Driver protocol, its context-manager base, and the explicit registry of URI schemes."""

from __future__ import annotations

from typing import Protocol

from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, LinkHealth, Pose, Setpoint
from perchd.core.uri import Registry


class Driver(Protocol):
    uri: str

    def connect(self) -> None:
        """Open the link and make the vehicle ready for setpoints; raises LinkError."""

    def send(self, setpoint: Setpoint) -> None:
        """Hand one SI setpoint to the vehicle (never blocks for long)."""

    def failsafe(self, reason: EndReason) -> None:
        """Make the vehicle safe (stop setpoint, land, disarm) and say why; idempotent."""

    def health(self) -> LinkHealth:
        """The link's state now; never blocks."""

    def observe_pose(self, pose: Pose) -> None:
        """Every pose the flight uses, before the setpoint computed from it: drivers that
        feed the vehicle's own estimator (Crazyflie extpose) or steer yaw use it."""

    def close(self) -> None:
        """Release the link; a vehicle left flying gets the failsafe first."""


class DriverBase:
    """Context-manager plumbing shared by the drivers: `with open_driver(...) as d:`."""

    def __enter__(self):
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def observe_pose(self, pose: Pose) -> None:
        """Most links have no use for the pose."""


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
