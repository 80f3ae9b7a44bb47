"""`perchd serve` as systemd runs it: notify socket, control socket, signals.

The flights are real-time: serve flies against `perchd sim` in another process (zmq://
driver, natnet:// mocap over loopback), or against sim:// in its own process, which the
service paces on the real clock.
"""

import json
import os
import signal
import subprocess
import sys
import time

import pytest
from svc import PLAN, Serve, SimProcess, ctl

from perchd.logs.flightlog import read_log

pytestmark = pytest.mark.slow


@pytest.fixture
def sim():
    s = SimProcess()
    yield s
    s.kill()


def test_sigterm_mid_flight_sends_the_failsafe_closes_the_log_and_exits_0(tmp_path, notify, sim):
    serve = Serve(tmp_path, notify, "--driver", sim.driver, "--mocap", sim.mocap)
    try:
        ready = notify.wait_for("READY=1")
        assert "STATUS=cf1: idle" in ready.split("\n")
        notify.wait_for("WATCHDOG=1")
        started = ctl(serve.sock, "fly", str(PLAN))
        assert started["ok"] and started["flying"]
        assert ctl(serve.sock, "fly", str(PLAN)) == {
            "ok": False,
            "error": "a flight is in progress; abort it or wait",
        }
        mid = serve.wait_phase({"stage1"})
        assert mid["state"] == "flying" and mid["x"] < 0
        pings = notify.count("WATCHDOG=1")
        notify.drain(0.6)  # the flight's own tick callback pings while flying
        assert notify.count("WATCHDOG=1") > pings
        assert any(m.startswith("STATUS=cf1: flying, stage1") for m in notify.messages)
        serve.proc.send_signal(signal.SIGTERM)
        code, err = serve.stop()
    finally:
        serve.kill()
    assert code == 0, err
    assert "SIGTERM: stopping" in err and "flight ended: SIGNAL" in err
    notify.wait_for("STOPPING=1", 2.0)
    log = read_log(started["log"])
    assert log.complete and log.end["outcome"] == "SIGNAL"
    assert log.end["summary"]["failsafe_sent"] is True
    assert log.rows[-1].end == "SIGNAL" and log.rows[-1].phase in ("stage1", "stage2", "abort")
    assert sim.summary()["stops"] >= 1 and not os.path.exists(serve.sock)


def test_abort_over_the_socket_ends_the_flight_and_the_service_flies_again(tmp_path, notify):
    serve = Serve(tmp_path, notify, "--driver", "sim://", "--mocap", "sim://")
    try:
        notify.wait_for("READY=1")
        first = ctl(serve.sock, "fly", PLAN.name)  # a name in plan_dir
        serve.wait_phase({"takeoff", "hold", "approach"})
        assert ctl(serve.sock, "abort")["aborting"] is True
        deadline = time.monotonic() + 5
        while (st := ctl(serve.sock, "status"))[
            "state"
        ] == "flying" and time.monotonic() < deadline:
            time.sleep(0.05)
        assert st["last"]["outcome"] == "OPERATOR_ABORT" and st["last"]["failsafe_sent"]
        assert ctl(serve.sock, "abort") == {"ok": True, "flying": False, "failsafe_sent": True}
        second = ctl(serve.sock, "fly", str(PLAN))
        assert second["ok"] and second["log"] != first["log"]
        serve.proc.send_signal(signal.SIGINT)
        code, _ = serve.stop()
    finally:
        serve.kill()
    assert code == 130  # Ctrl-C, as every command; SIGTERM (systemctl stop) exits 0
    assert read_log(first["log"]).end["outcome"] == "OPERATOR_ABORT"
    assert read_log(second["log"]).end["outcome"] == "SIGNAL"


