"""`perchd log plot` draws the perch up to the contact, not the estimate coasting past the
wall afterwards."""

from __future__ import annotations

from caseplans import case1_ipts
from simflight import Sim

from perchd.core.types import EndReason
from perchd.logs.flightlog import read_log
from perchd.logs.plot import PRE_TRIGGER_S, shown_rows


def test_the_plotted_flight_ends_at_the_contact_and_never_passes_the_wall(tmp_path):
    sim = Sim()
    res = sim.fly(case1_ipts(), tmp_path / "f.jsonl")
    assert res.outcome is EndReason.CONTACT
    log = read_log(tmp_path / "f.jsonl")
    contact = next(e.t for e in log.events if e.kind == "contact")
    assert max(r.x for r in log.rows if r.x is not None) > 0.05  # what the plot used to show
    t0, rows = shown_rows(log)
    assert rows[0].t >= t0 - PRE_TRIGGER_S and rows[-1].t == contact
    assert max(r.x for r in rows if r.x is not None) < 0.01  # one tick's travel at most
