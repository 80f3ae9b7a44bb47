"""Firmware in the loop: a vehicle's own flight firmware in its own process, our physics
(or the firmware's), and the true state published as mocap for `perchd fly`.

One harness for every firmware: a vehicle is anything that satisfies FirmwareVehicle
(start its processes through a ProcessGroup, say when it is ready to fly, give its true
state and the driver URI that reaches it). The Crazyflie's cf2 is the first
(perchd.sim.firmware.cf2); ArduPilot SITL and PX4 SIH bring their own physics and would
give their truth from it.

The harness publishes the truth at the mocap rate through perchd's pose outputs
(perchd.mocap.outputs: zmq:// or natnet://) and announces itself with the line
`perchd sim` uses (docs/contracts.md §2), so `perchd fly` and the tests treat both alike.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import math
import os
import random
import shutil
import subprocess
import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from perchd.core.clock import Clock, MonotonicClock
from perchd.core.errors import LinkError
from perchd.core.types import Pose, Quat, Vec3
from perchd.mocap.outputs import PoseOutput
from perchd.sim.world import Contact, MocapParams

STOP_GRACE_S = 2.0
"""[s] a process asked to stop (SIGTERM) gets this long before SIGKILL."""


@dataclass(frozen=True, slots=True)
class Truth:
    """The simulated vehicle's true state. t [s] on the harness clock (monotonic);
    p [m], v [m/s] world frame, Z up; q (x, y, z, w) body -> world; w [rad/s] body rates."""

    t: float
    p: Vec3
    v: Vec3
    q: Quat
    w: Vec3


class Interrupted(Exception):
    """The harness was told to stop (a signal) before the vehicle was ready."""


class FirmwareVehicle(Protocol):
    """A vehicle process whose true state the harness publishes as mocap."""

    name: str

    def start(self, procs: ProcessGroup, cancel: threading.Event) -> None:
        """Launch the firmware through `procs` and return once it is ready to fly.
        LinkError if it never gets there; Interrupted when `cancel` is set meanwhile."""

    def truth(self) -> Truth | None:
        """The newest true state (None before the physics has run)."""

    def driver_uri(self) -> str:
        """The URI `perchd fly --driver` reaches this vehicle's firmware with."""

    def contact(self) -> Contact | None:
        """Where and how fast it reached the perching surface, if it has."""

    def summary(self) -> dict[str, Any]:
        """Figures for the harness's summary (JSON-able)."""

    def close(self) -> None:
        """Stop its threads and sockets (its processes belong to the ProcessGroup)."""


