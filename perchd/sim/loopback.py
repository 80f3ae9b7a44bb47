"""`sim://[?latency=S&mass=KG&...]`: the in-process simulated vehicle (perchd.sim).

The reference driver: it keeps the Driver protocol's promises with no radio in between.
Setpoints go to the shared SimWorld's plant (after the configured command latency); the
failsafe sends a motors-off setpoint and silences later ones; health() reports the world's
link fault switch, so tests can cut the link.
"""

from __future__ import annotations

from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, LinkHealth, Setpoint
from perchd.core.uri import Uri
from perchd.drivers.base import DriverBase
from perchd.sim.world import SimWorld, world_for


def open_loopback(uri: Uri, runtime: Runtime) -> LoopbackDriver:
    return LoopbackDriver(uri.raw, world_for(uri, runtime, "driver"))


class LoopbackDriver(DriverBase):
    def __init__(self, uri: str, world: SimWorld) -> None:
        self.uri = uri
        self.world = world
        self._connected = False
        self._stopped = False
        self.failsafe_reasons: list[EndReason] = []

    def connect(self) -> None:
        self._connected, self._stopped = True, False

    def send(self, setpoint: Setpoint) -> None:
        if self._connected and not self._stopped and self.world.link_ok:
            self.world.command(setpoint)

    def failsafe(self, reason: EndReason) -> None:
        self.failsafe_reasons.append(reason)
        if not self._stopped:
            self.world.failsafe(reason)
        self._stopped = True

    def health(self) -> LinkHealth:
        if not self._connected:
            return LinkHealth(False, 0.0, "not connected")
        if not self.world.link_ok:
            return LinkHealth(False, 0.0, "simulated link cut")
        # The simulated link's echo would cross its command latency both ways.
        return LinkHealth(True, 0.0, rtt_s=2.0 * self.world.command_latency_s)

    def thrust_ceiling_n(self) -> float:
        """[N] the simulated plant's most thrust. Its mass (sim://?mass=) is the simulated
        truth, not a calibration: the flight's config may disagree, as a real vehicle's
        weight may (the hover learner finds out, flight/hover.py)."""
        return self.world.plant.params.thrust_max_n

    def close(self, hand_over: bool = True) -> None:  # nothing outlives the link
        if self._connected and not self._stopped:  # motors off, like every driver's close
            self.world.command(Setpoint.stop(self.world.clock.now()))
            self._stopped = True
        self._connected = False
