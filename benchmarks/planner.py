"""Median cold solve time of IPTS per order for both paper cases, and what each plan reaches.

Run: python benchmarks/planner.py [--repeat N] [--orders 2 3 4 5 6 7] [--json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

from perchd.tau import plan_bound, plan_ipts
from perchd.tau.cases import CASES


def measure(case, order: int, repeat: int) -> dict:
    times, plan = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        plan = plan_ipts(case.x0, case.v0, case.tau_s, case.v_contact, case.v_max,
                         case.a_max, order)
        times.append(time.perf_counter() - start)
    bound = plan_bound(plan)
    return {"case": case.name, "order": order, "duration": plan.duration,
            "v_contact": plan.v_contact, "bound": bound, "ratio": plan.duration / bound,
            "min_ms": 1e3 * min(times), "median_ms": 1e3 * statistics.median(times),
            "max_ms": 1e3 * max(times)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--orders", type=int, nargs="+", default=[2, 3, 4, 5, 6, 7])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = [measure(c, n, args.repeat) for c in CASES for n in args.orders]
    if args.json:
        print(json.dumps(rows))
        return
    print(f"{'case':6} {'n':>2} {'duration s':>11} {'V_c':>6} {'ratio':>7} "
          f"{'min ms':>8} {'median ms':>10} {'max ms':>8}")
    for r in rows:
        print(f"{r['case']:6} {r['order']:>2} {r['duration']:>11.5f} {r['v_contact']:>6.3f} "
              f"{r['ratio']:>7.4f} {r['min_ms']:>8.1f} {r['median_ms']:>10.1f} {r['max_ms']:>8.1f}")


if __name__ == "__main__":
    main()
