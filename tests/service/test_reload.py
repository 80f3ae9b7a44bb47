"""SIGHUP as systemd's Type=notify-reload sends it: RELOADING=1 with MONOTONIC_USEC in one
datagram at once, then the reload, then READY=1; during a flight, after the flight."""

import signal
import time

import pytest
from svc import PLAN, NotifyListener, Serve, ctl

pytestmark = pytest.mark.slow


def monotonic_usec() -> int:
    return time.clock_gettime_ns(time.CLOCK_MONOTONIC) // 1000


def reload_messages(notify: NotifyListener, serve: Serve) -> tuple[str, str, int, int]:
    """SIGHUP; the RELOADING=1 message, the READY=1 that ends the reload, and the
    CLOCK_MONOTONIC [us] before the signal and after RELOADING=1 arrived."""
    notify.drain(0.1)
    notify.messages.clear()
    before = monotonic_usec()
    serve.proc.send_signal(signal.SIGHUP)
    reloading = notify.wait_for("RELOADING=1", 5.0)
    after = monotonic_usec()
    return reloading, notify.wait_for("READY=1", 5.0), before, after


def fields(message: str) -> dict[str, str]:
    return dict(line.split("=", 1) for line in message.split("\n"))


def test_sighup_sends_reloading_with_the_monotonic_time_then_ready(tmp_path, notify):
    serve = Serve(tmp_path, notify, "--driver", "sim://", "--mocap", "sim://")
    try:
        notify.wait_for("READY=1")
        serve.config.write_text(serve.config.read_text() + 'vehicle = "cf9"\n')
        reloading, ready, before, after = reload_messages(notify, serve)
        assert before <= int(fields(reloading)["MONOTONIC_USEC"]) <= after
        assert notify.messages.index(reloading) < notify.messages.index(ready)
        assert fields(ready)["STATUS"] == "cf9: idle, config reloaded"
        assert ctl(serve.sock, "status")["vehicle"] == "cf9"

        serve.config.write_text(serve.config.read_text() + "bogus = 1\n")
        reloading, ready, before, after = reload_messages(notify, serve)
        assert before <= int(fields(reloading)["MONOTONIC_USEC"]) <= after
        assert fields(ready)["STATUS"].startswith("cf9: idle, reload failed: ")
        assert "bogus" in fields(ready)["STATUS"]
        assert ctl(serve.sock, "status")["vehicle"] == "cf9"  # the old config flies on
        serve.proc.send_signal(signal.SIGTERM)
        code, err = serve.stop()
    finally:
        serve.kill()
    assert code == 0 and "config not reloaded, keeping the old one" in err


def test_a_reload_during_a_flight_waits_for_the_flight_to_end(tmp_path, notify):
    serve = Serve(tmp_path, notify, "--driver", "sim://", "--mocap", "sim://")
    try:
        notify.wait_for("READY=1")
        started = ctl(serve.sock, "fly", str(PLAN))
        serve.wait_phase({"takeoff", "hold", "approach"})
        serve.config.write_text(serve.config.read_text() + 'vehicle = "cf9"\n')
        notify.drain(0.1)
        notify.messages.clear()
        serve.proc.send_signal(signal.SIGHUP)
        reloading = notify.wait_for("RELOADING=1", 5.0)
        assert "MONOTONIC_USEC" in fields(reloading)
        notify.drain(0.5)
        assert notify.count("READY=1") == 0  # not while flying ...
        mid = ctl(serve.sock, "status")
        assert mid["state"] == "flying" and mid["vehicle"] == "cf1"  # ... on the old config
        assert ctl(serve.sock, "abort")["aborting"] is True
        ready = notify.wait_for("READY=1", 10.0)
        assert fields(ready)["STATUS"] == "cf9: idle, config reloaded"
        after = ctl(serve.sock, "status")
        assert after["vehicle"] == "cf9" and after["last"]["log"] == started["log"]
        serve.proc.send_signal(signal.SIGTERM)
        code, err = serve.stop()
    finally:
        serve.kill()
    assert code == 0 and "reload deferred until the flight ends" in err
