"""The Driver protocol, its context-manager base, and the explicit registry of URI schemes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, Setpoint
from perchd.core.uri import Registry


@dataclass(frozen=True, slots=True)
class LinkHealth:
    """ok: the link is up.  age: [s] since the vehicle was last heard from (0 if it never
    answers, e.g. a one-way stream).  detail: why the link is down, if it is.
    rtt_s: [s] the link's round trip, measured by the driver's own echo (median of its
    recent samples), None where the driver cannot measure one."""

    ok: bool
    age: float = 0.0
    detail: str = ""
    rtt_s: float | None = None


class Driver(Protocol):
    uri: str

    def connect(self) -> None:
        """Open the link and make the vehicle ready for setpoints; raises LinkError."""

    def send(self, setpoint: Setpoint) -> None:
        """Hand one SI setpoint to the vehicle (never blocks for long)."""

    def failsafe(self, reason: EndReason) -> None:
        """Make the vehicle safe (stop setpoint, land, disarm) and say why; idempotent."""

    def health(self) -> LinkHealth:
        ...

    def close(self) -> None:
        """Release the link; a vehicle left flying gets the failsafe first."""


class DriverBase:
    """Context-manager plumbing shared by the drivers: `with open_driver(...) as d:`."""

    def __enter__(self):
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


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
