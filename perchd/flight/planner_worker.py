"""The trigger's planner off the loop thread: a worker process fed over pipes.

A retarget (perchd.tau.retarget) takes 60-270 ms cold and 2-30 ms from a library on an idle
PC, seconds on a loaded one; the control loop cannot wait for it (docs/architecture.md,
"Planning in flight"). The supervisor talks to a `Planner`: `request` a plan for a trigger
state, `poll` once per tick for the newest reply, never blocking. Two kinds:

- WorkerPlanner: `python -m perchd.flight.planner_worker` as a child process, one JSON line
  per request and per reply on its stdin/stdout (JSON, not pickle: nothing is evaluated,
  docs/safety.md). A thread in another process shares no GIL with the loop. It dies with
  the agent: PR_SET_PDEATHSIG on Linux, and EOF on its stdin everywhere.
- InlinePlanner: the solve in the calling thread, for a simulated clock, where a solve takes
  no simulated time and flights must be reproducible (both are `instant`).

A WorkerPlanner made `instant` is the real worker on a simulated clock: `poll` then waits
for the reply of the request in hand, so the flight is the same one the InlinePlanner flies.
"""

from __future__ import annotations

import json
import math
import os
import select
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from perchd.core.errors import PerchdError, PlanError

# The worker imports the planner (numpy, scipy: seconds on a busy PC) only after it has
# tied its life to the agent's (_die_with_parent).
if TYPE_CHECKING:
    from perchd.tau.plan import Plan

START_TIMEOUT_S = 30.0
"""[s] a worker that has not answered its first line in this long is a failed start."""
CLOSE_GRACE_S = 0.5
"""[s] a worker is given this long to leave after its stdin closes, then it is killed."""


@dataclass(frozen=True, slots=True)
class PlanReply:
    """The answer to request `id` for the trigger state (x0_m [m], v0_mps [m/s]): the plan,
    or None and `error` saying why; solve_s [s] the solve's own time (wall, in the worker)."""

    id: int
    x0_m: float
    v0_mps: float
    plan: Plan | None
    error: str
    solve_s: float


class Planner(Protocol):
    instant: bool
    """True when a reply is there by the next poll (a simulated clock): nothing to wait for."""

    @property
    def ready(self) -> bool:
        """It can take requests now (a worker has loaded); never blocks."""

    def request(self, x0_m: float, v0_mps: float) -> int:
        """Ask for the plan from (x0_m, v0_mps); its id. A newer request supersedes it."""

    def poll(self) -> PlanReply | None:
        """The reply to the newest request once it is in (once), else None; never blocks
        unless `instant`."""

    @property
    def busy(self) -> bool:
        """A request is out and unanswered."""

    def close(self) -> None: ...


def solve(plan: Plan, x0_m: float, v0_mps: float, library: Any) -> tuple[Plan | None, str, float]:
    """(plan, error, solve time [s]) of one retarget; a PlanError is an answer, not a crash."""
    from perchd.tau import retarget

    t0 = time.perf_counter()
    try:
        out, why = retarget(plan, x0_m, v0_mps, library=library), ""
    except PlanError as err:
        out, why = None, str(err)
    return out, why, time.perf_counter() - t0


class InlinePlanner:
    """The solve in the caller's thread; the reply is there at the next poll."""

    instant = True
    ready = True

    def __init__(self, plan: Plan, library: Any = None) -> None:
        self.plan, self.library = plan, library
        self._n = 0
        self._reply: PlanReply | None = None

    def request(self, x0_m: float, v0_mps: float) -> int:
        self._n += 1
        out, why, took = solve(self.plan, x0_m, v0_mps, self.library)
        self._reply = PlanReply(self._n, x0_m, v0_mps, out, why, took)
        return self._n

    def poll(self) -> PlanReply | None:
        reply, self._reply = self._reply, None
        return reply

    @property
    def busy(self) -> bool:
        return self._reply is not None

    def close(self) -> None:
        pass


