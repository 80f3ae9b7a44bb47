"""The `perchd` command: one subcommand per module in perchd.commands.

Each command module exposes `register(subparsers)`, which adds its parser and sets
`run=callable(args) -> int`. Errors reach the user as one line on stderr and exit code 2
(bad input) or 1 (a flight or link that failed); never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import Sequence

from perchd import __version__
from perchd.core.errors import PerchdError

COMMANDS = ("plan", "fly", "mocap", "sim", "serve", "ctl", "log", "bench")


class _Parser(argparse.ArgumentParser):
    """argparse whose usage errors are one line (no usage block) and exit code 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="perchd", description="Tau-based perching flight agent.")
    parser.add_argument("--version", action="version", version=f"perchd {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"perchd.commands.{name}")
        except ModuleNotFoundError as err:
            if err.name != f"perchd.commands.{name}":
                raise
            continue  # command not built yet in this checkout
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except PerchdError as err:
        print(f"perchd {args.command}: {err}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt:
        print(f"perchd {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
