"""What plug-in factories share for one run: the clock, and the simulated world if any."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from perchd.core.clock import Clock, MonotonicClock

if TYPE_CHECKING:  # for the annotation only: core never imports sim at run time
    from perchd.sim.world import SimWorld


@dataclass
class Runtime:
    """Passed to every driver and mocap factory.

    clock: the agent's clock (a simulated one when the vehicle is simulated).
    sim: the simulated world shared by the `sim://` driver and `sim://` mocap
         (perchd.sim.session builds it; a factory opened alone creates one).
    """

    clock: Clock
    sim: SimWorld | None = None

    @classmethod
    def real(cls) -> "Runtime":
        return cls(MonotonicClock())
