"""A `perchd` command run with its stderr on a real pseudo-terminal (pty.openpty), as a user
at a terminal sees it."""

from __future__ import annotations

import os
import pty
import subprocess
import sys


def run_on_terminal(*args: str, timeout: float = 120.0) -> tuple[int, str, str]:
    """`python -m perchd ARGS` with stderr on a pty: (exit code, stdout, what the pty got)."""
    leader, follower = pty.openpty()
    proc = subprocess.Popen(
        [sys.executable, "-m", "perchd", *args], stdout=subprocess.PIPE, stderr=follower, text=True
    )
    os.close(follower)
    seen = b""
    while True:
        try:
            chunk = os.read(leader, 4096)
        except OSError:  # EIO: the child closed the terminal
            break
        if not chunk:
            break
        seen += chunk
    os.close(leader)
    out, _ = proc.communicate(timeout=timeout)
    return proc.returncode, out, seen.decode()
