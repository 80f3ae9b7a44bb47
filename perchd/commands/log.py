"""`perchd log summary F [--json]`, `perchd log plot F [--out PNG]` and
`perchd log export F --mcap OUT`: read a flight log (docs/contracts.md §5). The plot is the
paper's figure 6 layout: distance, velocity and tau, each measured against the reference."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from perchd.console.outputs import draw
from perchd.core.extras import require
from perchd.core.safefile import check_output
from perchd.logs.flightlog import read_log
from perchd.logs.mcapexport import export_mcap
from perchd.logs.plot import plot_flights
from perchd.logs.summary import summarize, summary_text


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "log", help="summarise or plot a flight log", description=__doc__.splitlines()[0]
    )
    sub = p.add_subparsers(dest="action", required=True)
    s = sub.add_parser("summary", help="outcome, contact speed, perch time, tau RMS, loop jitter")
    s.add_argument("log", help="flight log (.jsonl)")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    q = sub.add_parser("plot", help="distance, velocity and tau against the reference (PNG)")
    q.add_argument(
        "log",
        nargs="+",
        help="flight log(s) (.jsonl): one column each, e.g. "
        "CTDTS and IPTS side by side as in the paper",
    )
    q.add_argument(
        "--out",
        help="image path (default: the first log's path with .png); its directory must exist",
    )
    q.add_argument("--force", action="store_true", help="overwrite an existing image")
    e = sub.add_parser(
        "export",
        help="as MCAP for Foxglove or PlotJuggler (needs perchd[mcap])",
        description="One channel per stream (/perchd/estimate, reference, "
        "setpoint, loop, phase, events, flight), JSON messages with "
        "a JSON Schema each, log times from the flight's clock. "
        "A log cut short exports what it has.",
    )
    e.add_argument("log", help="flight log (.jsonl)")
    e.add_argument(
        "--mcap", required=True, metavar="OUT", help="MCAP file to write; its directory must exist"
    )
    e.add_argument("--force", action="store_true", help="overwrite an existing MCAP file")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if args.action == "export":
        return export(args)
    if args.action == "summary":
        s = summarize(read_log(args.log))
        print(json.dumps(s.to_json()) if args.json else summary_text(s))
        return 0

    out = Path(args.out) if args.out else Path(args.log[0]).with_suffix(".png")
    check_output(out, "--out", args.force, inputs=tuple(args.log))
    logs = [read_log(p) for p in args.log]
    names = [Path(p).name for p in args.log]
    draw(lambda data, path: plot_flights(data, path, names, args.force), logs, out, "--out")
    print(out)
    return 0


def export(args: argparse.Namespace) -> int:
    """`log export`: exit 0 once written, a log cut short included (said on stderr)."""
    require("mcap.writer", "mcap")  # before any work: the one line naming the extra
    out = check_output(args.mcap, "--mcap", args.force, inputs=(args.log,))
    log = read_log(args.log)
    export_mcap(log, out, args.force)
    if not log.complete:
        print(
            f"perchd log export: {args.log}: no end line (a flight cut short); exported its "
            f"{len(log.rows)} rows and {len(log.events)} events",
            file=sys.stderr,
        )
    print(out)
    return 0
