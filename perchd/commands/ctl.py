"""`perchd ctl {fly P.json [--wait] | abort | status} [--socket PATH]`: talk to `perchd serve`
over its control socket (docs/contracts.md §4). Prints the reply as readable `key: value` lines
(--json: the reply as one JSON object); a refusal goes to stderr as one line. Exit 0 when it
says ok (with --wait: when the flight ended in contact), 1 otherwise."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

from perchd.core.errors import LinkError
from perchd.service.control_socket import request

DEFAULT_SOCKET = "/run/perchd/control.sock"
WAIT_POLL_S = 0.2


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("ctl", help="control a running perchd serve",
                              description=__doc__.splitlines()[0])
    p.add_argument("--socket", default=DEFAULT_SOCKET, help=f"control socket (default {DEFAULT_SOCKET})")
    p.add_argument("--json", action="store_true", help="print the reply as one JSON object")
    sub = p.add_subparsers(dest="cmd", required=True)
    fly = sub.add_parser("fly", help="start a flight along a plan file")
    fly.add_argument("plan", help="plan file inside the service's plan_dir: a name there, or a path under it")
    fly.add_argument("--wait", action="store_true", help="wait for the flight to end; print its outcome")
    sub.add_parser("abort", help="abort the flight (failsafe), or make an idle vehicle safe")
    sub.add_parser("status", help="the service's state and the flight in progress")
    for q in sub.choices.values():  # `ctl fly P --socket S` works as well as `ctl --socket S fly P`
        q.add_argument("--socket", default=argparse.SUPPRESS, help=argparse.SUPPRESS)
        q.add_argument("--json", action="store_true", default=argparse.SUPPRESS,
                       help=argparse.SUPPRESS)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:

    req: dict = {"cmd": args.cmd}
    if args.cmd == "fly":
        # a file that exists here goes by its absolute path; otherwise the service looks in plan_dir
        req["plan"] = os.path.abspath(args.plan) if os.path.exists(args.plan) else args.plan
    reply = ask(args.socket, req)
    if args.cmd == "fly" and reply.get("ok") and args.wait:
        reply = _wait(args.socket, reply["log"])
        show(reply, args.json)
        return 0 if reply.get("outcome") == "CONTACT" else 1
    show(reply, args.json)
    return 0 if reply.get("ok") else 1


def ask(socket_path: str, req: dict) -> dict:
    """One request; no service there is one line saying what to check (exit 1)."""
    try:
        return request(socket_path, req)
    except LinkError as err:
        raise LinkError(f"is perchd serve running? (socket {socket_path}: "
                        f"{str(err).rpartition(': ')[2]})") from None


def show(reply: dict, as_json: bool) -> None:
    """--json: the reply on stdout. Else readable lines, and a refusal on stderr."""
    if as_json:
        print(json.dumps(reply))
    elif reply.get("ok") is False or "error" in reply:
        print(f"perchd ctl: {reply.get('error', 'refused')}", file=sys.stderr)
    else:
        print("\n".join(lines(reply)))


def lines(reply: dict, prefix: str = "") -> list[str]:
    """`key: value` per field, nested objects as `outer.inner: value`; `ok` left out."""
    out = []
    for key, value in reply.items():
        if key == "ok" and not prefix:
            continue
        if isinstance(value, dict):
            out += lines(value, f"{prefix}{key}.")
        else:
            text = "-" if value is None else f"{value:.4g}" if isinstance(value, float) else value
            out.append(f"{prefix}{key}: {text}")
    return out


def _wait(socket_path: str, log: str) -> dict:
    """Poll status until the flight writing `log` has ended; its result."""

    while True:
        st = ask(socket_path, {"cmd": "status"})
        if st.get("state") != "flying" or st.get("log") != log:
            last = st.get("last") or {}
            return last if last.get("log") == log else {"ok": False, "error": "flight result lost"}
        time.sleep(WAIT_POLL_S)
