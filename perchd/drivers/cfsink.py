"""The sink the Crazyflie keeper holds once the agent is gone (drivers/cflink.py; docs/safety.md,
"When the agent dies"): the level thrust, in the driver's thrust units, that brings the
vehicle down at a speed it keeps, and when to cut the motors.

Two ways, one interface (`level_units(now)`, None: cut):
- `ClosedSink`, on the mocap: a PI on the vertical speed to SINK_MPS (SINK_LOW_MPS within
  LOW_M of the floor), the thrust through the thrust model about the hover estimate; the
  motors are cut once the vehicle rests (touchdown) or after a bound.
- `OpenSink`, without it: a climb or a fall met at the death is braked first (BRAKE_MPS2),
  then a short push below hover starts the descent, then hover less SINK_MARGIN holds a slow
  sink, until a bound from the last height known and the climb's stopping distance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from perchd.core.types import Pose
from perchd.drivers.mavlink.brake import VelocityTracker
from perchd.drivers.thrust import CrazyflieThrust, G

FLOOR_Z_M = 0.0
"""[m] the floor's world height (perchd's world: Z up, the floor at 0)."""
SINK_MPS = 0.5
"""[m/s] the sink held on the mocap ..."""
SINK_LOW_MPS = 0.3
"""[m/s] ... and within LOW_M of the floor."""
LOW_M = 0.3
KP_PER_S = 4.0
"""[1/s] vertical acceleration per m/s of speed error."""
KI_PER_S2 = 4.0
"""[1/s^2] integral gain: takes up the hover estimate's error."""
INTEGRAL_MAX_MPS2 = 2.0
"""[m/s^2] the integral's bound (20 % of the weight)."""
ACCEL_MIN_MPS2, ACCEL_MAX_MPS2 = -4.0, 4.0
"""[m/s^2] the vertical acceleration asked for, bounded: never a free fall."""
TOUCH_M = 0.1
"""[m] above the floor: within this, a vehicle that stops sinking has landed."""
REST_MPS = 0.1
"""[m/s] no faster than this, up or down, the vehicle rests ..."""
REST_S = 0.15
"""[s] ... when it has rested this long within TOUCH_M of the floor ..."""
STALL_S = 1.0
"""[s] ... or this long at any height (a floor that is not at FLOOR_Z_M: a table)."""
DESCENT_MAX_S = 12.0
"""[s] the longest descent, either way (from 3 m at 0.3 m/s, with margin)."""
MOCAP_LOST_S = 0.15
"""[s] no new pose this long: the mocap is lost, the open-loop sink takes over."""
KICK_FRACTION = 0.85
"""the open loop's push: this fraction of the hover thrust ..."""
KICK_S = 0.35
"""[s] ... for this long from the death (~0.4 m/s of sink), ramping RAMP_S each way."""
RAMP_S = 0.2
SINK_MARGIN = 0.03
"""then hover less this fraction of the weight: 0.3 m/s^2, from 1 m ~0.8 m/s at the floor."""
BRAKE_MPS2 = ACCEL_MAX_MPS2
"""[m/s^2] the open loop's brake on a climb (a kill in take-off) or a fall met at the
death: the closed loop's own bound, so a climb stops within climb^2 / 2 BRAKE_MPS2 and the
motors' lag, never by a free fall."""
OPEN_SINK_MPS = 0.6
"""[m/s] the open loop's mean sink, for its bound: the height known / this + OPEN_SPARE_S."""
OPEN_SPARE_S = 0.5
OPEN_UNKNOWN_S = 2.5
"""[s] the open loop's bound when no height is known."""


@dataclass(frozen=True)
class Hover:
    """The vehicle's hover in the driver's thrust model: newtons [N] that hold it, as the
    agent flew it (the hold thrusts' mean) and the model converts them."""

    model: CrazyflieThrust
    newtons: float

    def units(self, accel_mps2: float, tilt_factor: float = 1.0) -> int:
        """Level thrust units for a vertical acceleration [m/s^2] (thrust is lift)."""
        return self.model.units(self.newtons * (1.0 + accel_mps2 / G) * tilt_factor)


