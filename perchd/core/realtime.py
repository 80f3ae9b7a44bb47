"""Real-time scheduling for the agent's process: SCHED_FIFO, locked memory, a CPU of its own.

On a busy flight PC the normal scheduler shares a core between the control loop and every
other runnable program, so a pose can wait a whole time slice (milliseconds) for the loop to
run; under SCHED_FIFO the loop preempts them all as soon as its pose or deadline arrives
(benchmarks/README.md "Under load"). `apply` puts every thread of the process (and, by
inheritance, every thread and child it starts later) under SCHED_FIFO at one priority, locks
its memory so no page is faulted in mid-tick, and optionally pins it to one CPU. If the
system refuses any part, nothing stays changed and RealtimeRefused says in one line what is
missing (docs/contracts.md §6). Also here: settle_heap, the service's garbage collection
between flights (flight/loop.py keeps the collector off during one).
"""

from __future__ import annotations

import ctypes
import errno
import gc
import os
import resource
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from perchd.core.errors import ConfigError, PerchdError

PRIORITY_MAX = 99
"""Linux's highest SCHED_FIFO priority; kernel threads that must never wait sit at 50 and
above, so a flight loop is usually put at 50 or just below."""
DEFAULT_PRIORITY = 50
"""`perchd fly --realtime` without a value."""
CAP_SYS_NICE = 23
CAP_IPC_LOCK = 14
MCL_CURRENT, MCL_FUTURE = 1, 2


class RealtimeRefused(PerchdError, PermissionError):
    """The system refused real-time scheduling, memory locking or the CPU pin; the message
    names what is missing. The flight does not start (exit code 2, docs/contracts.md §6)."""


@dataclass(frozen=True)
class RealtimeConfig:
    """How the agent's process is scheduled while it flies.

    priority: SCHED_FIFO priority 1..99 for every thread of the process; 0 (the default):
        off, the normal scheduler, and nothing below applies.
    cpu: the CPU number the process is pinned to (sched_setaffinity); -1: any CPU.
    lock_memory: mlockall(MCL_CURRENT | MCL_FUTURE): every page of the process stays in RAM,
        so no tick waits for a page to be read back in (costs RAM: thread stacks are
        locked whole).
    """

    priority: int = 0
    cpu: int = -1
    lock_memory: bool = True

    def __post_init__(self) -> None:
        if not 0 <= self.priority <= PRIORITY_MAX:
            raise ConfigError(
                f"realtime priority {self.priority} is outside 0..{PRIORITY_MAX} (0: off)"
            )
        if self.cpu < -1:
            raise ConfigError(f"realtime cpu {self.cpu}: a CPU number, or -1 for any")

    @property
    def enabled(self) -> bool:
        return self.priority > 0

    def describe(self) -> str:
        """One line for logs: what `apply` grants."""
        if not self.enabled:
            return "normal scheduling"
        parts = [f"SCHED_FIFO priority {self.priority}"]
        parts += ["memory locked"] if self.lock_memory else []
        parts += [f"pinned to CPU {self.cpu}"] if self.cpu >= 0 else []
        return ", ".join(parts)


def apply(cfg: RealtimeConfig) -> None:
    """Grant `cfg` to the whole process, or raise RealtimeRefused with everything undone."""
    if not cfg.enabled:
        return
    if not sys.platform.startswith("linux"):
        raise RealtimeRefused("real-time scheduling (SCHED_FIFO, mlockall) is Linux only")
    undo: list[Callable[[], None]] = []
    try:
        if cfg.cpu >= 0:
            undo.append(_pin(cfg.cpu))
        if cfg.lock_memory:
            undo.append(_lock_memory())
        _fifo(cfg.priority)
    except RealtimeRefused:
        for step in reversed(undo):
            step()
        raise


def _threads() -> list[int]:
    """Thread ids of this process (sched_* calls act on one thread each)."""
    return [int(t) for t in os.listdir("/proc/self/task")]


def _each_thread(call: Callable[[int], None]) -> None:
    for tid in _threads():
        try:
            call(tid)
        except ProcessLookupError:  # the thread ended meanwhile
            pass


def _pin(cpu: int) -> Callable[[], None]:
    allowed = os.sched_getaffinity(0)
    if cpu not in allowed:
        raise RealtimeRefused(
            f"CPU {cpu} is not one this process may run on (allowed: "
            f"{_cpu_list(allowed)}; the unit's CPUAffinity= or taskset)"
        )
    _each_thread(lambda tid: os.sched_setaffinity(tid, {cpu}))
    return lambda: _each_thread(lambda tid: os.sched_setaffinity(tid, allowed))


