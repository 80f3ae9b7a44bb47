"""A simulated case-1 flight with faults set up, and the checks every failsafe end must pass."""

from __future__ import annotations

import dataclasses

from simflight import Sim, case1

from perchd.core.types import Phase
from perchd.flight.config import FlightConfig, SafetyConfig
from perchd.logs.flightlog import read_log

TRIGGER_T = 2.57
"""[s] simulated time of the trigger from the default start (measured in the nominal flight)."""


def safety(**kw) -> FlightConfig:
    return FlightConfig(safety=dataclasses.replace(SafetyConfig(), **kw))


def fly(tmp_path, cfg=FlightConfig(), setup=None, abort=None, on_tick=None):
    sim = Sim()
    if setup is not None:
        setup(sim)
    res = sim.fly(
        case1("ipts"), tmp_path / "f.jsonl", cfg, abort, on_tick(sim) if on_tick else None
    )
    return sim, res


def assert_failsafe_and_closed_log(sim, res, reason):
    assert res.outcome is reason
    assert res.failsafe_sent
    assert sim.driver.failsafe_reasons[0] is reason
    assert sim.world.failsafes == [reason]
    stop = sim.world.sent[-1]
    assert stop.thrust == 0.0 and stop.phase is Phase.ABORT
    log = read_log(res.log)
    assert log.complete and log.end["outcome"] == reason.name
    assert log.rows[-1].end == reason.name and log.rows[-1].phase == "abort"
    assert any(e.kind == "end" for e in log.events)
