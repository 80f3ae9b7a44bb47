"""A perchd process that announces `ready: mocap URI driver URI` on stderr (perchd sim and
perchd sim firmware both do), started once for every test that needs one."""

from __future__ import annotations

import re
import subprocess
import sys


def start_announced(*args: str, env: dict | None = None) -> tuple[subprocess.Popen, str, str]:
    """Start `python -m perchd ARGS`; its process and the mocap and driver URIs it announced."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "perchd", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    line = proc.stderr.readline()
    found = re.search(r"ready: mocap (\S+) driver (\S+)", line)
    if found is None:
        proc.kill()
        raise AssertionError(f"perchd {args[0]} did not start: {line}{proc.stderr.read()}")
    return proc, found.group(1), found.group(2)
