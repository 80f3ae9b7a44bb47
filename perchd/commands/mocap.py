"""`perchd mocap URI [--count N] [--json]`: print poses as they arrive, to check the mocap
before flying. With --json, one object per line: body, seq, t, p, q, valid, latency. No pose
for --timeout is one line and exit 1; SIGINT or SIGTERM end it with the counts in one line,
exit 130 or 143 (docs/contracts.md §6)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from perchd.console.stopping import interruptible
from perchd.core.errors import LinkError
from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.mocap.base import open_source


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "mocap",
        help="print the poses a mocap source delivers",
        description="Print poses as they arrive, e.g. natnet://10.0.0.5?body=cf1 or "
        "zmq://127.0.0.1:5555?body=cf1.",
    )
    parser.add_argument("uri", help="mocap source URI")
    parser.add_argument(
        "--count",
        type=_positive_int,
        default=None,
        help="stop after N poses (default: until interrupted)",
    )
    parser.add_argument("--json", action="store_true", help="one JSON object per pose")
    parser.add_argument(
        "--timeout",
        type=_positive_float,
        default=5.0,
        help="[s] give up when no pose arrives for this long (default 5)",
    )
    parser.set_defaults(run=run)


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"--count must be at least 1, got {value}")
    return value


def _positive_float(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"--timeout must be > 0 s, got {value:g}")
    return value


def pose_json(pose: Pose) -> str:
    return json.dumps(
        {
            "body": pose.body,
            "seq": pose.seq,
            "t": pose.t,
            "p": list(pose.p),
            "q": list(pose.q),
            "valid": pose.valid,
            "latency": pose.latency,
        }
    )


def pose_line(pose: Pose) -> str:
    p = " ".join(f"{v:+.4f}" for v in pose.p)
    q = " ".join(f"{v:+.4f}" for v in pose.q)
    state = "valid" if pose.valid else "NOT TRACKED"
    return (
        f"{pose.body} #{pose.seq} t={pose.t:.4f} s  p=[{p}] m  q=[{q}]  {state}  "
        f"latency {pose.latency * 1000:.2f} ms"
    )


def with_timeout(uri: str, timeout: float) -> str:
    """A natnet:// URI without its own timeout= waits --timeout for the server too (it said
    "within 2.0 s" whatever --timeout was); the URI's own value wins."""
    if not uri.startswith("natnet://") or "timeout=" in uri:
        return uri
    return f"{uri}{'&' if '?' in uri else '?'}timeout={min(max(timeout, 0.05), 60.0):g}"


def run(args: argparse.Namespace) -> int:

    source = None
    with interruptible() as caught:
        try:
            source = open_source(with_timeout(args.uri, args.timeout), Runtime.real())
            source.start()
            show(source, args)
            print(f"perchd mocap: {_summary(source)}", file=sys.stderr)
        finally:
            if source is not None:
                source.close()
        return 0
    caught.say("mocap", _summary(source) if source is not None else "nothing received")
    return caught.exit_code(130)


def show(source: Any, args: argparse.Namespace) -> None:
    """Print poses until --count; LinkError (its one line holds the counts) after
    --timeout without one."""
    shown, seq = 0, -(2**63)
    while args.count is None or shown < args.count:
        pose = source.wait(seq, args.timeout)
        if pose is None:
            raise LinkError(
                f"no pose from {args.uri} within {args.timeout:g} s ({_summary(source)})"
            )
        if pose.seq < seq:  # the sender restarted its numbering
            seq = pose.seq
        print(pose_json(pose) if args.json else pose_line(pose), flush=True)
        shown, seq = shown + 1, pose.seq


def _summary(source) -> str:
    stats = source.stats()
    return f"{stats.received} received, {stats.poses} poses, {stats.dropped} dropped"
