"""Simulated campaigns: one plan flown many times over a spread of trigger states and disturbances.

Each flight is `perchd fly --driver sim:// --mocap sim://` in-process on a simulated clock:
the plan is retargeted to the flight's trigger state (x0, v0) so that the approach aims there,
the vehicle starts hovering far enough back to reach it within the approach's acceleration
limit, and the trigger policy decides at the state it measures (a robust plan flies its
certified k_1..k_n from any state in its box and refuses one outside it). Disturbances: the
command latency, mocap noise (its own seed per flight) and a gust, one velocity kick at a
drawn moment of stage 1. Flights are independent, so they run in worker processes as well
as in this one, with the same figures.
"""

from __future__ import annotations

import dataclasses
import math
import signal
import statistics
import tempfile
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from perchd.campaign.tableformats import CsvTable
from perchd.core.errors import ConfigError, PlanError
from perchd.core.types import EndReason, Phase, Vec3
from perchd.flight.config import FlightConfig, TriggerPolicy
from perchd.flight.frame import PerchFrame
from perchd.flight.planguard import check_flight_plan
from perchd.flight.run import FlightResult, TickStatus
from perchd.session import open_session
from perchd.sim.plant import PlantParams
from perchd.sim.world import MocapParams, SimWorld, WorldParams
from perchd.tau import retarget
from perchd.tau.plan import Plan

Range = tuple[float, float]

ROBUST_INSET = 0.04
"""[m, m/s] default trigger ranges keep this far inside a robust box: the approach
arrives within about 2 cm and 1 cm/s of where it aimed."""
DEFAULT_SPREAD = 0.1
"""Plans without a box: default ranges are the plan's x0 and v0 +- this fraction."""
APPROACH_SHARE = 0.75
"""The computed start leaves the approach this share of its acceleration limit."""
START_MARGIN_M = 0.5
"""[m] extra run-up before the approach (the hold drifts a little)."""
GUST_WINDOW = (0.1, 0.6)
"""A gust comes at this fraction of the plan's duration after the trigger (drawn)."""


@dataclass(frozen=True)
class Spread:
    """What varies over a campaign. x0 [m] and v0 [m/s]: ranges of the trigger states aimed
    at; latency_s [s] command latency and noise_m [m] mocap noise std (the same for every
    flight; the noise has its own seed per flight); gust_mps [m/s]: largest velocity kick
    per world axis (0: no gust); start: [m] world start for every flight (None: computed
    from each trigger state); seed: of every draw."""

    x0: Range
    v0: Range
    latency_s: float = 0.0
    noise_m: float = 0.0
    gust_mps: float = 0.0
    start: Vec3 | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        for name, (lo, hi) in (("x0", self.x0), ("v0", self.v0)):
            if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
                raise ConfigError(f"--{name} {lo:g} {hi:g}: LO must not exceed HI (by {lo - hi:g})")
        if self.x0[1] >= 0.0:
            raise ConfigError(f"--x0 up to {self.x0[1]:g} m: a trigger gap must be < 0 m")
        if self.v0[0] <= 0.0:
            raise ConfigError(f"--v0 from {self.v0[0]:g} m/s: a closing speed must be > 0 m/s")
        if self.seed < 0:
            raise ConfigError(f"--seed {self.seed}: must be >= 0")
        if not 0.0 <= self.gust_mps <= 2.0:
            raise ConfigError(f"--gust {self.gust_mps:g} m/s is outside 0..2 m/s")


@dataclass(frozen=True)
class FlightSpec:
    """One flight: index; x0 [m], v0 [m/s] trigger state aimed at; gust_s [s] after the
    trigger and gust_dv [m/s] world-frame velocity kick (zero: none); seed of its noise."""

    index: int
    x0: float
    v0: float
    gust_s: float
    gust_dv: Vec3
    seed: int


