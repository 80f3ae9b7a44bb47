"""`perchd plan robust`: find and certify one IPTS k for a box of trigger states (CONTRACTS 2).

Three modes, by what --x0/--v0 give:
  --x0 LO HI --v0 LO HI   the box is given: least worst-case duration k certified over it
  --x0 X --v0 V           a nominal state: the largest certified box holding it
  (neither)               the largest certified box in --search-x0/--search-v0
The plan file is an IPTS plan (CONTRACTS 1) for the nominal state (the box centre unless
given) with "robust": {"x0": [lo, hi], "v0": [lo, hi]} and a "certificate" record.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from perchd.errors import PlanError
from perchd.tau.certify import Box, first_switch, scale_functions

METHOD = ("certify_box: monotone t_s in k0, mean-value enclosures on adaptive k0 x t cells "
          "(perchd/tau/certify.py)")


def register(plan_sub) -> None:
    """Add `robust` to the `perchd plan` subparsers."""
    p = plan_sub.add_parser("robust", help="one IPTS k certified over a box of trigger states")
    p.add_argument("--x0", type=float, nargs="+", metavar="X", help="box LO HI, or nominal [m]")
    p.add_argument("--v0", type=float, nargs="+", metavar="V", help="box LO HI, or nominal [m/s]")
    p.add_argument("--tau-s", type=float, required=True, help="stage switch tau [s] < 0")
    p.add_argument("--v-contact", type=float, nargs=2, required=True, metavar=("LO", "HI"))
    p.add_argument("--v-max", type=float, required=True)
    p.add_argument("--a-max", type=float, required=True)
    p.add_argument("--order", type=int, default=3)
    p.add_argument("--search-x0", type=float, nargs=2, default=(-4.0, -0.5), metavar=("LO", "HI"),
                   help="where boxes are looked for when none is given [m]")
    p.add_argument("--search-v0", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                   help="[m/s], default 0.2 .. v_max")
    p.add_argument("--maxiter", type=int, default=40, help="differential-evolution generations")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--start", metavar="PLAN", help="a lower-order robust plan whose k seeds the search")
    p.add_argument("--out", required=True, help="plan file to write")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)


def limits_from(args):
    from perchd.tau.robust import RobustLimits

    lo, hi = args.v_contact
    checks = [("--tau-s", args.tau_s < 0, f"must be < 0, got {args.tau_s:g}"),
              ("--v-contact", 0 < lo <= hi, f"needs 0 < LO <= HI, got {lo:g} {hi:g}"),
              ("--v-max", args.v_max >= hi, f"{args.v_max:g} is below V_u = {hi:g}"),
              ("--a-max", args.a_max > 0, f"must be > 0, got {args.a_max:g}"),
              ("--order", 1 <= args.order <= 7, f"must be 1..7, got {args.order}")]
    for name, ok, why in checks:
        if not ok:
            raise PlanError(f"{name} {why}")
    return RobustLimits(args.tau_s, (lo, hi), args.v_max, args.a_max)


def _pair(name: str, values, sign: int):
    if values is None:
        return None
    if len(values) not in (1, 2):
        raise PlanError(f"{name} takes LO HI (a box) or one value (a nominal state), got {len(values)}")
    if any(sign * v <= 0 for v in values):
        raise PlanError(f"{name} must be {'< 0' if sign < 0 else '> 0'}, got {values}")
    if len(values) == 2 and not values[0] < values[1]:
        raise PlanError(f"{name} LO must be below HI, got {values[0]:g} {values[1]:g}")
    return tuple(values)


def run(args) -> int:
    from perchd.tau.robust import SearchDomain, fastest_k, largest_box

    lim = limits_from(args)
    x0, v0 = _pair("--x0", args.x0, -1), _pair("--v0", args.v0, +1)
    if (x0 is None) != (v0 is None) or (x0 and len(x0) != len(v0)):
        raise PlanError("--x0 and --v0 go together: both boxes (LO HI) or both nominal values")
    v_search = tuple(args.search_v0) if args.search_v0 else (0.2, args.v_max)
    s_search = tuple(sorted(-x for x in args.search_x0))
    if x0 is not None and len(x0) == 2:
        result, nominal = fastest_k(args.order, Box(x0, v0), lim, seed=args.seed,
                                    maxiter=args.maxiter), None
        mode = "box"
    else:
        nominal = None if x0 is None else (x0[0], v0[0])
        dom = SearchDomain(s_search, v_search, contains=nominal)
        result = largest_box(args.order, lim, dom, seed=args.seed, maxiter=args.maxiter,
                             start=_start(args.start, lim))
        mode = "grow" if nominal else "largest"
    record = plan_record(result, lim, nominal)
    Path(args.out).write_text(json.dumps(record, indent=2) + "\n")
    summary = {"mode": mode, "order": args.order, "k": record["stage1"]["k"][1:],
               "robust": record["robust"], "area": record["certificate"]["area"],
               "duration_worst": record["certificate"]["duration"][1], "out": args.out}
    print(json.dumps(summary) if args.json else _table(summary))
    return 0


def _start(path, lim):
    """A RobustResult from a plan file, to seed a higher-order search."""
    from perchd.tau.robust import RobustResult

    if path is None:
        return None
    try:
        record = json.loads(Path(path).read_text())
    except (OSError, ValueError) as err:
        raise PlanError(f"--start {path}: {err}") from None
    cert = check_record(record)
    box = Box(tuple(record["robust"]["x0"]), tuple(record["robust"]["v0"]))
    return RobustResult(tuple(record["stage1"]["k"][1:]), box, cert)


def _table(s: dict) -> str:
    r = s["robust"]
    return "\n".join([
        f"robust IPTS order {s['order']} ({s['mode']}): k_1..k_n = "
        + ", ".join(f"{k:.6g}" for k in s["k"]),
        f"certified box: x0 {r['x0'][0]:.4f} .. {r['x0'][1]:.4f} m, "
        f"v0 {r['v0'][0]:.4f} .. {r['v0'][1]:.4f} m/s, area {s['area']:.4f} m*m/s",
        f"worst-case duration {s['duration_worst']:.4f} s; written to {s['out']}"])


def _inward(box: Box, digits: int = 4) -> Box:
    """The box with edges rounded inward (a sub-box of a certified box is certified)."""
    f = 10 ** digits
    return Box((math.ceil(box.x0[0] * f) / f, math.floor(box.x0[1] * f) / f),
               (math.ceil(box.v0[0] * f) / f, math.floor(box.v0[1] * f) / f))


def nominal_profile(k, x0: float, v0: float, tau_s: float, n: int = 20001) -> dict:
    """t_switch, duration, v_contact and peaks of the IPTS plan from (x0, v0)."""
    k0 = v0 / x0
    ts, why = first_switch(np.asarray(k, float), k0, tau_s)
    if ts is None:
        raise PlanError(f"tau never reaches tau_s from x0 = {x0:g} m, v0 = {v0:g} m/s ({why})")
    _, f1, f2 = scale_functions(np.asarray(k, float), k0, np.linspace(0.0, ts, n))
    s = -x0
    return {"t_switch": ts, "duration": ts + abs(tau_s), "v_contact": float(s * f1[-1]),
            "peaks": {"v": float(s * f1.max()), "a": float(s * np.abs(f2).max())}}


def plan_record(result, lim, nominal=None) -> dict:
    """The CONTRACTS 1 plan file of a robust result, flown from `nominal` (default: centre)."""
    box = _inward(result.box)
    cert = lim.certify(result.k, box)
    if not cert.certified:
        raise PlanError(f"rounded box lost its certificate: {cert.reason}")
    x0, v0 = nominal or (round(sum(box.x0) / 2, 4), round(sum(box.v0) / 2, 4))
    prof = nominal_profile(result.k, x0, v0, lim.tau_s)
    return {
        "schema": "perchd.plan/1", "strategy": "ipts", "x0": x0, "v0": v0, "tau_s": lim.tau_s,
        "stage1": {"k": [v0 / x0, *result.k]},
        "t_switch": prof["t_switch"], "duration": prof["duration"],
        "v_contact": prof["v_contact"],
        "limits": {"v_contact": list(lim.v_contact), "v_max": lim.v_max, "a_max": lim.a_max},
        "peaks": prof["peaks"],
        "robust": {"x0": list(box.x0), "v0": list(box.v0)},
        "certificate": {"method": METHOD, "area": box.area, "v_peak": cert.bounds["v_peak"],
                        "a_peak": cert.bounds["a_peak"],
                        "v_contact": [float(v) for v in cert.bounds["v_contact"]],
                        "duration": [float(d) for d in cert.duration]},
    }


def check_plan(plan):
    """`check_record` for a loaded Plan object (Plan API attributes: x0, v0, tau_s, k,
    limits, robust)."""
    lim = plan.limits
    return check_record({"x0": plan.x0, "v0": plan.v0, "tau_s": plan.tau_s,
                         "stage1": {"k": list(plan.k)},
                         "robust": {"x0": list(plan.robust[0]), "v0": list(plan.robust[1])},
                         "limits": {"v_contact": list(lim.v_contact), "v_max": lim.v_max,
                                    "a_max": lim.a_max}})


def check_record(record: dict):
    """Re-certify a robust plan file over its whole box (for `perchd plan check`).
    Returns the Certificate; PlanError names the field or the violated limit and state."""
    from perchd.tau.robust import RobustLimits

    try:
        rb, lim_d, k = record["robust"], record["limits"], record["stage1"]["k"]
        box = Box(tuple(map(float, rb["x0"])), tuple(map(float, rb["v0"])))
        lim = RobustLimits(float(record["tau_s"]), tuple(lim_d["v_contact"]),
                           float(lim_d["v_max"]), float(lim_d["a_max"]))
    except (KeyError, TypeError, ValueError) as err:
        raise PlanError(f"robust plan: missing or malformed field {err}") from None
    if not box.x0[0] < box.x0[1] < 0 < box.v0[0] < box.v0[1]:
        raise PlanError(f"robust: box must have x0 lo < hi < 0 < v0 lo < hi, got {rb}")
    if not math.isclose(k[0], record["v0"] / record["x0"], rel_tol=1e-9):
        raise PlanError(f"stage1.k[0] = {k[0]:g} is not v0/x0 = {record['v0'] / record['x0']:g}")
    cert = lim.certify(k[1:], box)
    if not cert.certified:
        raise PlanError(f"robust box not certified: {cert.reason}")
    return cert


def main(argv=None) -> int:
    """`python -m perchd.tau.robust_cli robust ...` until `perchd plan` carries it."""
    from perchd.errors import PerchdError
    import sys

    parser = argparse.ArgumentParser(prog="perchd plan")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except PerchdError as err:
        print(f"perchd plan robust: {err}", file=sys.stderr)
        return err.exit_code


if __name__ == "__main__":
    raise SystemExit(main())
