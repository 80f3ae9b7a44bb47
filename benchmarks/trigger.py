"""The control loop at the trigger's replan, with the solve in the tick against in the
planner worker (docs/architecture.md "Planning in flight").

    python benchmarks/trigger.py [--flights N] [--hogs H] [--library] [--json]
    python benchmarks/trigger.py --thread

Each flight is a real-time perch of the simulated vehicle (sim:// on the real clock, in this
process; 1 N per m/s and kg of drag and 20 ms command latency, so the approach ends short of
v0 and the trigger must replan), plan plans/case1-ipts-n3.json, [trigger] policy "replan".
"in the tick": the supervisor given an InlinePlanner, which solves on the loop thread (what
perchd did before the worker); "worker": the default, a planner worker process. Printed per
mode, without and with H CPU-bound processes beside the flight: ticks missed and the longest
tick (compute) from 0.2 s before to 0.5 s after the trigger, the whole flight's overruns and
missed deadlines, and how the trigger got its plan. The load average is printed with them.

--thread: why a process and not a thread: a 100 Hz sleep loop's lateness alone, then with
five cold solves in a thread of the same process (they hold the GIL most of the time).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from perchd.core.clock import MonotonicClock
from perchd.flight.config import FlightConfig, TriggerConfig, TriggerPolicy
from perchd.flight.planner_worker import InlinePlanner
from perchd.logs.flightlog import read_log
from perchd.session import open_session
from perchd.tau import load_plan, retarget
from perchd.tau.library import load_library

ROOT = Path(__file__).resolve().parents[1]
PLAN = ROOT / "plans" / "case1-ipts-n3.json"
LIBRARY = ROOT / "plans" / "libraries" / "case1-ipts-n3.json"
URI = "sim://?drag=1&latency=0.02&noise=0.001"
BEFORE_S, AFTER_S = 0.2, 0.5
"""[s] the window around the trigger the tick figures are taken over."""


@contextlib.contextmanager
def hogs(n: int) -> Iterator[None]:
    """n CPU-bound processes for the duration of the block (stopped by their pids)."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def one_flight(mode: str, library: bool, log: Path) -> dict:
    plan = load_plan(PLAN)
    cfg = FlightConfig(
        trigger=TriggerConfig(TriggerPolicy.REPLAN, library=str(LIBRARY) if library else None)
    )
    planner = (
        InlinePlanner(plan, load_library(LIBRARY) if library else None)
        if mode == "in the tick"
        else None
    )
    res = open_session(URI, clock=MonotonicClock()).fly(plan, log, cfg, planner=planner)
    return {
        "outcome": res.outcome.name,
        **trigger_window(read_log(log), 0.01),
        "overruns": res.loop.overruns,
        "missed": res.loop.missed,
        "action": res.trigger.action.split(":")[0] if res.trigger else res.detail[:60],
    }


def trigger_window(log, period: float) -> dict:
    """Ticks missed and the longest tick [ms] around the trigger (its first event)."""
    t = next(
        (e.t for e in log.events if e.kind in ("stage1", "trigger-wait", "end") and e.t > 0), None
    )
    # A row carries the tick before it's compute time (the loop's `last`), and a tick held
    # up shows as a jump in k: the first row past the window is in it too.
    later = [r for r in log.rows if r.t > t + AFTER_S][:1]
    rows = [r for r in log.rows if t - BEFORE_S <= r.t <= t + AFTER_S] + later
    missed = sum(b.k - a.k - 1 for a, b in zip(rows, rows[1:]))
    return {"trigger_missed": missed, "trigger_longest_ms": 1e3 * max(r.compute_s for r in rows)}


def run(flights: int, n_hogs: int, library: bool) -> list[dict]:
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for load in (0, n_hogs):
            with hogs(load):
                for mode in ("in the tick", "worker"):
                    for i in range(flights):
                        row = one_flight(mode, library, Path(tmp) / f"{mode}-{load}-{i}.jsonl")
                        out.append(
                            {"mode": mode, "hogs": load, "loadavg": os.getloadavg()[0], **row}
                        )
    return out


def lateness(period: float, stop: threading.Event | None, seconds: float = 2.0) -> list[float]:
    """[s] how late each tick of a `period` sleep loop woke, until `stop` (or `seconds`)."""
    late, t0, k = [], time.perf_counter(), 0
    while (not stop.is_set()) if stop else time.perf_counter() - t0 < seconds:
        k += 1
        due = t0 + k * period
        while (left := due - time.perf_counter()) > 0:
            time.sleep(left)
        late.append(time.perf_counter() - due)
    return sorted(late)


def thread_figure() -> None:
    plan = load_plan(PLAN)
    retarget(plan, -3.0, 1.45)  # imports and first-call costs out of the way
    done = threading.Event()

    def solve() -> None:
        for v in (1.40, 1.42, 1.44, 1.46, 1.48):
            retarget(plan, -3.0, v)
        done.set()

    alone = lateness(0.01, None)
    worker = threading.Thread(target=solve)
    worker.start()
    shared = lateness(0.01, done)
    worker.join()
    for name, late in (("100 Hz loop alone", alone), ("with a solver thread", shared)):
        n = len(late)
        print(
            f"{name:<22} ticks {n:4d}  lateness median {1e3 * late[n // 2]:6.2f} ms  "
            f"p99 {1e3 * late[int(0.99 * n)]:6.2f} ms  max {1e3 * late[-1]:6.2f} ms  "
            f"later than a period: {sum(x > 0.01 for x in late)}"
        )
    print(f"load average {os.getloadavg()[0]:.2f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--flights", type=int, default=3, help="flights per mode and load (3)")
    ap.add_argument("--hogs", type=int, default=3, help="CPU-bound processes beside (3)")
    ap.add_argument("--library", action="store_true", help="replan from the plan library")
    ap.add_argument("--json", action="store_true", help="one JSON object per flight")
    ap.add_argument(
        "--thread",
        action="store_true",
        help="only the loop's lateness beside a solver thread in its process",
    )
    args = ap.parse_args(argv)
    if args.thread:
        thread_figure()
        return 0
    rows = run(args.flights, args.hogs, args.library)
    if args.json:
        for row in rows:
            print(json.dumps(row))
        return 0
    print(
        f"{'mode':<12} {'hogs':>4} {'load':>5} {'missed@trig':>11} {'longest ms':>10} "
        f"{'overruns':>8} {'missed':>6}  outcome / plan"
    )
    for r in rows:
        print(
            f"{r['mode']:<12} {r['hogs']:>4} {r['loadavg']:>5.2f} {r['trigger_missed']:>11} "
            f"{r['trigger_longest_ms']:>10.1f} {r['overruns']:>8} {r['missed']:>6}  "
            f"{r['outcome']} / {r['action']}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
