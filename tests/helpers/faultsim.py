"""Simulated flights with faults injected, and the figures docs/safety.md quotes.

`fly` runs one simulated flight (simulated time, tests/closedloop/simflight.Sim) with frame
faults on the world's mocap; a recording fault placed last sees every frame that reaches
the agent and when, so a test can measure how long after the last usable frame an abort
came. `report` adds a line to the per-fault table printed at the end of the run.
"""

from __future__ import annotations

import json
import os
import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from simflight import Sim, case1

from perchd.core.types import Pose
from perchd.flight.config import FlightConfig, LoopSync
from perchd.logs.flightlog import FlightLog, read_log

PERIOD = 1.0 / 120.0
"""[s] the simulated mocap's frame period (120 Hz)."""
TICK = 0.01
"""[s] the control loop's period (100 Hz)."""
FIXED = FlightConfig(sync=LoopSync.FIXED)
"""The fault suites time their rules against the fixed 100 Hz tick (TICK); a test about the
mocap-synchronous loop (the default) says so."""

TABLE: list[dict[str, Any]] = []
INJECTED: list[str] = []
"""One entry per fault injected (a flight with two faults counts two)."""
FLIGHTS = {"simulated": 0, "real time": 0}


class Arrivals:
    """An identity frame fault that records when each frame (by seq) first reached the agent."""

    def __init__(self) -> None:
        self.at: dict[int, float] = {}
        self.claimed: dict[int, float] = {}  # measured + the latency the frame states

    def apply(self, arrive: float, pose: Pose) -> list[tuple[float, Pose]]:
        self.at.setdefault(pose.seq, arrive)
        self.claimed.setdefault(pose.seq, pose.t + pose.latency)
        return [(arrive, pose)]


@dataclass
class Flown:
    sim: Sim
    res: Any
    log: FlightLog
    arrivals: Arrivals
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def end_t(self) -> float:
        """[s] the tick that ended the flight (its failsafe went out on that tick)."""
        return self.log.rows[-1].t

    @property
    def since_last_fused(self) -> float:
        """[s] from the arrival of the newest frame the estimator fused to the end tick."""
        return self.end_t - self.arrivals.at[self.log.rows[-1].pose_seq]

    @property
    def age_of_last_fused(self) -> float:
        """[s] from when the newest fused frame says it arrived (measured + its latency) to
        the end tick: what the stale rule reads. Equals since_last_fused unless the frame
        was delayed on the way (late, reordered)."""
        return self.end_t - self.arrivals.claimed[self.log.rows[-1].pose_seq]


def fly(
    tmp_path: Path,
    *faults: Any,
    cfg: FlightConfig = FIXED,
    uri: str = "sim://",
    setup=None,
    on_tick=None,
    strategy: str = "ipts",
    name: str = "f",
) -> Flown:
    sim = Sim(uri)
    arrivals = Arrivals()
    sim.world.faults.mocap[:] = [*faults, arrivals]
    INJECTED.extend(type(f).__name__ for f in faults)
    FLIGHTS["simulated"] += 1
    if setup is not None:
        setup(sim)
    res = sim.fly(
        case1(strategy),
        tmp_path / f"{name}-{FLIGHTS['simulated']}.jsonl",
        cfg,
        on_tick=on_tick(sim) if on_tick else None,
    )
    return Flown(sim, res, read_log(res.log), arrivals)


def injected(*names: str, real_time: bool = False) -> None:
    """Count faults injected outside `fly` (links, signals, limits); real_time: in a flight
    of its own flown in real time."""
    INJECTED.extend(names)
    FLIGHTS["real time"] += real_time


def report(
    fault: str, detection: str, action: str, vehicle: str, samples_s: list[float] | None = None
) -> None:
    """One table line; samples_s [s] detection times measured (min/median/max quoted)."""
    figures = ""
    if samples_s:
        figures = (
            f"{1e3 * min(samples_s):.1f} / {1e3 * statistics.median(samples_s):.1f} / "
            f"{1e3 * max(samples_s):.1f} ms (n={len(samples_s)})"
        )
    TABLE.append(
        {
            "fault": fault,
            "detection": detection,
            "measured": figures,
            "action": action,
            "vehicle": vehicle,
        }
    )
    out = os.environ.get("PERCHD_FAULT_TABLE")
    if out:
        Path(out).write_text(
            json.dumps({"table": TABLE, "injected": len(INJECTED), "flights": FLIGHTS}, indent=1)
        )


def table_lines() -> list[str]:
    lines = [
        f"faults injected: {len(INJECTED)}; flights: {FLIGHTS['simulated']} simulated, "
        f"{FLIGHTS['real time']} real time",
        "fault | detection | measured min/median/max | action | vehicle",
    ]
    lines += [
        " | ".join((r["fault"], r["detection"], r["measured"] or "-", r["action"], r["vehicle"]))
        for r in TABLE
    ]
    return lines
