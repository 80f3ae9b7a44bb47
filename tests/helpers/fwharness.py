"""`perchd sim firmware` as the opt-in firmware tests start and stop it."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys


def start_harness(*args: str, env: dict | None = None) -> tuple[subprocess.Popen, str, str]:
    """Start `perchd sim firmware ARGS --json`; its process and the mocap and driver URIs of
    its ready line."""
    proc = subprocess.Popen([sys.executable, "-m", "perchd", "sim", "firmware", *args, "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    line = proc.stderr.readline()
    found = re.search(r"ready: mocap (\S+) driver (\S+)", line)
    if found is None:
        proc.kill()
        raise AssertionError(f"perchd sim firmware did not start: {line}{proc.stderr.read()}")
    return proc, found.group(1), found.group(2)


def stop_harness(proc: subprocess.Popen, timeout_s: float = 20.0) -> dict:
    """SIGTERM, then its JSON summary (killed if it does not stop in time)."""
    proc.send_signal(signal.SIGTERM)
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
    return json.loads(out)