@dataclass(frozen=True)
class FlightRow:
    """One row of the outcome table. Aimed x0_aim [m], v0_aim [m/s] and the disturbances;
    outcome (EndReason name) and detail; action: how the trigger chose the plan; trigger_x [m], trigger_v [m/s] measured;
    contact_speed [m/s] and perch_time [s, trigger to contact] from the simulator
    (contact_speed_est: the agent's estimate); plan_v_contact [m/s] and plan_duration [s]
    of the plan flown; v_lo..v_hi [m/s] its contact window and in_window;
    perch_error_s [s] = perch_time - plan_duration and speed_error_mps [m/s] = contact_speed -
    plan_v_contact. Figures without contact are None. strategy: the plan's; ticks: control
    ticks flown; mass_kg [kg] and thrust_max_n [N]: the vehicle's; agent_median_ms and
    agent_max_ms [ms]: the estimator + supervisor + controller part of a tick; cpu_s [s]:
    the flight's CPU time in its worker (the last three measure the machine)."""

    index: int
    x0_aim: float
    v0_aim: float
    latency_s: float
    noise_m: float
    gust_s: float
    gust_dvx: float
    gust_dvy: float
    gust_dvz: float
    seed: int
    outcome: str
    trigger_x: float | None
    trigger_v: float | None
    contact_speed: float | None
    contact_speed_est: float | None
    perch_time: float | None
    plan_duration: float
    plan_v_contact: float
    v_lo: float
    v_hi: float
    in_window: bool
    perch_error_s: float | None
    action: str
    detail: str
    strategy: str = ""
    speed_error_mps: float | None = None
    ticks: int = 0
    mass_kg: float = 0.0
    thrust_max_n: float = 0.0
    agent_median_ms: float = dataclasses.field(default=0.0, compare=False)
    agent_max_ms: float = dataclasses.field(default=0.0, compare=False)
    cpu_s: float = dataclasses.field(default=0.0, compare=False)


COLUMNS = tuple(f.name for f in dataclasses.fields(FlightRow))


@dataclass(frozen=True, slots=True)
class Brief:
    """What a campaign keeps of a row once the row is on disk: its key (index, seed) and
    the figures `summarize` takes, in FlightRow's units."""

    index: int
    seed: int
    outcome: str
    in_window: bool
    x0_aim: float
    v0_aim: float
    trigger_x: float | None
    trigger_v: float | None
    contact_speed: float | None
    plan_v_contact: float
    perch_error_s: float | None
    plan_duration: float

    @classmethod
    def of(cls, row: FlightRow) -> Brief:
        return cls(*(getattr(row, name) for name in cls.__slots__))


TIMING_COLUMNS = ("agent_median_ms", "agent_max_ms", "cpu_s")
"""Columns that measure the machine, not the flight: the same seed gives the same table
but for these (rows compare equal without them)."""


# --- what to fly ---------------------------------------------------------------------------
def default_ranges(plan: Plan) -> tuple[Range, Range]:
    """The plan's robust box inset by ROBUST_INSET, else its (x0, v0) +- DEFAULT_SPREAD."""
    if plan.robust is not None:
        (xl, xh), (vl, vh) = plan.robust
        return (xl + ROBUST_INSET, xh - ROBUST_INSET), (vl + ROBUST_INSET, vh - ROBUST_INSET)
    dx, dv = abs(plan.x0) * DEFAULT_SPREAD, plan.v0 * DEFAULT_SPREAD
    return (plan.x0 - dx, plan.x0 + dx), (plan.v0 - dv, plan.v0 + dv)


def default_policy(plan: Plan) -> TriggerPolicy:
    """Robust plans fly their box; any other is replanned from the measured state."""
    return TriggerPolicy.ROBUST if plan.robust is not None else TriggerPolicy.REPLAN


def _rng(seed: int, *stream: int):

    return np.random.default_rng([seed, *stream])


def _spec(spread: Spread, index: int, x0: float, v0: float, duration: float) -> FlightSpec:
    """The flight's own draws (gust, noise seed) depend only on (seed, index)."""
    rng = _rng(spread.seed, 1, index)
    frac = rng.uniform(*GUST_WINDOW)
    dv = tuple(float(v) for v in rng.uniform(-spread.gust_mps, spread.gust_mps, 3))
    noise_seed = int(rng.integers(0, 2**31))
    if spread.gust_mps == 0.0:
        frac, dv = 0.0, (0.0, 0.0, 0.0)
    return FlightSpec(index, float(x0), float(v0), frac * duration, dv, noise_seed)


def random_specs(spread: Spread, flights: int, duration: float) -> list[FlightSpec]:
    """`flights` trigger states uniform over the ranges. duration [s]: the plan's (gust time)."""
    if flights < 1:
        raise ConfigError(f"--flights {flights}: at least 1")
    rng = _rng(spread.seed, 0)
    xs, vs = rng.uniform(*spread.x0, flights), rng.uniform(*spread.v0, flights)
    return [_spec(spread, i, x, v, duration) for i, (x, v) in enumerate(zip(xs, vs))]


def grid_specs(spread: Spread, nx: int, nv: int, duration: float) -> list[FlightSpec]:
    """nx x nv trigger states on a grid spanning the ranges, corners included."""
    if nx < 1 or nv < 1:
        raise ConfigError(f"--grid {nx} {nv}: at least 1 point along each axis")
    xs = _span(spread.x0, nx)
    vs = _span(spread.v0, nv)
    pairs = [(x, v) for x in xs for v in vs]
    return [_spec(spread, i, x, v, duration) for i, (x, v) in enumerate(pairs)]


