"""The operator always wins: with every connection `perchd serve` serves held open by idle
clients, an abort mid-flight still ends the flight with OPERATOR_ABORT, over the control
socket (`perchd ctl abort`) or by SIGUSR1 (docs/safety.md "The operator always wins")."""

import json
import signal
import socket
import time

import pytest
from svc import PLAN, Serve, ctl, perchd

from perchd.logs.flightlog import read_log
from perchd.service.control_socket import MAX_CLIENTS

pytestmark = pytest.mark.slow


@pytest.fixture
def flying(tmp_path, notify):
    """A service on sim:// in the middle of a flight that hovers 30 s before its approach, so
    the abort comes before contact however loaded the machine; yields it and the log path."""
    serve = Serve(
        tmp_path,
        notify,
        "--driver",
        "sim://",
        "--mocap",
        "sim://",
        tables="[approach]\nhold_s = 30.0\n",
    )
    try:
        notify.wait_for("READY=1", timeout=30.0)
        started = ctl(serve.sock, "fly", PLAN.name)
        serve.wait_phase({"hold"}, timeout=30.0)
        yield serve, started["log"]
    finally:
        serve.kill()


def exhaust(sock) -> list[socket.socket]:
    """MAX_CLIENTS idle connections, and proof that the bound is reached: a status refused."""
    idle = []
    for _ in range(MAX_CLIENTS):
        c = socket.socket(socket.AF_UNIX)
        c.connect(str(sock))
        idle.append(c)
    refused = perchd("ctl", "--socket", str(sock), "status")
    assert refused.returncode == 1 and refused.stderr.count("\n") == 1
    assert refused.stderr.startswith(
        f"perchd ctl: {MAX_CLIENTS} clients connected already (the bound)"
    )
    return idle


def outcome_after(serve: Serve, log: str, idle: list[socket.socket]) -> str:
    """The flight's end reason once the idle clients have gone and it has ended."""
    for c in idle:
        c.close()
    deadline = time.monotonic() + 10
    while (st := ctl(serve.sock, "status"))["state"] == "flying":
        assert time.monotonic() < deadline, f"the flight did not end: {st}"
        time.sleep(0.05)
    assert st["last"]["log"] == log
    return st["last"]["outcome"]


def test_ctl_abort_mid_flight_gets_through_a_full_bound(flying):
    serve, log = flying
    idle = exhaust(serve.sock)
    done = perchd("ctl", "--socket", str(serve.sock), "--json", "abort")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == {"ok": True, "flying": True, "aborting": True, "log": log}
    assert outcome_after(serve, log, idle) == "OPERATOR_ABORT"
    assert read_log(log).end["outcome"] == "OPERATOR_ABORT"


def test_sigusr1_mid_flight_is_an_abort_however_many_clients_are_connected(flying):
    serve, log = flying
    idle = exhaust(serve.sock)
    serve.proc.send_signal(signal.SIGUSR1)
    assert outcome_after(serve, log, idle) == "OPERATOR_ABORT"
    serve.proc.send_signal(signal.SIGTERM)
    code, err = serve.stop()
    assert code == 0 and "SIGUSR1: abort (flight aborting)" in err
