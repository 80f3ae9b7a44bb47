"""The autopilot parameters perchd depends on, read at connect (docs/safety.md, "Autopilot
failsafe parameters"; docs/firmware.md, "Mocap to the autopilot").

Each rule names a parameter, says which values are safe and what ?configure=1 sets. A
vehicle with an unsafe value is refused before any mode change, every bad parameter named
with its value and the value wanted; with configure=1 the driver sets them (PARAM_SET, read
back, logged) instead.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Callable

from perchd.core.errors import ConfigError

log = logging.getLogger("perchd.drivers.mavlink")

ARDUPILOT, PX4 = 3, 12  # MAV_AUTOPILOT_ARDUPILOTMEGA, MAV_AUTOPILOT_PX4
EXTNAV = 6
"""ArduPilot EK3_SRCn_*: 6 = ExternalNav (VISION_POSITION_ESTIMATE through AP_VisualOdom)."""
EV_POS_YAW = 0b1011
"""PX4 EKF2_EV_CTRL bits 0 (horizontal position), 1 (vertical position), 3 (yaw)."""
EV_HEIGHT = 3
"""PX4 EKF2_HGT_REF 3: vision is the height reference."""
F32 = 1e-6
"""Parameters travel as float32: 0.3 comes back as 0.30000001."""
PX4_INT_PARAMS = {"COM_OBL_RC_ACT", "EKF2_EV_CTRL", "EKF2_HGT_REF"}
"""PX4 sends and takes integer parameters bytewise in PARAM_VALUE's float field."""


@dataclass(frozen=True, slots=True)
class ParamRule:
    """One autopilot parameter perchd depends on. ok(value): safe; wanted: the safe values,
    for the user; target(value): what ?configure=1 sets in place of `value`; reboot: the
    autopilot reads it only at boot."""

    name: str
    ok: Callable[[float], bool]
    wanted: str
    target: Callable[[float], float]
    reboot: bool = False


def _const(value: float) -> Callable[[float], float]:
    return lambda _old: value


FAILSAFE_RULES: dict[int, tuple[ParamRule, ...]] = {
    PX4: (
        ParamRule("COM_OF_LOSS_T", lambda v: 0.0 < v <= 0.3 + F32, "<= 0.3 s", _const(0.3)),
        ParamRule("COM_OBL_RC_ACT", lambda v: int(v) in (4, 5), "4 (Land) or 5 (Hold)",
                  _const(4)),
    ),
    ARDUPILOT: (
        ParamRule("GUID_TIMEOUT", lambda v: 0.0 < v <= 0.5 + F32, "<= 0.5 s", _const(0.5)),
        ParamRule("FS_GCS_ENABLE", lambda v: int(v) == 5, "5 (Land)", _const(5)),
        ParamRule("FS_GCS_TIMEOUT", lambda v: 0.0 < v <= 2.0 + F32, "<= 2 s", _const(2.0)),
        # perchd's mapping already divides thrust by cos(tilt) (flight/control.py): a second
        # 1/cos(tilt) in ArduPilot's attitude controller is +10 % at 25 deg
        ParamRule("ATC_ANGLE_BOOST", lambda v: int(v) == 0, "0 (perchd compensates tilt)",
                  _const(0)),
    ),
}
"""What the vehicle does once perchd is gone, and what it does to perchd's thrust."""

VISION_RULES: dict[int, tuple[ParamRule, ...]] = {
    PX4: (
        ParamRule("EKF2_EV_CTRL", lambda v: int(v) & EV_POS_YAW == EV_POS_YAW,
                  f"bits 0, 1 and 3 set (e.g. {EV_POS_YAW}: position and yaw)",
                  lambda v: float(int(v) | EV_POS_YAW)),
        ParamRule("EKF2_HGT_REF", lambda v: int(v) == EV_HEIGHT, f"{EV_HEIGHT} (vision)",
                  _const(EV_HEIGHT)),
    ),
    ARDUPILOT: (
        ParamRule("VISO_TYPE", lambda v: int(v) == 1, "1 (MAVLink)", _const(1), reboot=True),
        *(ParamRule(f"EK3_SRC1_{axis}", lambda v: int(v) == EXTNAV, f"{EXTNAV} (ExternalNav)",
                    _const(EXTNAV)) for axis in ("POSXY", "POSZ", "YAW")),
    ),
}
"""The autopilot's EKF takes perchd's mocap (drivers/mavvision.py) as its position and
heading, so its own failsafe can hold or land in place."""


def rules_for(autopilot: int, vision: bool) -> tuple[ParamRule, ...]:
    return FAILSAFE_RULES[autopilot] + (VISION_RULES[autopilot] if vision else ())


def check_params(uri: str, rules: tuple[ParamRule, ...], read: Callable[[str], float],
                 write: Callable[[str, float], float], configure: bool) -> None:
    """Refuse unsafe values by name, or (configure) set them and read them back.
    read(name) -> value; write(name, value) -> the value read back after setting it."""
    bad = [(r, v) for r in rules if not r.ok(v := read(r.name))]
    if bad and not configure:
        named = "; ".join(f"{r.name}={v:g} (wanted {r.wanted})" for r, v in bad)
        raise ConfigError(f"{uri}: unsafe autopilot parameters: {named}; set them "
                          f"on the vehicle or add configure=1 to the driver URI")
    for rule, old in bad:
        new = write(rule.name, rule.target(old))
        if not rule.ok(new):
            raise ConfigError(f"{uri}: set {rule.name}={rule.target(old):g} but the vehicle "
                              f"reads back {new:g} (wanted {rule.wanted})")
        log.warning("%s: set %s from %g to %g (configure=1)", uri, rule.name, old, new)
    rebooting = [r.name for r, _ in bad if r.reboot]
    if rebooting:
        raise ConfigError(f"{uri}: set {', '.join(rebooting)}, which the autopilot reads only "
                          f"at boot: reboot the vehicle and connect again")
