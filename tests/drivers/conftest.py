"""Fixtures the MAVLink driver's test modules share: a vehicle double per autopilot."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest


def _double(autopilot: str) -> Iterator[Any]:
    """A double of the autopilot named by its constant in tests/helpers/mavlink_double.py
    (ARDUPILOT, PX4), on loopback UDP, closed after the test."""
    pytest.importorskip("pymavlink")
    import mavlink_double

    vehicle = mavlink_double.VehicleDouble(getattr(mavlink_double, autopilot))
    yield vehicle
    vehicle.close()


@pytest.fixture
def ardupilot() -> Iterator[Any]:
    yield from _double("ARDUPILOT")


@pytest.fixture
def px4() -> Iterator[Any]:
    yield from _double("PX4")
