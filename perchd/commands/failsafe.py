"""`perchd failsafe`: make the service's vehicle safe after `perchd serve` stopped or died.

`perchd failsafe [--config perchd.toml] [--driver URI] [--timeout S]`, the units'
ExecStopPost=. One line on what it did; exit 0 when done, when there was nothing to do, or
after a clean stop ($SERVICE_RESULT=success); 1 when the vehicle was out of reach
(docs/safety.md, "When the service stops or dies")."""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time

from perchd.core.errors import LinkError, PerchdError
from perchd.service.config import load_config
from perchd.service.failsafe import Outcome, failsafe

DEFAULT_TIMEOUT_S = 5.0
"""[s] the whole command's bound: well inside the units' TimeoutStopSec=30."""
SERVICE_VARS = ("SERVICE_RESULT", "EXIT_CODE", "EXIT_STATUS")
"""What systemd tells ExecStopPost= about the main process's end (systemd.exec(5))."""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "failsafe",
        help="make the service's vehicle safe after the service stopped or died (ExecStopPost)",
        description=__doc__.splitlines()[0],
    )
    p.add_argument("--config", help="the service's configuration (its [service] driver)")
    p.add_argument("--driver", help="vehicle URI (overrides [service] driver)")
    p.add_argument(
        "--timeout",
        type=float,
        default=DEFAULT_TIMEOUT_S,
        help=f"[s] give up after this long (default {DEFAULT_TIMEOUT_S:g})",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if not args.config and not args.driver:
        raise PerchdError("give --config (the service's) or --driver")
    if not 0 < args.timeout <= 60:
        raise PerchdError(f"--timeout {args.timeout:g}: expected 0 < S <= 60")
    uri = args.driver or load_config(args.config).service.driver
    why = ", ".join(f"{v}={os.environ[v]}" for v in SERVICE_VARS if os.environ.get(v))
    try:
        outcome = bounded(uri, args.timeout)
    except LinkError as err:
        if os.environ.get("SERVICE_RESULT") != "success":
            raise LinkError(f"{err}" + (f" ({why})" if why else "")) from None
        # a clean stop: the service sent its own failsafe before it exited
        outcome = Outcome(False, f"{err}; the service stopped cleanly after its own failsafe")
    print(f"perchd failsafe: {outcome.text}" + (f" ({why})" if why else ""), flush=True)
    return 0


def bounded(uri: str, timeout_s: float) -> Outcome:
    """failsafe(uri) in a thread, given up after timeout_s: a link library that hangs must
    not hold systemd's stop (then one line and exit 1, the thread left behind)."""
    deadline = time.monotonic() + timeout_s
    result: list[Outcome | BaseException] = []

    def act() -> None:
        try:
            result.append(failsafe(uri, deadline))
        except BaseException as err:  # noqa: BLE001 - handed to the caller's thread
            result.append(err)

    worker = threading.Thread(target=act, name="failsafe", daemon=True)
    worker.start()
    worker.join(timeout_s + 1.0)  # the action's own deadline first, this as the backstop
    if not result:
        print(f"perchd failsafe: {uri}: gave up after {timeout_s:g} s", file=sys.stderr, flush=True)
        os._exit(1)  # a hung link library's threads would hold the interpreter's exit
    if isinstance(result[0], BaseException):
        raise result[0]
    return result[0]
