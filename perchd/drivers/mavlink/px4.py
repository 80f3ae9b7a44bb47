"""PX4: flown in OFFBOARD with SET_ATTITUDE_TARGET, which it takes only after more than a
second of them; its integer parameters travel bytewise in PARAM_VALUE's float."""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from perchd.drivers.mavlink.dialect import Mode
from perchd.drivers.mavlink.link import MAV_PARAM_TYPE_INT32, MAV_PARAM_TYPE_REAL32
from perchd.drivers.mavlink.params import F32, ParamRule, const

AUTOPILOT = 12  # MAV_AUTOPILOT_PX4
OFFBOARD_PORT = 14540
"""PX4 sends its offboard link to this fixed port (SITL instance N: 14540 + N)."""
PRESTREAM_S = 1.2
"""[s] setpoints streamed before asking for OFFBOARD (it wants > 1 s of them)."""
EV_POS_YAW = 0b1011
"""EKF2_EV_CTRL bits 0 (horizontal position), 1 (vertical position), 3 (yaw)."""
EV_HEIGHT = 3
"""EKF2_HGT_REF 3: vision is the height reference."""
INT_PARAMS = {"COM_OBL_RC_ACT", "EKF2_EV_CTRL", "EKF2_HGT_REF"}
"""Sent and taken bytewise in PARAM_VALUE's float field."""


def custom_mode(main: int, sub: int) -> int:
    """The heartbeat's custom_mode of a (main, sub) mode."""
    return (main << 16) | (sub << 24)


def px4_mode(main: int, sub: int) -> Mode:
    return Mode(main, sub, custom_mode(main, sub))


OFFBOARD = px4_mode(6, 0)
AUTO_LAND = px4_mode(4, 6)

FAILSAFE_RULES = (
    ParamRule("COM_OF_LOSS_T", lambda v: 0.0 < v <= 0.3 + F32, "<= 0.3 s", const(0.3)),
    ParamRule("COM_OBL_RC_ACT", lambda v: int(v) in (4, 5), "4 (Land) or 5 (Hold)", const(4)),
)
"""What the vehicle does once perchd is gone."""

VISION_RULES = (
    ParamRule(
        "EKF2_EV_CTRL",
        lambda v: int(v) & EV_POS_YAW == EV_POS_YAW,
        f"bits 0, 1 and 3 set (e.g. {EV_POS_YAW}: position and yaw)",
        lambda v: float(int(v) | EV_POS_YAW),
    ),
    ParamRule(
        "EKF2_HGT_REF", lambda v: int(v) == EV_HEIGHT, f"{EV_HEIGHT} (vision)", const(EV_HEIGHT)
    ),
)
"""Its EKF on perchd's mocap (vision.py) for position, height and heading."""


def param_float(value: int) -> float:
    """An integer as PX4 carries it in PARAM_SET/PARAM_VALUE's float (bytewise)."""
    return struct.unpack("<f", struct.pack("<i", int(value)))[0]


def param_int(value: float) -> int:
    return struct.unpack("<i", struct.pack("<f", value))[0]


@dataclass(frozen=True)
class Px4:
    """The Dialect (dialect.py) of PX4."""

    autopilot: int = AUTOPILOT
    hover_param: str = "MPC_THR_HOVER"
    flight: Mode = OFFBOARD
    land: Mode = AUTO_LAND
    prestream_s: float = PRESTREAM_S
    spools_up: bool = False
    failsafe_rules: tuple[ParamRule, ...] = FAILSAFE_RULES
    vision_rules: tuple[ParamRule, ...] = VISION_RULES

    def check_setup(self, uri: str, read: Callable[[str], float]) -> None:
        """The parameter rules say it all."""

    def param_wire(self, name: str, value: float) -> tuple[float, int]:
        if name in INT_PARAMS:
            return param_float(int(value)), MAV_PARAM_TYPE_INT32
        return float(value), MAV_PARAM_TYPE_REAL32

    def param_value(self, msg: Any) -> float:
        if 1 <= msg.param_type <= 8:  # an integer type
            return float(param_int(msg.param_value))
        return float(msg.param_value)


PX4 = Px4()
