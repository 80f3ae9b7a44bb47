"""The flags `perchd plan robust` and `perchd plan library` share: the stage switch and the
contact window of the IPTS plans they make, and the one file they write."""

from __future__ import annotations

import argparse


def stage_two(p: argparse.ArgumentParser) -> None:
    """--tau-s and the --v-contact window (LO HI)."""
    p.add_argument("--tau-s", type=float, required=True, help="stage switch tau [s] < 0")
    p.add_argument(
        "--v-contact",
        type=float,
        nargs=2,
        required=True,
        metavar=("LO", "HI"),
        help="contact speeds allowed [m/s], 0 < LO <= HI",
    )


def written_file(p: argparse.ArgumentParser, what: str) -> None:
    """--out (required), --force and --json."""
    p.add_argument("--out", required=True, help=f"{what} file to write; its directory must exist")
    p.add_argument("--force", action="store_true", help="overwrite an existing --out file")
    p.add_argument("--json", action="store_true", help="print one JSON object")
