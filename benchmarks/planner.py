"""IPTS cold solve times per order for both paper cases, what each plan reaches, and the
warm replan from the plan libraries: `perchd bench planner` with all orders 2..7 by default.

Run: python benchmarks/planner.py [any `perchd bench planner` option, e.g. --orders 3 5
--repeat 7 --load 3 --json]
"""

from __future__ import annotations

import sys

from perchd.cli import main

DEFAULT_ORDERS = ["--orders", "2", "3", "4", "5", "6", "7"]

if __name__ == "__main__":
    given = sys.argv[1:]
    orders = [] if "--orders" in given else DEFAULT_ORDERS
    raise SystemExit(main(["bench", "planner", *orders, *given]))
