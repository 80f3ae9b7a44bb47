"""Benchmark: what one driver.send() costs the control loop, and how long until the vehicle
end has the setpoint, for each driver over its real library on loopback.

    python3 benchmarks/links.py [--n 2000] [--json]

Prints medians and 99th percentiles in microseconds. Not a test: it asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests", "helpers"))

from rigs import MASS, CrazyflieRig, MavlinkRig, ZmqRig  # noqa: E402

from perchd.core.types import Phase, Setpoint  # noqa: E402
from perchd.drivers.base import open_driver  # noqa: E402
from perchd.drivers.thrust import G  # noqa: E402


def arrivals(rig) -> list[float]:
    """Arrival times of thrust-carrying setpoints at the vehicle end, oldest first."""
    peer = rig.peer
    if isinstance(rig, CrazyflieRig):
        return [s.t for s in peer.setpoints() if s.thrust]
    if isinstance(rig, MavlinkRig):
        return [t.t for t in peer.targets if t.thrust > 0]
    return peer.arrivals("setpoint")


def bench(rig_cls, n: int) -> dict[str, float]:
    rig = rig_cls()
    driver = open_driver(rig.uri, rig.runtime())
    driver.connect()
    send_us, latency_us = [], []
    try:
        for k in range(n):
            before = len(arrivals(rig))
            t0 = time.monotonic()
            driver.send(
                Setpoint(t0, 0.01, 0.0, 0.0, MASS * G * (1 + 1e-4 * (k % 7 + 1)), k, Phase.STAGE1)
            )
            t1 = time.monotonic()
            send_us.append((t1 - t0) * 1e6)
            deadline = t1 + 0.2
            while len(arrivals(rig)) <= before and time.monotonic() < deadline:
                time.sleep(0)
            got = arrivals(rig)
            if len(got) > before:
                latency_us.append((got[before] - t0) * 1e6)
            time.sleep(0.002)
    finally:
        driver.close()
        rig.close()
    return {
        "send_median_us": statistics.median(send_us),
        "send_p99_us": statistics.quantiles(send_us, n=100)[98],
        "arrival_median_us": statistics.median(latency_us),
        "arrival_p99_us": statistics.quantiles(latency_us, n=100)[98],
        "delivered": len(latency_us) / n,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    results = {
        name: bench(cls, args.n)
        for name, cls in (
            ("crazyflie-udp", CrazyflieRig),
            ("mavlink-udp", MavlinkRig),
            ("zmq-tcp", ZmqRig),
        )
    }
    if args.json:
        print(json.dumps(results))
        return
    for name, r in results.items():
        print(
            f"{name:14s} send {r['send_median_us']:7.1f} us (p99 {r['send_p99_us']:7.1f})  "
            f"at vehicle {r['arrival_median_us']:7.1f} us (p99 {r['arrival_p99_us']:7.1f})  "
            f"delivered {100 * r['delivered']:.1f}%"
        )


if __name__ == "__main__":
    main()
