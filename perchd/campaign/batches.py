"""A campaign's work units: batches of flights, each flown by one worker, and the loop that
hands them to an engine (perchd.campaign.engine) and their rows back as they end.

A flight takes ~0.1 CPU-s; a unit of up to Engine.most_per_unit flights keeps the engine's
cost per unit (scheduling, pickling the plan, a round trip) a small share of its work. A flight's row
depends only on the job and its spec, never on its batch or worker."""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from perchd.campaign.engine import Engine
from perchd.campaign.flights import FlightRow, FlightSpec, Spread, fly_one
from perchd.core.types import EndReason
from perchd.flight.config import FlightConfig
from perchd.tau.plan import Plan

UNITS_PER_WORKER = 4
"""A campaign is cut into at least this many units per worker, so they end together."""


@dataclass(frozen=True)
class CampaignJob:
    """What every flight of a campaign shares. log_dir: keep each flight's log there
    (flight-NNNN.jsonl, on the worker's disk); None: no log written."""

    plan: Plan
    cfg: FlightConfig
    spread: Spread
    log_dir: str | None = None


def unit_size(flights: int, workers: int, most: int) -> int:
    """Flights per unit for `flights` over `workers`, at most `most`."""
    return max(1, min(most, math.ceil(flights / (UNITS_PER_WORKER * workers))))


def units(specs: Sequence[FlightSpec], workers: int, most: int) -> list[tuple[FlightSpec, ...]]:
    """The specs in order, in units of unit_size, the first ones ramping up from one flight
    (1, 2, 4, ... a round of `workers` units each): the first rows come at once; and the
    last ones down, none over the flights left / (2 workers): the workers end together."""
    size = unit_size(len(specs), workers, most)
    out: list[tuple[FlightSpec, ...]] = []
    i, step = 0, 1
    while i < len(specs):
        tail = math.ceil((len(specs) - i) / (2 * workers))
        out.append(tuple(specs[i : i + min(step, size, tail)]))
        i += len(out[-1])
        step *= 2 if len(out) % workers == 0 else 1
    return out


def fly_unit(job: CampaignJob, specs: Sequence[FlightSpec]) -> list[FlightRow]:
    """Fly each spec (the worker's entry point); a flight that raises is a row too."""
    return [fly_spec(job, spec) for spec in specs]


def fly_spec(job: CampaignJob, spec: FlightSpec) -> FlightRow:
    log = None if job.log_dir is None else Path(job.log_dir) / f"flight-{spec.index:04d}.jsonl"
    t0 = time.process_time()
    try:
        row = fly_one(job.plan, job.cfg, job.spread, spec, log)
    except Exception as err:  # one broken flight is a row of the table, not a lost campaign
        row = failed_row(job, spec, f"{type(err).__name__}: {err}")
    v = job.cfg.vehicle
    return dataclasses.replace(
        row, mass_kg=v.mass_kg, thrust_max_n=v.thrust_max_n, cpu_s=time.process_time() - t0
    )


def failed_row(job: CampaignJob, spec: FlightSpec, detail: str) -> FlightRow:
    plan, spread = job.plan, job.spread
    lo, hi = plan.limits.v_contact
    return FlightRow(
        spec.index,
        spec.x0,
        spec.v0,
        spread.latency_s,
        spread.noise_m,
        spec.gust_s,
        *spec.gust_dv,
        spec.seed,
        EndReason.SOFTWARE_ERROR.name,
        None,
        None,
        None,
        None,
        None,
        float(plan.duration),
        float(plan.v_contact),
        lo,
        hi,
        False,
        None,
        "",
        detail,
        plan.strategy,
    )


def fly_campaign(
    job: CampaignJob,
    specs: Sequence[FlightSpec],
    engine: Engine,
    on_rows: Callable[[list[FlightRow]], None],
) -> None:
    """Fly every spec on `engine`; on_rows(rows) as each unit ends, in no set order."""
    if not specs:
        return
    work = units(specs, engine.workers, engine.most_per_unit)
    for rows in engine.map_unordered(functools.partial(fly_unit, job), work):
        on_rows(rows)
