"""The two plug-in Protocols the flight is written against: a Driver (setpoints out to a
vehicle) and a PoseSource (mocap poses in). They live in core so that the flight, the
service and the plug-ins share them while none imports another's package
(docs/architecture.md, "Layers")."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from perchd.core.types import EndReason, LinkHealth, Pose, Setpoint

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


@dataclass(frozen=True, slots=True)
class SourceStats:
    """Counters a source keeps; dropped packets are counted, never raised."""

    received: int = 0
    poses: int = 0
    dropped: int = 0


class PoseSource(Protocol):
    """A stream of poses for one body, converted to the world frame (Z up, metres)."""

    body: str

    def start(self) -> None:
        """Open sockets / threads; raises LinkError if the source cannot be reached."""

    def latest(self) -> Pose | None:
        """The newest pose received so far (None before the first); never blocks."""

    def wait(self, after_seq: int, timeout: float) -> Pose | None:
        """Block up to `timeout` [s] for a pose newer than `after_seq` (mocap-synchronous mode)."""

    def stats(self) -> SourceStats: ...

    def close(self) -> None: ...
