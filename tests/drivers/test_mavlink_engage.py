"""Connect, then engage (drivers/base.py), over real MAVLink (pymavlink at both ends,
loopback UDP): connect() checks the vehicle and changes nothing on it; engage(), once per
flight, takes it (level at its heading, offboard mode, arming, spool-up) while forwarding
the flight's poses, so an EKF on mocap alone can arm."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("pymavlink")

from mavlink_double import ARDUPILOT, PX4, VehicleDouble, connected
from stale import harness_config
from still_poses import StillPoses

from perchd.core.errors import LinkError
from perchd.core.types import EndReason, Pose

PLAN = Path(__file__).resolve().parents[2] / "plans" / "case1-ipts-n3.json"
GUIDED_NOGPS, LAND = 20, 9
PX4_OFFBOARD = 6 << 16


class Poses:
    """A PoseFeed: a new pose (seq + 1) at each read, as a 100 Hz mocap read at its rate."""

    def __init__(self) -> None:
        self.seq = 0

    def __call__(self) -> Pose:
        self.seq += 1
        return Pose("cf1", self.seq, time.monotonic(), (-4.5, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


def mode_commands(v: VehicleDouble) -> list[float]:
    return [t for t, c, _ in v.commands if c in (176, 400)]


@pytest.mark.parametrize("autopilot", [ARDUPILOT, PX4])
def test_connect_changes_nothing_and_a_failsafe_before_engage_commands_nothing(autopilot):
    v = VehicleDouble(autopilot, airborne=True)
    try:
        drv = connected(v, "&arm=1", engage=False)
        v.wait_for(lambda: False, timeout=0.5)
        assert drv.health().ok and v.gcs_heartbeats  # heard, and hearing us
        drv.failsafe(EndReason.OPERATOR_ABORT)
        v.wait_for(lambda: False, timeout=0.5)
        drv.close()
        assert mode_commands(v) == [] and v.targets == [] and v.modes == []
    finally:
        v.close()


def test_each_flight_engages_anew_and_nothing_re_engages_after_a_failsafe():
    v = VehicleDouble(ARDUPILOT)
    try:
        drv = connected(v, engage=False)
        drv.engage()
        assert v.custom_mode == GUIDED_NOGPS and v.targets
        drv.failsafe(EndReason.LOST_LINK)
        assert v.wait_for(lambda: v.custom_mode == LAND)
        landed = time.monotonic()
        v.wait_for(lambda: False, timeout=0.6)  # keep-alive and LAND repeats have had time
        assert [t for t in v.targets if t.t > landed] == []
        assert v.custom_mode == LAND and v.modes[-1][1] == LAND
        drv.engage()  # the next flight
        assert v.custom_mode == GUIDED_NOGPS and v.targets[-1].t > landed
        v.wait_for(lambda: False, timeout=0.6)  # the old failsafe's LAND is called off
        assert v.custom_mode == GUIDED_NOGPS and drv.health().ok
        drv.close()
        assert v.custom_mode == LAND
    finally:
        v.close()


def test_an_ekf_on_mocap_alone_arms_once_engage_has_forwarded_poses():
    """ArduCopter on ExternalNav alone refuses to arm until the mocap flows; engage forwards
    the flight's poses while it waits and asks again (before: connect armed with no pose)."""
    v = VehicleDouble(ARDUPILOT, vision_to_arm=20)
    try:
        drv = connected(v, "&arm=1", engage=False)
        drv.engage(Poses())
        assert v.armed and len(v.visions) >= 20
        arms = [t for t, c, _ in v.commands if c == 400]
        assert len(arms) >= 2 and drv.vision_sent >= 20  # refused, then asked again
        drv.close()
    finally:
        v.close()


def test_an_ekf_given_no_poses_is_a_named_refusal_within_the_wait():
    v = VehicleDouble(ARDUPILOT, vision_to_arm=20)
    try:
        drv = connected(v, "&arm=1&wait=1", engage=False)
        start = time.monotonic()
        with pytest.raises(
            LinkError,
            match=r"refused to arm \(MAV_RESULT 4\) for 1 s while "
            r"0 poses went to its EKF",
        ):
            drv.engage()
        assert time.monotonic() - start < 2.0 and not v.armed
        drv.close()
    finally:
        v.close()


def test_without_vision_a_refusal_is_not_asked_again():
    v = VehicleDouble(ARDUPILOT, refuse_arm=True)
    try:
        drv = connected(v, "&arm=1&vision=0", engage=False)
        with pytest.raises(LinkError, match=r"refused to arm \(MAV_RESULT 2\)$"):
            drv.engage(Poses())
        assert len([c for _, c, _ in v.commands if c == 400]) == 1
        drv.close()
    finally:
        v.close()


def test_perchd_fly_arms_an_ekf_on_mocap_alone_from_the_ground(tmp_path):
    """`perchd fly` from the ground with arm=1, the vehicle's EKF on mocap alone: its engage
    forwards the poses until the vehicle arms (before: connect armed before the loop handed
    the driver a pose, and the vehicle refused)."""
    v = VehicleDouble(ARDUPILOT, vision_to_arm=20)
    poses = StillPoses((-4.5, 0.0, 0.0))
    try:
        fly = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "perchd",
                "fly",
                str(PLAN),
                "--driver",
                f"{v.uri}?arm=1",
                "--mocap",
                poses.uri,
                "--config",
                str(harness_config(tmp_path)),
                "--log",
                str(tmp_path / "f.jsonl"),
                "--json",
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            armed = v.wait_for(lambda: v.armed or fly.poll() is not None, timeout=20.0)
            time.sleep(0.5)  # a few ticks of the flight
        finally:
            fly.send_signal(signal.SIGTERM)
            out, err = fly.communicate(timeout=20)
    finally:
        poses.close()
        v.close()
    assert armed and v.armed, err
    arms = [t for t, c, p in v.commands if c == 400 and p[0] == 1]
    assert len(arms) >= 2  # refused while the EKF had no mocap, then taken
    assert json.loads(out)["outcome"] == "SIGNAL"
    assert v.targets and v.modes[0][1] == GUIDED_NOGPS


def test_a_failsafe_from_another_thread_while_engaging_wins():
    """A stopping service sends the failsafe from its own thread when the flight's does not
    end in time: the engage under way must not take the vehicle back out of LAND."""
    v = VehicleDouble(ARDUPILOT, vision_to_arm=10**6)  # it never arms
    try:
        drv = connected(v, "&arm=1&wait=3", engage=False)
        timer = threading.Timer(0.5, drv.failsafe, args=(EndReason.SIGNAL,))
        timer.start()
        with pytest.raises(LinkError, match="failsafe while engaging"):
            drv.engage(Poses())
        timer.join()
        assert v.wait_for(lambda: v.custom_mode == LAND)
        stopped = time.monotonic()
        v.wait_for(lambda: False, timeout=0.6)
        assert [c for t, c, _ in v.commands if c == 400 and t > stopped + 0.05] == []
        assert v.custom_mode == LAND
        drv.close()
    finally:
        v.close()
