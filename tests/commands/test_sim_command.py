"""`perchd sim` as its own process: hardware-in-the-loop over real sockets.

The agent flies with the zmq:// driver and the natnet:// mocap against `perchd sim` in
another process, and must perch within the tolerances the in-process simulator meets
(tests/flight/test_perch_acceptance.py): contact inside the speed window and within
0.05 m/s of the plan's speed, the planned time within 5 %.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zmq
from announced import start_announced
from caseplans import PLANS, case1_ipts
from stale import harness_config

import perchd.flight.run as flight
from perchd.core.clock import ManualClock
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason
from perchd.drivers.base import open_driver
from perchd.mocap.base import open_source


class SimProcess:
    """`perchd sim` in a child process; .mocap and .driver are the URIs it announced."""

    def __init__(self, *extra: str, pose_out: str = "natnet://127.0.0.1:0") -> None:
        self.proc, self.mocap, self.driver = start_announced(
            "sim", "--pose-out", pose_out, "--setpoint-in", "zmq://127.0.0.1:0", "--json", *extra
        )

    def finish(self, timeout: float = 10.0) -> dict:
        """Its one JSON summary after --exit-on-stop (exit 0), or after a SIGTERM we send
        when it has not stopped (exit 143, docs/contracts.md §6)."""
        expected = 0
        try:
            out, _ = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.send_signal(signal.SIGTERM)
            out, _ = self.proc.communicate(timeout=5.0)
            expected = 128 + signal.SIGTERM
        assert self.proc.returncode == expected
        return json.loads(out)

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()


def fly_agent(sim: SimProcess, log: Path):
    """`perchd fly` against the sim process, as a user runs it, with the stale limit of a
    mocap process on these shared cores (stale.py)."""
    config = harness_config(log.parent)
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "perchd",
            "fly",
            str(PLANS / "case1-ipts-n3.json"),
            "--driver",
            sim.driver,
            "--mocap",
            sim.mocap,
            "--config",
            str(config),
            "--log",
            str(log),
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.stdout, done.stderr
    out = json.loads(done.stdout)
    return EndReason[out["outcome"]], out["contact_speed"], out["perch_time"]


def fly_in_process(plan, log: Path):
    runtime = Runtime(ManualClock(0.0))
    driver, source = open_driver("sim://", runtime), open_source("sim://", runtime)
    driver.connect()
    source.start()
    try:
        return flight.fly(plan, driver, source, runtime.clock, log, world=runtime.sim)
    finally:
        source.close()
        driver.close()


@pytest.mark.slow
@pytest.mark.solo  # a pose every mocap period across three processes: tests/conftest.py
@pytest.mark.parametrize(
    "pose_out", ["natnet://127.0.0.1:0", "zmq://127.0.0.1:0"], ids=["natnet", "zmq"]
)
def test_the_agent_perches_on_perchd_sim_in_another_process_as_in_process(pose_out, tmp_path):
    plan = case1_ipts()
    reference = fly_in_process(plan, tmp_path / "in_process.jsonl")
    sim = SimProcess("--exit-on-stop", pose_out=pose_out)
    try:
        outcome, speed, perch_time = fly_agent(sim, tmp_path / "hil.jsonl")
        report = sim.finish()
    finally:
        sim.kill()
    lo, hi = plan.limits.v_contact
    assert reference.outcome is outcome is EndReason.CONTACT
    assert lo <= report["contact_speed"] <= hi
    assert report["contact_speed"] == pytest.approx(reference.v_hold_mps, abs=0.05)
    assert report["contact_speed"] == pytest.approx(reference.true_contact_speed, abs=0.05)
    assert speed == pytest.approx(report["contact_speed"], abs=0.05)  # the agent's estimate
    assert perch_time == pytest.approx(plan.duration, rel=0.05)
    assert report["stops"] >= 1 and report["rejected"] == 0


def send(sock, topic: bytes, body: bytes) -> None:
    sock.send_multipart([topic, body])


def test_the_sim_counts_bad_setpoints_obeys_stop_and_reports_on_sigterm():
    sim = SimProcess("--start", "-4.5", "0", "1")
    pub = zmq.Context.instance().socket(zmq.PUB)
    try:
        pub.connect("tcp://" + sim.driver.split("//")[1].split("?")[0])
        time.sleep(0.3)  # let the subscription reach the publisher
        send(pub, b"setpoint", b"{not json")
        send(
            pub,
            b"setpoint",
            json.dumps(
                {
                    "vehicle": "cf1",
                    "seq": 0,
                    "t": 0.0,
                    "pose_seq": 0,
                    "roll": 0.0,
                    "pitch": 0.0,
                    "yaw": 0.0,
                    "thrust": 0.2943,
                    "phase": "hold",
                }
            ).encode(),
        )
        send(pub, b"stop", json.dumps({"vehicle": "cf1", "reason": "operator abort"}).encode())
        time.sleep(0.3)
        report = sim.finish(timeout=0.1)  # SIGTERMs it, which must exit 143
    finally:
        pub.close(0)
        sim.kill()
    assert (report["setpoints"], report["rejected"], report["stops"]) == (1, 1, 1)
    assert report["poses"] > 30 and report["contact"] is False


@pytest.mark.parametrize(
    "args, message",
    [
        (["--pose-out", "udp://x", "--setpoint-in", "zmq://127.0.0.1:0"], "a pose output is"),
        (
            ["--pose-out", "zmq://127.0.0.1:0", "--setpoint-in", "tcp://127.0.0.1:0"],
            "expected zmq://HOST:PORT",
        ),
        (
            [
                "--pose-out",
                "zmq://127.0.0.1:0",
                "--setpoint-in",
                "zmq://127.0.0.1:0",
                "--noise",
                "1",
            ],
            "--noise 1 m",
        ),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(args, message):
    done = subprocess.run(
        [sys.executable, "-m", "perchd", "sim", *args], capture_output=True, text=True, timeout=30
    )
    assert done.returncode == 2
    assert message in done.stderr and len(done.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_stops_the_sim_with_its_summary_and_the_table_s_exit_code(sig):
    """docs/contracts.md §6: 130 after SIGINT, 143 after SIGTERM, the summary still printed."""
    sim = SimProcess()
    try:
        sim.proc.send_signal(sig)
        out, err = sim.proc.communicate(timeout=10)
    finally:
        sim.kill()
    assert sim.proc.returncode == 128 + sig
    assert json.loads(out)["contact"] is False
    assert f"interrupted by {sig.name}" in err
