"""CPU-bound processes beside a measurement (`perchd bench loop|planner --load N`): what a
lab's flight PC does to perchd when Motive, a ground station or a compiler is busy too.

Each hog is a Python process spinning at the normal scheduler's policy (it drops any
real-time policy it inherited), stopped when the block ends however it ends (Ctrl-C
included), and ending by itself within ~0.1 s if its parent dies without stopping it.
"""

from __future__ import annotations

import contextlib
import subprocess
import sys
from collections.abc import Iterator

HOG = """
import os
parent = os.getppid()
os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
n = 0
while True:
    n += 1
    if n % 500000 == 0 and os.getppid() != parent:
        break
"""
MAX_HOGS = 64


@contextlib.contextmanager
def cpu_hogs(n: int) -> Iterator[list[subprocess.Popen]]:
    """`n` CPU-bound processes running inside the block."""
    procs: list[subprocess.Popen] = []
    try:
        for _ in range(n):
            procs.append(
                subprocess.Popen(
                    [sys.executable, "-c", HOG],
                    stdin=subprocess.DEVNULL,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                )
            )
        yield procs
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            p.wait()
