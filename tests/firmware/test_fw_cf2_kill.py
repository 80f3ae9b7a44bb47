"""Opt-in (PERCHD_CF2): SIGKILL of `perchd fly` 0.5 s into stage 1 against the Crazyflie
firmware in the loop. The link keeper (drivers/cflink.py) must fly the vehicle down and
stop its motors: from the harness's truth track, the vehicle rises no more than 0.1 m
after the kill and its motors stop within 2.5 s (docs/safety.md, "When the agent dies").

Figures are printed (pytest -s) and, with PERCHD_FW_REPORT=PATH, appended there."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from cf2rig import CF2, needs_cf2
from fwharness import ENV, PLAN, start_harness, stop_harness

pytestmark = [pytest.mark.firmware, needs_cf2]
pytest.importorskip("cflib")

INTO_STAGE1_S = 0.5
RISE_MAX_M = 0.1
MOTORS_STOP_S = 2.5


def stage1_row_seen(log: Path) -> bool:
    """The flight log is flushed per row: the first stage-1 row is the stage's start."""
    try:
        return any('"phase": "stage1"' in ln or '"phase":"stage1"' in ln
                   for ln in log.read_text().splitlines())
    except FileNotFoundError:
        return False


def after_kill(track: list[list], t_kill: float) -> dict:
    """Rise and motor stop from the truth track ([monotonic s, z m, motors on])."""
    before = [z for t, z, _ in track if t <= t_kill]
    after = [(t, z, on) for t, z, on in track if t > t_kill]
    on_after = [t for t, _, on in after if on]
    return {"z_at_kill": before[-1], "rise_m": max(z for _, z, _ in after) - before[-1],
            "motors_stop_s": (on_after[-1] - t_kill + 0.01) if on_after else 0.0,
            "z_at_stop": next((z for t, z, on in after if on_after and t > on_after[-1]), None),
            "track_after_s": after[-1][0] - t_kill}


def test_sigkill_in_stage1_gets_a_descent_and_a_stop(tmp_path):
    proc, mocap, driver = start_harness("--cf2", CF2, "--link", "udp://127.0.0.1:0",
                                        "--fw-log", str(tmp_path / "cf2.log"), env=ENV)
    log = tmp_path / "flight.jsonl"
    t_kill = None
    try:
        fly = subprocess.Popen(
            [sys.executable, "-m", "perchd", "fly", str(PLAN), "--driver", driver, "--mocap",
             mocap, "--log", str(log), "--json"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
        deadline = time.monotonic() + 60
        while fly.poll() is None and time.monotonic() < deadline and not stage1_row_seen(log):
            time.sleep(0.02)
        if fly.poll() is None and stage1_row_seen(log):
            time.sleep(INTO_STAGE1_S)
            fly.send_signal(signal.SIGKILL)
            t_kill = time.monotonic()
        fly.wait(10)
        out, err = fly.communicate()
        time.sleep(MOTORS_STOP_S + 1.0)  # the truth track after the stop
    finally:
        sim = stop_harness(proc, 15.0)
    if t_kill is None:
        pytest.skip(f"the flight ended before stage 1 (noted, not chased): {out}{err[-500:]}")
    figures = {"kill_after_stage1_s": INTO_STAGE1_S, **after_kill(sim["track"], t_kill),
               "launches": [r["outcome"] for r in sim["launches"]]}
    print("\n" + json.dumps(figures))
    if os.environ.get("PERCHD_FW_REPORT"):
        with open(os.environ["PERCHD_FW_REPORT"], "a") as f:
            f.write(json.dumps({"test": "sigkill", **figures}) + "\n")
    assert figures["rise_m"] <= RISE_MAX_M
    assert figures["motors_stop_s"] <= MOTORS_STOP_S
