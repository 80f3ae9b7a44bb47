"""What every socket pose source shares: validation, staleness, drop counting, latest/wait.

A receive thread offers poses and reports drops; the flight loop reads `latest()` or blocks
in `wait()`. Nothing here raises into the receive thread: bad input is counted, and a warning
is logged at most once per `warn_interval_s` with the counts since the last one.
"""

from __future__ import annotations

import enum
import logging
import math
import threading
import time
from dataclasses import dataclass, fields

from perchd.core.ports import SourceStats
from perchd.core.types import Pose


class Drop(enum.Enum):
    """Why a packet or pose was dropped; the value is what a warning says."""

    GARBAGE = "garbage"
    TRUNCATED = "truncated"
    OVERSIZED = "oversized"
    OUT_OF_ORDER = "out of order"
    STALE = "stale"
    BAD_VALUE = "bad value"
    WRONG_BODY = "wrong body"
    NO_BODY = "body missing from frame"


@dataclass(frozen=True, slots=True)
class DropCounts:
    """Packets or poses dropped so far, by reason."""

    garbage: int = 0
    truncated: int = 0
    oversized: int = 0
    out_of_order: int = 0
    stale: int = 0
    bad_value: int = 0
    wrong_body: int = 0
    no_body: int = 0

    @property
    def total(self) -> int:
        return sum(getattr(self, f.name) for f in fields(self))


@dataclass(frozen=True, slots=True)
class PoseLimits:
    """What a believable pose looks like.

    max_abs_m: [m] largest coordinate accepted (a mocap volume is far smaller).
    max_age_s: [s] a pose measured longer ago than this on arrival is stale.
    quat_norm_tol: largest |1 - |q|| accepted before normalising.
    resync_after: consecutive out-of-order poses after which the sender is taken to have
        restarted (Motive restarting, a bridge relaunched) and its numbering is followed.
    """

    max_abs_m: float = 1000.0
    max_age_s: float = 0.5
    quat_norm_tol: float = 0.1
    resync_after: int = 30


class Rejected(ValueError):
    """A pose that is not believable; `reason` says which rule it broke."""

    def __init__(self, reason: Drop, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason


def check_pose(pose: Pose, limits: PoseLimits) -> Pose:
    """The pose with q normalised, or Rejected naming the rule it breaks."""
    if not 0.0 <= pose.latency <= limits.max_age_s:
        raise Rejected(Drop.STALE, f"latency {pose.latency:.3f} s outside 0..{limits.max_age_s} s")
    if not pose.valid:  # carries no position: the estimator ignores it, but keep it printable
        if all(math.isfinite(v) for v in (*pose.p, *pose.q)):
            return pose
        return Pose(
            pose.body, pose.seq, pose.t, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), False, pose.latency
        )
    if not all(math.isfinite(v) for v in (*pose.p, *pose.q, pose.t)):
        raise Rejected(Drop.BAD_VALUE, f"non-finite value in p={pose.p} q={pose.q} t={pose.t}")
    if max(abs(v) for v in pose.p) > limits.max_abs_m:
        raise Rejected(Drop.BAD_VALUE, f"position {pose.p} beyond {limits.max_abs_m} m")
    norm = math.sqrt(sum(v * v for v in pose.q))
    if abs(norm - 1.0) > limits.quat_norm_tol:
        raise Rejected(Drop.BAD_VALUE, f"quaternion norm {norm:.3f} is not 1")
    q = (pose.q[0] / norm, pose.q[1] / norm, pose.q[2] / norm, pose.q[3] / norm)
    return Pose(pose.body, pose.seq, pose.t, pose.p, q, pose.valid, pose.latency)


class RateLimitedWarning:
    """Logs dropped-packet warnings at most once per interval, with counts in between.

    Uses wall-monotonic time on purpose: it paces messages for a human, not the flight."""

    def __init__(self, logger: logging.Logger, what: str, interval_s: float = 5.0) -> None:
        self._log, self._what, self._interval = logger, what, interval_s
        self._last = -math.inf
        self._suppressed = 0

    def __call__(self, reason: Drop, detail: str) -> None:
        now = time.monotonic()
        if now - self._last < self._interval:
            self._suppressed += 1
            return
        extra = (
            f" ({self._suppressed} more dropped since the last warning)" if self._suppressed else ""
        )
        self._log.warning("%s: dropped a packet, %s: %s%s", self._what, reason.value, detail, extra)
        self._last, self._suppressed = now, 0


class PoseStream:
    """Thread-safe newest pose of one body, with counters; the shared half of a PoseSource."""

    def __init__(self, body: str, limits: PoseLimits, warn: RateLimitedWarning) -> None:
        self.body = body
        self.limits = limits
        self._warn = warn
        self._cond = threading.Condition()
        self._latest: Pose | None = None
        self._received = 0
        self._poses = 0
        self._drops = {reason: 0 for reason in Drop}
        self._backwards = 0

    def packet(self) -> None:
        """Count one datagram or message received, good or bad."""
        with self._cond:
            self._received += 1

    def drop(self, reason: Drop, detail: str) -> None:
        with self._cond:
            self._drops[reason] += 1
        self._warn(reason, detail)

    def offer(self, pose: Pose) -> bool:
        """Validate and publish `pose`; False (and counted) when dropped."""
        try:
            checked = check_pose(pose, self.limits)
        except Rejected as err:
            self.drop(err.reason, str(err))
            return False
        with self._cond:
            why = self._store(checked)
        if why:
            self._warn(Drop.OUT_OF_ORDER, why)
            return False
        return True

    def _store(self, pose: Pose) -> str:
        """Publish `pose` unless it is out of order; the reason when not. Caller holds the lock."""
        last = self._latest
        if last is not None and pose.seq <= last.seq:
            self._backwards += 1
            if self._backwards < self.limits.resync_after:
                self._drops[Drop.OUT_OF_ORDER] += 1
                return f"seq {pose.seq} after {last.seq}"
        self._backwards = 0
        self._latest = pose
        self._poses += 1
        self._cond.notify_all()
        return ""

    def latest(self) -> Pose | None:
        with self._cond:
            return self._latest

    def wait(self, after_seq: int, timeout: float) -> Pose | None:
        deadline = time.monotonic() + max(0.0, timeout)
        with self._cond:
            while self._latest is None or self._latest.seq <= after_seq:
                left = deadline - time.monotonic()
                if left <= 0 or not self._cond.wait(left):
                    if self._latest is not None and self._latest.seq > after_seq:
                        break
                    return None
            return self._latest

    def stats(self) -> SourceStats:
        with self._cond:
            return SourceStats(self._received, self._poses, sum(self._drops.values()))

    def drops(self) -> DropCounts:
        with self._cond:
            return DropCounts(*(self._drops[reason] for reason in Drop))


class ThreadedSource:
    """The PoseSource half both socket sources share: reads go to the PoseStream, and one
    receive thread runs `_run` until `_stop` is set."""

    body: str
    _stream: PoseStream

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def latest(self) -> Pose | None:
        return self._stream.latest()

    def wait(self, after_seq: int, timeout: float) -> Pose | None:
        return self._stream.wait(after_seq, timeout)

    def stats(self) -> SourceStats:
        return self._stream.stats()

    def drops(self) -> DropCounts:
        return self._stream.drops()

    def _run(self) -> None:
        raise NotImplementedError

    def _start_thread(self, name: str) -> None:
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _stop_thread(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
