"""`perchd plan ctds|ctdts|ipts|robust|library|check` (docs/contracts.md §2)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from perchd.commands.plan.library import check_library
from perchd.commands.plan.library import register as register_library
from perchd.commands.plan.robust import register as register_robust
from perchd.console.argcheck import numbers_as_values, within
from perchd.console.outputs import draw
from perchd.core.errors import PlanError
from perchd.core.safefile import check_output, read_regular, write_text
from perchd.logs.planplot import plot_plan
from perchd.tau import load_plan, plan_ctds, plan_ctdts, plan_ipts, report
from perchd.tau.ipts import MAX_ORDER, UNBOUNDED
from perchd.tau.library import SCHEMA as LIBRARY_SCHEMA
from perchd.tau.planfile import plan_text


def register(sub) -> None:
    parser = sub.add_parser("plan", help="make, check and plot tau perching plans")
    plan_sub = parser.add_subparsers(dest="strategy", required=True)
    _ctds(plan_sub)
    _ctdts(plan_sub)
    _ipts(plan_sub)

    register_robust(plan_sub)

    register_library(plan_sub)
    check = plan_sub.add_parser("check", help="re-derive and verify a plan file or plan library")
    check.add_argument("file", help="a plan (perchd.plan/1) or a plan library (perchd.planlib/1)")
    check.add_argument("--json", action="store_true", help="print one JSON object")
    check.add_argument(
        "--plot",
        metavar="FILE.png",
        help="draw X, V, A and tau against time into this new image (its directory must exist)",
    )
    check.add_argument("--force", action="store_true", help="overwrite an existing --plot file")
    check.set_defaults(run=run_check)


def _common(p: argparse.ArgumentParser) -> None:
    numbers_as_values(p)
    p.add_argument("--x0", type=float, required=True, help="gap at trigger [m], < 0")
    p.add_argument("--v0", type=float, required=True, help="closing speed at trigger [m/s] > 0")
    p.add_argument("--out", help="plan file to write (default: none); its directory must exist")
    p.add_argument("--force", action="store_true", help="overwrite an existing --out file")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _limit_args(p: argparse.ArgumentParser, searched: bool) -> None:
    """--v-max and --a-max; unset means unconstrained, which the help and the run both say."""
    for flag, what, unit in (
        ("--v-max", "peak closing speed", "m/s"),
        ("--a-max", "peak |acceleration|", "m/s^2"),
    ):
        as_ = f", searched as {UNBOUNDED:g} {unit}" if searched else ""
        p.add_argument(flag, type=float, help=f"{what} limit [{unit}] (default: none{as_})")


def _ctds(plan_sub) -> None:
    p = plan_sub.add_parser("ctds", help="constant tau-dot: zero contact speed")
    _common(p)
    p.add_argument("--c", type=float, default=0.5, help="tau-dot in (0, 0.5] (default: 0.5)")
    p.set_defaults(run=lambda a: _make(a, _plan_ctds))


def _ctdts(plan_sub) -> None:
    p = plan_sub.add_parser("ctdts", help="constant tau-dot, then constant speed")
    _common(p)
    p.add_argument("--tau-s", type=float, required=True, help="stage switch tau [s] < 0")
    p.add_argument("--v-contact", type=float, required=True, help="contact speed [m/s]")
    p.add_argument(
        "--v-window",
        type=float,
        nargs=2,
        metavar=("LO", "HI"),
        help="contact speeds the vehicle tolerates [m/s] (default: V_c only)",
    )
    _limit_args(p, searched=False)
    p.set_defaults(run=lambda a: _make(a, _plan_ctdts))


def _ipts(plan_sub) -> None:
    p = plan_sub.add_parser("ipts", help="inverse polynomial, minimum time, then constant speed")
    _common(p)
    p.add_argument("--tau-s", type=float, required=True, help="stage switch tau [s] < 0")
    p.add_argument(
        "--v-contact",
        type=float,
        nargs=2,
        required=True,
        metavar=("LO", "HI"),
        help="contact speeds allowed [m/s], V_l <= V_u",
    )
    _limit_args(p, searched=True)
    p.add_argument(
        "--order", type=int, default=3, help=f"polynomial order 1..{MAX_ORDER} (default: 3)"
    )
    p.set_defaults(run=lambda a: _make(a, _plan_ipts))


def _note_unset_limits(a, searched: bool) -> None:
    """Say on stderr (stdout stays the plan or its JSON) which limits were left unset."""
    for name, unit in (("v_max", "m/s"), ("a_max", "m/s^2")):
        if getattr(a, name) is None:
            as_ = f" (searched as {UNBOUNDED:g} {unit})" if searched else ""
            print(
                f"perchd plan: note: no --{name.replace('_', '-')} given: {name} is "
                f"unconstrained{as_}",
                file=sys.stderr,
            )


def _plan_ctds(a):

    return plan_ctds(a.x0, a.v0, a.c)


def _plan_ctdts(a):

    plan = plan_ctdts(a.x0, a.v0, a.tau_s, a.v_contact, a.a_max, a.v_max, a.v_window)
    _note_unset_limits(a, searched=False)  # after planning: an error stays one line
    return plan


def _plan_ipts(a):

    plan = plan_ipts(a.x0, a.v0, a.tau_s, tuple(a.v_contact), a.v_max, a.a_max, a.order)
    _note_unset_limits(a, searched=True)  # after planning: an error stays one line
    return plan


MAX_METRES = 1000.0  # [m] largest |gap| planned for; larger is a typo, not a perch
MAX_SPEED = 1000.0  # [m/s], [m/s^2] and [s]: the same sanity bound on the other inputs


def check_numbers(a) -> None:
    """Every numeric flag finite and of sane size, before numpy sees it (1e308 overflowed there)."""
    within("--x0", a.x0, -MAX_METRES, MAX_METRES, "m", PlanError)
    within("--v0", a.v0, -MAX_SPEED, MAX_SPEED, "m/s", PlanError)
    for flag, unit in (
        ("tau_s", "s"),
        ("v_contact", "m/s"),
        ("v_window", "m/s"),
        ("c", ""),
        ("v_max", "m/s"),
        ("a_max", "m/s^2"),
    ):
        within(
            "--" + flag.replace("_", "-"),
            getattr(a, flag, None),
            -MAX_SPEED,
            MAX_SPEED,
            unit,
            PlanError,
        )


def _make(args, planner) -> int:
    """Check the numbers and --out before planning (nothing is destroyed), then plan."""
    check_numbers(args)
    if args.out:
        check_output(args.out, "--out", args.force)
    with np.errstate(all="ignore"):  # overflow is handled as infeasible; no warning line
        plan = planner(args)
    return _emit(args, plan)


def _emit(args, plan) -> int:
    if args.out:
        write_text(Path(args.out), plan_text(plan), "--out", args.force)
        print(f"perchd plan: wrote {args.out}", file=sys.stderr)
    rep = report(plan)
    print(json.dumps(rep.to_json()) if args.json else table(rep, plan))
    return 0 if rep.feasible else 1


def run_check(args) -> int:
    """A plan file verified (docs/contracts.md §1), or a plan library, every node of it."""
    text = read_regular(args.file, "", PlanError)
    if _schema(text) == LIBRARY_SCHEMA:
        if args.plot:
            raise PlanError(f"--plot {args.plot}: draws one plan; {args.file} is a plan library")
        return check_library(args.file, text, args.json)
    if args.plot:
        check_output(args.plot, "--plot", args.force, inputs=(args.file,))
    plan = load_plan(args.file, text)
    if args.plot:
        draw(lambda p, path: plot_plan(p, path, args.force), plan, args.plot, "--plot")
    return _emit(argparse.Namespace(out=None, json=args.json), plan)


def _schema(text: str) -> object:
    """The document's "schema" (None when it is not a JSON object: the loader says why)."""
    try:
        doc = json.loads(text)
    except (ValueError, RecursionError):
        return None
    return doc.get("schema") if isinstance(doc, dict) else None


