"""The fault suite prints its per-fault table (docs/safety.md) at the end of a verbose run."""

from __future__ import annotations

import faultsim


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if faultsim.TABLE and config.getoption("verbose") > 0:
        terminalreporter.section("fault table (docs/safety.md)")
        for line in faultsim.table_lines():
            terminalreporter.write_line(line)
