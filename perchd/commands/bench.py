"""`perchd bench planner|loop [--load N] [--json]`: timing figures with min/median/p99.

The loop figures are measured by perchd.bench.loop (also `python benchmarks/loop.py`).
--load N measures the same figures twice in one run, without load and with N CPU-bound
processes beside them (perchd.bench.cpuload), which are stopped however the run ends.
"""

from __future__ import annotations

import json
import os
import random
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from perchd.bench import loop as loopbench
from perchd.bench.cpuload import MAX_HOGS, cpu_hogs
from perchd.console.stopping import interruptible
from perchd.core import realtime
from perchd.core.errors import ConfigError
from perchd.flight.loop import spread
from perchd.tau import plan_bound, plan_ipts
from perchd.tau.cases import CASES
from perchd.tau.library import build_library, load_library


def register(sub) -> None:
    parser = sub.add_parser("bench", help="measure planner (and loop) speed")
    bench_sub = parser.add_subparsers(dest="bench", required=True)
    p = bench_sub.add_parser("planner", help="IPTS cold solve time per order, both paper cases")
    p.add_argument(
        "--orders",
        type=int,
        nargs="+",
        default=[3, 5, 7],
        help="IPTS polynomial orders to time (default: 3 5 7)",
    )
    p.add_argument("--repeat", type=int, default=5, help="solves per (case, order) (default: 5)")
    p.add_argument(
        "--replans",
        type=int,
        default=200,
        help="warm replans from each plan library (the first 10 also cold-solved) (default: 200)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON list")
    add_load(p, "the solves (as a flight's planner worker runs under fly --realtime)")
    p.set_defaults(run=measuring(run_planner))
    lp = bench_sub.add_parser(
        "loop",
        help="control loop: 500 Hz jitter, overruns per minute "
        "at 100 and 500 Hz, agent compute, "
        "pose-to-setpoint latency over ZMQ, CPU",
    )
    lp.add_argument(
        "--seconds",
        type=float,
        default=5.0,
        help="[s] length of the 500 Hz run and of each ZMQ mode (default 5; "
        "60 for the overrun figure)",
    )
    lp.add_argument("--json", action="store_true", help="print one JSON object")
    add_load(lp, "the loops, the rig and the agent (perchd fly --realtime)")
    lp.set_defaults(run=measuring(run_loop))


def measuring(work: Callable[[Any], int]) -> Callable[[Any], int]:
    """`work(args)` ended by SIGINT or SIGTERM as on Ctrl-C (perchd.console.stopping): its
    load processes and its agent stopped, one line, exit 130 or 143."""

    def run(args: Any) -> int:
        with interruptible() as caught:
            return work(args)
        caught.say("bench", "nothing measured is printed")
        return caught.exit_code(130)

    return run


def add_load(parser, what: str) -> None:
    """--load N and --realtime[=PRIO] (for `what`)."""
    parser.add_argument(
        "--load",
        type=int,
        default=0,
        metavar="N",
        help="measure without load, then again with N CPU-bound processes "
        "running beside (stopped at the end, Ctrl-C included), and print "
        "the two side by side",
    )
    parser.add_argument(
        "--realtime",
        nargs="?",
        type=int,
        const=realtime.DEFAULT_PRIORITY,
        default=0,
        metavar="PRIO",
        help=f"run {what} under SCHED_FIFO at PRIO (default "
        f"{realtime.DEFAULT_PRIORITY}); the load processes stay at the "
        "normal policy",
    )


def check_load(n: int) -> None:
    if not 0 <= n <= MAX_HOGS:
        raise ConfigError(f"--load {n} is outside 0..{MAX_HOGS} processes")


def percentiles_ms(times_s: list[float]) -> dict:
    """min/median/p99 [ms] of solve times [s] (p99 by nearest rank, as the loop's)."""

    lo, median, p99, _ = spread(times_s)
    return {"min_ms": 1e3 * lo, "median_ms": 1e3 * median, "p99_ms": 1e3 * p99}


def planner_rows(orders: list[int], repeat: int) -> list[dict]:
    """Cold global IPTS solves of both paper cases per order."""

    rows = []
    for case in CASES:
        for order in orders:
            times, plan = [], None
            for _ in range(repeat):
                start = time.perf_counter()
                plan = plan_ipts(
                    case.x0, case.v0, case.tau_s, case.v_contact, case.v_max, case.a_max, order
                )
                times.append(time.perf_counter() - start)
            bound = plan_bound(plan)
            rows.append(
                {
                    "case": case.name,
                    "order": order,
                    "solve": "cold",
                    "duration_s": plan.duration,
                    "v_contact": plan.v_contact,
                    "bound_s": bound,
                    "ratio": plan.duration / bound,
                    **percentiles_ms(times),
                }
            )
    return rows


