"""Every registered driver keeps the same promises (drivers/base.py Driver protocol)."""

from __future__ import annotations

import pytest
from rigs import MASS, NOT_HERE, RIGS
from ticks import level, ticks_until_lost
from ticks import wait_for as _wait

from perchd.core.types import EndReason, LinkHealth, Phase, Setpoint
from perchd.drivers.base import DRIVERS, open_driver
from perchd.drivers.thrust import G

WEIGHT = MASS * G


def rig_factory(scheme: str):
    if scheme in NOT_HERE:
        pytest.skip(NOT_HERE[scheme])
    return RIGS[scheme]


@pytest.fixture(params=DRIVERS.schemes)
def rig(request):
    r = rig_factory(request.param)()
    yield r
    r.close()


@pytest.fixture
def driver(rig):
    d = open_driver(rig.uri, rig.runtime())
    d.connect()
    d.engage()  # as a flight does (flight/run.py)
    yield d
    d.close()


def test_every_registered_scheme_has_a_rig_or_a_reason():
    assert set(DRIVERS.schemes) <= set(RIGS) | set(NOT_HERE)


def test_opening_a_driver_does_not_connect_it(rig):
    d = open_driver(rig.uri, rig.runtime())
    assert d.uri == rig.uri
    health = d.health()
    assert isinstance(health, LinkHealth) and not health.ok
    d.close()  # closing what never connected is harmless


def test_connecting_commands_nothing_and_a_failsafe_before_engage_neither(rig):
    """connect() checks the vehicle; only engage() takes it (drivers/base.py)."""
    d = open_driver(rig.uri, rig.runtime())
    d.connect()
    try:
        assert d.health().ok
        d.failsafe(EndReason.OPERATOR_ABORT)
        _wait(lambda: False, 0.3)
        assert rig.commanded() is None
    finally:
        d.close()


def test_a_connected_driver_is_healthy_and_carries_an_si_setpoint(rig, driver):
    assert driver.health().ok
    sp = Setpoint(0.0, 0.1, -0.15, 0.0, WEIGHT, 1, Phase.STAGE1)
    # streamed like the loop does, so a keep-alive can never be the newest command
    assert _wait(lambda: driver.send(sp) or (rig.commanded() or (0,))[0] != 0)
    roll, pitch, thrust = rig.commanded()
    assert roll == pytest.approx(0.1, abs=1e-4)
    assert pitch == pytest.approx(-0.15, abs=1e-4)
    assert thrust == pytest.approx(WEIGHT, rel=2e-3)


def test_failsafe_reaches_the_vehicle_is_idempotent_and_silences_later_setpoints(rig, driver):
    driver.send(level(WEIGHT))
    assert _wait(lambda: rig.commanded() is not None)
    driver.failsafe(EndReason.OPERATOR_ABORT)
    driver.failsafe(EndReason.OPERATOR_ABORT)
    assert _wait(rig.stopped)
    before = rig.commanded()
    driver.send(Setpoint(0.0, 0.3, 0.3, 0.0, 2 * WEIGHT, 2, Phase.STAGE1))
    _wait(lambda: False, 0.2)
    assert rig.commanded() == before


def test_leaving_the_context_stops_a_flying_vehicle_and_closing_twice_is_harmless(rig):
    with open_driver(rig.uri, rig.runtime()) as d:
        d.send(level(WEIGHT))
    assert _wait(rig.stopped)
    d.close()
    assert not d.health().ok


@pytest.mark.solo
def test_a_vehicle_end_that_dies_is_reported_within_3_ticks_at_100_hz(rig, driver):
    lost_after = ticks_until_lost(driver, 100.0, level(WEIGHT), rig.kill)
    assert lost_after is not None and lost_after <= 3
