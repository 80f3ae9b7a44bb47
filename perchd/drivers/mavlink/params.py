"""The autopilot parameters perchd depends on, read at connect (docs/safety.md, "Autopilot
failsafe parameters"; docs/firmware.md, "Mocap to the autopilot").

Each dialect (ardupilot.py, px4.py) states its rules. Each rule names a parameter, says
which values are safe and what ?configure=1 sets. A vehicle with an unsafe value is refused
before any mode change, every bad parameter named with its value and the value wanted; with
configure=1 the driver sets them (PARAM_SET, read back, logged) instead.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

from perchd.core.errors import ConfigError

log = logging.getLogger(__name__)

F32 = 1e-6
"""Parameters travel as float32: 0.3 comes back as 0.30000001."""


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


def const(value: float) -> Callable[[float], float]:
    return lambda _old: value


def check_params(
    uri: str,
    rules: tuple[ParamRule, ...],
    read: Callable[[str], float],
    write: Callable[[str, float], float],
    configure: bool,
) -> None:
    """Refuse unsafe values by name, or (configure) set them and read them back.
    read(name) -> value; write(name, value) -> the value read back after setting it."""
    bad = [(r, v) for r in rules if not r.ok(v := read(r.name))]
    if bad and not configure:
        named = "; ".join(f"{r.name}={v:g} (wanted {r.wanted})" for r, v in bad)
        raise ConfigError(
            f"{uri}: unsafe autopilot parameters: {named}; set them "
            f"on the vehicle or add configure=1 to the driver URI"
        )
    for rule, old in bad:
        new = write(rule.name, rule.target(old))
        if not rule.ok(new):
            raise ConfigError(
                f"{uri}: set {rule.name}={rule.target(old):g} but the vehicle "
                f"reads back {new:g} (wanted {rule.wanted})"
            )
        log.warning("%s: set %s from %g to %g (configure=1)", uri, rule.name, old, new)
    rebooting = [r.name for r, _ in bad if r.reboot]
    if rebooting:
        raise ConfigError(
            f"{uri}: set {', '.join(rebooting)}, which the autopilot reads only "
            f"at boot: reboot the vehicle and connect again"
        )
