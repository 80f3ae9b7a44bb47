"""Opt-in (PERCHD_PX4 = a PX4 SITL build folder, docs/firmware.md): perchd against PX4 SIH
over real MAVLink. PX4 takes off to its own Hold; then
- the driver takes the vehicle over in the air without losing more than 0.1 m;
- `perchd fly` perches on a surface placed ahead along the heading (figures printed with
  -s and, with PERCHD_FW_REPORT=PATH, appended there as JSON lines);
- a SIGKILLed `perchd fly` mid-approach leaves PX4 holding or landing, never returning home.
PERCHD_PX4_INSTANCE (default 0) moves every PX4 port by N (one px4 per instance per machine)."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from fwharness import YawWatch, flight_window, heading_error, lag_event, start_placed
from perchd.drivers.base import open_driver

from perchd.core.runtime import Runtime
from perchd.core.types import Phase, Pose, Setpoint
from perchd.sim.firmware.harness import ProcessGroup, yaw_of
from perchd.sim.firmware.px4 import SIH_MASS_KG, Px4Params, Px4Vehicle

PX4 = os.environ.get("PERCHD_PX4", "")
INSTANCE = int(os.environ.get("PERCHD_PX4_INSTANCE", "0"))
pytestmark = [pytest.mark.firmware, pytest.mark.skipif(
    not (PX4 and os.access(Path(PX4) / "bin" / "px4", os.X_OK)),
    reason="set PERCHD_PX4 to a PX4 SITL build folder (docs/firmware.md)")]
pytest.importorskip("pymavlink")

ROOT = Path(__file__).parents[2]
PLAN = ROOT / "plans" / "case1-ipts-n3.json"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
G = 9.81
DRAG = 0.1
"""[N/(m/s)] SIH's linear drag, 1.0 by default: 1.5 m/s^2 against a 1 kg vehicle at the
plan's v0 = 1.5 m/s, more than the plan's a_max = 1.4 m/s^2 (the run-up never reached v0)."""
AHEAD_M = 8.0
"""[m] surface ahead of the hover point: 5 m of run-up to the plan's x0 = -3 m (with 1.5 m,
PX4's attitude lag left the approach at 1.1 of v0 = 1.5 m/s and the trigger refused)."""
CONFIG = f"""version = 1
[vehicle]
mass_kg = {SIH_MASS_KG}
thrust_min_n = 2.0
thrust_max_n = 18.0
[safety]
stale_timeout_s = 0.25
"""
"""SIH's quadrotor: 1 kg, 4 x 5 N; perchd's default vehicle is a 30 g Crazyflie. The stale
limit is 0.25 s instead of 3 mocap periods: on a 2-core machine shared with px4 and the
harness, `perchd fly` was descheduled 35-80 ms at a time (the harness's own mocap stream
measured alone: gaps <= 18 ms)."""


def report(figures: dict) -> None:
    print("\n" + json.dumps(figures))
    if os.environ.get("PERCHD_FW_REPORT"):
        with open(os.environ["PERCHD_FW_REPORT"], "a") as f:
            f.write(json.dumps(figures) + "\n")


# -- take-over in the air, in this process ----------------------------------------------------

def test_taking_over_px4_in_the_air_loses_no_more_than_10_cm(tmp_path):
    """Measured from the acknowledged switch: before it PX4's own Hold flies, and that
    wanders +-0.2 m on its GPS-height estimate (docs/firmware.md)."""
    with ProcessGroup() as procs:
        v = Px4Vehicle(Px4Params(PX4, INSTANCE, surface_ahead_m=None, log=tmp_path / "px4.log"))
        try:
            v.start(procs, threading.Event())
            time.sleep(4.0)  # past the take-off's overshoot
            heights: list[tuple[float, float]] = []
            sampling = threading.Event()
            sampler = threading.Thread(target=sample_heights, args=(v, heights, sampling))
            sampler.start()
            z0, t0, yaw0 = v.truth().p[2], time.monotonic(), yaw_of(v.truth().q)
            drv = open_driver(v.driver_uri(), Runtime.real())
            try:
                drv.connect()
                t_switch, z_switch = time.monotonic(), v.truth().p[2]
                hold_height(v, drv, z_switch, yaw0, 3.0)
            finally:
                sampling.set()
                sampler.join()
                drv.close()
            lowest = min(z for t, z, _ in heights if t_switch <= t <= t_switch + 3.0)
            figures = {"test": "px4-takeover", "z_connect": z0, "z_switch": z_switch,
                       "loss_m": z_switch - lowest,
                       "connect_s": t_switch - t0, "yaw_change_deg": math.degrees(
                           math.remainder(yaw_of(v.truth().q) - yaw0, math.tau)),
                       "yaw_deg": [round(math.degrees(y), 1) for t, z, y in heights][::20],
                       "modes": v.summary()["modes"]}
            report(figures)
            assert z_switch - lowest <= 0.1, figures
        finally:
            v.close()


def sample_heights(v: Px4Vehicle, out: list, stop: threading.Event) -> None:
    while not stop.is_set():
        out.append((time.monotonic(), v.truth().p[2], yaw_of(v.truth().q)))
        time.sleep(0.01)


