"""Hardware in the loop through libmotioncapture: `perchd sim` serves its poses as Motive
would (NatNet 4.1, multicast on loopback), and `perchd fly` reads them with the library's
optitrack backend, then perches in real time inside the plan's window."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest
from announced import start_announced
from caseplans import PLANS, case1_ipts
from freeport import free_udp_port
from stale import harness_config

from perchd.core.types import EndReason

pytest.importorskip("motioncapture")


pytestmark = pytest.mark.solo  # real-time bounds: see tests/conftest.py


@pytest.mark.slow
def test_the_agent_perches_on_perchd_sim_read_through_libmotioncapture(tmp_path):
    plan = case1_ipts()
    sim, natnet, driver = start_announced(
        "sim",
        "--pose-out",
        f"natnet://127.0.0.1:0?multicast=1&data_port={free_udp_port()}",
        "--setpoint-in",
        "zmq://127.0.0.1:0",
        "--exit-on-stop",
        "--json",
    )
    try:
        command_port = re.search(r"natnet://127\.0\.0\.1:(\d+)", natnet).group(1)
        mocap = (
            "motioncapture://optitrack?hostname=127.0.0.1&interface_ip=127.0.0.1"
            f"&port_command={command_port}&body=cf1"
        )
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "perchd",
                "fly",
                str(PLANS / "case1-ipts-n3.json"),
                "--driver",
                driver,
                "--mocap",
                mocap,
                "--config",
                str(harness_config(tmp_path)),
                "--log",
                str(tmp_path / "hil.jsonl"),
                "--json",
            ],
            capture_output=True,
            text=True,
            timeout=60,
        )
        report = json.loads(sim.communicate(timeout=10)[0])
    finally:
        if sim.poll() is None:
            sim.kill()
            sim.communicate()
    assert done.stdout, done.stderr
    out = json.loads(done.stdout)
    lo, hi = plan.limits.v_contact
    assert EndReason[out["outcome"]] is EndReason.CONTACT
    assert lo <= report["contact_speed"] <= hi
    assert out["perch_time"] == pytest.approx(plan.duration, rel=0.05)
    assert report["stops"] >= 1 and report["rejected"] == 0
