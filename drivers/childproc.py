"""The drivers' helper processes (the Crazyflie link keeper, drivers/cflink.py; the MAVLink
sentinel, drivers/mavsentinel.py): started with this very perchd first on their path, so they
run the agent's own code, and reaped in the background once told to end; `say` is how they
write a line to the agent's stderr."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import perchd


def start(module: str, args: list[str], fds: tuple[int, ...]) -> subprocess.Popen:
    """`python -m MODULE ARGS`, inheriting the file descriptors `fds`."""
    root = str(Path(perchd.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        p for p in (root, os.environ.get("PYTHONPATH", "")) if p)}
    return subprocess.Popen([sys.executable, "-m", module, *args], pass_fds=fds, env=env,
                            stdin=subprocess.DEVNULL)


def say(who: str, text: str) -> None:
    """One line on stderr (the service's journal), lost rather than raised: the agent's
    terminal may have hung up, and a helper must go on landing the vehicle."""
    try:
        sys.stderr.write(f"perchd {who}: {text}\n")
        sys.stderr.flush()
    except (OSError, ValueError):
        pass


def reap_later(proc: subprocess.Popen, timeout_s: float, name: str) -> None:
    """Wait for `proc` in a background thread; killed if still running after timeout_s [s]."""
    threading.Thread(target=_reap, args=(proc, timeout_s), name=name, daemon=True).start()


def _reap(proc: subprocess.Popen, timeout_s: float) -> None:
    try:
        proc.wait(timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
