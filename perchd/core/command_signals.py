"""SIGINT and SIGTERM in the `perchd` command's own process, from perchd's first line to the
process's exit (docs/contracts.md §6): the exit is 130 or 143 with one line, or the
command's own code when it had already ended; never a traceback, never death by the signal.

perchd/__init__.py calls `take()` from its first lines when this process is the command (its
console script, or `python -m perchd`; not a program that imports perchd, nor a helper
started as `python -m perchd.service...`): one handler then serves the whole life. A SIGINT
met before it is in place, perchd/__init__.py ends the process on itself, with the line.

- STARTING (imports, up to cli.main's `try`): the process ends at once, with the line.
- RUNNING (the command): KeyboardInterrupt for SIGINT, Terminated for SIGTERM, raised once;
  the command's own handling and cli.main turn it into its summary, its line and its code.
  A command may install handlers of its own meanwhile; it puts this one back. Raised where
  Python cannot raise (a weakref callback, as importlib's module locks have, or a __del__),
  it would be printed as "Exception ignored" and lost: it is kept instead
  (sys.unraisablehook) and the next signal raises again. A command that ends in another way
  after the handler raised (the KeyboardInterrupt swallowed, lost, or made another exception:
  an extension module's import turns it into ImportError) ends as interrupted all the same.
- OVER (cli.main saying how the command ended, returning, and the interpreter's shutdown:
  threads joined, atexit callbacks): the end is decided, a signal changes nothing; a
  second one ends the process at once with the command's code, should the shutdown hang.

Two ways the interpreter would end the process by SIGINT (-2) after all:
- it resets a Python handler to the default action late in its shutdown (after the atexit
  callbacks, before it tears the modules down): the atexit callback registered first, which
  runs last, ignores both signals instead;
- under `python -m`, a KeyboardInterrupt that once left a string given to exec (dataclasses and
  namedtuple build their methods so, at import) marks the run as ended by an unhandled
  KeyboardInterrupt, caught or not, and the interpreter then kills itself by SIGINT
  whatever the exit code: cli.main's return (`ended`) clears that mark with a string exec of
  its own, which starts by clearing it.

Outside: a signal before perchd's first line runs (the interpreter's start-up, site, the
console script's own `import re, sys`, the import machinery finding perchd) meets the
interpreter's handling: death by the signal before the interpreter has set its SIGINT
handler, and after that a KeyboardInterrupt with a traceback and death by SIGINT; SIGTERM
kills by its default action. A SIGINT that arrived in that time is raised as the first
perchd frame starts, before its first line.
"""

from __future__ import annotations

import atexit
import os
import signal
import sys
from typing import Any

STARTING, RUNNING, OVER = "starting", "running", "over"


class Terminated(KeyboardInterrupt):
    """SIGTERM where a command has no handling of its own: it ends as Ctrl-C would."""


class _State:
    taken = False  # this process is the command, and the handler is in place
    phase = STARTING
    command = ""  # the name in the line
    said = False  # a line saying how the command ended is out
    code: int | None = None  # the command's exit code, once cli.main returned it
    noted = 0  # signals met once the command was over
    raised: KeyboardInterrupt | None = None  # the one the handler raised
    lost: KeyboardInterrupt | None = None  # ... where Python could not raise it


def command_from(argv: list[str]) -> str:
    """The command's name as the line gives it before its arguments are parsed."""
    return next((a for a in argv if not a.startswith("-")), "")


def stopped_line(command: str, signum: int) -> str:
    """The line of a command stopped by `signum` (no command named yet: `perchd:`)."""
    by = " by SIGTERM" if signum == signal.SIGTERM else ""
    return f"perchd {command}: interrupted{by}" if command else f"perchd: interrupted{by}"


def take() -> None:
    """Both signals to one handler, from now to the exit (this process is the command). A
    SIGINT that the process was started ignoring (`nohup`, a shell's `&`) stays ignored."""
    _State.command = command_from(sys.argv[1:])
    signal.signal(signal.SIGTERM, _handler)
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        signal.signal(signal.SIGINT, _handler)
    _State.taken = True
    atexit.register(_ignore_from_here)
    previous = sys.unraisablehook

    def unraisable(info: Any) -> None:
        if info.exc_value is not None and info.exc_value is _State.raised:
            _State.lost, _State.raised = _State.raised, None
            if _State.phase == OVER:
                _State.phase = RUNNING  # the next signal stops the command
            return
        previous(info)

    sys.unraisablehook = unraisable


def taken() -> bool:
    return _State.taken


def command() -> str:
    return _State.command


def running(command: str) -> None:
    """cli.main starts the command: a signal now stops it through its own handling."""
    _State.command = command
    if _State.phase == STARTING:
        _State.phase = RUNNING


def over() -> None:
    """cli.main knows how the command ended: a signal now changes nothing."""
    _State.phase = OVER


def say(line: str) -> None:
    """The line that says how the command ended, on stderr, once."""
    if not _State.taken:
        print(line, file=sys.stderr)
        return
    data = f"{line}\n".encode(sys.stderr.encoding or "utf-8", "backslashreplace")
    _flush(sys.stderr)
    if not _State.said:
        _State.said = True
        # one system call, no Python code between it and the flag: a handler cannot come
        # between them and say it twice, or neither
        os.write(2, data)


def raised() -> KeyboardInterrupt | None:
    """The stop the handler raised, if it did: cli.main takes a command that then ends in
    another way (its KeyboardInterrupt swallowed, lost where Python cannot raise, or turned
    into another exception, as a C extension's import makes an ImportError of it) as
    stopped by it."""
    return _State.raised or _State.lost


def ended(code: int) -> int:
    """cli.main returns `code`: what a signal from here to the exit leaves as the exit."""
    _State.code = code
    _State.phase = OVER
    if _State.taken:
        exec("pass", {})  # clears the interpreter's "unhandled KeyboardInterrupt" mark
    return code


def _handler(signum: int, _frame: object) -> None:
    if _State.phase == RUNNING:
        _State.phase = OVER  # once: the command's own end is not cut short by a second
        _State.raised = Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()
        raise _State.raised
    if _State.phase == STARTING:
        _end_now(128 + signum, stopped_line(_State.command, signum))
    _State.noted += 1
    if _State.noted < 2:
        return
    # a second one: what is left (its clean-up, or the shutdown) hangs; ended at once
    if _State.code is not None:
        _end_now(_State.code, None)
    _end_now(128 + signum, stopped_line(_State.command, signum))


def _end_now(code: int, line: str | None) -> None:
    _flush(sys.stdout)
    if line is not None and not _State.said:
        _State.said = True
        try:
            os.write(2, f"{line}\n".encode(sys.stderr.encoding or "utf-8", "backslashreplace"))
        except OSError:
            pass  # stderr gone: the code still says it
    os._exit(code)


def _flush(stream: object) -> None:
    try:
        stream.flush()  # type: ignore[attr-defined]
    except (OSError, ValueError, RuntimeError, AttributeError):
        pass  # closed, gone, or being written by the code the handler interrupted


def _ignore_from_here() -> None:
    """The last atexit callback: the interpreter is about to reset the handler to the
    default action (death by the signal); ignored instead, the exit stays the command's."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
