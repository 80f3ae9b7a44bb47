"""`perchd plan robust`: find and certify one IPTS k for a box of trigger states (docs/contracts.md §2).

Three modes, by what --x0/--v0 give:
  --x0 LO HI --v0 LO HI   the box is given: least worst-case duration k certified over it
  --x0 X --v0 V           a nominal state: the largest certified box holding it
  (neither)               the largest certified box in --search-x0/--search-v0
The plan file is an IPTS plan (docs/contracts.md §1) for the nominal state (the box centre unless
given) with "robust": {"x0": [lo, hi], "v0": [lo, hi]} and a "certificate" record. On a
terminal, stderr shows the search's generations so far; elsewhere nothing.
"""

from __future__ import annotations

import json
from pathlib import Path

from perchd.commands.plan import flags
from perchd.console.argcheck import numbers_as_values
from perchd.console.progress import Progress
from perchd.core.errors import PlanError
from perchd.core.safefile import check_output, write_text
from perchd.tau.certify import Box
from perchd.tau.planfile import load_plan, plan_text
from perchd.tau.robust import (
    RobustLimits,
    RobustResult,
    SearchDomain,
    fastest_k,
    largest_box,
)
from perchd.tau.robustplan import certified_plan, check_plan


def register(plan_sub) -> None:
    """Add `robust` to the `perchd plan` subparsers."""
    p = numbers_as_values(
        plan_sub.add_parser("robust", help="one IPTS k certified over a box of trigger states")
    )
    p.add_argument("--x0", type=float, nargs="+", metavar="X", help="box LO HI, or nominal [m]")
    p.add_argument("--v0", type=float, nargs="+", metavar="V", help="box LO HI, or nominal [m/s]")
    flags.stage_two(p)
    p.add_argument("--v-max", type=float, required=True, help="peak closing speed limit [m/s]")
    p.add_argument("--a-max", type=float, required=True, help="peak |acceleration| limit [m/s^2]")
    p.add_argument("--order", type=int, default=3, help="polynomial order (default: 3)")
    p.add_argument(
        "--search-x0",
        type=float,
        nargs=2,
        default=(-4.0, -0.5),
        metavar=("LO", "HI"),
        help="where boxes are looked for when none is given [m] (default: -4 -0.5)",
    )
    p.add_argument(
        "--search-v0",
        type=float,
        nargs=2,
        default=None,
        metavar=("LO", "HI"),
        help="[m/s], default 0.2 .. v_max",
    )
    p.add_argument(
        "--maxiter", type=int, default=40, help="differential-evolution generations (default: 40)"
    )
    p.add_argument("--seed", type=int, default=0, help="search random seed (default: 0)")
    p.add_argument(
        "--start",
        metavar="PLAN",
        help="a robust plan of order <= --order whose k seeds the search (every mode)",
    )
    flags.written_file(p, "plan")
    p.set_defaults(run=run)


def limits_from(args):

    lo, hi = args.v_contact
    checks = [
        ("--tau-s", args.tau_s < 0, f"must be < 0, got {args.tau_s:g}"),
        ("--v-contact", 0 < lo <= hi, f"needs 0 < LO <= HI, got {lo:g} {hi:g}"),
        ("--v-max", args.v_max >= hi, f"{args.v_max:g} is below V_u = {hi:g}"),
        ("--a-max", args.a_max > 0, f"must be > 0, got {args.a_max:g}"),
        ("--order", 1 <= args.order <= 7, f"must be 1..7, got {args.order}"),
    ]
    for name, ok, why in checks:
        if not ok:
            raise PlanError(f"{name} {why}")
    return RobustLimits(args.tau_s, (lo, hi), args.v_max, args.a_max)


def _pair(name: str, values, sign: int):
    if values is None:
        return None
    if len(values) not in (1, 2):
        raise PlanError(
            f"{name} takes LO HI (a box) or one value (a nominal state), got {len(values)}"
        )
    if any(sign * v <= 0 for v in values):
        raise PlanError(f"{name} must be {'< 0' if sign < 0 else '> 0'}, got {values}")
    if len(values) == 2 and not values[0] < values[1]:
        raise PlanError(f"{name} LO must be below HI, got {values[0]:g} {values[1]:g}")
    return tuple(values)


def run(args) -> int:

    lim = limits_from(args)
    check_output(args.out, "--out", args.force, inputs=(args.start,) if args.start else ())
    x0, v0 = _pair("--x0", args.x0, -1), _pair("--v0", args.v0, +1)
    if (x0 is None) != (v0 is None) or (x0 and len(x0) != len(v0)):
        raise PlanError("--x0 and --v0 go together: both boxes (LO HI) or both nominal values")
    v_search = tuple(args.search_v0) if args.search_v0 else (0.2, args.v_max)
    s_search = tuple(sorted(-x for x in args.search_x0))
    start = _start(args.start, args.order)
    progress = Progress(args.maxiter, "generations", "plan robust", lines=False)
    try:
        if x0 is not None and len(x0) == 2:
            result, nominal = (
                fastest_k(
                    args.order,
                    Box(x0, v0),
                    lim,
                    seed=args.seed,
                    maxiter=args.maxiter,
                    start=None if start is None else start.k,
                    progress=progress.at,
                ),
                None,
            )
            mode = "box"
        else:
            nominal = None if x0 is None else (x0[0], v0[0])
            dom = SearchDomain(s_search, v_search, contains=nominal)
            result = largest_box(
                args.order,
                lim,
                dom,
                seed=args.seed,
                maxiter=args.maxiter,
                start=start,
                progress=progress.at,
            )
            mode = "grow" if nominal else "largest"
    finally:
        progress.close()

    plan = certified_plan(result, lim, nominal)
    write_text(Path(args.out), plan_text(plan), "--out", args.force)
    cert = plan.extra["certificate"]
    summary = {
        "mode": mode,
        "order": args.order,
        "k": list(plan.k[1:]),
        "robust": {"x0": list(plan.robust[0]), "v0": list(plan.robust[1])},
        "area": cert["area"],
        "duration_worst": cert["duration"][1],
        "out": args.out,
    }
    print(json.dumps(summary) if args.json else _table(summary))
    return 0


def _start(path: str | None, order: int) -> RobustResult | None:
    """A RobustResult from a robust plan file of order `order` at most, to seed the search.
    Every mode takes it: its k (padded with zeros) seeds the k search, and where boxes are
    searched (no box given) its box is one candidate too."""

    if path is None:
        return None
    plan = load_plan(path)
    if plan.robust is None or plan.k is None:
        raise PlanError(f"--start {path}: not a robust plan (no robust box)")
    if len(plan.k) - 1 > order:
        raise PlanError(
            f"--start {path}: an order-{len(plan.k) - 1} plan cannot seed --order {order}"
        )
    return RobustResult(tuple(plan.k[1:]), Box(*plan.robust), check_plan(plan))


def _table(s: dict) -> str:
    r = s["robust"]
    return "\n".join(
        [
            f"robust IPTS order {s['order']} ({s['mode']}): k_1..k_n = "
            + ", ".join(f"{k:.6g}" for k in s["k"]),
            f"certified box: x0 {r['x0'][0]:.4f} .. {r['x0'][1]:.4f} m, "
            f"v0 {r['v0'][0]:.4f} .. {r['v0'][1]:.4f} m/s, area {s['area']:.4f} m*m/s",
            f"worst-case duration {s['duration_worst']:.4f} s; written to {s['out']}",
        ]
    )