def replan_rows(states: int, compare: int, seed: int = 1) -> list[dict]:
    """Warm replans from each paper case's order-3 plan library at random trigger states of
    its grid; the first `compare` of them are cold-solved too, for the largest gap [s]."""

    rows = []
    for case, lib in _libraries():
        rng, times, gap, lim = random.Random(seed), [], 0.0, lib.limits
        for n in range(states):
            x0 = rng.uniform(lib.x0s[0], lib.x0s[-1])
            v0 = rng.uniform(lib.v0s[0], lib.v0s[-1])
            start = time.perf_counter()
            warm = lib.replan(x0, v0)
            times.append(time.perf_counter() - start)
            if n < compare:
                cold = plan_ipts(x0, v0, lib.tau_s, lim.v_contact, lim.v_max, lim.a_max, lib.order)
                gap = max(gap, abs(warm.duration - cold.duration))
        rows.append(
            {
                "case": case,
                "order": lib.order,
                "solve": "warm",
                "states": states,
                "max_gap_to_cold_s": gap,
                **percentiles_ms(times),
            }
        )
    return rows


LIBRARY_GRID = ((-3.3, -2.7), (1.3, 1.7), (7, 9))
"""x0 [m], v0 [m/s] ranges and node counts of plans/libraries/case{1,2}-ipts-n3.json."""


def _libraries():
    """(case name, library) for both paper cases: the checkout's plans/libraries files, or,
    where those are not beside the package (an installed copy), the same grid built now."""

    folder = Path(__file__).resolve().parents[2] / "plans" / "libraries"
    for case in CASES:
        path = folder / f"{case.name}-ipts-n3.json"
        if path.exists():
            yield case.name, load_library(path)
            continue
        print(
            f"perchd bench: {path} not found; building {case.name}'s library (63 cold solves)",
            file=sys.stderr,
        )
        yield (
            case.name,
            build_library(*LIBRARY_GRID, case.tau_s, case.v_contact, case.v_max, case.a_max, 3),
        )


def run_planner(args) -> int:
    check_load(args.load)
    realtime.apply(realtime.RealtimeConfig(args.realtime))
    if args.load:
        return planner_under_load(args)
    rows = planner_rows(args.orders, args.repeat)
    warm = replan_rows(args.replans, min(args.replans, 10))
    if args.json:
        print(json.dumps(rows + warm))
        return 0
    print(
        f"{'case':6} {'n':>2} {'duration s':>11} {'ratio':>7} {'min ms':>8} "
        f"{'median ms':>10} {'p99 ms':>8}   (cold global solve)"
    )
    for r in rows:
        print(
            f"{r['case']:6} {r['order']:>2} {r['duration_s']:>11.5f} {r['ratio']:>7.4f} "
            f"{r['min_ms']:>8.1f} {r['median_ms']:>10.1f} {r['p99_ms']:>8.1f}"
        )
    for r in warm:
        print(
            f"{r['case']:6} {r['order']:>2} warm replan from the library, {r['states']} states:"
            f" min {r['min_ms']:.2f} median {r['median_ms']:.2f} p99 {r['p99_ms']:.2f} ms;"
            f" largest gap to a cold solve {r['max_gap_to_cold_s']:.1e} s"
        )
    return 0


def planner_under_load(args) -> int:
    """Cold solves and warm replans without load, then with args.load hogs: medians side
    by side, and the loaded cold median as a multiple of the idle one."""
    planner_rows(args.orders[:1], 1)  # imports and first-call costs out of the idle figures
    load_before = os.getloadavg()[0]
    idle = planner_rows(args.orders, args.repeat) + replan_rows(args.replans, 0)
    with cpu_hogs(args.load):
        busy = planner_rows(args.orders, args.repeat) + replan_rows(args.replans, 0)
        load_during = os.getloadavg()[0]
    rows = [
        {
            **a,
            "loaded_median_ms": b["median_ms"],
            "loaded_p99_ms": b["p99_ms"],
            "ratio_loaded": b["median_ms"] / a["median_ms"],
        }
        for a, b in zip(idle, busy)
    ]
    if args.json:
        print(
            json.dumps(
                {
                    "hogs": args.load,
                    "realtime": args.realtime,
                    "load_before": load_before,
                    "load_during": load_during,
                    "rows": rows,
                }
            )
        )
        return 0
    print(
        f"{args.load} CPU-bound processes beside the loaded run; {os.cpu_count()} cores; load "
        f"average {load_before:.2f} before, {load_during:.2f} loaded; BLAS threads "
        f"{os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}; --realtime: "
        f"{realtime.RealtimeConfig(args.realtime).describe()}"
    )
    print(
        f"{'case':6} {'n':>2} {'solve':5} {'median ms':>10} {'loaded ms':>10} {'x idle':>7}"
        f"   (target for cold solves: x idle <= 3)"
    )
    for r in rows:
        print(
            f"{r['case']:6} {r['order']:>2} {r['solve']:5} {r['median_ms']:>10.2f} "
            f"{r['loaded_median_ms']:>10.2f} {r['ratio_loaded']:>7.2f}"
        )
    return 0


def run_loop(args) -> int:
    if not 0.1 <= args.seconds <= 3600:
        raise ConfigError(f"--seconds {args.seconds:g} is outside 0.1..3600 s")
    check_load(args.load)
    realtime.apply(realtime.RealtimeConfig(args.realtime))
    if args.load:
        figures = loopbench.measure_under_load(args.seconds, args.load, args.realtime)
        print(json.dumps(figures) if args.json else loopbench.load_text(figures))
        return 0
    figures = loopbench.measure(args.seconds, args.realtime)
    print(json.dumps(figures) if args.json else loopbench.text(figures))
    return 0
