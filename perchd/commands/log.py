"""`perchd log summary F [--json]` and `perchd log plot F [--out PNG]`: read a flight log
(docs/contracts.md §5). The plot is the paper's figure 6 layout: distance, velocity and tau, each
measured against the reference."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from perchd.commands.plan import draw
from perchd.core.errors import PerchdError
from perchd.core.safefile import check_output
from perchd.logs.flightlog import read_log
from perchd.logs.plot import plot_flights
from perchd.logs.summary import summarize, summary_text


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("log", help="summarise or plot a flight log",
                              description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="action", required=True)
    s = sub.add_parser("summary", help="outcome, contact speed, perch time, tau RMS, loop jitter")
    s.add_argument("log", help="flight log (.jsonl)")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    q = sub.add_parser("plot", help="distance, velocity and tau against the reference (PNG)")
    q.add_argument("log", nargs="+", help="flight log(s) (.jsonl): one column each, e.g. "
                                          "CTDTS and IPTS side by side as in the paper")
    q.add_argument("--out", help="image path (default: the first log's path with .png); "
                                 "its directory must exist")
    q.add_argument("--force", action="store_true", help="overwrite an existing image")
    p.set_defaults(run=run)


def _read(path: str):

    try:
        return read_log(path)
    except OSError as err:
        raise PerchdError(f"{path}: cannot read: {err.strerror}") from None


def run(args: argparse.Namespace) -> int:
    if args.action == "summary":

        s = summarize(_read(args.log))
        print(json.dumps(s.to_json()) if args.json else summary_text(s))
        return 0

    out = Path(args.out) if args.out else Path(args.log[0]).with_suffix(".png")
    check_output(out, "--out", args.force, inputs=tuple(args.log))
    logs = [_read(p) for p in args.log]
    names = [Path(p).name for p in args.log]
    draw(lambda data, path: plot_flights(data, path, names), logs, out, "--out")
    print(out)
    return 0
