"""A hung simulated link: `sim://?stall=AT,FOR` holds whoever next asks the world anything.

At AT [s] after the world starts, the next call into the world (the driver sending a
setpoint, the mocap source reading a pose: in a flight, the control loop's own thread) blocks
for FOR [s] on the world's clock, once. On the real clock (`perchd serve` with sim:// links)
that is a control loop stalled in a driver call, which must stop the WATCHDOG=1 pings; on a
simulated clock simulated time just jumps by FOR. Only simulated links can be told to stall.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from perchd.core.errors import UriError
from perchd.core.uri import Uri

AT_MAX_S = 3600.0
FOR_MAX_S = 60.0


@dataclass(frozen=True)
class Stall:
    """at_s [s] after the world's start; for_s [s] the caller is held."""

    at_s: float
    for_s: float

    def __call__(self, world: Any) -> None:
        """A world disturbance (Faults.at): sleep on the world's clock, holding its lock."""
        world.clock.sleep_until(world.clock.now() + self.for_s)


def stall_from_uri(uri: Uri) -> Stall | None:
    """The URI's stall=AT,FOR option; a bad value is one UriError naming it."""
    text = uri.param("stall")
    if text is None:
        return None
    try:
        at, dur = (float(v) for v in text.split(","))
    except ValueError:
        raise UriError(f"{uri.raw}: stall={text!r} must be AT,FOR in seconds") from None
    if not (math.isfinite(at) and 0.0 <= at <= AT_MAX_S):
        raise UriError(f"{uri.raw}: stall AT={at:g} s is outside 0..{AT_MAX_S:g} s")
    if not (math.isfinite(dur) and 0.0 < dur <= FOR_MAX_S):
        raise UriError(f"{uri.raw}: stall FOR={dur:g} s is outside 0..{FOR_MAX_S:g} s (above 0)")
    return Stall(at, dur)
