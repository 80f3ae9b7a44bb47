"""The firmware harness on real loopback sockets, with a test double of cf2's socket side
(tests/sim/fake_cf2.py) launched as the firmware: handshake, 1 kHz IMU, relaunch after a
start-up hang, cflib's udp:// link through the relay, and `perchd sim firmware` itself."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from perchd.core.errors import LinkError, UriError
from perchd.core.runtime import Runtime
from perchd.core.types import Phase, Setpoint
from perchd.sim.firmware.cf2 import Cf2Params, Cf2Vehicle
from perchd.sim.firmware.harness import ProcessGroup
from perchd.sim.firmware.relay import ClientRelay

FAKE = Path(__file__).with_name("fake_cf2.py")


@pytest.fixture
def fake(tmp_path, monkeypatch):
    """An executable that runs the fake firmware, and where it reports on SIGTERM."""
    exe = tmp_path / "cf2"
    exe.write_text(f'#!/bin/sh\nexec {sys.executable} {FAKE} "$@"\n')
    exe.chmod(0o755)
    monkeypatch.setenv("FAKE_CF2_REPORT", str(tmp_path / "report.json"))
    return exe


def params(exe: Path, tmp_path: Path, **kw) -> Cf2Params:
    return Cf2Params(
        str(exe),
        link="udp://127.0.0.1:0",
        start=(-1.0, 0.0, 0.0),
        log=tmp_path / "fw.log",
        settle_s=0.2,
        **kw,
    )


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_the_relay_answers_cflibs_scan_probe_and_forwards_the_rest_both_ways():
    relay = ClientRelay("udp://127.0.0.1:0")
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.settimeout(1.0)
    try:
        client.connect(("127.0.0.1", relay.port))  # as cflib's udp driver does
        client.send(b"\xff")
        client.send(bytes.fromhex("3C 00000000 00000000 00000000 0000"))
        time.sleep(0.05)
        assert relay.poll(5) == [bytes.fromhex("3C 00000000 00000000 00000000 0000")]
        assert client.recv(64) == b"\xff"  # the scan's answer; the probe is not forwarded
        relay.send(bytes.fromhex("FC 7064"))
        assert client.recv(64) == bytes.fromhex("FC 7064")
        assert (relay.counts.probes, relay.counts.from_client, relay.counts.to_client) == (1, 1, 1)
    finally:
        client.close()
        relay.close()


def test_the_relay_hands_over_at_most_limit_packets_per_poll():
    relay = ClientRelay("udp://127.0.0.1:0")
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for k in range(5):
            client.sendto(bytes([0x3C, k]), ("127.0.0.1", relay.port))
        time.sleep(0.05)
        assert relay.poll(2) == [b"\x3c\x00", b"\x3c\x01"]
        assert relay.poll(10) == [b"\x3c\x02", b"\x3c\x03", b"\x3c\x04"]
    finally:
        client.close()
        relay.close()


def test_cf2_gets_a_handshake_1khz_imu_and_ext_pose_and_is_ready(fake, tmp_path):
    with ProcessGroup() as procs:
        v = Cf2Vehicle(params(fake, tmp_path))
        try:
            v.start(procs, threading.Event())
            assert [r["outcome"] for r in v.launches] == ["ready"]
            pid = v.launches[0]["pid"]
            time.sleep(1.0)
            stats = v.summary()
        finally:
            v.close()
    assert not alive(pid)  # stopped with the group
    report = json.loads((tmp_path / "report.json").read_text())
    # 1 g of the model's gravity, 9.80665 m/s^2, in the IMU's 9.81 scale: 2047.3 -> 2047
    assert report["acc_last"] == [0, 0, 2047] and report["gyro_last"] == [0, 0, 0]
    assert 900 <= stats["imu"]["rate_hz"] <= 1010  # real time, however loaded the CI is
    assert report["imu"] >= 1800  # calibration (>= 1 s) + 0.2 s settle + 1 s
    assert 0.08 <= report["extpose"] / report["imu"] <= 0.11  # 100 Hz
    assert report["pose_last"] == pytest.approx([-1, 0, 0, 0, 0, 0, 1])


def test_a_firmware_that_stalls_before_calibrating_is_killed_and_launched_again(
    fake, tmp_path, monkeypatch
):
    monkeypatch.setenv("FAKE_CF2_HANG", str(tmp_path / "hung-once"))
    with ProcessGroup() as procs:
        v = Cf2Vehicle(params(fake, tmp_path, calibration_timeout_s=2.0))
        try:
            v.start(procs, threading.Event())
            hung, ready = v.launches
            assert (hung["outcome"], ready["outcome"]) == ("calibration stalled", "ready")
            assert not alive(hung["pid"]) and alive(ready["pid"])
            assert [p.pid for p in procs.running] == [ready["pid"]]
        finally:
            v.close()
    assert not alive(ready["pid"])


def test_a_start_on_or_past_the_surface_is_refused(fake, tmp_path):
    with pytest.raises(UriError, match=r"start .* is on or past the surface"):
        Cf2Vehicle(Cf2Params(str(fake), link="udp://127.0.0.1:0", start=(0.5, 0.0, 0.0)))


def test_a_firmware_that_never_runs_is_one_link_error_naming_the_launches(tmp_path):
    exe = tmp_path / "cf2"
    exe.write_text("#!/bin/sh\nexit 3\n")
    exe.chmod(0o755)
    with ProcessGroup() as procs:
        v = Cf2Vehicle(params(exe, tmp_path, launches=2, handshake_timeout_s=0.5))
        try:
            with pytest.raises(LinkError, match=r"not ready after 2 launches \(exited, exited\)"):
                v.start(procs, threading.Event())
        finally:
            v.close()


def test_perchds_crazyflie_driver_reaches_the_firmware_through_the_relay(fake, tmp_path):
    pytest.importorskip("cflib")
    from perchd.drivers.base import open_driver

    with ProcessGroup() as procs:
        v = Cf2Vehicle(params(fake, tmp_path))
        try:
            v.start(procs, threading.Event())
            with open_driver(v.driver_uri(), Runtime.real()) as cf:  # connect = link echo
                weight = v.params.model.mass_kg * 9.81
                heights = []
                for k in range(40):  # the fake passes the thrust to the motors
                    cf.send(Setpoint(0.0, 0.0, 0.0, 0.0, 1.3 * weight, k, Phase.TAKEOFF))
                    time.sleep(0.01)
                    heights.append(v.truth().p[2])
                assert cf.health().ok
            counts = v.relay.counts
        finally:
            v.close()
    assert max(heights) > 0.01  # it took off: the thrust went round
    assert counts.from_client > 40 and counts.to_client > 5  # echoes came back


def test_perchd_sim_firmware_announces_itself_and_stops_everything_on_sigterm(fake, tmp_path):
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "perchd",
            "sim",
            "firmware",
            "--cf2",
            str(fake),
            "--link",
            "udp://127.0.0.1:0",
            "--fw-log",
            str(tmp_path / "fw.log"),
            "--json",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(Path(__file__).parents[2])},
    )
    try:
        line = proc.stderr.readline()
        found = re.search(r"^perchd sim: ready: mocap (zmq://\S+) driver (udp://\S+)$", line)
        assert found, line + proc.stderr.read()
        assert "hover=38780" in found.group(2)
        time.sleep(0.5)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, err  # SIGTERM: docs/contracts.md §6
    summary = json.loads(out)
    assert summary["mocap"] == found.group(1) and summary["poses"] > 20
    assert summary["launches"][0]["outcome"] == "ready"
    assert not alive(summary["launches"][0]["pid"])
    assert summary["contact"] is None and summary["final"]["p"] == [-4.5, 0.0, 0.0]


@pytest.mark.skipif(
    not Path("/usr/bin/setpriv").exists() and not os.path.exists("/bin/setpriv"),
    reason="util-linux's setpriv is not installed",
)
def test_a_firmware_dies_with_a_harness_killed_by_sigkill(tmp_path):
    """A harness SIGKILLed cannot stop its children: the kernel does (tied_to_parent)."""
    pidfile = tmp_path / "child.pid"
    harness = subprocess.Popen(
        [
            sys.executable,
            "-c",
            (
                "import sys, time\n"
                "from pathlib import Path\n"
                "from perchd.sim.firmware.harness import ProcessGroup\n"
                "proc = ProcessGroup().launch(['sleep', '60'], Path(sys.argv[1]))\n"
                "Path(sys.argv[2]).write_text(str(proc.pid))\n"
                "time.sleep(60)\n"
            ),
            str(tmp_path / "fw.log"),
            str(pidfile),
        ]
    )
    try:
        deadline = time.monotonic() + 10.0
        while not pidfile.exists() or not pidfile.read_text():
            assert time.monotonic() < deadline, "the harness never launched its child"
            time.sleep(0.02)
        child = int(pidfile.read_text())
        assert alive(child)
        harness.kill()
        harness.wait()
        deadline = time.monotonic() + 2.0
        while alive(child) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert not alive(child), "the firmware outlived its harness"
    finally:
        harness.kill()


@pytest.mark.skipif(not Path("/proc/self/timerslack_ns").exists(), reason="Linux timer slack")
def test_a_child_started_with_fine_timer_slack_sleeps_to_the_microsecond(tmp_path):
    """PX4 SIH sleeps each 4 ms step's remainder: at Linux's default 50 us slack it fell
    0.4-1.1 % behind the wall clock. The child inherits 1 us through exec; the harness's own
    thread gets its slack back."""
    from perchd.sim.firmware.harness import fine_timer_slack

    before = Path("/proc/self/timerslack_ns").read_text()
    group = ProcessGroup()
    try:
        with fine_timer_slack():
            proc = group.launch(["cat", "/proc/self/timerslack_ns"], tmp_path / "cat.log")
        proc.wait(5)
    finally:
        group.close()
    assert (tmp_path / "cat.log").read_text().strip() == "1000"
    assert Path("/proc/self/timerslack_ns").read_text() == before
