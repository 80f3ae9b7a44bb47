"""Opt-in (PERCHD_CF2): a whole perch against the Crazyflie firmware in the loop, as a
user runs it: `perchd sim firmware --cf2 ...` in one process, `perchd fly
plans/case1-ipts-n3.json --driver udp://... --mocap zmq://...` in another.

Figures (contact speed, perch time against the plan's, trigger speed, yaw range, the lag
and drag the flight identified, the harness's IMU rate) are printed (pytest -s) and, with
PERCHD_FW_REPORT=PATH, appended there as JSON lines. The mocap carries 1 mm of noise."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from cf2rig import CF2, needs_cf2
from fwharness import ENV, PLAN, lag_event, start_harness, stop_harness
from stale import harness_config

from perchd.drivers.thrust import CrazyflieThrust

pytestmark = [pytest.mark.firmware, needs_cf2]
pytest.importorskip("cflib")

HOVER_TRUE_N = CrazyflieThrust().newtons(38780)
"""[N] the SITL vehicle's weight (it hovers at 38780 units) in the newtons of the driver's
default thrust model, which the flight flies in when no hover= calibrates it."""


def harness(tmp: Path) -> tuple[subprocess.Popen, str, str]:
    return start_harness(
        "--cf2",
        CF2,
        "--link",
        "udp://127.0.0.1:0",
        "--noise",
        "0.001",
        "--fw-log",
        str(tmp / "cf2.log"),
        env=ENV,
    )


@pytest.mark.parametrize("flight", [1, 2, 3])
def test_the_agent_perches_on_the_firmware_in_the_loop(tmp_path, flight):
    plan = json.loads(PLAN.read_text())
    proc, mocap, driver = harness(tmp_path)
    driver = driver.split("?")[0]  # no mass, no hover: the hold learns it
    config = harness_config(tmp_path)  # as benchmarks/firmware.py flies cf2
    try:
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "perchd",
                "fly",
                str(PLAN),
                "--driver",
                driver,
                "--mocap",
                mocap,
                "--config",
                str(config),
                "--log",
                str(tmp_path / "flight.jsonl"),
                "--state",
                str(tmp_path / "vehicles.json"),
                "--json",
            ],
            capture_output=True,
            text=True,
            timeout=90,
            env=ENV,
        )
    finally:
        sim = stop_harness(proc, 15.0)
    assert done.stdout, done.stderr
    fly = json.loads(done.stdout)
    lo, hi = plan["limits"]["v_contact"]
    yaws = sim["yaw_range_rad"]  # the true heading over the whole run
    figures = {
        "flight": flight,
        "outcome": fly["outcome"],
        "contact_speed": fly["contact_speed"],
        "true_contact_speed": sim["contact"] and sim["contact"]["speed"],
        "perch_time": fly["perch_time"],
        "plan_duration": plan["duration"],
        "trigger_speed": fly["trigger"] and fly["trigger"]["v"],
        "hover_n": fly["hover_n"],
        "hover_true_n": HOVER_TRUE_N,
        "yaw_range_rad": yaws,
        "lag": lag_event(tmp_path / "flight.jsonl"),
        "imu_rate_hz": sim["imu"]["rate_hz"],
        "imu_late_max_ms": sim["imu"]["late_max_ms"],
        "imu_skipped": sim["imu"]["skipped_late"],
        "launches": [r["outcome"] for r in sim["launches"]],
    }
    print("\n" + json.dumps(figures))
    if os.environ.get("PERCHD_FW_REPORT"):
        with open(os.environ["PERCHD_FW_REPORT"], "a") as f:
            f.write(json.dumps(figures) + "\n")
    assert fly["outcome"] == "CONTACT", fly.get("detail")
    assert sim["contact"] is not None
    assert lo <= sim["contact"]["speed"] <= hi
    # measured (docs/firmware.md): -0.03 m/s and +1.4..2 % with the lag and drag identified,
    # -0.055 m/s and +5.2 % without
    assert sim["contact"]["speed"] == pytest.approx(fly["v_hold_mps"], abs=0.05)
    assert fly["perch_time"] == pytest.approx(plan["duration"], rel=0.03)
    assert 0.05 <= figures["lag"]["lag_s"] <= 0.3 and 0.1 <= figures["lag"]["drag_per_s"] <= 0.4
    assert fly["hover_n"] == pytest.approx(HOVER_TRUE_N, rel=0.03)
    # The approach's speed integral: without it x0 was reached 0.085-0.089 m/s slow; with
    # it the error spreads +-0.031 m/s over 30 flights (benchmarks/firmware.py). The
    # approach now leads into the plan's first acceleration (1.2 m/s^2 against its 0.75),
    # which the firmware starts to answer before its identified lag: +0.027 m/s median over
    # 35 flights of benchmarks/firmware.py and benchmarks/ablation_firmware.py (0.048 at
    # most), and one of this test's flights at 0.060.
    assert abs(fly["trigger"]["v"] - plan["v0"]) < 0.07
    assert max(abs(y) for y in yaws) < 0.1  # the heading held (a yaw run-away fails here)
