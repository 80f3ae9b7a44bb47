"""The README perch flies bit for bit as it did with the phases, the end rules and the
references in one module (flight/supervisor.py, flight/endrules.py, flight/references.py)."""

from __future__ import annotations

import pytest
from simflight import Sim, case1

from perchd.core.types import EndReason

# From plans/case1-ipts-n3.json flown on sim:// with a manual clock (the model with its
# quadratic drag, stage 2's loop from the lag: references.hold_loop): a simulated flight
# repeats to the last bit.
CONTACT_SPEED = 0.9679173670398736  # [m/s] the agent's estimate
PERCH_TIME = 2.0245068868016944  # [s] trigger to contact, the agent's estimate
TICKS = 573


def test_the_readme_perch_flies_the_recorded_flight(tmp_path):
    res = Sim().fly(case1("ipts"), tmp_path / "f.jsonl")
    assert res.outcome is EndReason.CONTACT
    assert res.contact_speed == pytest.approx(CONTACT_SPEED, abs=1e-12)
    assert res.perch_time == pytest.approx(PERCH_TIME, abs=1e-12)
    assert res.loop.ticks == TICKS
