"""IPTS cold solve times per order for both paper cases, what each plan reaches, and the
warm replan from the plan libraries: the same figures as `perchd bench planner`, with all
orders 2..7 by default.

Run: python benchmarks/planner.py [--repeat N] [--orders 2 3 4 5 6 7] [--replans N] [--json]
"""

from __future__ import annotations

import argparse

from perchd.commands.bench import run_planner


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--orders", type=int, nargs="+", default=[2, 3, 4, 5, 6, 7])
    ap.add_argument("--replans", type=int, default=200)
    ap.add_argument("--json", action="store_true")
    return run_planner(ap.parse_args())


if __name__ == "__main__":
    raise SystemExit(main())
