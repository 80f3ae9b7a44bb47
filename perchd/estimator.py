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
(without updating) to the control tick `t`, which compensates the mocap latency. Outliers
(a jump from the last accepted position implying more than `outlier_speed_mps`) are dropped;
after `outlier_max_rejects` in a row the filter re-initialises on the new position, since the
old track is then the unbelievable one. `State.age` is the time since the newest accepted pose
was measured. tau is None when Xdot <= `min_speed_mps` (no division near zero speed).
"""

from __future__ import annotations

import math

import numpy as np

from perchd.flightconfig import EstimatorConfig
from perchd.perchframe import PerchFrame
from perchd.types import Pose, State


def _transition(dt: float) -> np.ndarray:
    return np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])


def _process_noise(q: float, dt: float) -> np.ndarray:
    d2, d3, d4, d5 = dt * dt, dt ** 3, dt ** 4, dt ** 5
    return q * np.array([[d5 / 20, d4 / 8, d3 / 6], [d4 / 8, d3 / 3, d2 / 2],
                         [d3 / 6, d2 / 2, dt]])


class Estimator:
    def __init__(self, cfg: EstimatorConfig, frame: PerchFrame) -> None:
        self.cfg = cfg
        self.frame = frame
        self._x: np.ndarray | None = None  # rows p, v, a; columns X, Y, Z
        self._P = np.zeros((3, 3))
        self._t = 0.0
        self._last: Pose | None = None
        self._last_p: np.ndarray | None = None
        self._yaw = 0.0
        self._tilt = 0.0
        self._rejects = 0
        self.rejected = 0
        self.accepted = 0
        self._period = None  # [s] smoothed interval between accepted poses

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
        z = np.array(self.frame.to_frame(pose.p))
        if self._x is None or self._is_outlier(pose, z):
            if self._x is not None:
                self.rejected += 1
                self._rejects += 1
                if self._rejects <= self.cfg.outlier_max_rejects:
                    return False
            self._init(pose, z)
        else:
            self._update(pose, z)
        self._accept(pose, z)
        return True

    def _is_outlier(self, pose: Pose, z: np.ndarray) -> bool:
        dt = pose.t - self._last.t
        jump = float(np.linalg.norm(z - self._last_p))
        return jump > self.cfg.outlier_speed_mps * dt + 6.0 * self.cfg.meas_std_m

    def _init(self, pose: Pose, z: np.ndarray) -> None:
        self._x = np.zeros((3, 3))
        self._x[0] = z
        r = self.cfg.meas_std_m ** 2
        self._P = np.diag([r, 4.0, 16.0])  # speed and acceleration unknown: metres per second
        self._t = pose.t
        self._period = None

    def _update(self, pose: Pose, z: np.ndarray) -> None:
        dt = pose.t - self._t
        F = _transition(dt)
        x = F @ self._x
        P = F @ self._P @ F.T + _process_noise(self.cfg.jerk_psd, dt)
        s = P[0, 0] + self.cfg.meas_std_m ** 2
        k = P[:, 0] / s
        self._x = x + np.outer(k, z - x[0])
        self._P = P - np.outer(k, P[0, :])
        self._t = pose.t
        # per source frame: frames the loop never saw (it polls slower than mocap sends)
        # do not make the mocap slower, or the stale limit grows with the loop's period
        frames = pose.seq - self._last.seq
        dt = dt / frames if 0 < frames <= 100 else dt
        self._period = dt if self._period is None else 0.9 * self._period + 0.1 * dt

    def _accept(self, pose: Pose, z: np.ndarray) -> None:
        self._rejects = 0
        self.accepted += 1
        self._last, self._last_p = pose, z
        qx, qy, qz, qw = pose.q
        self._tilt = math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (qx * qx + qy * qy))))
        self._yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))

    def state(self, t: float) -> State | None:
        """The state predicted to time t [s] (None before the first pose)."""
        if self._x is None:
            return None
        x = _transition(max(0.0, t - self._t)) @ self._x
        X, Y, Z = x[0]
        Xd, Yd, Zd = x[1]
        tau = float(X / Xd) if Xd > self.cfg.min_speed_mps else None
        return State(t, float(X), float(Xd), float(x[2, 0]), float(Y), float(Z), float(Yd),
                     float(Zd), tau, self._yaw, self._tilt, t - self._last.t, self._last.seq)
