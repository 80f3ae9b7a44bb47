"""The stage-2 switch: the tick the measured tau reaches tau_s (docs/errata.md §9)."""

from __future__ import annotations

import pytest
from simflight import Sim, case1

from perchd.core.types import EndReason
from perchd.logs.flightlog import read_log

LATE_FAST_DRAG = "sim://?latency=0.1&attitude_tau=0.2&qdrag=0.2"
"""~0.3 s of lag and drag growing with speed (tests/flight/test_stage1_tracking.py)."""


@pytest.mark.parametrize("uri", ["sim://", LATE_FAST_DRAG])
def test_stage_2_begins_on_the_tick_the_measured_tau_reaches_tau_s(tmp_path, uri):
    """Late or not, the switch is the paper's: on the measured tau, not before it reaches
    tau_s (-0.5 s), and the tick before it had not."""
    plan, log = case1("ipts"), tmp_path / "f.jsonl"
    res = Sim(uri).fly(plan, log)
    assert res.outcome is EndReason.CONTACT, res.detail
    flown = read_log(log)
    switch = next(e for e in flown.events if e.kind == "stage2")
    assert switch.detail == "measured tau reached tau_s"
    assert switch.values["tau"] >= plan.tau_s
    row = next(r for r in flown.rows if r.t >= switch.t)
    assert row.phase == "stage2" and row.tau >= plan.tau_s
    before = [r for r in flown.rows if r.t < switch.t and r.phase == "stage1"]
    assert before and (before[-1].tau is None or before[-1].tau < plan.tau_s)
