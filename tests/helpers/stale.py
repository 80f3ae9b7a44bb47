"""The stale-mocap limit of a flight whose mocap is a process beside it on this machine's
two shared cores (a firmware harness, `perchd sim`, a test's own publisher), and the check
that every such flight in the tests flies it (tests/conftest.py)."""

from __future__ import annotations

import json
from pathlib import Path

HARNESS_STALE_S = 0.25
HARNESS_SAFETY = f"[safety]\nstale_timeout_s = {HARNESS_STALE_S}\n"
"""Such a pose stream is descheduled past the default three mocap periods (30 ms at 100 Hz;
40-106 ms seen), which measures the machine, not the flight. A lab's mocap keeps its rate;
the stale rule has tests of its own (tests/faults), marked `own_stale_limit` where they fly
a pose stream of this machine with a shorter limit."""


def harness_config(directory: Path, tables: str = "") -> Path:
    """A flight configuration under `directory`: HARNESS_SAFETY, then `tables` (which may
    hold a [safety] table of their own instead)."""
    path = directory / "harness.toml"
    path.write_text("version = 1\n" + ("" if "[safety]" in tables else HARNESS_SAFETY) + tables)
    return path


def below_the_harness_limit(root: Path) -> list[str]:
    """The flight logs under `root` whose mocap was a live stream (not sim://, the simulated
    clock's) flown with a stale limit shorter than HARNESS_STALE_S: 'log: mocap, limit'."""
    found = []
    for log in sorted(root.rglob("*.jsonl")):
        header = _header(log)
        if header is None or str(header.get("mocap", "sim://")).startswith("sim://"):
            continue
        limit = header.get("config", {}).get("safety", {}).get("stale_timeout_s")
        if limit is None or limit < HARNESS_STALE_S:
            found.append(f"{log.name}: {header['mocap']}, stale_timeout_s {limit}")
    return found


def _header(log: Path) -> dict | None:
    if not log.is_file():  # a test's FIFO named *.jsonl: opening it would wait for a writer
        return None
    try:
        with log.open() as f:
            header = json.loads(f.readline())
    except (OSError, ValueError):
        return None
    return header if isinstance(header, dict) and "schema" in header else None
