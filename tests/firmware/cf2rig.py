"""What the opt-in firmware tests share: the cf2 binary from PERCHD_CF2 (docs/firmware.md),
the vehicle in this process, and a small altitude hold so attitude commands can be tried in
the air through perchd's Crazyflie driver."""

from __future__ import annotations

import math
import os
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from perchd.commands.sim.firmware import GIL_SWITCH_S
from perchd.core.types import Phase, Pose, Setpoint
from perchd.sim.firmware.cf2 import Cf2Params, Cf2Vehicle
from perchd.sim.firmware.harness import ProcessGroup
from perchd.sim.firmware.quadrotor import euler_zyx

CF2 = os.environ.get("PERCHD_CF2", "")
needs_cf2 = pytest.mark.skipif(
    not (CF2 and os.access(CF2, os.X_OK)),
    reason="set PERCHD_CF2 to the built cf2 binary (docs/firmware.md)",
)
MASS = 0.0282
"""[kg] the SITL vehicle (perchd.sim.firmware.quadrotor.QuadModel)."""
CALIBRATION = f"?mass={MASS}&hover=38780"
"""The driver's thrust calibration for this vehicle, until the driver takes the flight
config's mass (docs/firmware.md, "thrust")."""


@contextmanager
def cf2_vehicle(tmp: Path, **kw) -> Iterator[Cf2Vehicle]:
    previous = sys.getswitchinterval()
    sys.setswitchinterval(GIL_SWITCH_S)  # as `perchd sim firmware` does: the 1 kHz thread first
    with ProcessGroup() as procs:
        v = Cf2Vehicle(
            Cf2Params(
                CF2,
                link="udp://127.0.0.1:0",
                start=(0.0, 0.0, 0.0),
                surface=None,
                log=tmp / "cf2.log",
                **kw,
            )
        )
        try:
            v.start(procs, threading.Event())
            yield v
        finally:
            v.close()
            sys.setswitchinterval(previous)


def rpy(v: Cf2Vehicle) -> tuple[float, float, float]:
    return euler_zyx(v.truth().q)


class Pilot:
    """Streams setpoints at 100 Hz through the driver, feeding it the true pose (as mocap
    would), with thrust from a PD on height unless the caller fixes it."""

    def __init__(self, vehicle: Cf2Vehicle, driver) -> None:
        self.v, self.cf, self.k = vehicle, driver, 0
        self.z_ref = 0.5

    def fly(
        self,
        seconds: float,
        roll: float = 0.0,
        pitch: float = 0.0,
        yaw: float = 0.0,
        thrust: float | None = None,
        every=None,
    ) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            tr = self.v.truth()
            self.k += 1
            self.cf.observe_pose(Pose("cf1", self.k, tr.t, tr.p, tr.q))
            f = thrust
            if f is None:
                r, p, _ = euler_zyx(tr.q)
                acc = 9.81 + 4.0 * (self.z_ref - tr.p[2]) - 3.0 * tr.v[2]
                f = MASS * acc / max(0.5, math.cos(r) * math.cos(p))
            self.cf.send(Setpoint(tr.t, roll, pitch, yaw, f, self.k, Phase.HOLD))
            if every is not None:
                every(tr)
            time.sleep(0.01)

    def hover(self, seconds: float = 1.5) -> None:
        self.fly(seconds)
