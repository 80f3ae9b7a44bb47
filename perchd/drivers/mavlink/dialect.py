"""What differs between autopilots, as the driver sees it: one Dialect each (ardupilot.py,
px4.py), found by the autopilot its heartbeat names (vehicle.dialect_for)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from perchd.drivers.mavlink.params import ParamRule


@dataclass(frozen=True, slots=True)
class Mode:
    """A flight mode: DO_SET_MODE's param2 and param3 (main, sub) and the custom_mode the
    vehicle's heartbeat shows in it."""

    main: int
    sub: int
    custom: int


class Dialect(Protocol):
    """autopilot: MAV_AUTOPILOT in its heartbeat; hover_param: its normalised hover thrust;
    flight: the offboard mode perchd flies in; land: its landing mode; prestream_s [s]:
    setpoints streamed before it takes the flight mode; spools_up: armed on the ground it
    is held at a fraction of the hover thrust until its motors have spooled up;
    failsafe_rules, vision_rules: the parameters checked at connect (params.py)."""

    autopilot: int
    hover_param: str
    flight: Mode
    land: Mode
    prestream_s: float
    spools_up: bool
    failsafe_rules: tuple[ParamRule, ...]
    vision_rules: tuple[ParamRule, ...]

    def check_setup(self, uri: str, read: Callable[[str], float]) -> None:
        """Refuse (ConfigError) a set-up no parameter rule covers; read(name) -> value."""

    def param_wire(self, name: str, value: float) -> tuple[float, int]:
        """(PARAM_SET's param_value, its MAV_PARAM_TYPE) for a value."""

    def param_value(self, msg: Any) -> float:
        """A PARAM_VALUE's value."""


def rules_for(dialect: Dialect, vision: bool) -> tuple[ParamRule, ...]:
    return dialect.failsafe_rules + (dialect.vision_rules if vision else ())