def _span(rng: Range, n: int) -> list[float]:
    lo, hi = rng
    return [(lo + hi) / 2] if n == 1 else [lo + (hi - lo) * i / (n - 1) for i in range(n)]


def start_for(x0: float, v0: float, cfg: FlightConfig) -> Vec3:
    """[m] world hover start from which the approach reaches (x0, v0) using APPROACH_SHARE of
    its acceleration limit, kept inside the geofence (perching frame = world rotated about
    the surface point; the start is 1 m above the surface point)."""

    run_up = v0 * v0 / (2.0 * APPROACH_SHARE * cfg.approach.accel_max_mps2) + START_MARGIN_M
    x = max(x0 - run_up, cfg.safety.x_min_m + 0.2)
    frame = PerchFrame.from_surface(cfg.surface.point, cfg.surface.normal)
    off = frame.rotate_out((x, 0.0, 0.0))
    p = cfg.surface.point
    return (p[0] + off[0], p[1] + off[1], p[2] + off[2] + 1.0)


# --- flying --------------------------------------------------------------------------------
def campaign_config(cfg: FlightConfig, policy: TriggerPolicy) -> FlightConfig:
    return dataclasses.replace(cfg, trigger=dataclasses.replace(cfg.trigger, policy=policy))


def fly_one(
    plan: Plan, cfg: FlightConfig, spread: Spread, spec: FlightSpec, log_path: str | Path
) -> FlightRow:
    """Fly `plan` aimed at spec's trigger state in a fresh simulated world; one table row."""

    try:
        aimed = check_flight_plan(retarget(plan, spec.x0, spec.v0), cfg)
    except PlanError as err:  # the aimed state admits no plan: recorded, not fatal
        return _row(spec, spread, plan, None, f"no plan at the aimed state: {err}")
    return _row(spec, spread, aimed, _simulate(aimed, cfg, spread, spec, log_path), "")


def _simulate(
    plan: Plan, cfg: FlightConfig, spread: Spread, spec: FlightSpec, log_path: str | Path
) -> FlightResult:
    session = open_session(
        params=WorldParams(
            plant=PlantParams(latency_s=spread.latency_s),
            mocap=MocapParams(noise_m=spread.noise_m),
            start=spread.start or start_for(spec.x0, spec.v0, cfg),
            seed=spec.seed,
        ),
        surface=cfg.surface,
    )
    # log_force: --logs was checked by the command (an existing log there only with --force,
    # or a resumed campaign's torn one); a replaced log is still renamed into place whole
    return session.fly(
        plan,
        log_path,
        cfg,
        on_tick=_gust_hook(session.world, spec),
        header={"campaign_flight": dataclasses.asdict(spec)},
        log_force=True,
    )


def _gust_hook(world: SimWorld, spec: FlightSpec) -> Callable[[TickStatus], None] | None:
    """An on_tick that schedules the kick spec.gust_s after the trigger, once."""
    if not any(spec.gust_dv):
        return None
    armed = [True]

    def kick(w: SimWorld) -> None:
        for i in range(3):
            w.plant.v[i] += spec.gust_dv[i]

    def on_tick(status: TickStatus) -> None:
        if armed[0] and status.phase is Phase.STAGE1:
            armed[0] = False
            world.faults.at.append((world.clock.now() + spec.gust_s, kick))

    return on_tick


def _row(
    spec: FlightSpec, spread: Spread, plan: Plan, res: FlightResult | None, why: str
) -> FlightRow:
    """The table row of a flight result, or (res None) of an aim no plan could be made for."""
    lo, hi = plan.limits.v_contact
    trig = res.trigger if res else None
    hit = (
        res is not None and res.outcome is EndReason.CONTACT and res.true_contact_speed is not None
    )
    speed, perch = (res.true_contact_speed, res.true_perch_time) if hit else (None, None)
    duration = res.plan_duration if res else float(plan.duration)
    return FlightRow(
        spec.index,
        spec.x0,
        spec.v0,
        spread.latency_s,
        spread.noise_m,
        spec.gust_s,
        *spec.gust_dv,
        spec.seed,
        res.outcome.name if res else EndReason.TRIGGER_REFUSED.name,
        trig and trig.x,
        trig and trig.v,
        speed,
        res.contact_speed if hit else None,
        perch,
        duration,
        res.v_contact_plan if res else float(plan.v_contact),
        lo,
        hi,
        hit and lo <= speed <= hi,
        None if perch is None else perch - duration,
        trig.action if trig else "",
        res.detail if res else why,
        plan.strategy,
        None if speed is None else speed - res.v_contact_plan,
        **(_loop_figures(res.loop) if res else {}),
    )


