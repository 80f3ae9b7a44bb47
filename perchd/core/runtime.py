"""What plug-in factories share for one run: the clock, and the simulated world if any."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from perchd.core.clock import Clock, MonotonicClock


@dataclass
class Runtime:
    """Passed to every driver and mocap factory.

    clock: the agent's clock (a simulated one when the vehicle is simulated).
    sim: the simulated world (perchd.sim.world.SimWorld) shared by the `sim://` driver and
         `sim://` mocap; typed Any so that core names nothing of the packages above it
         (perchd.session builds it; a factory opened alone creates one).
    """

    clock: Clock
    sim: Any = None

    @classmethod
    def real(cls) -> Runtime:
        return cls(MonotonicClock())
