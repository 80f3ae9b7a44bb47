"""The drivers' helper processes (the Crazyflie link keeper, drivers/cflink.py; the MAVLink
sentinel, drivers/mavlink/sentinel.py): started with this very perchd first on their path, so they
run the agent's own code, and reaped in the background once told to end; `say` is how they
write a line to the agent's stderr."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import threading
from pathlib import Path

import perchd


def start(module: str, args: list[str], fds: tuple[int, ...]) -> subprocess.Popen[bytes]:
    """`python -m MODULE ARGS`, inheriting the file descriptors `fds`."""
    root = str(Path(perchd.__file__).resolve().parents[1])
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH", "")) if p),
    }
    return subprocess.Popen(
        [sys.executable, "-m", module, *args], pass_fds=fds, env=env, stdin=subprocess.DEVNULL
    )


def say(who: str, text: str) -> None:
    """One line on stderr (the service's journal), lost rather than raised: the agent's
    terminal may have hung up, and a helper must go on landing the vehicle."""
    try:
        sys.stderr.write(f"perchd {who}: {text}\n")
        sys.stderr.flush()
    except (OSError, ValueError):
        pass


def let_go_of_pipes() -> None:
    """Point stdout and stderr at /dev/null where they are pipes: whoever reads the agent's
    output through one (`perchd fly ... | tee`, a test's communicate()) waits for its EOF,
    which a helper still running (the sentinel's relay) would hold back. A terminal, a file
    or the journal stays."""
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in (1, 2):
            try:
                if stat.S_ISFIFO(os.fstat(fd).st_mode):
                    os.dup2(null, fd)
            except OSError:
                pass  # closed already: nothing held
    finally:
        os.close(null)


def reap_later(proc: subprocess.Popen[bytes], timeout_s: float, name: str) -> None:
    """Wait for `proc` in a background thread; killed if still running after timeout_s [s]."""
    threading.Thread(target=_reap, args=(proc, timeout_s), name=name, daemon=True).start()


def _reap(proc: subprocess.Popen[bytes], timeout_s: float) -> None:
    try:
        proc.wait(timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