def test_sighup_reloads_the_config_and_a_bad_one_is_kept_out(tmp_path, notify):
    serve = Serve(tmp_path, notify, "--driver", "sim://", "--mocap", "sim://")
    try:
        notify.wait_for("READY=1")
        serve.config.write_text(serve.config.read_text() + 'vehicle = "cf9"\n')
        serve.proc.send_signal(signal.SIGHUP)
        notify.wait_for("STATUS=cf9: idle, config reloaded")
        assert ctl(serve.sock, "status")["vehicle"] == "cf9"
        serve.config.write_text(serve.config.read_text() + "bogus = 1\n")
        serve.proc.send_signal(signal.SIGHUP)
        time.sleep(0.5)
        assert ctl(serve.sock, "status")["vehicle"] == "cf9"
        serve.proc.send_signal(signal.SIGTERM)
        code, err = serve.stop()
    finally:
        serve.kill()
    assert code == 0 and "config not reloaded, keeping the old one" in err and "bogus" in err


def test_sigkill_loses_at_most_100_ms_of_the_log(tmp_path, notify):
    serve = Serve(tmp_path, notify, "--driver", "sim://", "--mocap", "sim://")
    try:
        notify.wait_for("READY=1")
        started = ctl(serve.sock, "fly", str(PLAN))
        serve.wait_phase({"approach", "stage1"})
        killed_at = time.monotonic()  # CLOCK_MONOTONIC: the same clock the service logs on
        serve.proc.kill()
        serve.proc.communicate()
    finally:
        serve.kill()
    log = read_log(started["log"])
    assert not log.complete and len(log.rows) > 50
    assert 0 <= killed_at - log.rows[-1].t <= 0.100


def test_the_idle_watchdog_stops_when_the_link_to_the_vehicle_dies(tmp_path, notify, sim):
    serve = Serve(tmp_path, notify, "--driver", sim.driver, "--mocap", sim.mocap)
    try:
        notify.wait_for("READY=1")
        notify.drain(1.2)
        assert notify.count("WATCHDOG=1") >= 2  # every WATCHDOG_USEC / 4 = 0.5 s while healthy
        sim.kill()
        deadline = time.monotonic() + 5
        while ctl(serve.sock, "status")["link_ok"] and time.monotonic() < deadline:
            time.sleep(0.1)
        assert ctl(serve.sock, "status")["link_ok"] is False
        notify.drain(0.1)  # pings already on their way
        notify.messages.clear()
        notify.drain(1.5)
        assert notify.count("WATCHDOG=1") == 0  # systemd would now restart the service
        assert ctl(serve.sock, "fly", str(PLAN)) == {
            "ok": False,
            "error": "the link to the vehicle is down",
        }
        serve.proc.send_signal(signal.SIGTERM)
        code, _ = serve.stop()
    finally:
        serve.kill()
    assert code == 0


@pytest.mark.solo  # a real-time perch: a pose every mocap period (tests/conftest.py)
def test_a_flight_through_ctl_wait_perches_on_the_configured_surface(tmp_path, notify):
    wall = "[surface]\npoint = [2.0, 1.0, 0.0]\nnormal = [0.0, 1.0, 0.0]\n"
    serve = Serve(tmp_path, notify, "--driver", "sim://", "--mocap", "sim://", tables=wall)
    try:
        notify.wait_for("READY=1")
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "perchd",
                "ctl",
                "fly",
                str(PLAN),
                "--wait",
                "--json",
                "--socket",
                str(serve.sock),
            ],
            capture_output=True,
            text=True,
            timeout=30,
        )
        serve.proc.send_signal(signal.SIGTERM)
        serve.stop()
    finally:
        serve.kill()
    out = json.loads(done.stdout)
    assert done.returncode == 0 and out["outcome"] == "CONTACT"
    assert out["true_contact_speed"] is not None  # the simulated wall is where the config says
    assert (
        0.7 <= out["contact_speed"] <= 1.0
        and abs(out["perch_time"] / out["plan_duration"] - 1) < 0.05
    )
    assert out["loop"]["jitter_median_s"] < 0.005  # paced on the real clock, not simulated time