class OpenSink:
    """The open-loop descent from t0_s, the vehicle sinking at `sink_mps` [m/s] (> 0 down)
    at the death. First a brake of BRAKE_MPS2 about the hover brings that sink into
    0..SINK_MPS: a climb stops (a kill in take-off), a fall slows (never faster toward the
    floor than it was going). From rest, a kick: from `hold_units` (the last command's level
    thrust, never above the hover: nothing after the death climbs) down to KICK_FRACTION of
    the hover; a vehicle already sinking at SINK_LOW_MPS needs none. Then hover less
    SINK_MARGIN until the bound from `height_m` [m] above the floor (None: unknown) and the
    climb's stopping distance. Every thrust is the hover's, never the last command's: a
    death mid-brake (a command below hover) kicks no harder."""

    def __init__(
        self,
        t0_s: float,
        hold_units: int,
        hover: Hover,
        height_m: float | None,
        sink_mps: float = 0.0,
    ) -> None:
        self.t0_s = t0_s
        self.hold_units = hold_units
        goal = min(max(sink_mps, 0.0), SINK_MPS)
        excess = sink_mps - goal  # > 0: falling too fast; < 0: climbing
        self.brake_s = abs(excess) / BRAKE_MPS2
        self.brake_units = hover.units(math.copysign(BRAKE_MPS2, excess))
        self.kick_s = 0.0 if goal >= SINK_LOW_MPS else KICK_S
        self.low_units = hover.units((KICK_FRACTION - 1.0) * G)
        self.sink_units = hover.units(-SINK_MARGIN * G)
        self.top_units = (
            min(hold_units, hover.units(0.0)) if self.brake_s == 0.0 else self.low_units
        )
        rise_m = max(0.0, -excess) * self.brake_s / 2.0
        sink_s = (
            OPEN_UNKNOWN_S
            if height_m is None
            else (max(0.0, height_m) + rise_m) / OPEN_SINK_MPS + OPEN_SPARE_S
        )
        self.end_s = t0_s + min(self.brake_s + self.kick_s + sink_s, DESCENT_MAX_S)

    def level_units(self, now: float) -> int | None:
        t = now - self.t0_s
        if now >= self.end_s or self.hold_units <= 0:
            return None
        if t < self.brake_s:
            return self.brake_units
        t -= self.brake_s
        if t < self.kick_s:
            return _ramp(self.top_units, self.low_units, t / RAMP_S)
        start = self.low_units if self.kick_s else self.top_units
        return _ramp(start, self.sink_units, (t - self.kick_s) / RAMP_S)


def _ramp(a: int, b: int, share: float) -> int:
    return int(a + (b - a) * min(1.0, max(0.0, share)))


class ClosedSink:
    """The closed-loop descent on the mocap from t0_s: feed every pose (`observe`); while
    `flying`, `level_units` gives the thrust, None once the vehicle rests or after
    DESCENT_MAX_S; with the mocap lost an OpenSink goes on from what it learned (`open_sink`)."""

    def __init__(self, t0_s: float, hover: Hover) -> None:
        self.t0_s = t0_s
        self.hover = hover
        self.velocity = VelocityTracker()
        self.z_m: float | None = None
        self.vz_mps: float | None = None
        self.pose_at_s = t0_s  # time.monotonic() of the newest pose
        self.integral_mps2 = 0.0
        self.last_s: float | None = None
        self.rest_from_s: float | None = None
        self.landed = False

    def observe(self, pose: Pose, now: float) -> None:
        if not pose.valid:
            return
        v = self.velocity.update(pose.t, pose.p)
        if v is None:
            return
        self.z_m, self.vz_mps, self.pose_at_s = pose.p[2], v[2], now
        resting = abs(v[2]) <= REST_MPS
        self.rest_from_s = (self.rest_from_s or now) if resting else None

    def lost(self, now: float) -> bool:
        return now - self.pose_at_s > MOCAP_LOST_S

    def height_m(self) -> float | None:
        return None if self.z_m is None else self.z_m - FLOOR_Z_M

    def target_mps(self) -> float:
        h = self.height_m()
        return SINK_LOW_MPS if h is not None and h < LOW_M else SINK_MPS

    def flying(self, now: float) -> bool:
        """The loop has a vertical speed, and a fresh one."""
        return self.vz_mps is not None and not self.lost(now)

    def level_units(self, now: float) -> int | None:
        """While flying(now): the level thrust, None once landed or past DESCENT_MAX_S."""
        if self.vz_mps is None or self._done(now):
            return None
        dt = 0.0 if self.last_s is None else min(now - self.last_s, 0.1)
        self.last_s = now
        error = -self.target_mps() - self.vz_mps
        self.integral_mps2 = max(
            -INTEGRAL_MAX_MPS2, min(INTEGRAL_MAX_MPS2, self.integral_mps2 + KI_PER_S2 * error * dt)
        )
        accel = max(ACCEL_MIN_MPS2, min(ACCEL_MAX_MPS2, KP_PER_S * error + self.integral_mps2))
        return self.hover.units(accel)

    def _done(self, now: float) -> bool:
        h = self.height_m()
        rest = 0.0 if self.rest_from_s is None else now - self.rest_from_s
        self.landed = (h is not None and h < TOUCH_M and rest >= REST_S) or rest >= STALL_S
        return self.landed or now - self.t0_s >= DESCENT_MAX_S

    def open_sink(self, now: float, hold_units: int) -> OpenSink:
        """The open loop from here: the hover this loop learned, the height and sink last seen."""
        learned = Hover(self.hover.model, self.hover.newtons * (1.0 + self.integral_mps2 / G))
        sink = 0.0 if self.vz_mps is None else -self.vz_mps
        return OpenSink(now, hold_units, learned, self.height_m(), sink)


def hover_mean(mean_n: float, newtons: float, dt_s: float, tau_s: float = 1.0) -> float:
    """[N] the exponential mean of the hold thrust over tau_s [s]: the hover estimate the
    agent's own hold learned (take-off's climb thrust and a perch's pushes average out)."""
    share = 1.0 - math.exp(-max(0.0, dt_s) / tau_s)
    return mean_n + (newtons - mean_n) * share
