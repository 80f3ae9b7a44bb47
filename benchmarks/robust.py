"""Robust-plan figures: certification time, and (with --search) the largest certified boxes.

    python benchmarks/robust.py [--json] [--repeat N] [--search] [--maxiter G]

certify: median wall time of certify_box over each plans/robust-*.json box and over the
    paper's Table 2 k-sets (which fail fast), with the number of cells examined.
search: for orders 3, 4, 5 under the experiment's limits (v_max 2.5, a_max 1.4,
    V_c in [0.7, 1.0], tau_s = -0.5, |x0| <= 4 m), the largest certified box, each order
    seeded with the previous one, beside the paper's printed Table 2 areas.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

from perchd.tau.certify import Box
from perchd.tau.robust import RobustLimits, contact_ratio, largest_box

LIM = RobustLimits(-0.5, (0.7, 1.0), 2.5, 1.4)
PLANS = Path(__file__).resolve().parents[1] / "plans"
TABLE2 = {  # order: (k_1..k_n, x0 range, v0 range) as printed
    3: ((-0.60, -0.057, 0.054), (-3.88, -3.73), (1.89, 1.99)),
    4: ((-0.60, 0.15, -0.31, 0.14), (-2.92, -2.0), (1.0, 1.65)),
    5: ((-0.57, 0.13, -0.57, 0.53, -0.14), (-3.43, -2.0), (1.4, 2.15)),
}


def _median_time(fn, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def certify_figures(repeat: int) -> list[dict]:
    rows = []
    cases = [(p.name, json.loads(p.read_text())) for p in sorted(PLANS.glob("robust-*.json"))]
    for name, rec in cases:
        box = Box(tuple(rec["robust"]["x0"]), tuple(rec["robust"]["v0"]))
        sec, cert = _median_time(lambda: LIM.certify(rec["stage1"]["k"][1:], box), repeat)
        rows.append(
            {
                "case": name,
                "area": box.area,
                "certified": cert.certified,
                "cells": cert.cells,
                "median_ms": 1e3 * sec,
            }
        )
    for order, (k, x0, v0) in TABLE2.items():
        box = Box(x0, v0)
        sec, cert = _median_time(lambda: LIM.certify(k, box), repeat)
        rows.append(
            {
                "case": f"paper Table 2 n={order}",
                "area": box.area,
                "certified": cert.certified,
                "verdict": cert.reason,
                "contact_ratio": contact_ratio(box)[0],
                "median_ms": 1e3 * sec,
            }
        )
    return rows


def search_figures(maxiter: int) -> list[dict]:
    rows, prev = [], None
    for order in (3, 4, 5):
        t = time.perf_counter()
        r = largest_box(order, LIM, maxiter=maxiter, start=prev)
        prev = r
        rows.append(
            {
                "order": order,
                "k": r.k,
                "x0": list(r.box.x0),
                "v0": list(r.box.v0),
                "area": r.box.area,
                "paper_area": Box(*TABLE2[order][1:]).area,
                "worst_duration": r.certificate.duration[1],
                "search_s": time.perf_counter() - t,
            }
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--search", action="store_true")
    ap.add_argument("--maxiter", type=int, default=40)
    args = ap.parse_args()
    out = {"certify": certify_figures(args.repeat)}
    if args.search:
        out["search"] = search_figures(args.maxiter)
    if args.json:
        print(json.dumps(out))
        return
    for row in out["certify"]:
        verdict = "certified" if row["certified"] else row.get("verdict", "not certified")
        print(
            f"certify {row['case']:<34} area {row['area']:.4f}  median {row['median_ms']:8.2f} ms  {verdict}"
        )
    for row in out.get("search", []):
        print(
            f"order {row['order']}: area {row['area']:.4f} (paper {row['paper_area']:.3f})  "
            f"x0 {row['x0'][0]:.4f}..{row['x0'][1]:.4f}  v0 {row['v0'][0]:.4f}..{row['v0'][1]:.4f}  "
            f"worst duration {row['worst_duration']:.4f} s  k {', '.join(f'{k:.5g}' for k in row['k'])}"
            f"  ({row['search_s']:.0f} s)"
        )


if __name__ == "__main__":
    main()
