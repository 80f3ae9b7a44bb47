"""engage()'s steps, once per flight: level at the vehicle's heading, the flight mode, arming
and, for a dialect whose motors spool up on the ground, the spool-up.

Until the mode switch perchd's heartbeat is all the vehicle hears. Taking over a vehicle in
the air (armed, not landed) streams level at its current heading with the hover thrust,
never zero thrust, and flies as soon as the mode switch is acknowledged (COMMAND_ACK
ACCEPTED), not at the next 1 Hz heartbeat. An EKF on mocap alone refuses to arm until it has
some, so arming is asked again every ARM_RETRY_S while the poses flow. ArduCopter armed on
the ground is held at a fraction of the hover thrust until its motors have spooled up
(ATTITUDE_TARGET shows the thrust applied).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from perchd.core.errors import LinkError
from perchd.drivers.mavlink.dialect import Dialect
from perchd.drivers.mavlink.link import (
    CMD_ARM,
    CMD_DO_SET_MODE,
    MAV_RESULT_ACCEPTED,
    MAV_RESULT_IN_PROGRESS,
    Connection,
    Waiter,
)
from perchd.drivers.mavlink.setpoints import SetpointStream
from perchd.drivers.mavlink.vehicle import VehicleView

log = logging.getLogger(__name__)

SPOOL_FRACTION = 0.25
"""ArduCopter on the ground: after arming, level at this fraction of the hover thrust (well
below lift-off) until ATTITUDE_TARGET shows the thrust applied, i.e. the motors have spooled
up (MOT_SAFE_TIME + MOT_SPOOL_TIME, ~1.5 s) and it left its landed state. Before that it
flies thrust 0 whatever is sent, and a take-off ramp started meanwhile winds up."""
ARM_RETRY_S = 0.5
"""[s] an arming refused while mocap flows to an EKF that needs it is asked again this often
(ArduPilot on ExternalNav alone has no position or heading until the poses come)."""
REPLIES = ("HEARTBEAT", "COMMAND_ACK")
"""What shows a command's outcome: its acknowledgement, or the state it asked for."""


@dataclass(frozen=True)
class Takeover:
    """The steps on `link` to the vehicle `vehicle` speaks `dialect`, streaming `stream`,
    each wait through `waiter`; `uri` names the driver in errors."""

    link: Connection
    waiter: Waiter
    vehicle: VehicleView
    stream: SetpointStream
    dialect: Dialect
    uri: str

    def prestream(self, hover: float) -> bool:
        """Level at the vehicle's current heading until the loop runs: in the air with the
        `hover` thrust (zero thrust would drop it for as long as the switch takes), on the
        ground with none; for the dialect's prestream_s. Whether it is airborne."""
        v = self.vehicle
        self.waiter.until(
            ("ATTITUDE",), lambda: v.yaw_ned is not None, "the vehicle's attitude (ATTITUDE)"
        )
        heading, airborne = v.yaw_ned, v.airborne()
        thrust = hover if airborne else 0.0
        log.info(
            "%s: taking over %s, streaming level at heading %.1f deg, thrust %.3f",
            self.uri,
            "in the air" if airborne else "on the ground",
            math.degrees(heading),
            thrust,
        )
        self.stream.level(heading, thrust)
        if self.dialect.prestream_s > 0.0:
            self.waiter.pause(self.dialect.prestream_s)  # the keep-alive streams meanwhile
        return airborne

    def switch_mode(self) -> None:
        """Ask for the flight mode; its COMMAND_ACK ACCEPTED is the confirmation (the
        heartbeat that shows it may be a second away), a refusal is named."""
        v, mode = self.vehicle, self.dialect.flight
        v.acks.pop(CMD_DO_SET_MODE, None)
        v.mode_seen = False
        result = lambda: v.acks.get(CMD_DO_SET_MODE, MAV_RESULT_IN_PROGRESS)  # noqa: E731
        self.waiter.until(
            REPLIES,
            lambda: v.mode == mode.custom or result() != MAV_RESULT_IN_PROGRESS,
            f"the switch to custom mode {mode.custom}",
            ask=lambda: self.link.set_mode(v.target, mode.main, mode.sub),
        )
        if v.mode != mode.custom and result() != MAV_RESULT_ACCEPTED:
            raise LinkError(
                f"{self.uri}: the vehicle refused custom mode {mode.custom} (MAV_RESULT {result()})"
            )
        v.switched(mode.custom)

    def arm(self, again: bool, fed: Callable[[], str]) -> None:
        """Arm; again: a refusal is asked again every ARM_RETRY_S until the wait has passed
        (the poses flow meanwhile: an EKF on mocap alone cannot arm before it has them);
        fed(): what went to the EKF meanwhile, for the refusal."""
        v = self.vehicle
        deadline = time.monotonic() + self.waiter.wait_s
        while True:
            v.acks.pop(CMD_ARM, None)
            self.waiter.until(
                REPLIES,
                lambda: (
                    v.armed
                    or v.acks.get(CMD_ARM, 0) not in (MAV_RESULT_ACCEPTED, MAV_RESULT_IN_PROGRESS)
                ),
                "arming",
                ask=lambda: self.link.command(v.target, CMD_ARM, 1),
            )
            if v.armed:
                return
            if not again or time.monotonic() + ARM_RETRY_S > deadline:
                break
            self.waiter.pause(ARM_RETRY_S)
        raise LinkError(
            f"{self.uri}: the vehicle refused to arm (MAV_RESULT {v.acks.get(CMD_ARM)}){fed()}"
        )

    def spool_up(self, hover: float) -> None:
        """Hold the vehicle on the ground, level, at a fraction of the `hover` thrust until
        it applies it (ATTITUDE_TARGET thrust > 0): only then does
        the loop's take-off start, so the ramp and the height integral do not wind up
        against motors still spooling."""
        v = self.vehicle
        v.thrust = None
        self.stream.level(self.stream.level_yaw or 0.0, SPOOL_FRACTION * hover)
        self.waiter.until(
            ("ATTITUDE_TARGET",),
            lambda: (v.thrust or 0.0) > 0.0,
            "the motors to spool up (ATTITUDE_TARGET thrust above 0)",
        )
        log.info("%s: spooled up (ATTITUDE_TARGET thrust %.3f)", self.uri, v.thrust)
