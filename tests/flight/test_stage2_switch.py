"""The stage-2 switch judged on the tau the tau PID acts on (TauGains.switch_predicted,
docs/errata.md §9-§10)."""

from __future__ import annotations

import dataclasses

from simflight import Sim, case1

from perchd.core.types import EndReason
from perchd.flight.config import FlightConfig
from perchd.logs.flightlog import read_log

LATE_FAST_DRAG = "sim://?latency=0.1&attitude_tau=0.2&qdrag=0.2"
"""~0.3 s of lag and drag growing with speed (tests/flight/test_stage1_tracking.py)."""


def fly(tmp_path, uri: str, predicted: bool):
    """(result, the stage-2 event, the log row of the switch's tick)."""
    c, log = FlightConfig(), tmp_path / f"switch-{predicted}.jsonl"
    cfg = dataclasses.replace(
        c, tau_gains=dataclasses.replace(c.tau_gains, switch_predicted=predicted)
    )
    res = Sim(uri).fly(case1("ipts"), log, cfg)
    assert res.outcome is EndReason.CONTACT
    flown = read_log(log)
    switch = next(e for e in flown.events if e.kind == "stage2")
    return res, switch, next(r for r in flown.rows if r.t >= switch.t)


def test_a_lagging_vehicle_switches_when_its_predicted_tau_reaches_tau_s(tmp_path):
    """On a 0.3 s lag the predicted tau reaches tau_s (-0.5 s) a horizon (0.2 s) before
    the measured one: the switch comes that much earlier, where the measured tau is still
    short of it, and the perch is nearer the plan's time (+0.7 % against +1.4 %)."""
    plan = case1("ipts")
    late = {}
    for predicted in (False, True):
        res, switch, row = fly(tmp_path, LATE_FAST_DRAG, predicted)
        late[predicted] = (res, switch)
        assert switch.values["tau"] >= plan.tau_s
        if predicted:
            assert switch.detail == "predicted tau reached tau_s"
            assert switch.values["horizon_s"] > 0.15
            assert row.tau < plan.tau_s - 0.05  # the measured one has not reached it
        else:
            assert switch.detail == "measured tau reached tau_s"
            assert row.tau >= plan.tau_s
    (measured, at_measured), (predicted, at_predicted) = late[False], late[True]
    assert at_predicted.t - predicted.trigger.t < at_measured.t - measured.trigger.t - 0.15
    error = {k: abs(r.true_perch_time / plan.duration - 1.0) for k, (r, _) in late.items()}
    assert error[True] < 0.6 * error[False]


def test_a_vehicle_that_answers_within_the_gains_switches_on_the_measured_tau(tmp_path):
    """perchd's own plant answers within ff_lead_s: nothing is predicted, and the switch is
    the paper's, tick for tick."""
    flights = [fly(tmp_path, "sim://", predicted) for predicted in (False, True)]
    (_, off, _), (_, on, _) = flights
    assert on.detail == off.detail == "measured tau reached tau_s"
    assert (
        on.values["horizon_s"] == 0.0
        and on.t - flights[1][0].trigger.t == off.t - flights[0][0].trigger.t
    )