def table(rep, plan) -> str:
    params = (
        f"c = {plan.c:.4f}"
        if plan.c is not None
        else "k = (" + ", ".join(f"{k:.4f}" for k in plan.k) + ")"
    )
    rows = [
        ("strategy", f"{rep.strategy}{'' if rep.order is None else f' n={rep.order}'}"),
        ("trigger", f"x0 = {rep.x0:g} m, v0 = {rep.v0:g} m/s"),
        ("stage 1", params),
        (
            "switch",
            "-" if rep.tau_s is None else f"tau_s = {rep.tau_s:g} s at t = {rep.t_switch:.4f} s",
        ),
        ("duration", f"{rep.duration:.4f} s"),
        ("contact speed", f"{rep.v_contact:.4f} m/s"),
        ("peak speed", f"{rep.v_peak:.4f} m/s"),
        ("peak |accel|", f"{rep.a_peak:.4f} m/s^2"),
        ("lower bound", f"{rep.bound:.4f} s (ratio {rep.ratio:.4f})"),
        (
            "robust box",
            "-"
            if rep.robust is None
            else f"x0 {rep.robust['x0']} m, v0 {rep.robust['v0']} m/s (certified)"
            if rep.feasible
            else "NOT certified",
        ),
        ("feasible", "yes" if rep.feasible else "NO: " + "; ".join(rep.violations)),
    ]
    return "\n".join(f"{k:>14}  {v}" for k, v in rows)
