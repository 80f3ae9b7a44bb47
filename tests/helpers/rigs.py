"""One rig per registered driver scheme: the far end of the link and how to read it back.

Each rig turns what its vehicle received back into SI (roll, pitch [rad], thrust [N]) with
its own decoding, so the conformance suite holds every driver to the same numbers.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Protocol

from perchd.core.clock import MonotonicClock
from perchd.core.runtime import Runtime
from perchd.core.types import Phase, Setpoint
from perchd.core.vehicle import CRAZYFLIE_MASS_KG
from perchd.drivers.thrust import CrazyflieThrust, G
from perchd.sim.world import SimWorld, WorldParams

MASS = CRAZYFLIE_MASS_KG
"""[kg] the vehicle every rig pretends to be (a Crazyflie 2.0 with markers, as
VehicleConfig and the default thrust model have it)."""


class RealLink:
    """Rigs whose peer is a real socket: drivers run on the real clock."""

    def runtime(self) -> Runtime:
        return Runtime.real()


class Rig(Protocol):
    uri: str

    def commanded(self) -> tuple[float, float, float] | None:
        """The newest (roll rad, pitch rad, thrust N) the vehicle received, or None."""

    def stopped(self) -> bool:
        """The vehicle was told to stop (stop setpoint, land mode, stop message)."""

    def kill(self) -> None:
        """The vehicle end of the link dies."""

    def runtime(self) -> Runtime:
        """The runtime a driver for this rig is opened in."""

    def close(self) -> None: ...


class CrazyflieRig(RealLink):
    def __init__(self) -> None:
        from crtp_responder import CrtpResponder

        self.peer = CrtpResponder()
        self.uri = self.peer.uri
        self._model = CrazyflieThrust()

    def commanded(self):
        sps = [s for s in self.peer.setpoints() if s.thrust]
        if not sps:
            return None
        s = sps[-1]
        return (
            math.radians(s.roll_deg),
            math.radians(-s.wire_pitch_deg),
            self._model.newtons(s.thrust),
        )

    def stopped(self) -> bool:
        return bool(self.peer.stops())

    def kill(self) -> None:
        self.peer.die()

    def close(self) -> None:
        self.peer.close()


class MavlinkRig(RealLink):
    HOVER = 0.35

    def __init__(self) -> None:
        from mavlink_double import ARDUPILOT, SAFE_PARAMS, VehicleDouble

        self.peer = VehicleDouble(params={**SAFE_PARAMS[ARDUPILOT], "MOT_THST_HOVER": self.HOVER})
        self.uri = f"{self.peer.uri}?mass={MASS}"

    def commanded(self):
        from pymavlink.quaternion import Quaternion

        targets = [t for t in self.peer.targets if t.thrust > 0]
        if not targets:
            return None
        roll, pitch, _ = Quaternion(list(targets[-1].q)).euler
        return roll, -pitch, targets[-1].thrust * MASS * G / self.HOVER

    def stopped(self) -> bool:
        return self.peer.custom_mode == 9  # LAND

    def kill(self) -> None:
        self.peer.die()

    def close(self) -> None:
        self.peer.close()


class ZmqRig(RealLink):
    def __init__(self) -> None:
        from zmq_subscriber import SetpointSubscriber

        self.peer = SetpointSubscriber()
        self.uri = self.peer.uri

    def commanded(self):
        sps = self.peer.of("setpoint")
        return (sps[-1]["roll"], sps[-1]["pitch"], sps[-1]["thrust"]) if sps else None

    def stopped(self) -> bool:
        return bool(self.peer.of("stop"))

    def kill(self) -> None:
        self.peer.die()

    def close(self) -> None:
        self.peer.close()


class LoopbackRig:
    """The in-process simulator on a real clock; the rig reads the world the driver steers,
    so tests open the driver on this rig's runtime."""

    def __init__(self) -> None:
        self.uri = "sim://"
        self._runtime = Runtime(MonotonicClock())
        self.world = self._runtime.sim = SimWorld(WorldParams(), self._runtime.clock)

    def runtime(self) -> Runtime:
        return self._runtime

    def commanded(self):
        sent = [sp for sp in self.world.sent if sp.thrust > 0]
        return (sent[-1].roll, sent[-1].pitch, sent[-1].thrust) if sent else None

    def stopped(self) -> bool:
        return bool(self.world.sent) and self.world.sent[-1].thrust == 0.0

    def kill(self) -> None:
        self.world.faults.link_ok = False

    def close(self) -> None:
        pass


RIGS = {"udp": CrazyflieRig, "mavlink": MavlinkRig, "zmq": ZmqRig, "sim": LoopbackRig}
NOT_HERE = {"radio": "needs a Crazyradio; the same driver as udp://, see tests/hardware"}


def bridge(rig, world, stop: threading.Event) -> None:
    """What the peer understood is what the simulated vehicle does."""
    last = None
    while not stop.wait(0.002):
        cmd = rig.commanded()
        if cmd is not None and cmd != last:
            last = cmd
            world.command(Setpoint(world.clock.now(), cmd[0], cmd[1], 0.0, cmd[2], -1, Phase.HOLD))


def kill_after(rig, world, n_setpoints: int, killed: list[float]) -> None:
    while len(world.sent) < n_setpoints:
        time.sleep(0.001)
    rig.kill()
    killed.append(time.monotonic())  # the peer's socket is closed: the link is dead now