def _loop_figures(loop: Any) -> dict[str, Any]:
    """The row's figures of the flight's flight.loop.LoopSummary."""
    return {
        "ticks": loop.ticks,
        "agent_median_ms": loop.agent_median_s * 1e3,
        "agent_max_ms": loop.agent_max_s * 1e3,
    }


def _fly_logged(args: tuple) -> FlightRow:
    """Worker entry point (picklable): fly one spec, logging into log_dir."""
    plan, cfg, spread, spec, log_dir = args
    return fly_one(plan, cfg, spread, spec, Path(log_dir) / f"flight-{spec.index:04d}.jsonl")


def run_campaign(
    plan: Plan,
    cfg: FlightConfig,
    spread: Spread,
    specs: Iterable[FlightSpec],
    jobs: int = 1,
    log_dir: str | Path | None = None,
    on_row: Callable[[FlightRow], None] | None = None,
) -> list[FlightRow]:
    """Fly every spec (in `jobs` processes); rows in spec order. on_row(row) as each ends.
    log_dir keeps each flight's log (flight-NNNN.jsonl); None: logs go to a temporary
    directory and are removed."""
    if jobs < 1:
        raise ConfigError(f"--jobs {jobs}: at least 1")
    check_flight_plan(plan, cfg)  # the campaign's plan, before any flight
    with tempfile.TemporaryDirectory(prefix="perchd-campaign-") as tmp:
        where = Path(log_dir) if log_dir is not None else Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        work = [(plan, cfg, spread, spec, str(where)) for spec in specs]
        rows = []
        for row in _map(work, jobs):
            rows.append(row)
            if on_row is not None:
                on_row(row)
    return sorted(rows, key=lambda r: r.index)


def _map(work: list[tuple], jobs: int) -> Iterator[FlightRow]:
    if jobs == 1 or len(work) < 2:
        yield from map(_fly_logged, work)
        return

    pool = ProcessPoolExecutor(max_workers=min(jobs, len(work)), initializer=_leave_signals)
    try:
        for fut in as_completed([pool.submit(_fly_logged, w) for w in work]):
            yield fut.result()
    finally:  # interrupted: drop the queued flights, let the running ones end
        pool.shutdown(wait=True, cancel_futures=True)


def _leave_signals() -> None:
    """Workers ignore Ctrl-C: the parent decides, and writes what has finished."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# --- the table and its summary -------------------------------------------------------------
def write_table(rows: list[FlightRow], path: str | Path) -> None:
    """CSV, one row per flight in the order given, COLUMNS as the header; floats to 7
    significant digits, None as an empty cell; replaced whole (core/safefile.py write_atomic).
    Makes no directory (the caller's choice, docs/contracts.md §2)."""
    table = CsvTable(Path(path), FlightRow)
    table.write(rows)
    table.finish()


@dataclass(frozen=True)
class Stat:
    """min, median, max of some figure (None when there is nothing to take them of)."""

    min: float | None
    median: float | None
    max: float | None

    @classmethod
    def of(cls, values: list[float]) -> Stat:
        if not values:
            return cls(None, None, None)
        return cls(min(values), statistics.median(values), max(values))


@dataclass(frozen=True)
class Summary:
    """flights; outcomes: EndReason name -> count; in_window: contacts inside their plan's
    window; contact_speed [m/s], speed_error_mps [m/s] (contact speed - the plan's),
    perch_error_s [s] and perch_error_pct [%] of the contacts; trigger_dx_m [m] / trigger_dv_mps [m/s]: measured minus aimed trigger state."""

    flights: int
    outcomes: dict[str, int]
    in_window: int
    contact_speed: Stat
    speed_error_mps: Stat
    perch_error_s: Stat
    perch_error_pct: Stat
    trigger_dx_m: Stat
    trigger_dv_mps: Stat


def summarize(rows: Sequence[FlightRow] | Sequence[Brief]) -> Summary:
    hits = [r for r in rows if r.contact_speed is not None]
    trig = [r for r in rows if r.trigger_x is not None]
    return Summary(
        len(rows),
        dict(Counter(r.outcome for r in rows).most_common()),
        sum(r.in_window for r in rows),
        Stat.of([r.contact_speed for r in hits]),
        Stat.of([r.contact_speed - r.plan_v_contact for r in hits]),
        Stat.of([r.perch_error_s for r in hits]),
        Stat.of([100.0 * r.perch_error_s / r.plan_duration for r in hits]),
        Stat.of([r.trigger_x - r.x0_aim for r in trig]),
        Stat.of([r.trigger_v - r.v0_aim for r in trig]),
    )
