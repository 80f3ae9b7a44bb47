"""SIGINT and SIGTERM for a command whose work runs in its main thread (`perchd mocap`,
`perchd bench`): either signal raises KeyboardInterrupt there, wherever the thread is, so the
command's own clean-up (its `finally` and `with` blocks: sockets closed, the processes it
started stopped) runs as on Ctrl-C; the command then says so in one line and exits 130 or
143 (docs/contracts.md §6). A command whose work runs in threads of its own (`perchd fly`,
`perchd sim`) uses perchd.core.interrupts.catching, whose handler only sets a flag."""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator

from perchd.core.interrupts import STOP_SIGNALS, Caught


@contextlib.contextmanager
def interruptible() -> Iterator[Caught]:
    """While the block runs, SIGINT and SIGTERM end it (the KeyboardInterrupt stops here);
    after it, `caught` names the signal, or None when the block ran to its end."""
    caught = Caught()

    def handler(signum: int, _frame: object) -> None:
        if caught.signum is None:
            caught.signum = signum
            raise KeyboardInterrupt

    previous = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    try:
        yield caught
    except KeyboardInterrupt:
        if caught.signum is None:  # raised by other means than the handler
            caught.signum = signal.SIGINT
    finally:
        for s, old in previous.items():
            signal.signal(s, old)