def _lock_memory() -> Callable[[], None]:
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        err = ctypes.get_errno()
        soft, _ = resource.getrlimit(resource.RLIMIT_MEMLOCK)
        limit = "unlimited" if soft == resource.RLIM_INFINITY else f"{soft // 1024} KiB"
        cap = "" if _has_cap(CAP_IPC_LOCK) else "no CAP_IPC_LOCK, "
        raise RealtimeRefused(
            f"mlockall refused ({errno.errorcode.get(err, err)}): this "
            f"process has {cap}RLIMIT_MEMLOCK {limit}; raise it (ulimit -l "
            "unlimited, the unit's LimitMEMLOCK=infinity) or set "
            "lock_memory = false"
        )
    return lambda: libc.munlockall()


def _fifo(priority: int) -> None:
    before = {tid: (os.sched_getscheduler(tid), os.sched_getparam(tid)) for tid in _threads()}
    try:
        _each_thread(
            lambda tid: os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
        )
    except PermissionError:
        for tid, (policy, param) in before.items():
            try:
                os.sched_setscheduler(tid, policy, param)
            except (ProcessLookupError, PermissionError):
                pass
        raise RealtimeRefused(_fifo_missing(priority)) from None


def _fifo_missing(priority: int) -> str:
    """What stops SCHED_FIFO at `priority`: the capability, the rlimit, or the kernel."""
    soft, _ = resource.getrlimit(resource.RLIMIT_RTPRIO)
    rtprio = "unlimited" if soft == resource.RLIM_INFINITY else str(soft)
    if _has_cap(CAP_SYS_NICE) or (soft != resource.RLIM_INFINITY and soft >= priority):
        return (
            f"SCHED_FIFO priority {priority} refused although this process may ask for "
            f"it (RLIMIT_RTPRIO {rtprio}): the kernel gives its cgroup no real-time "
            "time (cpu.rt_runtime_us), or it runs in a container without it"
        )
    return (
        f"SCHED_FIFO priority {priority} refused: it needs CAP_SYS_NICE or "
        f"RLIMIT_RTPRIO >= {priority}, and this process has no CAP_SYS_NICE and "
        f"RLIMIT_RTPRIO {rtprio} (under systemd: CPUSchedulingPolicy=fifo and "
        f"LimitRTPRIO={priority} in the unit; else ulimit -r {priority} or "
        "setcap cap_sys_nice)"
    )


def _has_cap(bit: int) -> bool:
    """Is capability `bit` in this process's effective set (/proc/self/status CapEff)?"""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("CapEff:"):
                return bool(int(line.split()[1], 16) >> bit & 1)
    except OSError:
        pass
    return False


def _cpu_list(cpus: set[int]) -> str:
    return ",".join(str(c) for c in sorted(cpus))


def below_loop(pid: int) -> None:
    """Put child `pid` (the trigger's planner worker) just below this thread's real-time
    priority: it inherited the loop's SCHED_FIFO priority, and at an equal priority a
    CPU-bound solve would hold its CPU until it finished while the loop waited. One below,
    it still runs before every normal program; at priority 1 it goes back to the normal
    scheduler. Nothing changes when this process is not real-time."""
    if not sys.platform.startswith("linux") or os.sched_getscheduler(0) != os.SCHED_FIFO:
        return
    priority = os.sched_getparam(0).sched_priority
    policy = os.SCHED_FIFO if priority > 1 else os.SCHED_OTHER
    try:
        os.sched_setscheduler(pid, policy, os.sched_param(priority - 1 if priority > 1 else 0))
    except (ProcessLookupError, PermissionError):  # gone already; lowering is always allowed
        pass


def leave_realtime() -> None:
    """Back to the normal scheduler, for a helper process (the live view) that inherited the
    agent's SCHED_FIFO: a niceness means nothing to a real-time thread, and a busy helper
    at the loop's priority would delay it. Lowering needs no privilege."""
    if sys.platform.startswith("linux") and os.sched_getscheduler(0) != os.SCHED_OTHER:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def settle_heap() -> None:
    """Between flights: collect every cycle, then freeze what survives (gc.freeze) so later
    collections never scan the long-lived objects again (modules, the open links)."""
    gc.unfreeze()
    gc.collect()
    gc.freeze()
