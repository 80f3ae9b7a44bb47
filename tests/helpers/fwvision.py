"""Firmware tests of mocap to the autopilot: feed a vehicle's truth to the MAVLink driver as
mocap (observe_pose), climb on it, and compare the autopilot's own position estimate
(LOCAL_POSITION_NED, MavlinkDriver.ekf_position_ned) with the pose in NED."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

from perchd.core.ned import ned_vec
from perchd.core.types import Phase, Pose, Setpoint
from perchd.sim.firmware.harness import Truth, yaw_of

G = 9.81


class PoseFeed:
    """Every truth, as a pose, to drv.observe_pose at rate_hz on a thread: the mocap flows
    from before connect() (a vehicle whose EKF needs it to arm) until stop()."""

    def __init__(self, truth: Callable[[], Truth], drv, rate_hz: float = 50.0) -> None:
        self.truth, self.drv, self.period = truth, drv, 1.0 / rate_hz
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        k = 0
        while not self._stop.wait(self.period):
            tr = self.truth()
            if tr is not None:
                k += 1
                self.drv.observe_pose(Pose("fw", k, tr.t, tr.p, tr.q))

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)


def climb_and_compare(
    truth: Callable[[], Truth],
    drv,
    mass_kg: float,
    clock_now,
    seconds: float = 6.0,
    settle_s: float = 2.0,
) -> dict:
    """Climb to 1 m on the true height (a PD at 50 Hz, level at the start heading), then
    compare LOCAL_POSITION_NED with the pose in NED once settle_s has passed."""
    z0, yaw = truth().p[2], yaw_of(truth().q)
    errs, trace, k = [], [], 0
    start = time.monotonic()
    while (elapsed := time.monotonic() - start) < seconds:
        tr = truth()
        k += 1
        z_ref = min(z0 + 1.0, z0 + 0.5 * elapsed)
        acc = G + 2.0 * (z_ref - tr.p[2]) - 2.0 * tr.v[2]
        drv.send(Setpoint(clock_now(), 0.0, 0.0, yaw, mass_kg * acc, k, Phase.HOLD))
        ekf = drv.ekf_position_ned
        if ekf is not None and drv.yaw0 is not None and elapsed > settle_s:
            want = ned_vec(tr.p, drv.yaw0)
            errs.append(math.dist(ekf, want))
            trace.append([round(c, 3) for c in (*ekf, *want)])
        time.sleep(0.02)
    return {
        "climbed_m": truth().p[2] - z0,
        "samples": len(errs),
        "max_error_m": max(errs) if errs else math.inf,
        "mean_error_m": sum(errs) / len(errs) if errs else math.inf,
        "vision_sent": drv.vision_sent,
        "trace_ekf_vs_mocap_ned": trace[::30],
    }