def plan_to_wire(plan: Plan) -> dict:
    from perchd.tau.planfile import plan_to_json

    return plan_to_json(plan)


def plan_from_wire(doc: dict) -> Plan:
    """A plan the worker made, taken as sent: every float survives JSON exactly (repr), and
    re-deriving its figures (plan_from_json) would cost the loop milliseconds."""
    from perchd.tau.limits import Limits
    from perchd.tau.plan import Peaks, Plan

    lim = doc["limits"]
    stage1 = doc["stage1"]
    robust = doc.get("robust")
    return Plan(
        doc["strategy"],
        doc["x0"],
        doc["v0"],
        doc["tau_s"],
        stage1.get("c"),
        None if "k" not in stage1 else tuple(stage1["k"]),
        doc["t_switch"],
        doc["duration"],
        doc["v_contact"],
        Limits(tuple(lim["v_contact"]), lim["v_max"], lim["a_max"]),
        Peaks(doc["peaks"]["v"], doc["peaks"]["a"]),
        None if robust is None else (tuple(robust["x0"]), tuple(robust["v0"])),
    )


class WorkerPlanner:
    """The real worker process. plan: the flight's plan (what retarget keeps); library: a
    plan library path or None; delay_s [s]: added to every solve (a slow-PC test seam);
    instant: poll waits for the reply in hand (simulated clock). Starting it does not wait:
    it loads (seconds on a busy PC) while the vehicle takes off and holds; `ready` says when
    it has. A worker that died answers every request with why (never an exception in a tick)."""

    def __init__(
        self, plan: Plan, library: str | None = None, *, delay_s: float = 0.0, instant: bool = False
    ) -> None:
        self.instant = instant
        self._n = 0
        self._asked: int | None = None  # id of the newest request not yet answered
        self._up = False  # its start line said it is ready
        self._dead = ""  # why it can answer no more
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "perchd.flight.planner_worker", str(os.getpid())],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            close_fds=True,
        )
        self._lines = _Lines(self.proc.stdout.fileno())
        self._send({"plan": plan_to_wire(plan), "library": library, "delay_s": delay_s})

    @property
    def pid(self) -> int:
        return self.proc.pid

    @property
    def busy(self) -> bool:
        return self._asked is not None

    @property
    def ready(self) -> bool:
        """It has loaded (or died: its requests are then answered at once with why). An
        instant worker (simulated clock) is waited for: loading takes no simulated time."""
        if not (self._up or self._dead):
            self._next(START_TIMEOUT_S if self.instant else 0.0)
        return self._up or bool(self._dead)

    def wait_ready(self, timeout_s: float = START_TIMEOUT_S) -> None:
        """Block until the worker has loaded; PerchdError if it cannot."""
        deadline = time.monotonic() + timeout_s
        while not self.ready and time.monotonic() < deadline:
            self._next(max(0.0, deadline - time.monotonic()))
        if self._dead or not self._up:
            raise PerchdError(f"planner worker did not start: {self._dead or 'no answer'}")

    def request(self, x0_m: float, v0_mps: float) -> int:
        self._n += 1
        self._asked = self._n
        self._send({"id": self._n, "x0": x0_m, "v0": v0_mps})
        return self._n

    def poll(self) -> PlanReply | None:
        while self._asked is not None:
            line = None if self._dead else self._next(START_TIMEOUT_S if self.instant else 0.0)
            if self._dead:
                line = {"id": self._asked, "error": self._dead}
            elif line is None:
                if not self.instant:
                    return None
                self._dead = "planner worker stopped answering"
                continue
            if line.get("id") == self._asked:
                self._asked = None
                return _reply(line)
        return None

    def close(self) -> None:
        """Close its stdin (it leaves), kill it if it has not within CLOSE_GRACE_S, reap it."""
        if self.proc.poll() is None:
            try:
                self.proc.stdin.close()
            except OSError:
                pass
            try:
                self.proc.wait(CLOSE_GRACE_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc.stdout.close()

    def _send(self, doc: dict) -> None:
        try:
            self.proc.stdin.write(json.dumps(doc).encode() + b"\n")
            self.proc.stdin.flush()
        except OSError as err:
            self._dead = self._dead or f"planner worker gone: {err}"

    def _next(self, timeout_s: float) -> dict | None:
        """The next reply line within timeout_s [s], or None; its start line is noted on the
        way, and so is its death."""
        while not self._dead:
            try:
                line = self._lines.line(timeout_s)
            except EOFError:
                self._dead = f"planner worker exited (status {self.proc.poll()})"
                return None
            if line is None or "ready" not in line:
                return line
            self._up = bool(line["ready"])
            self._dead = "" if self._up else f"planner worker: {line.get('error')}"
        return None


def _reply(doc: dict) -> PlanReply:
    plan = None if doc.get("plan") is None else plan_from_wire(doc["plan"])
    return PlanReply(
        doc["id"],
        doc.get("x0", math.nan),
        doc.get("v0", math.nan),
        plan,
        doc.get("error", ""),
        doc.get("solve_s", math.nan),
    )


# --------------------------------------------------------------------------- the worker


def _die_with_parent(parent: int) -> None:
    """SIGKILL this process when the agent dies, however it dies (Linux prctl)."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    PR_SET_PDEATHSIG = 1
    ctypes.CDLL(None).prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(0)


def _emit(doc: dict) -> None:
    sys.stdout.write(json.dumps(doc) + "\n")
    sys.stdout.flush()


class _Lines:
    """JSON lines read from a pipe's descriptor, never more than is there."""

    def __init__(self, fd: int) -> None:
        self.fd, self.buf = fd, b""

    def line(self, timeout_s: float | None = None) -> dict | None:
        """The next line, waiting up to timeout_s [s] (None: for ever; 0: not at all), None
        if none came; EOFError once the other end has closed."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while b"\n" not in self.buf:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            if not select.select([self.fd], [], [], left)[0]:
                return None
            chunk = os.read(self.fd, 1 << 16)
            if not chunk:
                raise EOFError
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        return json.loads(line)

    def newest(self) -> dict:
        """The next line, skipping to the last one already sent: requests that queued up
        while the worker solved are superseded (only the newest is of use to the trigger)."""
        doc = self.line()
        while (nxt := self.line(0.0)) is not None:
            doc = nxt
        return doc


def main(argv: list[str]) -> int:
    """The worker (argv: the agent's pid): one start line (plan, library, delay), then a
    reply per request line, until its stdin closes."""
    _die_with_parent(int(argv[0]))
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a terminal's Ctrl-C is the agent's to handle
    requests = _Lines(sys.stdin.fileno())
    try:
        first = requests.line()
    except EOFError:
        return 0
    from perchd.tau.planfile import plan_from_json

    try:
        plan = plan_from_json(first["plan"])
        library = None
        if first["library"] is not None:
            from perchd.tau.library import load_library

            library = load_library(first["library"])
    except PerchdError as err:
        _emit({"ready": False, "error": str(err)})
        return 1
    solve(plan, plan.x0, plan.v0, library)  # warm: the first solve pays for imports
    _emit({"ready": True, "pid": os.getpid()})
    delay = float(first.get("delay_s", 0.0))
    while True:
        try:
            req = requests.newest()
        except EOFError:  # the agent closed its end, or died
            return 0
        out, why, took = solve(plan, req["x0"], req["v0"], library)
        if delay > 0.0:
            time.sleep(delay)
            took += delay
        _emit(
            {
                "id": req["id"],
                "x0": req["x0"],
                "v0": req["v0"],
                "error": why,
                "solve_s": took,
                "plan": None if out is None else plan_to_wire(out),
            }
        )


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
