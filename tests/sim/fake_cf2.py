#!/usr/bin/env python3
"""A test double of cf2's socket side (the Crazyflie SITL firmware), run as `fake_cf2.py
PORT ADDRESS` in place of the real binary, for CI where the firmware is not built.

It speaks what the harness relies on (perchd/sim/firmware/cf2wire.py): the 0xF3 hello
(re-sent until answered), IMU/pose/baro packets in, the 90 01 "calibrated" packet once
1024 IMU samples and 1 s have passed, link echoes (port 15 ch 0) answered as the firmware's
link service does, and replies sent to the source of the last datagram it received. As
"control" it passes an RPYT packet's thrust straight to the four motors (no attitude loop).

Environment: FAKE_CF2_HANG=PATH: if PATH does not exist, create it and stall before
calibrating (the start-up hang), so only the first launch hangs. FAKE_CF2_REPORT=PATH:
on SIGTERM write what it received as JSON there.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import struct
import sys
import time


def main() -> None:
    port, host = int(sys.argv[1]), sys.argv[2]
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("0.0.0.0", 0))
    peer = (host, port)
    hang = os.environ.get("FAKE_CF2_HANG")
    hang_now = bool(hang) and not os.path.exists(hang)
    if hang_now:
        open(hang, "w").close()
    seen = {
        "imu": 0,
        "extpose": 0,
        "baro": 0,
        "rpyt": [],
        "echo": 0,
        "other": 0,
        "acc_last": None,
        "gyro_last": None,
        "pose_last": None,
        "pid": os.getpid(),
    }

    def report(*_):
        path = os.environ.get("FAKE_CF2_REPORT")
        if path:
            with open(path, "w") as f:
                json.dump(seen, f)
        sys.exit(0)

    signal.signal(signal.SIGTERM, report)
    sock.settimeout(0.05)
    while True:  # hello until answered
        sock.sendto(b"\xf3", peer)
        try:
            data, addr = sock.recvfrom(64)
        except TimeoutError:
            continue
        if data == b"\xf3":
            break
    print("SOCKET_LINK: Connection established", flush=True)
    t0 = time.monotonic()
    calibrated = False
    sock.settimeout(None)
    while True:
        data, addr = sock.recvfrom(64)
        reply_to = addr  # the firmware answers the last sender
        hdr = data[0] & 0xF3
        if hdr == 0x90 and len(data) == 14 and data[1] == 0:
            seen["imu"] += 1
            raw = struct.unpack("<6h", data[2:])
            seen["acc_last"], seen["gyro_last"] = raw[:3], raw[3:]
            if (
                not calibrated
                and not hang_now
                and seen["imu"] >= 1024
                and time.monotonic() - t0 > 1.0
            ):
                calibrated = True
                sock.sendto(bytes([data[0], 0x01]), reply_to)
        elif hdr == 0x90 and len(data) >= 2 and data[1] == 2:
            seen["baro"] += 1
        elif hdr == 0x61 and data[1] == 8:
            seen["extpose"] += 1
            seen["pose_last"] = struct.unpack("<7f", data[2:30])
        elif hdr == 0xF0:  # link echo
            seen["echo"] += 1
            sock.sendto(data, reply_to)
        elif hdr == 0x30 and len(data) == 15:  # RPYT <fffH
            roll, pitch, yaw, thrust = struct.unpack("<fffH", data[1:])
            seen["rpyt"].append([roll, pitch, yaw, thrust])
            seen["rpyt"] = seen["rpyt"][-50:]
            if calibrated:
                sock.sendto(struct.pack("<B4H", 0x90, thrust, thrust, thrust, thrust), reply_to)
        else:
            seen["other"] += 1


if __name__ == "__main__":
    main()
