"""The `perchd` command: one subcommand per module in perchd.commands.

Each command module exposes `register(subparsers)`, which adds its parser and sets
`run=callable(args) -> int`. Errors reach the user as one line on stderr and exit code 2
(bad input) or 1 (a flight or link that failed); never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
from collections.abc import Sequence

from perchd import __version__
from perchd.core.errors import PerchdError

COMMANDS = ("plan", "fly", "vehicle", "mocap", "sim", "serve", "ctl", "failsafe", "log", "bench")


class _Parser(argparse.ArgumentParser):
    """argparse whose usage errors are one line (no usage block) and exit code 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def build_parser(argv: Sequence[str] = ()) -> argparse.ArgumentParser:
    """The parser, with only the named command's module imported when argv names one: a
    flight command pulls in numpy and scipy, `perchd ctl status` should not wait for them."""
    parser = _Parser(prog="perchd", description="Tau-based perching flight agent.")
    parser.add_argument("--version", action="version", version=f"perchd {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    named = next((a for a in argv if not a.startswith("-")), None)
    for name in (named,) if named in COMMANDS else COMMANDS:
        importlib.import_module(f"perchd.commands.{name}").register(sub)
    return parser


class Terminated(KeyboardInterrupt):
    """SIGTERM before a command installs its own handling: ends it as Ctrl-C would."""


def _terminate(_signum: int, _frame: object) -> None:
    raise Terminated


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    name = next((a for a in argv if not a.startswith("-")), "")
    # From the first line on, SIGTERM ends the command in one line as SIGINT does, even
    # while it is still importing numpy and scipy (a command may install its own after).
    signal.signal(signal.SIGTERM, _terminate)
    try:
        args = build_parser(argv).parse_args(argv)
        name = args.command
        return int(args.run(args) or 0)
    except PerchdError as err:
        print(f"perchd {name}: {err}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt as stop:
        term = isinstance(stop, Terminated)
        print(f"perchd {name}: interrupted{' by SIGTERM' if term else ''}", file=sys.stderr)
        return 143 if term else 130
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
