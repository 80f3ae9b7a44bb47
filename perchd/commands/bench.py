"""`perchd bench planner|loop [--json]`: timing figures with min/median/p99 (issue 7).

The loop figures are measured by perchd.loopbench (also `python benchmarks/loop.py`).
"""

from __future__ import annotations

import json
import statistics
import time


def register(sub) -> None:
    parser = sub.add_parser("bench", help="measure planner (and loop) speed")
    bench_sub = parser.add_subparsers(dest="bench", required=True)
    p = bench_sub.add_parser("planner", help="IPTS cold solve time per order, both paper cases")
    p.add_argument("--orders", type=int, nargs="+", default=[3, 5, 7])
    p.add_argument("--repeat", type=int, default=5, help="solves per (case, order)")
    p.add_argument("--json", action="store_true", help="print one JSON list")
    p.set_defaults(run=run_planner)
    lp = bench_sub.add_parser("loop", help="control loop: 500 Hz jitter, agent compute, "
                                            "pose-to-setpoint latency over ZMQ, CPU")
    lp.add_argument("--seconds", type=float, default=5.0,
                    help="[s] length of the 500 Hz run and of each ZMQ mode (default 5; "
                         "60 for the issue's overrun figure)")
    lp.add_argument("--json", action="store_true", help="print one JSON object")
    lp.set_defaults(run=run_loop)


def percentiles_ms(times_s: list[float]) -> dict:
    """min/median/p99 [ms] of solve times [s] (p99 by nearest rank)."""
    ordered = sorted(times_s)
    p99 = ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]
    return {"min_ms": 1e3 * ordered[0], "median_ms": 1e3 * statistics.median(ordered),
            "p99_ms": 1e3 * p99}


def planner_rows(orders: list[int], repeat: int) -> list[dict]:
    from perchd.tau import plan_bound, plan_ipts
    from perchd.tau.cases import CASES

    rows = []
    for case in CASES:
        for order in orders:
            times, plan = [], None
            for _ in range(repeat):
                start = time.perf_counter()
                plan = plan_ipts(case.x0, case.v0, case.tau_s, case.v_contact, case.v_max,
                                 case.a_max, order)
                times.append(time.perf_counter() - start)
            bound = plan_bound(plan)
            rows.append({"case": case.name, "order": order, "duration_s": plan.duration,
                         "ratio": plan.duration / bound, **percentiles_ms(times)})
    return rows


def run_planner(args) -> int:
    rows = planner_rows(args.orders, args.repeat)
    if args.json:
        print(json.dumps(rows))
        return 0
    print(f"{'case':6} {'n':>2} {'duration s':>11} {'ratio':>7} {'min ms':>8} "
          f"{'median ms':>10} {'p99 ms':>8}")
    for r in rows:
        print(f"{r['case']:6} {r['order']:>2} {r['duration_s']:>11.5f} {r['ratio']:>7.4f} "
              f"{r['min_ms']:>8.1f} {r['median_ms']:>10.1f} {r['p99_ms']:>8.1f}")
    return 0


def run_loop(args) -> int:
    from perchd.errors import ConfigError
    from perchd import loopbench
    if not 0.1 <= args.seconds <= 3600:
        raise ConfigError(f"--seconds {args.seconds:g} is outside 0.1..3600 s")
    figures = loopbench.measure(args.seconds)
    print(json.dumps(figures) if args.json else loopbench.text(figures))
    return 0
