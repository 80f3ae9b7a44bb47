"""`perchd ctl {fly P.json [--wait] | abort | status} [--socket PATH]`: talk to `perchd serve`
over its control socket (docs/contracts.md §4). Prints the reply as one JSON object; exit 0 when it
says ok (with --wait: when the flight ended in contact), 1 otherwise."""

from __future__ import annotations

import argparse
import json
import os
import time

from perchd.service.control_socket import request

DEFAULT_SOCKET = "/run/perchd/control.sock"
WAIT_POLL_S = 0.2


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("ctl", help="control a running perchd serve",
                              description=__doc__.splitlines()[0])
    p.add_argument("--socket", default=DEFAULT_SOCKET, help=f"control socket (default {DEFAULT_SOCKET})")
    sub = p.add_subparsers(dest="cmd", required=True)
    fly = sub.add_parser("fly", help="start a flight along a plan file")
    fly.add_argument("plan", help="plan file inside the service's plan_dir: a name there, or a path under it")
    fly.add_argument("--wait", action="store_true", help="wait for the flight to end; print its outcome")
    sub.add_parser("abort", help="abort the flight (failsafe), or make an idle vehicle safe")
    sub.add_parser("status", help="the service's state and the flight in progress")
    for q in sub.choices.values():  # `ctl fly P --socket S` works as well as `ctl --socket S fly P`
        q.add_argument("--socket", default=argparse.SUPPRESS, help=argparse.SUPPRESS)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:

    req: dict = {"cmd": args.cmd}
    if args.cmd == "fly":
        # a file that exists here goes by its absolute path; otherwise the service looks in plan_dir
        req["plan"] = os.path.abspath(args.plan) if os.path.exists(args.plan) else args.plan
    reply = request(args.socket, req)
    if args.cmd == "fly" and reply.get("ok") and args.wait:
        reply = _wait(args.socket, reply["log"])
        print(json.dumps(reply))
        return 0 if reply.get("outcome") == "CONTACT" else 1
    print(json.dumps(reply))
    return 0 if reply.get("ok") else 1


def _wait(socket_path: str, log: str) -> dict:
    """Poll status until the flight writing `log` has ended; its result."""

    while True:
        st = request(socket_path, {"cmd": "status"})
        if st.get("state") != "flying" or st.get("log") != log:
            last = st.get("last") or {}
            return last if last.get("log") == log else {"ok": False, "error": "flight result lost"}
        time.sleep(WAIT_POLL_S)
