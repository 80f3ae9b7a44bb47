"""Opt-in (PERCHD_CF2): SIGKILL of `perchd fly` in each phase of a perch (take-off, hold,
approach, stage 2) against the Crazyflie firmware in the loop. The link keeper
(drivers/cflink.py) must bring the vehicle down at a sink it holds on the mocap and stop its
motors: from the harness's truth track, the vehicle rises no more than RISE_MAX_M after the
kill, touches the floor sinking at no more than TOUCHDOWN_MAX_MPS, and its motors stop
(docs/safety.md, "When the agent dies").

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
from stale import harness_config

from perchd.drivers import cflink, cfsink

pytestmark = [pytest.mark.firmware, needs_cf2]
pytest.importorskip("cflib")

RISE_MAX_M = 0.1
REACTION_S = 0.08
"""[s] the keeper's tick, the firmware's commander and the motors' lag, before its brake bites."""
TOUCHDOWN_MAX_MPS = 1.0
FLOOR_M = 0.002
"""[m] the harness's floor is z = 0: at or below this the vehicle is down."""
MOTORS_STOP_S = cflink.DESCENT_MAX_S + 1.0
KILLS = {  # phase: (the first row of the phase that kills, seconds after it)
    "takeoff": (lambda row: row.get("phase") == "takeoff" and (row.get("z") or 0) >= 0.8, 0.0),
    "hold": (lambda row: row.get("phase") == "hold", 0.5),
    "approach": (lambda row: row.get("phase") == "approach", 0.3),
    "stage2": (lambda row: row.get("phase") == "stage2", 0.0),
}


def rows(log: Path) -> list[dict]:
    """The flight log's rows so far (it is flushed per row; a torn last line is skipped)."""
    try:
        lines = log.read_text().splitlines()
    except FileNotFoundError:
        return []
    out = []
    for ln in lines:
        try:
            out.append(json.loads(ln).get("row") or {})
        except json.JSONDecodeError:
            pass
    return out


def touchdown(after: list[tuple[float, float, bool]], t_kill: float) -> dict:
    """The first floor sample after the kill and the sink over the two samples before it."""
    i = next((k for k, (_, z, _) in enumerate(after) if z <= FLOOR_M), None)
    if i is None or i < 2:
        return {"touchdown_s": None, "touchdown_mps": None}
    (t1, z1, _), (t2, z2, _) = after[i - 2], after[i - 1]
    return {
        "touchdown_s": round(after[i][0] - t_kill, 3),
        "touchdown_mps": round((z1 - z2) / (t2 - t1), 3),
    }


def climb_at(track: list[list], t_kill: float, window_s: float = 0.05) -> float:
    """[m/s] the vertical speed over the window_s before the kill, by the truth track."""
    before = [(t, z) for t, z, _ in track if t_kill - window_s <= t <= t_kill]
    (t0, z0), (t1, z1) = before[0], before[-1]
    return (z1 - z0) / (t1 - t0) if t1 > t0 else 0.0


def after_kill(track: list[list], t_kill: float) -> dict:
    """Rise, touchdown and motor stop from the truth track ([monotonic s, z m, motors on])."""
    before = [z for t, z, _ in track if t <= t_kill]
    after = [(t, z, on) for t, z, on in track if t > t_kill]
    on_after = [t for t, _, on in after if on]
    return {
        "z_at_kill": before[-1],
        "vz_at_kill": round(climb_at(track, t_kill), 3),
        "rise_m": round(max(z for _, z, _ in after) - before[-1], 4),
        **touchdown(after, t_kill),
        "motors_stop_s": round(on_after[-1] - t_kill + 0.01, 3) if on_after else 0.0,
        "track_after_s": round(after[-1][0] - t_kill, 3),
    }


def fly_and_kill(tmp_path: Path, phase: str) -> dict | None:
    """A perch, its agent SIGKILLed where KILLS says; the figures, None if never reached."""
    proc, mocap, driver = start_harness(
        "--cf2", CF2, "--link", "udp://127.0.0.1:0", "--fw-log", str(tmp_path / "cf2.log"), env=ENV
    )
    log, (due, delay) = tmp_path / "flight.jsonl", KILLS[phase]
    t_kill = None
    try:
        fly = subprocess.Popen(
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
                str(harness_config(tmp_path)),
                "--log",
                str(log),
                "--json",
            ],
            stdout=subprocess.DEVNULL,
            stderr=(tmp_path / "fly.err").open("w"),
            env=ENV,
        )
        deadline = time.monotonic() + 60
        while fly.poll() is None and time.monotonic() < deadline:
            if any(due(r) for r in rows(log)):
                time.sleep(delay)
                fly.send_signal(signal.SIGKILL)
                t_kill = time.monotonic()
                break
            time.sleep(0.02)
        fly.wait(10)
        time.sleep(MOTORS_STOP_S + 1.0)  # the truth track through the stop
    finally:
        sim = stop_harness(proc, 15.0)
    if t_kill is None:
        return None
    return {
        "phase": phase,
        **after_kill(sim["track"], t_kill),
        "launches": [r["outcome"] for r in sim["launches"]],
    }


@pytest.mark.parametrize("phase", list(KILLS))
def test_sigkill_gets_a_held_sink_a_soft_touchdown_and_a_stop(tmp_path, phase):
    figures = fly_and_kill(tmp_path, phase)
    if figures is None:
        err = (tmp_path / "fly.err").read_text()[-400:]
        pytest.skip(f"the flight ended before the {phase} kill (noted, not chased): {err}")
    print("\n" + json.dumps(figures))
    if os.environ.get("PERCHD_FW_REPORT"):
        with open(os.environ["PERCHD_FW_REPORT"], "a") as f:
            f.write(json.dumps({"test": "sigkill", **figures}) + "\n")
    assert figures["rise_m"] <= RISE_MAX_M
    # no climb of the keeper's own: at most the climb's stopping distance at the open
    # loop's brake, plus the climb over its reaction (the keeper's tick, the motors' lag)
    climb = max(0.0, figures["vz_at_kill"])
    assert figures["rise_m"] <= climb**2 / (2 * cfsink.BRAKE_MPS2) + climb * REACTION_S + 0.005
    assert figures["touchdown_mps"] is not None  # came down to the floor
    assert figures["touchdown_mps"] <= TOUCHDOWN_MAX_MPS
    assert figures["motors_stop_s"] <= MOTORS_STOP_S
