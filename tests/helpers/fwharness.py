"""`perchd sim firmware` as the opt-in firmware tests start and stop it."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
from pathlib import Path

from announced import start_announced


def start_harness(*args: str, env: dict | None = None) -> tuple[subprocess.Popen, str, str]:
    """Start `perchd sim firmware ARGS --json`; its process and the announced URIs."""
    return start_announced("sim", "firmware", *args, "--json", env=env)


def start_placed(*args: str, env: dict | None = None
                 ) -> tuple[subprocess.Popen, str, str, list[str]]:
    """`perchd sim firmware ARGS --json` for a vehicle whose harness places the surface
    itself (PX4: ahead along its heading, said on stderr before the ready line): its
    process, mocap and driver URIs, and the `--surface ... --normal ...` options for
    `perchd fly` (none when the harness said nothing)."""
    proc = subprocess.Popen([sys.executable, "-m", "perchd", "sim", "firmware", *args, "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    surface: list[str] = []
    for line in proc.stderr:
        if (found := re.search(r"surface (\S+ \S+ \S+) normal (\S+ \S+ \S+)", line)):
            surface = ["--surface", *found.group(1).split(), "--normal", *found.group(2).split()]
        if (found := re.search(r"ready: mocap (\S+) driver (\S+)", line)):
            return proc, found.group(1), found.group(2), surface
    proc.kill()
    raise RuntimeError(f"perchd sim firmware {' '.join(args[:2])} did not start: "
                       f"{proc.stderr.read()}")


def lag_event(log: Path) -> dict:
    """The flight's lag-identified (or -unidentified) event from its log as {"kind": ...,
    **values} (docs/contracts.md, flight log); {} without one."""
    if not log.exists():
        return {}
    for line in log.read_text().splitlines():
        if '"kind":"lag-' in line:
            ev = json.loads(line)["event"]
            return {"kind": ev["kind"], **ev["values"]}
    return {}


def stop_harness(proc: subprocess.Popen, timeout_s: float = 20.0) -> dict:
    """SIGTERM, then its JSON summary (killed if it does not stop in time)."""
    proc.send_signal(signal.SIGTERM)
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
    return json.loads(out)
