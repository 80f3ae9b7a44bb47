"""Kalman filter: mocap poses -> State (X, Xdot, Xddot, tau, Y, Z) in the perching frame.

Model: constant acceleration (position, velocity, acceleration per axis, white jerk of
spectral density `jerk_psd` [m^2/s^5]), chosen over constant velocity because a perch is
flown at sustained accelerations (the approach, and stage 1 up to a_max = 1.4 m/s^2 for
seconds). A constant-velocity filter lags by about sqrt(2) a / w in speed under a constant
acceleration a (0.05 m/s, 3 % of tau, at w = 40 rad/s); raising its bandwidth to hide the
lag lets millimetre mocap noise straight into Xdot and thus into tau. The CA model tracks a
constant acceleration with no steady-state lag, and its acceleration state gives Xddot for
the log. The three axes share one model and one measurement schedule, so they share one
covariance P: one 3x3 update per pose serves all axes.

Timing: each pose is applied at its own measurement time `pose.t`; `state(t)` predicts
(without updating) to the control tick `t`, which compensates the mocap latency. Outliers (a
jump from the last accepted position implying more than `outlier_speed_mps`) are dropped;
after `outlier_max_rejects` in a row the filter re-initialises on the new position, since
the old track is then the unbelievable one. A frame inside that gate but off the track's
prediction by more than `glitch_speed_mps` of speed error waits for the next frame: back on
the track, it was a glitch (a reflection tracked as the body for a frame) and is dropped;
off the track too, the vehicle did move so (a shove) and both are fused, one frame late.
`State.age` is the time since the newest accepted pose was measured. tau is None when Xdot
<= `min_speed_mps` (no division near zero speed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from perchd.core.types import Pose, State
from perchd.flight.frame import PerchFrame


@dataclass(frozen=True)
class EstimatorConfig:
    """The filter's constants (fixed by design, not flight settings; tests vary them).

    jerk_psd: [m^2/s^5] white-jerk spectral density of the constant-acceleration model.
    meas_std_m: [m] mocap position noise (a motion-capture system's: about 1 mm).
    outlier_speed_mps: [m/s] a jump implying more than this speed is rejected.
    outlier_max_rejects: consecutive rejections after which the filter re-initialises.
    glitch_speed_mps: [m/s] a frame off the track's prediction by more than this speed error
        (over the interval since the last fused frame, plus 6 sigma) waits for the next.
    min_speed_mps: [m/s] tau is undefined (None) when Xdot is at or below this.
    """

    jerk_psd: float = 2.0
    meas_std_m: float = 0.001
    outlier_speed_mps: float = 10.0
    outlier_max_rejects: int = 5
    glitch_speed_mps: float = 1.0
    min_speed_mps: float = 0.05


Cov = tuple[float, float, float, float, float, float, float, float, float]
"""A 3x3 covariance, row major (p, v, a)."""


def _predict_cov(P: Cov, dt: float, q: float) -> Cov:
    """F P F^T + Q for the constant-acceleration transition F over dt [s] and the white-jerk
    noise Q of spectral density q. Written out in floats: this runs once per pose, and
    numpy's per-call overhead on 3x3 arrays is ten times the arithmetic."""
    h = 0.5 * dt * dt
    p00, p01, p02, p10, p11, p12, p20, p21, p22 = P
    # F P: row 0 = p0 + dt p1 + h p2, row 1 = p1 + dt p2, row 2 = p2
    a0, a1, a2 = p00 + dt * p10 + h * p20, p01 + dt * p11 + h * p21, p02 + dt * p12 + h * p22
    b0, b1, b2 = p10 + dt * p20, p11 + dt * p21, p12 + dt * p22
    c0, c1, c2 = p20, p21, p22
    d2, d3, d4, d5 = dt * dt, dt**3, dt**4, dt**5
    q00, q01, q02 = q * (d5 / 20), q * (d4 / 8), q * (d3 / 6)
    q11, q12, q22 = q * (d3 / 3), q * (d2 / 2), q * dt
    # (F P) F^T: column 0 = r0 + dt r1 + h r2, column 1 = r1 + dt r2, column 2 = r2
    return (
        a0 + dt * a1 + h * a2 + q00,
        a1 + dt * a2 + q01,
        a2 + q02,
        b0 + dt * b1 + h * b2 + q01,
        b1 + dt * b2 + q11,
        b2 + q12,
        c0 + dt * c1 + h * c2 + q02,
        c1 + dt * c2 + q12,
        c2 + q22,
    )


class Estimator:
    def __init__(self, cfg: EstimatorConfig, frame: PerchFrame) -> None:
        self.cfg = cfg
        self.frame = frame
        # Per axis X, Y, Z: position, velocity, acceleration (None before the first pose).
        self._pos: list[float] | None = None
        self._vel = [0.0, 0.0, 0.0]
        self._acc = [0.0, 0.0, 0.0]
        self._P: Cov = (0.0,) * 9
        self._t = 0.0
        self._last: Pose | None = None
        self._last_p: tuple[float, float, float] | None = None
        self._moved_t = 0.0
        self._yaw = 0.0
        self._tilt = 0.0
        self._lean_x = 0.0
        self._rejects = 0
        self._held: tuple[Pose, tuple[float, float, float]] | None = None
        self.rejected = 0
        self.accepted = 0
        self._period = None  # [s] smoothed interval between accepted poses
        self._r = cfg.meas_std_m**2
        self._gate = 6.0 * cfg.meas_std_m

    @property
    def mocap_period(self) -> float | None:
        """[s] smoothed source frame period: interval between accepted poses over the
        frames (seq numbers) between them (None before two)."""
        return self._period

    @property
    def last_pose(self) -> Pose | None:
        return self._last

    def offer(self, pose: Pose | None) -> bool:
        """Fuse `pose` if it is new, valid and believable; returns whether it was used."""
        if pose is None or not pose.valid or not all(map(math.isfinite, (*pose.p, *pose.q))):
            return False  # a NaN/inf frame would poison the filter (and hide the tilt)
        if self._last is not None and (pose.seq == self._last.seq or pose.t <= self._t):
            return False
        z = self.frame.to_frame(pose.p)
        if z == self._last_p and math.hypot(*self._vel) > self.cfg.min_speed_mps:
            self.rejected += 1  # moving, yet not moved at all: a tracker re-sending a frame
            return False
        if self._pos is None or self._is_outlier(pose, z):
            if self._pos is not None:
                self.rejected += 1
                self._rejects += 1
                if self._rejects <= self.cfg.outlier_max_rejects:
                    return False
            self._init(pose, z)
        elif self._settled(pose, z):
            self._update(pose, z)
        else:
            return False
        self._accept(pose, z)
        return True

    def _settled(self, pose: Pose, z: tuple[float, float, float]) -> bool:
        """May z be fused now? Off the track, it is held for the next frame to tell a
        glitch (the next back on the track: dropped) from a move (the next off it too: the
        held frame is fused first)."""
        off = math.dist(z, self._position_at(pose.t))
        held, self._held = self._held, None
        # one frame's speed error: after a held frame, back on the track means within it
        # since that frame, not since the last fused (a shove would pass twice the gate)
        since = pose.t - (held[0].t if held is not None else self._t)
        if off <= self.cfg.glitch_speed_mps * since + self._gate:
            if held is not None:
                self.rejected += 1  # the held frame was a glitch
            return True
        if held is None:
            self._held = (pose, z)
            return False
        self._update(*held)
        self._accept(*held)
        return True

    def _is_outlier(self, pose: Pose, z: tuple[float, float, float]) -> bool:
        dt = pose.t - self._last.t
        lx, ly, lz = self._last_p
        jump = math.sqrt((z[0] - lx) ** 2 + (z[1] - ly) ** 2 + (z[2] - lz) ** 2)
        return jump > self.cfg.outlier_speed_mps * dt + self._gate

    def _init(self, pose: Pose, z: tuple[float, float, float]) -> None:
        self._held = None
        self._pos, self._vel, self._acc = list(z), [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        # speed and acceleration unknown: metres per second (squared)
        self._P = (self._r, 0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0, 16.0)
        self._t = pose.t
        self._period = None

    def _position_at(self, t: float) -> list[float]:
        """[m] the track's position predicted to t [s] (constant acceleration)."""
        dt = t - self._t
        h = 0.5 * dt * dt
        pos, vel, acc = self._pos or [0.0, 0.0, 0.0], self._vel, self._acc  # pos: once fused
        return [pos[i] + dt * vel[i] + h * acc[i] for i in range(3)]

    def _update(self, pose: Pose, z: tuple[float, float, float]) -> None:
        dt = pose.t - self._t
        P = _predict_cov(self._P, dt, self.cfg.jerk_psd)
        s = P[0] + self._r
        k0, k1, k2 = P[0] / s, P[3] / s, P[6] / s
        pos, vel, acc = self._pos, self._vel, self._acc
        predicted = self._position_at(pose.t)
        for i in range(3):  # the three axes share P and hence the gain
            p, v, a = predicted[i], vel[i] + dt * acc[i], acc[i]
            innovation = z[i] - p
            pos[i], vel[i], acc[i] = p + k0 * innovation, v + k1 * innovation, a + k2 * innovation
        r0, r1, r2 = P[0], P[1], P[2]
        self._P = (
            P[0] - k0 * r0,
            P[1] - k0 * r1,
            P[2] - k0 * r2,
            P[3] - k1 * r0,
            P[4] - k1 * r1,
            P[5] - k1 * r2,
            P[6] - k2 * r0,
            P[7] - k2 * r1,
            P[8] - k2 * r2,
        )
        self._t = pose.t
        # per source frame: frames the loop never saw (it polls slower than mocap sends)
        # do not make the mocap slower, or the stale limit grows with the loop's period
        frames = pose.seq - self._last.seq
        dt = dt / frames if 0 < frames <= 100 else dt
        self._period = dt if self._period is None else 0.9 * self._period + 0.1 * dt

    def _accept(self, pose: Pose, z: tuple[float, float, float]) -> None:
        if z != self._last_p:
            self._moved_t = pose.t  # measured when the position last changed
        self._rejects = 0
        self.accepted += 1
        self._last, self._last_p = pose, z
        qx, qy, qz, qw = pose.q
        self._yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        s = 2.0 / (qx * qx + qy * qy + qz * qz + qw * qw)  # a tracker's q may be off unit
        bz = (
            s * (qx * qz + qw * qy),
            s * (qy * qz - qw * qx),
            1.0 - s * (qx * qx + qy * qy),
        )  # the body z axis in the world
        self._tilt = math.acos(max(-1.0, min(1.0, bz[2])))
        self._lean_x = self.frame.rotate_in(bz)[0]

    def state(self, t: float) -> State | None:
        """The state predicted to time t [s] (None before the first pose)."""
        if self._pos is None:
            return None
        dt = max(0.0, t - self._t)
        h = 0.5 * dt * dt
        (px, py, pz), (vx, vy, vz), (ax, ay, az) = self._pos, self._vel, self._acc
        X, Xd = px + dt * vx + h * ax, vx + dt * ax
        tau = X / Xd if Xd > self.cfg.min_speed_mps else None
        return State(
            t,
            X,
            Xd,
            ax,
            py + dt * vy + h * ay,
            pz + dt * vz + h * az,
            vy + dt * ay,
            vz + dt * az,
            tau,
            self._yaw,
            self._tilt,
            t - self._last.t,
            self._last.seq,
            self._last.t - self._moved_t,
            az,
            self._lean_x,
        )
