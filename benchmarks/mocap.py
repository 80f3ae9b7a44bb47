"""Mocap figures: how long a real NatNet frame takes to parse, and what the sources add
between a packet's arrival and the Pose a flight loop can read.

    python benchmarks/mocap.py [--json] [--frames N]

parse: decode_frame on the recorded Motive 2.1 / NatNet 3.0 frames (one rigid body, six
    labelled markers, 332 bytes), median over batches.
arrival-to-pose: the client's whole receive path for one datagram (header, frame decode,
    axis conversion, validation, publish to waiters), median per datagram.
loopback: send on a real socket -> a thread blocked in wait() wakes with the Pose, for
    NatNet (emulator -> client, unicast) and ZMQ (publisher -> SUB source); median and p99.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import threading
import time
from pathlib import Path

from perchd.core.clock import MonotonicClock
from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.core.uri import parse_uri
from perchd.mocap.base import open_source
from perchd.mocap.frames import UpAxis
from perchd.mocap.natnet import protocol as proto
from perchd.mocap.natnet.client import NatNetConfig, NatNetSource
from perchd.mocap.natnet.clock import ClockSync
from perchd.mocap.natnet.frame import (
    Frame,
    RigidBodySample,
    Timing,
    decode_frame,
    encode_frame,
)
from perchd.mocap.natnet.uris import NatNetServer, open_natnet
from perchd.mocap.zmq import ZmqPosePublisher

SESSION = (
    Path(__file__).resolve().parents[1]
    / "tests"
    / "fixtures"
    / "natnet"
    / "motive-2.1-session"
    / "packets"
)


def recorded_frames() -> list[bytes]:
    return [p.read_bytes() for p in sorted(SESSION.glob("*_msg7_*.bin"))]


def per_call_us(fn, items: list, batches: int = 200) -> float:
    """Median [us] of one call, from batches over all items (timer overhead amortised)."""
    samples = []
    for _ in range(batches):
        start = time.perf_counter()
        for item in items:
            fn(item)
        samples.append((time.perf_counter() - start) / len(items))
    return statistics.median(samples) * 1e6


def parse_us(datagrams: list[bytes]) -> float:
    payloads = [d[4:] for d in datagrams[:100]]
    return per_call_us(lambda payload: decode_frame(payload, (3, 0)), payloads)


def arrival_to_pose_us(datagrams: list[bytes]) -> float:
    source = NatNetSource(NatNetConfig("127.0.0.1", "RaceQuad", up=UpAxis.Y), MonotonicClock())
    source.info = proto.ServerInfo("Motive", (2, 1, 0, 0), (3, 0, 0, 0), 3312787)
    source._body_id, source._sync = 2, ClockSync(3312787)
    arrival = 1.0e6  # later than every recorded stamp, so no pose is refused as old
    seq = iter(range(10**9))

    def handle(datagram: bytes) -> None:
        # each datagram gets a fresh frame number so none is dropped as out of order
        n = next(seq)
        source.handle_datagram(datagram[:4] + n.to_bytes(4, "little") + datagram[8:], arrival)

    us = per_call_us(handle, datagrams[:100], batches=100)
    assert source.stats().dropped == 0, source.drops()
    return us


def loopback_ms(send, source, n: int) -> tuple[float, float]:
    """Median and p99 [ms] from send() to wait() returning the new pose on another thread."""
    delays, last = [], -1
    for i in range(n):
        woke = threading.Event()
        result = {}

        def waiter(after=last):
            result["pose"] = source.wait(after, 1.0)
            result["t"] = time.perf_counter()
            woke.set()

        thread = threading.Thread(target=waiter)
        thread.start()
        time.sleep(0.0005)  # let the waiter block first
        start = time.perf_counter()
        send(i + 1)
        woke.wait(2.0)
        thread.join()
        if result.get("pose") is not None:
            delays.append(result["t"] - start)
            last = result["pose"].seq
    delays.sort()
    return statistics.median(delays) * 1e3, delays[int(0.99 * (len(delays) - 1))] * 1e3


def natnet_loopback(n: int) -> tuple[float, float]:
    clock = MonotonicClock()
    with NatNetServer({"cf1": 1}, (4, 1)) as server:
        source = open_natnet(parse_uri(server.uri + "&body=cf1&up=z"), Runtime(clock))
        source.start()
        try:

            def send(number: int) -> None:
                now = server.ticks(clock.now())
                frame = Frame(
                    number,
                    (RigidBodySample(1, (1.0, 2.0, 3.0), (0, 0, 0, 1.0)),),
                    Timing(1.0, now, now, now),
                )
                server.send_raw(proto.pack(proto.NAT_FRAMEOFDATA, encode_frame(frame, (4, 1))))

            return loopback_ms(send, source, n)
        finally:
            source.close()


def zmq_loopback(n: int) -> tuple[float, float]:
    clock = MonotonicClock()
    publisher = ZmqPosePublisher()
    source = open_source(publisher.uri("cf1"), Runtime(clock))
    source.start()
    try:
        publisher.wait_for_subscriber(2.0)
        return loopback_ms(
            lambda seq: publisher.publish(
                Pose("cf1", seq, clock.now(), (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0))
            ),
            source,
            n,
        )
    finally:
        source.close()
        publisher.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--frames", type=int, default=500, help="loopback samples per source")
    args = parser.parse_args(argv)
    datagrams = recorded_frames()
    nat_med, nat_p99 = natnet_loopback(args.frames)
    zmq_med, zmq_p99 = zmq_loopback(args.frames)
    figures = {
        "parse_real_frame_us": round(parse_us(datagrams), 2),
        "arrival_to_pose_us": round(arrival_to_pose_us(datagrams), 2),
        "natnet_loopback_ms": round(nat_med, 3),
        "natnet_loopback_p99_ms": round(nat_p99, 3),
        "zmq_loopback_ms": round(zmq_med, 3),
        "zmq_loopback_p99_ms": round(zmq_p99, 3),
        "frames": len(datagrams),
        "samples": args.frames,
        "python": sys.version.split()[0],
    }
    if args.json:
        print(json.dumps(figures))
        return 0
    print(
        f"parse one real NatNet 3.0 frame (332 B)   median {figures['parse_real_frame_us']:8.2f} us"
    )
    print(
        f"packet arrival -> Pose (client path)      median {figures['arrival_to_pose_us']:8.2f} us"
    )
    print(
        f"NatNet send -> waiting loop has the Pose  median {nat_med:8.3f} ms   p99 {nat_p99:.3f} ms"
    )
    print(
        f"ZMQ send -> waiting loop has the Pose     median {zmq_med:8.3f} ms   p99 {zmq_p99:.3f} ms"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