class ProcessGroup:
    """Every process the harness starts, stopped by close() (and at interpreter exit).

    Each child is started by setsid, in a process group of its own, so a Ctrl-C at the
    terminal reaches only the harness, which then stops its children in order rather than
    leaving a firmware half-killed.
    A harness that cannot stop them (killed itself) takes them with it: each is tied to
    the thread that launches it (tied_to_parent), so launch from the thread that outlives
    them (the main thread)."""

    def __init__(self) -> None:
        self._procs: list[subprocess.Popen] = []
        self._logs: list[Any] = []
        self._lock = threading.Lock()
        atexit.register(self.close)

    def launch(self, argv: Sequence[str], log: Path) -> subprocess.Popen:
        """Start argv with stdout and stderr appended to `log`; LinkError if it cannot run."""
        out = open(log, "ab")
        try:
            proc = subprocess.Popen(
                tied_to_parent(argv),
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        except OSError as err:
            out.close()
            raise LinkError(f"cannot start {argv[0]}: {err.strerror or err}") from None
        with self._lock:
            self._procs.append(proc)
            self._logs.append(out)
        return proc

    @property
    def running(self) -> list[subprocess.Popen]:
        with self._lock:
            return [p for p in self._procs if p.poll() is None]

    def stop(self, proc: subprocess.Popen, grace_s: float = STOP_GRACE_S) -> int | None:
        """SIGTERM to its pid, SIGKILL after grace_s; its exit code."""
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(grace_s)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        return proc.returncode

    def close(self) -> None:
        with self._lock:
            procs, self._procs = self._procs, []
            logs, self._logs = self._logs, []
        for proc in reversed(procs):
            self.stop(proc)
        for out in logs:
            out.close()

    def __enter__(self) -> ProcessGroup:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def line_buffered(argv: Sequence[str]) -> list[str]:
    """argv run with a line-buffered stdout when coreutils' stdbuf is there (a firmware's
    printf log is block-buffered into a file otherwise); stdbuf execs, so the pid is kept."""
    stdbuf = shutil.which("stdbuf")
    return [stdbuf, "-oL", *argv] if stdbuf else list(argv)


def tied_to_parent(argv: Sequence[str]) -> list[str]:
    """argv run so that the kernel SIGKILLs it when the thread that started it dies, even
    by SIGKILL (a new session no longer shares the terminal's fate, and a firmware left
    running holds its ports for the next harness). util-linux's setpriv sets the
    parent-death signal and execs, so the pid is kept; argv as is where it is missing."""
    setpriv = shutil.which("setpriv")
    return [setpriv, "--pdeathsig", "KILL", "--", *argv] if setpriv else list(argv)


PR_GET_TIMERSLACK, PR_SET_TIMERSLACK = 30, 29
"""prctl(2) options: a thread's timer slack, which its children inherit through exec."""


@contextlib.contextmanager
def fine_timer_slack(slack_ns: int = 1000) -> Iterator[None]:
    """Children started inside sleep to within slack_ns [ns] of their deadline instead of
    Linux's default 50 us: a lockstep simulator that sleeps each step's remainder (PX4 SIH)
    otherwise falls behind the wall clock by the overshoot, ~1 % at 250 Hz
    (docs/firmware.md, "PX4 SIH"). Where prctl is missing, nothing changes."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        before = libc.prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0)
        changed = before > 0 and libc.prctl(PR_SET_TIMERSLACK, slack_ns, 0, 0, 0) == 0
    except (OSError, AttributeError):
        changed = False
    try:
        yield
    finally:
        if changed:
            libc.prctl(PR_SET_TIMERSLACK, before, 0, 0, 0)


def default_log(name: str) -> Path:
    return Path(os.environ.get("TMPDIR", "/tmp")) / f"perchd-{name}-{os.getpid()}.log"


def ready_line(mocap_uri: str, driver_uri: str) -> str:
    """The one line on stderr that says where to connect (as `perchd sim` prints it)."""
    return f"perchd sim: ready: mocap {mocap_uri} driver {driver_uri}"


class TruthPublisher:
    """Publishes a vehicle's truth as mocap poses at a fixed rate, on the caller's thread."""

    def __init__(
        self,
        vehicle: FirmwareVehicle,
        output: PoseOutput,
        params: MocapParams,
        clock: Clock | None = None,
        body: str = "cf1",
        seed: int = 0,
    ) -> None:
        """params: the simulated mocap's rate and noise (its latency is the publishing's own:
        a truth goes out when it is sampled); body: the rigid body's name; seed of the noise."""
        self.vehicle, self.output, self.params, self.body = vehicle, output, params, body
        self.clock = clock or MonotonicClock()
        self.poses = 0
        self.yaw_range: tuple[float, float] | None = None  # [rad] of the true poses published
        self._rng = random.Random(seed)
        self._sent_t: float | None = None  # [s] stamp of the last truth published

    def pose(self, truth: Truth) -> Pose:
        n = self.params.noise_m
        p = truth.p if n <= 0 else tuple(c + self._rng.gauss(0.0, n) for c in truth.p)
        return Pose(self.body, self.poses + 1, truth.t, p, truth.q)  # type: ignore[arg-type]

    def step(self) -> None:
        """Publish the vehicle's newest truth, unless it was published already: the same
        sample again is no news to a tracker, and a later stamp on it would be a speed the
        vehicle never had."""
        truth = self.vehicle.truth()
        if truth is None or truth.t == self._sent_t:
            return
        self._sent_t = truth.t
        self.output.publish(self.pose(truth))
        self.poses += 1
        yaw = yaw_of(truth.q)
        lo, hi = self.yaw_range or (yaw, yaw)
        self.yaw_range = (min(lo, yaw), max(hi, yaw))

    def run(self, done: threading.Event, until: float | None = None) -> None:
        """Until `done` is set or the clock reaches `until` [s]."""
        period = 1.0 / self.params.rate_hz
        due = self.clock.now()
        while not done.is_set():
            self.step()
            due += period
            now = self.clock.now()
            if until is not None and now >= until:
                return
            if due < now - period:  # fell behind (a stalled process): no burst of stale poses
                due = now
            done.wait(max(0.0, due - now))


def yaw_of(q: Quat) -> float:
    """[rad] Z-Y-X yaw of an (x, y, z, w) quaternion."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def contact_json(c: Contact | None, t0: float) -> dict[str, Any] | None:
    """[s] after t0, [m/s] along the normal, [m] world position."""
    if c is None:
        return None
    return {"t": c.t - t0, "speed": c.speed, "p": list(c.p)}


def wait_or_cancel(event: threading.Event, timeout_s: float, cancel: threading.Event) -> bool:
    """event.wait(timeout_s), but Interrupted as soon as `cancel` is set."""
    deadline = time.monotonic() + timeout_s
    while not event.is_set():
        if cancel.is_set():
            raise Interrupted()
        left = deadline - time.monotonic()
        if left <= 0:
            return False
        event.wait(min(left, 0.05))
    return True
