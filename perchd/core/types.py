"""The values that travel between perchd's modules, all SI, each field's frame and unit named.

World frame: right-handed, Z up, metres. Perching frame: origin on the surface, X along the
approach direction, so before contact X < 0, Xdot > 0 and tau = X / Xdot < 0.
Quaternions are (x, y, z, w). Times are seconds on the agent's injected clock.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


@dataclass(frozen=True, slots=True)
class Pose:
    """One rigid-body pose from a mocap source.

    t: [s] when the pose was *measured*, on the agent's clock (arrival time minus the
       latency the source measured); the estimator uses it to compensate latency.
    p: [m] position in the world frame.  q: orientation (x, y, z, w), world frame.
    valid: the mocap system's tracking-valid flag; invalid poses carry no position.
    latency: [s] measured from exposure to arrival, 0.0 where the source cannot tell.
    """

    body: str
    seq: int
    t: float
    p: Vec3
    q: Quat
    valid: bool = True
    latency: float = 0.0


class Phase(enum.Enum):
    """Flight phases, in the order a perch goes through them."""

    IDLE = "idle"
    TAKEOFF = "takeoff"
    HOLD = "hold"
    APPROACH = "approach"
    STAGE1 = "stage1"
    STAGE2 = "stage2"
    CONTACT = "contact"
    DONE = "done"
    ABORT = "abort"


class EndReason(enum.Enum):
    """Every way a flight can end; the value is the message a user reads."""

    CONTACT = "contact with the surface"
    PLAN_COMPLETE = "plan complete without contact"
    OPERATOR_ABORT = "operator abort"
    STALE_MOCAP = "stale mocap: no valid pose in time"
    LOST_LINK = "lost link to the vehicle"
    GEOFENCE = "geofence violated"
    TILT_LIMIT = "tilt limit exceeded"
    SPEED_LIMIT = "speed limit exceeded"
    TAU_DIVERGENCE = "tau diverged from its reference"
    DEADLINE_OVERRUN = "control loop missed its deadlines"
    SIGNAL = "stopped by a signal"
    TRIGGER_REFUSED = "trigger state outside what the plan allows"
    HOVER_UNLEARNED = "hover thrust not learned"
    TIMEOUT = "flight took too long"
    SOFTWARE_ERROR = "flight software error"

    @property
    def is_success(self) -> bool:
        return self is EndReason.CONTACT


@dataclass(frozen=True, slots=True)
class State:
    """The estimator's output, predicted to the control tick `t` [s].

    x, xdot, xddot: [m], [m/s], [m/s^2] along the perching normal (x < 0 before contact).
    y, z, ydot, zdot: [m], [m/s] lateral position/velocity in the perching frame.
    tau: [s] x / xdot, or None when xdot is too small for tau to be defined.
    yaw: [rad] heading of the body in the world frame.  tilt: [rad] angle of body z from up.
    age: [s] since the newest accepted pose was measured (staleness).
    pose_seq: sequence number of the newest pose used.
    frozen_s: [s] how long the newest poses used have had a bit-identical position (0 when
        the last one moved): a flying body never stays bit-still, a stuck tracker does.
    zddot: [m/s^2] acceleration along the perching frame's z (the hover-thrust learner
        reads it: flight/hover.py).
    lean_x: the body z axis's component along the perching normal X, as the newest pose
        measured it (at t - age): where the thrust points (flight/lagid.py fits the
        attitude's response to the setpoints on it).
    """

    t: float
    x: float
    xdot: float
    xddot: float
    y: float
    z: float
    ydot: float
    zdot: float
    tau: float | None
    yaw: float
    tilt: float
    age: float
    pose_seq: int
    frozen_s: float = 0.0
    zddot: float = 0.0
    lean_x: float = 0.0


@dataclass(frozen=True, slots=True)
class Setpoint:
    """An attitude/thrust command, SI, as every driver accepts it.

    roll, pitch, yaw: [rad] body attitude in the world frame, Z-Y-X order.
    thrust: [N] collective thrust along body z.
    t: [s] when it was computed.  pose_seq: newest pose it was computed from.
    """

    t: float
    roll: float
    pitch: float
    yaw: float
    thrust: float
    pose_seq: int
    phase: Phase

    @staticmethod
    def stop(t: float, pose_seq: int = -1) -> Setpoint:
        """Motors off, level: what a failsafe sends when nothing better is possible."""
        return Setpoint(t, 0.0, 0.0, 0.0, 0.0, pose_seq, Phase.ABORT)


@dataclass(frozen=True, slots=True)
class LinkHealth:
    """ok: the link is up.  age: [s] since the vehicle was last heard from (0 if it never
    answers, e.g. a one-way stream).  detail: why the link is down, if it is.
    rtt_s: [s] the link's round trip, measured by the driver's own echo (median of its
    recent samples), None where the driver cannot measure one."""

    ok: bool
    age: float = 0.0
    detail: str = ""
    rtt_s: float | None = None
