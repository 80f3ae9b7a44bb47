"""Control-loop figures: the same measurement as `perchd bench loop`.

    python benchmarks/loop.py [--json] [--seconds S] [--load N] [--realtime[=PRIO]]

500 Hz fixed-rate loop jitter, overruns per minute at 500 and 100 Hz, the agent's compute per tick, pose-arrival to
setpoint latency over real ZMQ sockets in mocap-synchronous and fixed-rate mode, and the
agent's CPU load at 100 Hz; see perchd/bench/loop.py for how each is taken.
"""

from __future__ import annotations

import sys

from perchd.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "loop", *sys.argv[1:]]))
