"""The fault suite reuses the closed-loop, driver and service test helpers by import, and
prints the per-fault table (docs/safety.md) at the end of the run."""

from __future__ import annotations

import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
for helpers in ("closedloop", "drivers", "service", "faults"):
    if str(TESTS / helpers) not in sys.path:
        sys.path.insert(0, str(TESTS / helpers))


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    import faultsim
    if faultsim.TABLE:
        terminalreporter.section("fault table (docs/safety.md)")
        for line in faultsim.table_lines():
            terminalreporter.write_line(line)
