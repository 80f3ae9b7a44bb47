"""The controller on vehicles it has never met: the vehicle family (perchd/sim/family.py).

    python benchmarks/family.py [--n N] [--seed S] [--jobs J] [--plan FILE] [--json OUT]

Draws N members (default 2000) and flies each once, on its first flight (no vehicle
profile: no learned hover), on a simulated clock, with the config a lab
would write for it (family.lab_config: its mass and thrust, every gain the default's). The
trigger replans from the measured state (policy "replan", warm from
plans/libraries/<plan's file name> when that library exists) or, for a robust plan, flies
its box. Prints one table: count, contact inside the plan's window (the simulator's
contact speed), perch time within +-3 % of the plan's, unstable endings
(familyrun.UNSTABLE), outcome counts, flights/s; where in its range each parameter of the
misses sits; then the worst ten with their parameters. --json OUT: summary and rows.
Targets: 0 unstable, >= 99 % in the window, >= 95 % on time.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from perchd.campaign.familyrun import PARAMETERS, FamilyRow, fly_member
from perchd.flight.config import FlightConfig, TriggerConfig, TriggerPolicy
from perchd.sim.family import FAMILY, FamilyVehicle, sample
from perchd.tau import load_plan
from perchd.tau.plan import Plan

ROOT = Path(__file__).resolve().parents[1]
PLAN = ROOT / "plans" / "case1-ipts-n3.json"
TARGETS = {"unstable": 0, "in_window_pct": 99.0, "on_time_pct": 95.0}


def base_config(plan_path: Path, plan: Plan) -> FlightConfig:
    """The defaults with the trigger a fixed plan is flown with in a campaign."""
    if plan.robust is not None:
        return FlightConfig(trigger=TriggerConfig(policy=TriggerPolicy.ROBUST))
    library = plan_path.parent / "libraries" / plan_path.name
    return FlightConfig(
        trigger=TriggerConfig(
            policy=TriggerPolicy.REPLAN, library=str(library) if library.exists() else None
        )
    )


def _fly(job: tuple[Plan, FlightConfig, FamilyVehicle, str]) -> FamilyRow:
    plan, base, member, log_dir = job
    return fly_member(plan, member, base, Path(log_dir) / f"member-{member.index:05d}.jsonl")


def fly_all(
    plan: Plan, base: FlightConfig, members: list[FamilyVehicle], jobs: int
) -> Iterator[FamilyRow]:
    """Rows in member order; `jobs` processes fed in chunks."""
    with tempfile.TemporaryDirectory(prefix="perchd-family-") as logs:
        work = [(plan, base, m, logs) for m in members]
        if jobs == 1:
            yield from map(_fly, work)
            return
        chunk = max(1, len(work) // (jobs * 16))
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            yield from pool.map(_fly, work, chunksize=chunk)


def badness(row: FamilyRow) -> tuple[int, float]:
    """Sort key, worst first: unstable, no contact, outside the window (by how far),
    off time (by how much), then the rest by their perch-time error."""
    err = abs(row.perch_error_pct or 0.0)
    if row.unstable:
        return 0, 0.0
    if row.contact_speed is None:
        return 1, 0.0
    if not row.in_window:
        return 2, -max(row.v_lo - row.contact_speed, row.contact_speed - row.v_hi)
    return (4 if row.on_time else 3), -err


def thirds(name: str, rows: list[FamilyRow]) -> dict[str, float | None]:
    """In-window and on-time rates [%] of the members in the lower and the upper third of
    the family's range of `name` (the mass's on its log scale): where the misses gather."""
    span = getattr(FAMILY, name)
    scale = math.log if span.log else float
    lo, hi = scale(span.lo), scale(span.hi)
    place = {id(r): (scale(getattr(r, name)) - lo) / (hi - lo) for r in rows}
    low = [r for r in rows if place[id(r)] < 1 / 3]
    high = [r for r in rows if place[id(r)] > 2 / 3]
    rate = lambda rs, key: 100.0 * sum(getattr(r, key) for r in rs) / len(rs) if rs else None  # noqa: E731
    return {
        "in_window_low": rate(low, "in_window"),
        "in_window_high": rate(high, "in_window"),
        "on_time_low": rate(low, "on_time"),
        "on_time_high": rate(high, "on_time"),
    }


def summarize(rows: list[FamilyRow], wall_s: float) -> dict:
    n = len(rows)
    speeds = [r.contact_speed for r in rows if r.contact_speed is not None]
    errs = sorted(r.perch_error_pct for r in rows if r.perch_error_pct is not None)
    misses = [r for r in rows if not (r.in_window and r.on_time)]
    return {
        "vehicles": n,
        "in_window": sum(r.in_window for r in rows),
        "in_window_pct": 100.0 * sum(r.in_window for r in rows) / n,
        "on_time": sum(r.on_time for r in rows),
        "on_time_pct": 100.0 * sum(r.on_time for r in rows) / n,
        "unstable": sum(r.unstable for r in rows),
        "outcomes": dict(Counter(r.outcome for r in rows).most_common()),
        "contact_speed_mps": _quantiles(sorted(speeds)),
        "perch_error_pct": _quantiles(errs),
        "misses": len(misses),
        "by_third": {p: thirds(p, rows) for p in PARAMETERS},
        "wall_s": wall_s,
        "flights_per_s": n / wall_s if wall_s > 0 else None,
    }


def _quantiles(xs: list[float]) -> dict[str, float] | None:
    """min, p5, median, p95, max of sorted xs (nearest rank)."""
    if not xs:
        return None
    at = lambda q: xs[min(len(xs) - 1, round(q * (len(xs) - 1)))]  # noqa: E731
    return {"min": xs[0], "p5": at(0.05), "median": at(0.5), "p95": at(0.95), "max": xs[-1]}


def print_table(s: dict, worst: list[FamilyRow], out=sys.stdout) -> None:
    def q(d: dict, f: str) -> str:
        return (
            " / ".join(format(d[k], f) for k in ("min", "p5", "median", "p95", "max")) if d else "-"
        )

    print(f"vehicles                       {s['vehicles']}", file=out)
    print(
        f"CONTACT in the window          {s['in_window']} ({s['in_window_pct']:.1f} %, "
        f"target >= {TARGETS['in_window_pct']:g} %)",
        file=out,
    )
    print(
        f"perch time within +-3 %        {s['on_time']} ({s['on_time_pct']:.1f} %, "
        f"target >= {TARGETS['on_time_pct']:g} %)",
        file=out,
    )
    print(f"unstable endings               {s['unstable']} (target 0)", file=out)
    print(
        "outcomes                       " + ", ".join(f"{k} {v}" for k, v in s["outcomes"].items()),
        file=out,
    )
    print(
        f"contact speed [m/s]            {q(s['contact_speed_mps'], '.3f')} "
        "(min / p5 / median / p95 / max)",
        file=out,
    )
    print(f"perch time - plan [%]          {q(s['perch_error_pct'], '+.2f')}", file=out)
    print(
        f"flights/s                      {s['flights_per_s']:.2f} ({s['wall_s']:.0f} s)", file=out
    )
    print(f"misses (outside the window or off time): {s['misses']}", file=out)
    print_thirds(s["by_third"], out)
    print_worst(worst, out)


def print_thirds(by_third: dict, out=sys.stdout) -> None:
    print("rates [%] in the lower / upper third of each range:  in window  |  on time", file=out)
    for name, t in by_third.items():
        cells = [
            _fmt(t[k], ".1f")
            for k in ("in_window_low", "in_window_high", "on_time_low", "on_time_high")
        ]
        print(f"  {name:<18} {cells[0]:>6} / {cells[1]:<6} | {cells[2]:>6} / {cells[3]}", file=out)


def print_worst(worst: list[FamilyRow], out=sys.stdout) -> None:
    heads = ("index", "outcome", "v_contact", "perch_err_pct", *PARAMETERS)
    widths = [max(8, len(h)) for h in heads]
    print("worst ten:", file=out)
    print(" ".join(f"{h:>{w}}" for h, w in zip(heads, widths, strict=True)), file=out)
    for r in worst:
        cells = (
            r.index,
            r.outcome,
            _fmt(r.contact_speed),
            _fmt(r.perch_error_pct),
            *(_fmt(getattr(r, p)) for p in PARAMETERS),
        )
        print(" ".join(f"{c:>{w}}" for c, w in zip(cells, widths, strict=True)), file=out)


def _fmt(v: float | None, spec: str = ".4g") -> str:
    return "-" if v is None else format(v, spec)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2000, help="members flown")
    ap.add_argument("--seed", type=int, default=0, help="the family's draw")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--plan", type=Path, default=PLAN)
    ap.add_argument("--json", type=Path, metavar="OUT", help="write summary and rows here")
    args = ap.parse_args()
    plan = load_plan(args.plan)
    base = base_config(args.plan, plan)
    t0 = time.perf_counter()
    rows = []
    for row in fly_all(plan, base, sample(args.n, args.seed), max(1, args.jobs)):
        rows.append(row)
        if len(rows) % max(1, args.n // 10) == 0:
            print(f"{len(rows)} of {args.n} flown", file=sys.stderr, flush=True)
    s = summarize(rows, time.perf_counter() - t0)
    print_table(s, sorted(rows, key=badness)[:10])
    if args.json:
        args.json.write_text(
            json.dumps(
                {"command": sys.argv, "summary": s, "rows": [dataclasses.asdict(r) for r in rows]},
                indent=1,
            )
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
