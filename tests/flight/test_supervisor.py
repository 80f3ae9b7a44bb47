"""The supervisor checks the end rules in their documented order on every tick."""

from __future__ import annotations

import pytest
from simflight import case1

from perchd.core.types import EndReason, LinkHealth, State
from perchd.flight.config import FlightConfig
from perchd.flight.endrules import Conditions
from perchd.flight.frame import PerchFrame
from perchd.flight.supervisor import Supervisor

CFG = FlightConfig()
FRAME = PerchFrame.from_surface((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
OK, DOWN = LinkHealth(True), LinkHealth(False, 0.0, "gone")


def state(x=-4.5, tilt=0.0, xdot=0.0):
    return State(0.0, x, xdot, 0.0, 0.0, 1.0, 0.0, 0.0, None, 0.0, tilt, 0.004, 1)


def first_end(*, abort=None, age=0.004, health=OK, st=None, streak=0):
    sup = Supervisor(case1("ipts"), CFG, FRAME)
    sup.tick(
        0.0, state(), Conditions(OK, 0, None, 1 / 120, 0.004)
    )  # starts: HOLD at the start point
    rep = sup.tick(0.01, st or state(), Conditions(health, streak, abort, 1 / 120, age))
    return rep.end


@pytest.mark.parametrize(
    "faults,expected",
    [
        (dict(abort=EndReason.OPERATOR_ABORT, age=1.0, health=DOWN), EndReason.OPERATOR_ABORT),
        (dict(abort=EndReason.SIGNAL, age=1.0), EndReason.SIGNAL),
        (dict(age=1.0, health=DOWN, st=state(x=-9.0)), EndReason.STALE_MOCAP),
        (dict(health=DOWN, st=state(x=-9.0)), EndReason.LOST_LINK),
        (dict(st=state(x=-9.0, tilt=1.5)), EndReason.GEOFENCE),
        (dict(st=state(tilt=1.5, xdot=5.0)), EndReason.TILT_LIMIT),
        (dict(st=state(xdot=5.0), streak=50), EndReason.SPEED_LIMIT),
        (dict(streak=50), EndReason.DEADLINE_OVERRUN),
        ({}, None),
    ],
)
def test_when_several_rules_break_at_once_the_first_in_order_names_the_end(faults, expected):
    assert first_end(**faults) is expected


def test_stale_means_more_than_three_mocap_periods_since_the_newest_pose_arrived():
    assert first_end(age=3 / 120 - 1e-6) is None
    assert first_end(age=3 / 120 + 1e-6) is EndReason.STALE_MOCAP
