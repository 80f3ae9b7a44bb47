"""ArduPilot (ArduCopter): flown in GUIDED_NOGPS with SET_ATTITUDE_TARGET, which reads the
thrust field as a climb rate unless GUID_OPTIONS bit 3 (value 8) is set: the dialect reads
the parameter and refuses to fly without it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from perchd.core.errors import ConfigError
from perchd.drivers.mavlink.dialect import Mode
from perchd.drivers.mavlink.link import MAV_PARAM_TYPE_REAL32
from perchd.drivers.mavlink.params import F32, ParamRule, const

AUTOPILOT = 3  # MAV_AUTOPILOT_ARDUPILOTMEGA
GUIDED_NOGPS, LAND = 20, 9
EXTNAV = 6
"""EK3_SRCn_*: 6 = ExternalNav (VISION_POSITION_ESTIMATE through AP_VisualOdom)."""
GUIDED_THRUST_BIT = 8
"""GUID_OPTIONS bit 3: SET_ATTITUDE_TARGET thrust is thrust, not climb rate."""

FAILSAFE_RULES = (
    ParamRule("GUID_TIMEOUT", lambda v: 0.0 < v <= 0.5 + F32, "<= 0.5 s", const(0.5)),
    ParamRule("FS_GCS_ENABLE", lambda v: int(v) == 5, "5 (Land)", const(5)),
    ParamRule("FS_GCS_TIMEOUT", lambda v: 0.0 < v <= 2.0 + F32, "<= 2 s", const(2.0)),
    # perchd's mapping already divides thrust by cos(tilt) (flight/control.py): a second
    # 1/cos(tilt) in ArduPilot's attitude controller is +10 % at 25 deg
    ParamRule("ATC_ANGLE_BOOST", lambda v: int(v) == 0, "0 (perchd compensates tilt)", const(0)),
)
"""What the vehicle does once perchd is gone, and what it does to perchd's thrust."""

VISION_RULES = (
    ParamRule("VISO_TYPE", lambda v: int(v) == 1, "1 (MAVLink)", const(1), reboot=True),
    *(
        ParamRule(
            f"EK3_SRC1_{axis}", lambda v: int(v) == EXTNAV, f"{EXTNAV} (ExternalNav)", const(EXTNAV)
        )
        for axis in ("POSXY", "POSZ", "YAW")
    ),
)
"""Its EKF on perchd's mocap (vision.py) for position and heading."""


@dataclass(frozen=True)
class ArduPilot:
    """The Dialect (dialect.py) of ArduPilot."""

    autopilot: int = AUTOPILOT
    hover_param: str = "MOT_THST_HOVER"
    flight: Mode = Mode(GUIDED_NOGPS, 0, GUIDED_NOGPS)
    land: Mode = Mode(LAND, 0, LAND)
    prestream_s: float = 0.0
    spools_up: bool = True
    failsafe_rules: tuple[ParamRule, ...] = FAILSAFE_RULES
    vision_rules: tuple[ParamRule, ...] = VISION_RULES

    def check_setup(self, uri: str, read: Callable[[str], float]) -> None:
        options = int(read("GUID_OPTIONS"))
        if not options & GUIDED_THRUST_BIT:
            raise ConfigError(
                f"{uri}: GUID_OPTIONS={options} lacks bit 3 (thrust as thrust); "
                f"set GUID_OPTIONS={options | GUIDED_THRUST_BIT} on the vehicle"
            )

    def param_wire(self, name: str, value: float) -> tuple[float, int]:
        return float(value), MAV_PARAM_TYPE_REAL32

    def param_value(self, msg: Any) -> float:
        """ArduPilot casts integer parameters to float."""
        return float(msg.param_value)


ARDUPILOT = ArduPilot()
