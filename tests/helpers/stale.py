"""The stale-mocap limit of a flight whose mocap is a process beside it on this machine's
two shared cores: a firmware harness, `perchd sim`, a test's own publisher."""

from __future__ import annotations

HARNESS_SAFETY = "[safety]\nstale_timeout_s = 0.25\n"
"""Such a pose stream is descheduled past the default three mocap periods (30 ms at 100 Hz;
48-106 ms seen), which measures the machine, not the flight. A lab's mocap keeps its rate;
the stale rule has tests of its own (tests/faults)."""
