"""The autopilot's tilt error, measured against the mocap and sent back into the setpoint.

An autopilot flies its own attitude estimate: it leans until its *estimate* matches the
setpoint, so an estimate that is off by a degree leans the vehicle a degree off what perchd
asked for, 0.17 m/s^2 of push no model of the commands can foresee (docs/firmware.md, "The
autopilot's tilt error"). The mocap measures the true attitude; the autopilot reports its
estimate (ATTITUDE). Their roll and pitch difference, paired at one instant, is the error,
and a setpoint rotated by it is flown as asked.

- Pairing: ATTITUDE carries the autopilot's boot time. `BootClock` puts it on perchd's
  clock by the least-delayed recent message (arrival - boot time, smallest over
  CLOCK_WINDOW_S), and the mocap's roll and pitch are interpolated at that instant: at a
  stage switch the lean swings tens of degrees per second, and 10 ms of mismatch would read
  as a fifth of a degree of error.
- Only the change is sent: the correction is the error low-passed over FAST_S less its
  baseline over SLOW_S. What stays (a rigid body defined a degree off the vehicle's axes,
  an accelerometer's trim) is the outer loop's, as it was; what moves within a perch (the
  estimate pulled by the approach's accelerations, the stage switch) is taken out a
  message after it shows.
- Bounded: at most MAX_RAD per axis, and nothing once the estimates stop (STALE_S).

Angles are the autopilot's: body FRD in NED, Z-Y-X (roll, pitch), at the heading yaw0
aligns (yaw0.py).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

CLOCK_WINDOW_S = 1.0
"""[s] the boot clock's offset is the smallest arrival delay over this long: 50 ATTITUDE
messages, one of which left without queueing; short against a simulator whose clock runs
1 % off the wall clock (10 ms over the window)."""
FAST_S = 0.05
"""[s] the error's low-pass: 2-3 ATTITUDE messages at 50 Hz, against the mocap's noise."""
SLOW_S = 10.0
"""[s] the baseline's: longer than a perch (hold, approach and stages, ~6 s)."""
MAX_RAD = math.radians(3.0)
"""[rad] the most the correction leans a setpoint, per axis (PX4 SIH's estimate was
0.8-2 deg off in stage 2)."""
STALE_S = 0.1
"""[s] no paired estimate this long: no correction (the link is failing; the outer loop
flies alone)."""
POSE_KEEP = 64
"""Mocap samples kept to pair with (0.64 s at 100 Hz)."""


@dataclass(frozen=True, slots=True)
class Tilt:
    """roll_rad, pitch_rad: body FRD in NED, Z-Y-X."""

    roll_rad: float
    pitch_rad: float


NO_TILT = Tilt(0.0, 0.0)


class BootClock:
    """The autopilot's boot time on perchd's clock, from messages' arrival times."""

    def __init__(self, window_s: float = CLOCK_WINDOW_S) -> None:
        self.window_s = window_s
        self._delays: deque[tuple[float, float]] = deque()  # (arrival [s], arrival - boot [s])
        self._first: float | None = None  # [s] the first message's arrival

    def settled(self, arrival_s: float) -> bool:
        """A whole window of messages heard: before it, the least delay is only the least of
        a few."""
        return self._first is not None and arrival_s - self._first >= self.window_s

    def local(self, boot_s: float, arrival_s: float) -> float:
        """[s] perchd's time of a message stamped boot_s [s] that arrived at arrival_s."""
        d = arrival_s - boot_s
        self._first = arrival_s if self._first is None else self._first
        while self._delays and arrival_s - self._delays[0][0] > self.window_s:
            self._delays.popleft()
        while self._delays and self._delays[-1][1] >= d:  # kept increasing: [0] is the least
            self._delays.pop()
        self._delays.append((arrival_s, d))
        return boot_s + self._delays[0][1]


class TiltCorrection:
    """The autopilot's tilt error (estimate - mocap), its change sent back: `on_estimate`
    from the link's receive thread, `on_pose` and `correction` from the control thread."""

    def __init__(self) -> None:
        self.clock = BootClock()
        # (t [s], roll, pitch), at most as many as poses kept: estimates no pose reaches
        # (poses on another clock) are dropped, not hoarded
        self._estimates: deque[tuple[float, float, float]] = deque(maxlen=POSE_KEEP)
        self._poses: deque[tuple[float, float, float]] = deque(maxlen=POSE_KEEP)
        self._fast: Tilt | None = None
        self._slow = NO_TILT
        self._at: float | None = None  # [s] time of the last paired estimate
        self.paired = 0

    def on_estimate(self, boot_s: float, arrival_s: float, roll: float, pitch: float) -> None:
        """One ATTITUDE: its boot time [s], arrival [s] and angles [rad]. deque.append is
        atomic: the control thread takes these in order."""
        t = self.clock.local(boot_s, arrival_s)
        if self.clock.settled(arrival_s):
            self._estimates.append((t, roll, pitch))

    def on_pose(self, t: float, roll: float, pitch: float) -> None:
        """One mocap attitude at t [s]; pairs every estimate it and the pose before bracket."""
        self._poses.append((t, roll, pitch))
        while self._estimates and self._estimates[0][0] <= t:
            te, roll_e, pitch_e = self._estimates.popleft()
            true = self._mocap_at(te)
            if true is not None:
                self._update(
                    te,
                    Tilt(
                        math.remainder(roll_e - true.roll_rad, math.tau), pitch_e - true.pitch_rad
                    ),
                )

    def correction(self, now: float) -> Tilt:
        """[rad] to add to the setpoint's roll and pitch (FRD in NED) at time now [s]."""
        if self._fast is None or self._at is None or now - self._at > STALE_S:
            return NO_TILT
        return Tilt(
            _clamp(self._fast.roll_rad - self._slow.roll_rad),
            _clamp(self._fast.pitch_rad - self._slow.pitch_rad),
        )

    def _mocap_at(self, t: float) -> Tilt | None:
        """The mocap's angles interpolated at t; None outside the poses kept. Searched from
        the newest: an estimate is paired within a pose or two of it."""
        before = next(
            (i for i in range(len(self._poses) - 1, -1, -1) if self._poses[i][0] < t), None
        )
        if before is None or before == len(self._poses) - 1:  # not inside the poses kept
            return None
        (t0, r0, p0), (t1, r1, p1) = self._poses[before], self._poses[before + 1]
        f = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
        return Tilt(r0 + f * math.remainder(r1 - r0, math.tau), p0 + f * (p1 - p0))

    def _update(self, t: float, err: Tilt) -> None:
        if self._fast is None or self._at is None:
            self._fast = self._slow = err
        else:
            dt = max(0.0, t - self._at)
            self._fast = _toward(self._fast, err, min(1.0, dt / FAST_S))
            self._slow = _toward(self._slow, err, min(1.0, dt / SLOW_S))
        self._at = t
        self.paired += 1


def _toward(a: Tilt, b: Tilt, gain: float) -> Tilt:
    return Tilt(
        a.roll_rad + gain * (b.roll_rad - a.roll_rad),
        a.pitch_rad + gain * (b.pitch_rad - a.pitch_rad),
    )


def _clamp(v: float) -> float:
    """[rad] a tilt error within +-MAX_RAD."""
    return max(-MAX_RAD, min(MAX_RAD, v))
