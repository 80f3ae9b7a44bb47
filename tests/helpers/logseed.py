"""A short flight log as FlightLogWriter writes it (header, rows, an event, the end): the seed
the log-reader fuzzing mutates (tests/fuzz/test_fuzz_files.py, benchmarks/fuzz.py)."""

from __future__ import annotations

from pathlib import Path

from perchd.logs.flightlog import FlightLogWriter, LogEvent, LogRow


def log_row(k: int, x: float = -1.0, end: str | None = None) -> LogRow:
    """Tick k of a steady stage-1 approach at distance x [m] (every other field fixed)."""
    return LogRow(
        k * 0.01, k, "stage1", x, 1.0, -1.0, -1.0, -1.0, 1.0, -0.5, 0.0, 1.0, 0.0, 0.1, 0.0,
        0.3, -0.5, 0.0, 0.0, 0.01, 0.004, k, 0.0, 1e-4, end,
    )  # fmt: skip


def log_seed(path: Path) -> bytes:
    """The log's bytes, written at `path` (a new file)."""
    w = FlightLogWriter(
        path,
        {
            "plan": {"duration": 1.2, "v_contact": 0.8, "strategy": "ipts"},
            "config": {"rate_hz": 100.0, "sync": "clock"},
        },
    )
    for k in range(4):
        w.row(log_row(k))
    w.event(LogEvent(0.02, "contact", "touched", {"speed": 0.8, "flag": True}))
    w.close({"outcome": "CONTACT", "detail": "", "summary": {"contact_speed": 0.8}})
    return path.read_bytes()
