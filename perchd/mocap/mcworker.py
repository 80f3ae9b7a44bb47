"""The process libmotioncapture runs in, and the lines it writes to the agent.

    python -m perchd.mocap.mcworker FD TYPE BODY OPTIONS_JSON

It connects (`motioncapture.connect(TYPE, OPTIONS)`), then writes one JSON line per frame to
file descriptor FD:
    {"ready": true}                                      connected
    {"error": "bind: Address already in use"}            connect failed (then exit 1)
    {"seq": N, "t": T, "p": [x, y, z], "q": [x, y, z, w]}    BODY in frame N
    {"seq": N, "t": T, "seen": ["wand", ...]}                BODY absent (untracked, unknown)
T is time.monotonic() when the library handed the frame over (the pipe's delay is then known;
the camera's is not: the binding gives no latency). Positions are in the server's axes.

Why a process: the binding's `connect` holds the interpreter lock while it waits for the
server, which it may do for ever, so in a thread it would stall the whole agent; and a receive
blocked in C++ cannot be interrupted, only ended with its process (which frees its sockets).
"""

from __future__ import annotations

import json
import os
import sys
import threading
import time
from typing import Any, TextIO

from perchd.core.types import Quat, Vec3


def frame_line(bodies: dict[str, Any], body: str, seq: int, t: float) -> str:
    """The line for frame `seq` of the library's `rigidBodies`, following `body`."""
    rb = bodies.get(body)
    if rb is None:
        return json.dumps({"seq": seq, "t": t, "seen": sorted(bodies)}) + "\n"
    r = rb.rotation
    return (
        json.dumps(
            {"seq": seq, "t": t, "p": [float(v) for v in rb.position], "q": [r.x, r.y, r.z, r.w]}
        )
        + "\n"
    )


def parse_line(line: str) -> dict[str, Any]:
    """A worker line as a dict; ValueError when it is not one."""
    msg = json.loads(line)
    if not isinstance(msg, dict):
        raise ValueError(f"not a JSON object: {line[:80]!r}")
    return msg


def sample(msg: dict[str, Any]) -> tuple[Vec3, Quat] | None:
    """(p, q) of a frame line that has the body, else None; ValueError when malformed."""
    if "p" not in msg:
        return None
    p, q = msg["p"], msg["q"]
    if len(p) != 3 or len(q) != 4:
        raise ValueError(f"p and q of 3 and 4 numbers expected: {p!r}, {q!r}")
    return (float(p[0]), float(p[1]), float(p[2])), (
        float(q[0]),
        float(q[1]),
        float(q[2]),
        float(q[3]),
    )


def serve(out: TextIO, kind: str, body: str, options: dict[str, str]) -> int:
    import motioncapture  # the optional library: only this process loads it

    try:
        mc = motioncapture.connect(kind, options)
    except Exception as err:  # noqa: BLE001 - whatever the library raises, said in one line
        out.write(json.dumps({"error": str(err) or type(err).__name__}) + "\n")
        return 1
    out.write('{"ready": true}\n')
    seq = 0
    while True:
        mc.waitForNextFrame()
        seq += 1
        out.write(frame_line(mc.rigidBodies, body, seq, time.monotonic()))


def _end_with_parent(poll_s: float = 0.5) -> None:
    """End this process once the agent has gone (it is then re-parented). Polled in a thread,
    not PR_SET_PDEATHSIG, which fires when the spawning thread ends, not the agent; while the
    library's connect holds the interpreter lock this waits, and the agent's close or its
    connect timeout is what ends it."""
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_s)
        os._exit(0)

    threading.Thread(target=watch, name="mcworker-parent", daemon=True).start()


def main(argv: list[str]) -> int:
    fd, kind, body, options = int(argv[0]), argv[1], argv[2], json.loads(argv[3])
    _end_with_parent()
    os.dup2(2, 1)  # the library prints to stdout, which may be the agent's JSON output
    with os.fdopen(fd, "w", buffering=1) as out:
        try:
            return serve(out, kind, body, options)
        except (BrokenPipeError, KeyboardInterrupt):
            return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
