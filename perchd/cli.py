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
from perchd.core import command_signals
from perchd.core.command_signals import Terminated
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


def _terminate(_signum: int, _frame: object) -> None:
    raise Terminated


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    name = command_signals.command_from(argv)
    if not command_signals.taken():
        # called by a program, not the command: SIGTERM ends it in one line as SIGINT
        # does, even while it is still importing numpy and scipy (the command's own
        # process has had both since perchd's first line: perchd/core/command_signals.py)
        signal.signal(signal.SIGTERM, _terminate)
    try:
        code, line = _run(argv, name)
    except KeyboardInterrupt as stop:  # a signal while _run said how the command ended
        command_signals.over()
        code, line = _stopped(command_signals.command(), stop)
    lost = command_signals.raised()
    if lost is not None and code == 0 and line is None:  # its KeyboardInterrupt was lost
        code, line = _stopped(command_signals.command(), lost)
    if line is not None:
        command_signals.say(line)
    return command_signals.ended(code)


def _run(argv: list[str], name: str) -> tuple[int, str | None]:
    """The command's exit code, and the line that says how it ended (None: nothing)."""
    try:
        command_signals.running(name)
        args = build_parser(argv).parse_args(argv)
        name = args.command
        command_signals.running(name)
        return int(args.run(args) or 0), None
    except PerchdError as err:
        return err.exit_code, f"perchd {name}: {err}"
    except KeyboardInterrupt as stop:
        return _stopped(name, stop)
    except BrokenPipeError:
        return 0, None
    except SystemExit as done:  # argparse's --help, --version and usage errors
        if done.code is None or isinstance(done.code, int):
            return done.code or 0, None
        return 1, str(done.code)
    except Exception:
        became = command_signals.raised()
        if became is None:
            raise
        return _stopped(name, became)  # what the stop became (an import's ImportError)
    finally:
        command_signals.over()  # a signal from here on changes nothing


def _stopped(name: str, stop: KeyboardInterrupt) -> tuple[int, str]:
    signum = signal.SIGTERM if isinstance(stop, Terminated) else signal.SIGINT
    return 128 + signum, command_signals.stopped_line(name, signum)


if __name__ == "__main__":
    sys.exit(main())
