"""`perchd sim report TABLE [--plots DIR] [--worst N] [--json] [--force]`: a campaign's
table read back: its summary printed as `perchd sim --campaign` prints it, the worst
flights listed, and with --plots its figures drawn into an existing directory
(perchd.campaign.plot). Exit 0, or 2 for a table that cannot be read."""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

from perchd.campaign.flights import FlightRow, summarize
from perchd.campaign.plot import WORST_COLUMNS, plot_campaign, text, worst
from perchd.campaign.results import summary_path
from perchd.campaign.tableformats import table_format
from perchd.commands.sim.campaign import summary_text
from perchd.core.safefile import OutputError, read_regular, regular_file


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report", help="a campaign table's summary and plots", description=__doc__.splitlines()[0]
    )
    p.add_argument("table", metavar="TABLE", help="a campaign's .parquet or .csv table")
    p.add_argument(
        "--plots", metavar="DIR", help="draw the figures (PNG) into this existing directory"
    )
    p.add_argument(
        "--worst",
        type=int,
        default=10,
        metavar="N",
        help="flights listed and drawn as the worst (default 10)",
    )
    p.add_argument("--json", action="store_true", help="the summary as one JSON object")
    p.add_argument("--force", action="store_true", help="overwrite existing figures")
    p.set_defaults(run=run)


def load_rows(path: Path) -> list[FlightRow]:
    regular_file(path, "table", OutputError)
    try:
        return sorted(table_format(path, FlightRow).load(), key=lambda r: r.index)
    except (ImportError, OSError, ValueError, TypeError) as err:
        raise OutputError(f"{path}: not a campaign table ({err})") from None


def made(path: Path) -> dict[str, Any]:
    """The campaign's own summary beside the table ({} without one)."""
    beside = summary_path(path)
    if not beside.is_file():
        return {}
    try:
        doc = json.loads(read_regular(beside, "", OutputError))
    except ValueError as err:
        raise OutputError(f"{beside}: not a campaign summary ({err})") from None
    return doc if isinstance(doc, dict) else {}


def run(args: argparse.Namespace) -> int:
    table = Path(args.table)
    rows = load_rows(table)
    if args.plots and not Path(args.plots).is_dir():
        raise OutputError(f"--plots {args.plots}: not an existing directory (perchd creates none)")
    summary, bad = summarize(rows), worst(rows, args.worst)
    meta = made(table)
    plots = (
        [str(p) for p in plot_campaign(rows, Path(args.plots), args.force, args.worst)]
        if args.plots
        else []
    )
    if args.json:
        print(
            json.dumps(
                {
                    **asdict(summary),
                    "table": str(table),
                    "plots": plots,
                    "complete": meta.get("complete"),
                    "campaign": meta.get("campaign"),
                    "worst": [asdict(r) for r in bad],
                }
            )
        )
        return 0
    print(summary_text(summary, table, meta.get("wall_s", 0.0)))
    print("worst: " + "  ".join(c for c, _ in WORST_COLUMNS))
    for r in bad:
        print("  " + "  ".join(text(getattr(r, c), f) for c, f in WORST_COLUMNS))
    for p in plots:
        print(f"plot: {p}")
    return 0
