"""`perchd sim firmware` as the opt-in firmware tests start and stop it."""

from __future__ import annotations

import json
import signal
import subprocess

from announced import start_announced


def start_harness(*args: str, env: dict | None = None) -> tuple[subprocess.Popen, str, str]:
    """Start `perchd sim firmware ARGS --json`; its process and the announced URIs."""
    return start_announced("sim", "firmware", *args, "--json", env=env)


def stop_harness(proc: subprocess.Popen, timeout_s: float = 20.0) -> dict:
    """SIGTERM, then its JSON summary (killed if it does not stop in time)."""
    proc.send_signal(signal.SIGTERM)
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
    return json.loads(out)