def hold_height(v: Px4Vehicle, drv, z_ref: float, yaw: float, seconds: float) -> None:
    """Level at a fixed heading (PX4 steers its own estimate's yaw, a few degrees off the
    truth: commanding the true yaw would chase that offset), thrust from a PD on the true
    height, at 50 Hz."""
    end, k = time.monotonic() + seconds, 0
    while time.monotonic() < end:
        tr = v.truth()
        acc = G + 2.0 * (z_ref - tr.p[2]) - 2.0 * tr.v[2]
        k += 1
        drv.observe_pose(Pose("px4", k, tr.t, tr.p, tr.q))  # as perchd fly does: yaw0=auto
        drv.send(Setpoint(tr.t, 0.0, 0.0, yaw, SIH_MASS_KG * acc, k, Phase.HOLD))
        time.sleep(0.02)


# -- whole perches through the CLI ------------------------------------------------------------

def harness(tmp: Path, *extra: str) -> tuple[subprocess.Popen, str, str, list[str]]:
    return start_placed("--px4", PX4, "--px4-instance", str(INSTANCE), "--ahead",
                        str(AHEAD_M), "--px4-param", f"SIH_KDV={DRAG}", "--fw-log",
                        str(tmp / "px4.log"), *extra, env=ENV)


def fly_argv(tmp: Path, mocap: str, driver: str, surface: list[str]) -> list[str]:
    config = tmp / "px4.toml"
    config.write_text(CONFIG)
    return [sys.executable, "-m", "perchd", "fly", str(PLAN), "--driver", driver, "--mocap",
            mocap, "--config", str(config), *surface, "--log", str(tmp / "flight.jsonl"), "--json"]


def stop(proc: subprocess.Popen) -> dict:
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=20)
    return json.loads(out)


@pytest.mark.parametrize("flight", [1, 2, 3])
def test_the_agent_perches_on_px4_sih(tmp_path, flight):
    """With SIH's default drag (1 N per m/s) three flights in ten end TRIGGER_REFUSED
    (docs/firmware.md, "Lag and drag"): these fly with DRAG and AHEAD_M."""
    plan = json.loads(PLAN.read_text())
    proc, mocap, driver, surface = harness(tmp_path)
    watch = YawWatch(mocap)
    try:
        done = subprocess.run(fly_argv(tmp_path, mocap, driver, surface), capture_output=True,
                              text=True, timeout=120, env=ENV)
        time.sleep(1.0)
        sim = stop(proc)
    finally:
        watch.close()
        if proc.poll() is None:
            proc.kill()
    assert done.stdout, done.stderr
    fly = json.loads(done.stdout)
    heading = sim["start_heading_rad"]
    figures = {
        "test": "px4-perch", "flight": flight, "outcome": fly["outcome"],
        "contact_speed": fly["contact_speed"],
        "true_contact_speed": sim["contact"] and sim["contact"]["speed"],
        "perch_time": fly["perch_time"], "plan_duration": plan["duration"],
        "trigger_speed": fly["trigger"] and fly["trigger"]["v"],
        "yaw_error_deg": math.degrees(heading_error(
            watch.between(*flight_window(tmp_path / "flight.jsonl")), heading)),
        "yaw_error_whole_run_deg": math.degrees(heading_error(sim["yaw_range_rad"], heading)),
        "lag": lag_event(tmp_path / "flight.jsonl"), "modes": sim["modes"]}
    report(figures)
    assert fly["outcome"] == "CONTACT", fly.get("detail")
    assert sim["contact"] is not None
    lo, hi = plan["limits"]["v_contact"]
    assert lo - 0.1 <= sim["contact"]["speed"] <= hi + 0.2  # measured: 1.00-1.10 m/s
    assert fly["perch_time"] == pytest.approx(plan["duration"], rel=0.10)  # measured: +5-7 %
    assert figures["yaw_error_deg"] <= 5.0
    assert "AUTO.RTL" not in sim["modes"]


@pytest.mark.parametrize("boot", ["safe-params", "stock-params+configure"])
def test_a_killed_agent_leaves_px4_holding_or_landing_never_returning(tmp_path, boot):
    """PX4's defaults (COM_OBL_RC_ACT = 0: Position, without RC escalating to Return) are
    either set at boot by the harness or by the driver's ?configure=1."""
    stock = boot != "safe-params"
    proc, mocap, driver, surface = harness(tmp_path, *(["--px4-stock-params"] if stock else []))
    driver += "&configure=1" if stock else ""
    try:
        fly = subprocess.Popen(fly_argv(tmp_path, mocap, driver, surface), env=ENV,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        log = tmp_path / "flight.jsonl"
        assert wait_for_phase(log, "approach", 60.0), "the flight never reached its approach"
        time.sleep(0.4)  # mid-approach
        fly.send_signal(signal.SIGKILL)
        fly.wait()
        time.sleep(8.0)  # COM_OF_LOSS_T, then PX4's own action
        sim = stop(proc)
    finally:
        for p in (proc,):
            if p.poll() is None:
                p.kill()
    modes = sim["modes"]
    report({"test": "px4-sigkill", "boot": boot, "modes": modes})
    assert "OFFBOARD" in modes
    after = modes[len(modes) - 1 - modes[::-1].index("OFFBOARD") + 1:]
    assert after and after[0] in ("AUTO.LAND", "AUTO.LOITER"), modes
    assert "AUTO.RTL" not in modes


def wait_for_phase(log: Path, phase: str, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if log.exists() and f'"phase":"{phase}"' in log.read_text():
            return True
        time.sleep(0.05)
    return False
