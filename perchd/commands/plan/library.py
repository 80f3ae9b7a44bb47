"""`perchd plan library`: precompute minimum-time IPTS plans over a grid of trigger states
into one file, so a flight can replan at its trigger within one control tick. On a terminal,
stderr shows the nodes planned so far (docs/contracts.md §2); elsewhere nothing.

    perchd plan library --x0 -3.5 -2.5 --v0 1.2 1.8 --nodes 11 13 --tau-s -0.5 \\
        --v-contact 0.7 1.0 --v-max 2.5 --a-max 1.4 --order 3 --out L.json
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from perchd.commands.plan import flags
from perchd.console.argcheck import numbers_as_values
from perchd.console.progress import Progress
from perchd.core.safefile import check_output, write_text
from perchd.tau import report
from perchd.tau.library import SCHEMA, build_library, library_from_json, library_text
from perchd.tau.plan import make_plan
from perchd.tau.planfile import load_json


def register(plan_sub) -> None:
    """Add `library` to the `perchd plan` subparsers."""
    p = numbers_as_values(
        plan_sub.add_parser("library", help="IPTS plans over a grid of trigger states, one file")
    )
    p.add_argument(
        "--x0",
        type=float,
        nargs=2,
        required=True,
        metavar=("LO", "HI"),
        help="trigger gaps the grid spans [m], < 0",
    )
    p.add_argument(
        "--v0",
        type=float,
        nargs=2,
        required=True,
        metavar=("LO", "HI"),
        help="trigger closing speeds the grid spans [m/s], > 0",
    )
    p.add_argument(
        "--nodes",
        type=int,
        nargs=2,
        default=(11, 13),
        metavar=("NX", "NV"),
        help="grid nodes along x0 and v0 (default 11 13)",
    )
    flags.stage_two(p)
    p.add_argument(
        "--v-max",
        type=float,
        help="peak closing speed limit [m/s] (default: none, searched as 1000 m/s)",
    )
    p.add_argument(
        "--a-max",
        type=float,
        help="peak |acceleration| limit [m/s^2] (default: none, searched as 1000 m/s^2)",
    )
    p.add_argument("--order", type=int, default=3, help="polynomial order 1..9 (default: 3)")
    flags.written_file(p, "library")
    p.set_defaults(run=run)


def run(a) -> int:

    check_output(a.out, "--out", a.force)  # before minutes of planning
    start = time.perf_counter()
    progress = Progress(a.nodes[0] * a.nodes[1], "nodes", "plan library", lines=False)
    try:
        lib = build_library(
            tuple(a.x0),
            tuple(a.v0),
            tuple(a.nodes),
            a.tau_s,
            tuple(a.v_contact),
            a.v_max,
            a.a_max,
            a.order,
            progress=progress.at,
        )
    finally:
        progress.close()
    write_text(Path(a.out), library_text(lib), "--out", a.force)
    plans = sum(node is not None for row in lib.nodes for node in row)
    out = {
        "library": a.out,
        "nodes": len(lib.x0s) * len(lib.v0s),
        "plans": plans,
        "build_s": time.perf_counter() - start,
    }
    if a.json:
        print(json.dumps(out))
    else:
        print(
            f"{out['library']}: {plans} of {out['nodes']} nodes have a plan "
            f"(built in {out['build_s']:.1f} s)"
        )
    return 0  # nodes without a plan are reported; replans near them fall back on neighbours


def check_library(path: str, text: str, as_json: bool) -> int:
    """`perchd plan check L.json` on a library: every node's plan re-derived and verified
    against the library's limits, as a plan file is; exit 0 when all hold, else 1."""
    lib = load_json(path, library_from_json, "plan library", text)
    broken, plans = [], 0
    for i, x0 in enumerate(lib.x0s):
        for j, v0 in enumerate(lib.v0s):
            node = lib.nodes[i][j]
            if node is None:
                continue
            plans += 1
            rep = report(make_plan("ipts", x0, v0, lib.tau_s, lib.limits, k=node.k))
            if not rep.feasible:
                broken.append(
                    f"nodes[{i}][{j}] (x0 {x0:g} m, v0 {v0:g} m/s): " + "; ".join(rep.violations)
                )
    out = {
        "schema": SCHEMA,
        "strategy": "ipts",
        "order": lib.order,
        "x0": [lib.x0s[0], lib.x0s[-1]],
        "v0": [lib.v0s[0], lib.v0s[-1]],
        "nodes": len(lib.x0s) * len(lib.v0s),
        "plans": plans,
        "feasible": not broken,
        "violations": broken,
    }
    if as_json:
        print(json.dumps(out))
    else:
        print(
            f"library: IPTS order {lib.order}, x0 {out['x0'][0]:g}..{out['x0'][1]:g} m "
            f"({len(lib.x0s)} nodes) x v0 {out['v0'][0]:g}..{out['v0'][1]:g} m/s "
            f"({len(lib.v0s)} nodes)"
        )
        print(
            f"plans: {plans} of {out['nodes']} nodes; "
            + (
                "every one meets the limits"
                if not broken
                else "NOT feasible: "
                + broken[0]
                + (f" (and {len(broken) - 1} more)" if len(broken) > 1 else "")
            )
        )
    return 0 if not broken else 1
