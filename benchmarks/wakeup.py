"""How a fixed-rate loop's wake-ups fare on this machine: sleep against spin, normal
scheduler against SCHED_FIFO. An empty tick, so every overrun is a late wake-up.

    python benchmarks/wakeup.py [--seconds 30] [--rate 500] [--spin-ms 0.3] [--fifo 50]

Prints overruns, lateness p99/max, the CPU it cost and the hypervisor's steal meanwhile
(benchmarks/README.md "Loop: latency by default, overruns, load and real-time scheduling").
"""

from __future__ import annotations

import argparse
import json
import os
import time

from perchd.bench.loop import StealMeter, stats_us
from perchd.core.clock import MonotonicClock
from perchd.core.realtime import RealtimeConfig, apply
from perchd.flight.loop import FixedRateLoop


class SpinningClock(MonotonicClock):
    """Sleeps until spin_s [s] before each deadline, then spins on the clock."""

    def __init__(self, spin_s: float) -> None:
        self.spin_s = spin_s

    def sleep_until(self, deadline: float) -> None:
        super().sleep_until(deadline - self.spin_s)
        while time.monotonic() < deadline:
            pass


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--rate", type=float, default=500.0, help="[Hz]")
    ap.add_argument("--spin-ms", type=float, default=0.0, help="[ms] spun before each deadline")
    ap.add_argument("--fifo", type=int, default=0, help="SCHED_FIFO priority (0: normal)")
    args = ap.parse_args()
    apply(RealtimeConfig(args.fifo, lock_memory=False))
    clock = SpinningClock(args.spin_ms / 1e3) if args.spin_ms > 0 else MonotonicClock()
    loop = FixedRateLoop(clock, args.rate)
    steal, cpu0 = StealMeter(), time.process_time()
    end = time.monotonic() + args.seconds
    stats = loop.run(lambda k, t: t < end)
    late = stats_us(stats.jitter)
    print(
        json.dumps(
            {
                "rate_hz": args.rate,
                "spin_ms": args.spin_ms,
                "fifo": args.fifo,
                "seconds": stats.wall_s,
                "overruns": stats.overruns,
                "lateness_p99_us": late["p99_us"],
                "lateness_max_us": late["max_us"],
                "cpu_fraction": (time.process_time() - cpu0) / stats.wall_s,
                "steal_ms": steal.ms(),
                "load": os.getloadavg()[0],
            }
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
