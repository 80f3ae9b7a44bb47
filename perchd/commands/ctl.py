"""`perchd ctl {fly P.json [--wait] | abort | status} [--socket PATH]`: talk to `perchd serve`
over its control socket (docs/contracts.md §4). Prints the reply as readable `key: value` lines
(--json: the reply as one JSON object); a refusal goes to stderr as one line. Exit 0 when it
says ok (with --wait: when the flight ended in contact), 2 when the service refused the
plan (perchd.flight.planguard, as `perchd fly` does), 1 otherwise. No reply is one line
saying why (no such socket, permission denied, the bound reached, a timeout). An abort the
socket does not take is sent as SIGUSR1, which perchd serve treats as abort, to the pid
listening there (docs/safety.md "The operator always wins")."""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from pathlib import Path

from perchd.core.errors import LinkError
from perchd.service.control_client import TIMEOUT_S, Unreachable, exchange

DEFAULT_SOCKET = "/run/perchd/control.sock"
WAIT_POLL_S = 0.2


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "ctl", help="control a running perchd serve", description=__doc__.splitlines()[0]
    )
    p.add_argument(
        "--socket", default=DEFAULT_SOCKET, help=f"control socket (default {DEFAULT_SOCKET})"
    )
    p.add_argument("--json", action="store_true", help="print the reply as one JSON object")
    sub = p.add_subparsers(dest="cmd", required=True)
    fly = sub.add_parser("fly", help="start a flight along a plan file")
    fly.add_argument(
        "plan", help="plan file inside the service's plan_dir: a name there, or a path under it"
    )
    fly.add_argument(
        "--wait", action="store_true", help="wait for the flight to end; print its outcome"
    )
    sub.add_parser("abort", help="abort the flight (failsafe), or make an idle vehicle safe")
    sub.add_parser("status", help="the service's state and the flight in progress")
    for q in sub.choices.values():  # `ctl fly P --socket S` works as well as `ctl --socket S fly P`
        q.add_argument("--socket", default=argparse.SUPPRESS, help=argparse.SUPPRESS)
        q.add_argument(
            "--json", action="store_true", default=argparse.SUPPRESS, help=argparse.SUPPRESS
        )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:

    req: dict = {"cmd": args.cmd}
    if args.cmd == "fly":
        # a file that exists here goes by its absolute path; otherwise the service looks in plan_dir
        req["plan"] = os.path.abspath(args.plan) if os.path.exists(args.plan) else args.plan
    reply = abort(args.socket) if args.cmd == "abort" else ask(args.socket, req)
    if args.cmd == "fly" and reply.get("ok") and args.wait:
        reply = _wait(args.socket, reply["log"])
        show(reply, args.json)
        return 0 if reply.get("outcome") == "CONTACT" else 1
    show(reply, args.json)
    return 0 if reply.get("ok") else 2 if reply.get("refused") == "plan" else 1


def ask(socket_path: str, req: dict) -> dict:
    """One request; no reply is a LinkError saying why (exit 1)."""
    return exchange(socket_path, req).reply


def abort(socket_path: str, timeout_s: float = TIMEOUT_S) -> dict:
    """Abort over the socket, else by SIGUSR1 to the serve process listening there."""
    try:
        answer = exchange(socket_path, {"cmd": "abort"}, timeout_s)
    except Unreachable as err:
        why, pid = str(err), err.server_pid
    else:
        if answer.reply.get("ok"):
            return answer.reply
        why, pid = answer.reply.get("error", "refused"), answer.server_pid
    if pid is None or not _is_serve(pid):
        raise LinkError(f"abort not delivered: {why}")
    try:
        os.kill(pid, signal.SIGUSR1)
    except OSError as err:
        raise LinkError(
            f"abort not delivered: {why}; SIGUSR1 to perchd serve (pid {pid}): {err.strerror}"
        ) from None
    return {"ok": True, "signalled": pid, "signal": "SIGUSR1", "socket_refused": why}


def _is_serve(pid: int) -> bool:
    """pid runs `perchd serve`: not systemd, which listens for a socket-activated service."""
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except OSError:
        return False
    return b"serve" in argv and any(b"perchd" in a for a in argv)


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
