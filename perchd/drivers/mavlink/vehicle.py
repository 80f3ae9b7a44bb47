"""The vehicle as its messages show it, kept by the driver's receiving thread: who it is
(its first autopilot heartbeat: system, component, dialect), its mode, arming, landed
state, heading, the thrust it applies and its own position estimate."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from perchd.core.types import Vec3
from perchd.drivers.mavlink.ardupilot import ARDUPILOT
from perchd.drivers.mavlink.dialect import Dialect
from perchd.drivers.mavlink.px4 import PX4

LANDED_ON_GROUND = 1  # MAV_LANDED_STATE
MAV_AUTOPILOT_INVALID = 8
GCS_OR_COMPANION = (6, 18)  # MAV_TYPE_GCS, MAV_TYPE_ONBOARD_CONTROLLER
ARMED_FLAG = 128  # MAV_MODE_FLAG_SAFETY_ARMED
MODE_CONFIRM_S = 1.5
"""[s] after an acknowledged mode switch a heartbeat still showing the old mode is one sent
before the switch (heartbeats come at 1 Hz); past this the vehicle really is elsewhere."""


def dialect_for(autopilot: int | None) -> Dialect | None:
    """The dialect of a MAV_AUTOPILOT, None for one perchd does not fly."""
    return {d.autopilot: d for d in (ARDUPILOT, PX4)}.get(autopilot)


def is_vehicle_heartbeat(msg: Any) -> bool:
    """A heartbeat from an autopilot, not from a GCS or a companion computer."""
    return msg.autopilot != MAV_AUTOPILOT_INVALID and msg.type not in GCS_OR_COMPANION


@dataclass
class VehicleView:
    """target: (system, component) of the first autopilot heard; heard_s [s]: the driver's
    clock at its last message (None: not heard yet); mode: custom_mode of its last
    heartbeat; yaw_ned [rad]: its heading (ATTITUDE); thrust: the normalised thrust it
    applies (ATTITUDE_TARGET); ekf_position_ned [m]: its own estimate (LOCAL_POSITION_NED);
    acks: MAV_RESULT by command; flight_mode: the custom_mode perchd flies in, once asked
    for; mode_seen: a heartbeat has shown it; switched_s [s]: time.monotonic() of the
    acknowledged switch."""

    target: tuple[int, int] = (0, 0)
    autopilot: int | None = None
    heard_s: float | None = None
    mode: int | None = None
    armed: bool = False
    landed_state: int | None = None
    yaw_ned: float | None = None
    thrust: float | None = None
    ekf_position_ned: Vec3 | None = None
    acks: dict[int, int] = field(default_factory=dict)
    flight_mode: int | None = None
    mode_seen: bool = False
    switched_s: float = 0.0

    @property
    def dialect(self) -> Dialect | None:
        return dialect_for(self.autopilot)

    def on_message(self, msg: Any, now: float) -> bool:
        """Keep what `msg` says, received at `now` [s]; False for one not from the vehicle."""
        kind = msg.get_type()
        if kind == "HEARTBEAT" and is_vehicle_heartbeat(msg):
            self._on_heartbeat(msg, now)
        if self.heard_s is None or msg.get_srcSystem() != self.target[0]:
            return False
        self.heard_s = now
        if kind == "COMMAND_ACK":
            self.acks[msg.command] = msg.result
        elif kind == "ATTITUDE":
            self.yaw_ned = float(msg.yaw)
        elif kind == "EXTENDED_SYS_STATE":
            self.landed_state = int(msg.landed_state)
        elif kind == "LOCAL_POSITION_NED":
            self.ekf_position_ned = (float(msg.x), float(msg.y), float(msg.z))
        elif kind == "ATTITUDE_TARGET":
            self.thrust = float(msg.thrust)
        return True

    def airborne(self) -> bool:
        """Armed and not known to be on the ground (EXTENDED_SYS_STATE, when it streams)."""
        return self.armed and self.landed_state != LANDED_ON_GROUND

    def switched(self, mode: int) -> None:
        """The switch to the flight mode `mode` was acknowledged (or seen)."""
        self.switched_s = time.monotonic()
        self.flight_mode = mode
        self.mode_seen = self.mode == mode

    def left_flight_mode(self) -> bool:
        if self.flight_mode is None or self.mode == self.flight_mode:
            return False
        return self.mode_seen or time.monotonic() - self.switched_s > MODE_CONFIRM_S

    def _on_heartbeat(self, msg: Any, now: float) -> None:
        if self.heard_s is None:
            self.target = (msg.get_srcSystem(), msg.get_srcComponent())
            self.autopilot = msg.autopilot
            self.heard_s = now
        if msg.get_srcSystem() == self.target[0]:
            self.mode = msg.custom_mode
            self.mode_seen = self.mode_seen or (
                self.flight_mode is not None and self.mode == self.flight_mode
            )
            self.armed = bool(msg.base_mode & ARMED_FLAG)
