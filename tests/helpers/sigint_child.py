"""A child process that handles SIGINT whatever this process inherited."""

from __future__ import annotations

import signal
import subprocess
from typing import Any


def popen_handling_sigint(argv: list[str], **kwargs: Any) -> subprocess.Popen:
    """subprocess.Popen(argv, **kwargs) with SIGINT at Python's default handler while the
    child starts: a runner started in the background (`cmd &` from a script) passes SIGINT
    ignored, which exec keeps, and Python then installs no KeyboardInterrupt handler; a
    handled one is reset to the default at exec."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        return subprocess.Popen(argv, **kwargs)
    finally:
        signal.signal(signal.SIGINT, previous)
