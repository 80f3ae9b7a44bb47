"""The MAVLink driver (ArduPilot, PX4), one module per concern: driver.py composes them;
the registry (drivers/base.py) opens `mavlink:` URIs through open_mavlink (uri.py).

The names below are imported when first asked for: the helper processes (the sentinel, the
Crazyflie keeper's brake) import the one module they need, not the whole driver, and start
that much sooner."""

from __future__ import annotations

from importlib import import_module
from typing import Any

_EXPORTS = {
    "ARDUPILOT": "ardupilot",
    "PX4": "px4",
    "Dialect": "dialect",
    "Mode": "dialect",
    "MavlinkDriver": "driver",
    "CMD_DO_SET_MODE": "link",
    "HEARTBEAT_S": "link",
    "MAV_RESULT_ACCEPTED": "link",
    "Connection": "link",
    "bind_source_port": "link",
    "open_connection": "link",
    "wait_for": "link",
    "LAND_RETRY_S": "landing",
    "ned_attitude": "setpoints",
    "SPOOL_FRACTION": "takeover",
    "open_mavlink": "uri",
    "dialect_for": "vehicle",
    "is_vehicle_heartbeat": "vehicle",
}
"""Exported name -> the module of this package that defines it."""

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f"{__name__}.{module}"), name)
