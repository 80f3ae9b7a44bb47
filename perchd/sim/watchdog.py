"""The vehicle's own setpoint watchdog, for `perchd sim` (setpoints over a socket).

As the Crazyflie firmware's commander (COMMANDER_WDT_TIMEOUT_STABILIZE / _SHUTDOWN):
- level_s [s] after the newest setpoint, the vehicle levels out: roll and pitch 0, the
  last yaw and thrust kept;
- cut_s [s] after it, the motors are cut and the thrust is locked: setpoints are refused
  until one with zero thrust unlocks it (the firmware's thrust lock, which the crazyflie
  driver's connect answers).
It watches only once a setpoint has come (a vehicle waiting for its agent hovers on), and
not after a `stop` (the motors are off already). Pure logic on injected times; the
commands it issues go to the vehicle through `command` (on the vehicle: after the link's
latency, as the setpoint it replaces would have).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from perchd.core.errors import ConfigError
from perchd.core.types import Setpoint


@dataclass(frozen=True)
class WatchdogParams:
    """level_s, cut_s [s] of silence after the newest setpoint (firmware: 0.5 and 2)."""

    level_s: float = 0.5
    cut_s: float = 2.0

    def __post_init__(self) -> None:
        if not 0.0 < self.level_s <= self.cut_s <= 60.0:
            raise ConfigError(
                f"--watchdog {self.level_s:g} {self.cut_s:g}: need 0 < LEVEL_S <= CUT_S <= 60 s"
            )


class SetpointWatchdog:
    """feed() each setpoint from the link, stopped() on a stop, check() now and then."""

    def __init__(self, params: WatchdogParams, command: Callable[[Setpoint], None]) -> None:
        self.params = params
        self._command = command
        self._last: Setpoint | None = None  # the newest accepted setpoint, while watched
        self._last_at = 0.0
        self._levelled = False
        self.locked = False
        self.levels: list[float] = []  # [s] of silence when it levelled the vehicle
        self.cuts: list[float] = []  # [s] of silence when it cut the motors
        self.refused = 0  # setpoints refused by the thrust lock

    def feed(self, sp: Setpoint, now: float) -> bool:
        """A setpoint arrived at `now` [s]; False if the thrust lock refuses it."""
        if self.locked:
            if sp.thrust != 0.0:
                self.refused += 1
                return False
            self.locked = False
        self._last, self._last_at, self._levelled = sp, now, False
        self._command(sp)
        return True

    def stopped(self) -> None:
        """A stop: the motors are off, nothing to watch until the next setpoint."""
        self._last = None

    def check(self, now: float) -> float | None:
        """Act on the silence up to `now` [s]; [s] until the next deadline, None if idle."""
        if self._last is None:
            return None
        silent = now - self._last_at
        if silent >= self.params.cut_s:
            self._cut(now, silent)
            return None
        if silent >= self.params.level_s and not self._levelled:
            self._levelled = True
            self.levels.append(silent)
            sp = self._last
            self._command(Setpoint(now, 0.0, 0.0, sp.yaw, sp.thrust, sp.pose_seq, sp.phase))
        return (self.params.cut_s if self._levelled else self.params.level_s) - silent

    def _cut(self, now: float, silent: float) -> None:
        self._last, self.locked = None, True
        self.cuts.append(silent)
        self._command(Setpoint.stop(now))
