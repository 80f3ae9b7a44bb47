"""`perchd sim --campaign P.json`: the campaign options of `perchd sim`, its progress bar on
stderr, the outcome table (CSV) and the printed summary. The flying is perchd.campaign.flights.

    perchd sim --campaign P.json [--flights N | --grid NX NV] [--x0 LO HI] [--v0 LO HI]
               [--latency S] [--noise M] [--gust DV] [--seed N] [--start X Y Z]
               [--surface X Y Z] [--normal NX NY NZ] [--config F] [--policy P]
               [--table OUT.parquet|OUT.csv] [--logs DIR] [--jobs J]
               [--cluster local[:N] | tcp://SCHEDULER:8786] [--json]

Each flight is a row of the table, written as it ends, with a JSON summary beside it
(OUT.summary.json). The same command on an existing table flies only the flights missing
from it (perchd.campaign.results); a different campaign on it is refused. `perchd sim report
TABLE` prints a table's summary and draws its plots.

Exit 0 when every flight made contact inside its plan's contact window, 1 otherwise.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

from perchd.campaign import flights as cp
from perchd.campaign.batches import CampaignJob, fly_campaign
from perchd.campaign.engine import Engine, open_engine, parse_cluster
from perchd.campaign.results import CampaignTable, digest, summary_path
from perchd.campaign.tableformats import have_pyarrow
from perchd.console.flightargs import load_config
from perchd.console.progress import Progress
from perchd.core.errors import ConfigError
from perchd.core.interrupts import exit_code
from perchd.core.safefile import OutputError, check_output
from perchd.flight.config import TriggerPolicy
from perchd.flight.planguard import check_flight_plan
from perchd.logs.flightlog import jsonable
from perchd.tau import load_plan

DEFAULT_FLIGHTS = 20
LIVE_ONLY = ("pose_out", "setpoint_in", "duration", "exit_on_stop")
"""Options of a live `perchd sim` (all unset by default) that mean nothing to a campaign."""
CAMPAIGN_DEFAULTS = {
    "flights": None,
    "grid": None,
    "x0": None,
    "v0": None,
    "gust": 0.0,
    "seed": 0,
    "policy": None,
    "config": None,
    "table": None,
    "logs": None,
    "jobs": None,
    "force": False,
    "cluster": None,
}


FLIGHTS_PER_WORKER = 200
"""A worker process costs about a second to start (20 flights' worth): the local default
starts one per core only for a campaign with this many flights per core."""


def default_jobs(flights: int) -> int:
    """Worker processes for `flights` when --jobs is not given: the cores the campaign fills."""
    return max(1, min(os.cpu_count() or 1, flights // FLIGHTS_PER_WORKER))


def add_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group(
        "campaign",
        "many simulated flights of one plan in this process, on a simulated "
        "clock; --latency, --noise, --surface, --normal and --json apply too, and --start "
        "(default: far enough back for each trigger state)",
    )
    g.add_argument("--campaign", metavar="P.json", help="fly this plan file many times")
    n = g.add_mutually_exclusive_group()
    n.add_argument("--flights", type=int, help=f"random trigger states (default {DEFAULT_FLIGHTS})")
    n.add_argument(
        "--grid",
        nargs=2,
        type=int,
        metavar=("NX", "NV"),
        help="a grid of NX x NV trigger states, corners included (default: random draws)",
    )
    g.add_argument(
        "--x0",
        nargs=2,
        type=float,
        metavar=("LO", "HI"),
        help="[m] trigger gap range (default: the plan's robust box less 0.04, "
        "else its x0 +- 10 %%)",
    )
    g.add_argument(
        "--v0",
        nargs=2,
        type=float,
        metavar=("LO", "HI"),
        help="[m/s] closing speed range (default as --x0)",
    )
    g.add_argument(
        "--gust",
        type=float,
        default=CAMPAIGN_DEFAULTS["gust"],
        metavar="DV",
        help="[m/s] one velocity kick per flight, uniform in +-DV per axis, at "
        "10..60 %% of the plan's duration after the trigger (default 0: none)",
    )
    g.add_argument(
        "--seed", type=int, default=CAMPAIGN_DEFAULTS["seed"], help="seed of every draw (default 0)"
    )
    g.add_argument(
        "--policy",
        choices=("robust", "replan", "refuse"),
        help="trigger policy (default robust for a plan with a box, else replan)",
    )
    g.add_argument("--config", help="flight configuration file (TOML), as for perchd fly")
    g.add_argument(
        "--table",
        help="outcome table, .parquet (pyarrow) or .csv; its directory "
        "must exist; the same command again resumes it (default "
        "./campaigns/<time>-<plan>.parquet, or .csv without "
        "pyarrow; directory made)",
    )
    g.add_argument(
        "--logs",
        help="keep each flight's log (flight-NNNN.jsonl) in this existing "
        "directory (default: none kept)",
    )
    g.add_argument(
        "--force",
        action="store_true",
        help="overwrite an existing --table file or flight logs in --logs",
    )
    g.add_argument(
        "--jobs",
        type=int,
        default=CAMPAIGN_DEFAULTS["jobs"],
        help="worker processes on this machine (default: one per core once the "
        f"campaign has {FLIGHTS_PER_WORKER} flights per core to fly, else this process)",
    )
    g.add_argument(
        "--cluster",
        metavar="local[:N]|tcp://HOST:PORT",
        help="where flights run: local[:N], N worker processes here (a Dask "
        "LocalCluster, or a process pool without Dask; N defaults to --jobs), "
        "or a Dask scheduler's address (pip install 'perchd[cluster]')",
    )


def check_mode(args: argparse.Namespace) -> None:
    """One clear error when a live option meets --campaign, or the other way round."""
    if args.campaign:
        given = [o for o in LIVE_ONLY if getattr(args, o) not in (None, False)]
        if given:
            opts = ", ".join("--" + o.replace("_", "-") for o in given)
            raise ConfigError(
                f"{opts}: for a live simulator, not a --campaign (which flies in this process)"
            )
        return
    given = [o for o, v in CAMPAIGN_DEFAULTS.items() if getattr(args, o) != v]
    if given:
        opts = ", ".join("--" + o for o in given)
        raise ConfigError(f"{opts}: only with --campaign P.json")
    if not args.pose_out or not args.setpoint_in:
        raise ConfigError(
            "--pose-out and --setpoint-in are required (or --campaign P.json "
            "for simulated flights in this process)"
        )


def _stat(s: Any, fmt: str, scale: float = 1.0) -> str:
    if s.median is None:
        return "--"
    return " / ".join(format(v * scale, fmt) for v in (s.min, s.median, s.max))


def summary_text(summary: Any, table: Path, wall_s: float) -> str:
    outcomes = ", ".join(f"{k} {v}" for k, v in summary.outcomes.items())
    contacts = summary.outcomes.get("CONTACT", 0)
    return "\n".join(
        [
            f"flights: {summary.flights} in {wall_s:.1f} s; {outcomes}",
            f"contact inside the plan's window: {summary.in_window} of {summary.flights}",
            f"contact speed min / median / max: {_stat(summary.contact_speed, '.3f')} m/s "
            f"({contacts} contacts); - plan: {_stat(summary.speed_error_mps, '+.3f')} m/s",
            f"perch time - plan: {_stat(summary.perch_error_s, '+.1f', 1e3)} ms "
            f"({_stat(summary.perch_error_pct, '+.2f')} %)",
            f"trigger - aim: x {_stat(summary.trigger_dx_m, '+.3f')} m, "
            f"v {_stat(summary.trigger_dv_mps, '+.3f')} m/s",
            f"table: {table}",
        ]
    )


def build(args: argparse.Namespace) -> tuple[Any, Any, Any, list[Any]]:
    """(plan, flight config, spread, specs) from the options; errors name the option."""

    plan = load_plan(args.campaign)
    if args.jobs is not None and args.jobs < 1:  # before the table is made
        raise ConfigError(f"--jobs {args.jobs}: at least 1")
    xr, vr = cp.default_ranges(plan)
    if not 0.0 <= args.latency <= 1.0:
        raise ConfigError(f"--latency {args.latency:g} s is outside 0..1 s")
    if not 0.0 <= args.noise <= 0.1:
        raise ConfigError(f"--noise {args.noise:g} m is outside 0..0.1 m")
    spread = cp.Spread(
        tuple(args.x0 or xr),
        tuple(args.v0 or vr),
        args.latency,
        args.noise,
        args.gust,
        tuple(args.start) if args.start else None,
        args.seed,
    )
    policy = TriggerPolicy(args.policy) if args.policy else cp.default_policy(plan)
    cfg = cp.campaign_config(load_config(args), policy)
    check_flight_plan(plan, cfg)  # before the table is made: exit 2 naming the field
    if args.grid:
        specs = cp.grid_specs(spread, *args.grid, plan.duration)
    else:
        flights = DEFAULT_FLIGHTS if args.flights is None else args.flights
        specs = cp.random_specs(spread, flights, plan.duration)
    return plan, cfg, spread, specs


def table_path(args: argparse.Namespace) -> Path:
    """--table checked (no directory made; an existing table is resumed or refused by
    CampaignTable, replaced only with --force), or the default in ./campaigns, the one
    directory a campaign creates."""
    if args.table:
        table = Path(args.table)
        if not args.force and (table.exists() or summary_path(table).exists()):
            return table
        return check_output(args.table, "--table", args.force, inputs=(args.campaign,))
    suffix = ".parquet" if have_pyarrow() else ".csv"
    table = (
        Path("campaigns") / f"{time.strftime('%Y%m%d-%H%M%S')}-{Path(args.campaign).stem}{suffix}"
    )
    return check_output(table, "--table", args.force) if table.parent.is_dir() else table


def check_log_dir(logs: str | None, indices: list[int], force: bool) -> None:
    """--logs must be an existing directory whose flight logs are not overwritten unless --force."""
    if logs is None:
        return
    if not Path(logs).is_dir():
        raise OutputError(f"--logs {logs}: not an existing directory (perchd creates none)")
    for i in indices:
        check_output(Path(logs) / f"flight-{i:04d}.jsonl", "--logs", force)


def identity(args: argparse.Namespace, cfg: Any, spread: Any, flights: int) -> dict[str, Any]:
    """What makes a campaign's table: the plan file, policy, configuration, spread and draw
    (not where or how fast it flies)."""
    draw = {"grid": list(args.grid)} if args.grid else {"flights": flights}
    return {
        "plan": digest(Path(args.campaign).read_bytes()),
        "policy": cfg.trigger.policy.value,
        "config": digest(jsonable(cfg)),
        "spread": asdict(spread),
        "draw": draw,
    }


def run(args: argparse.Namespace) -> int:

    plan, cfg, spread, specs = build(args)
    cluster = parse_cluster(args.cluster)
    table = table_path(args)
    results = CampaignTable(table, identity(args, cfg, spread, len(specs)), args.force)
    todo = results.missing(specs)
    check_log_dir(args.logs, [s.index for s in todo], args.force)
    make_default_dir(table)
    progress = Progress(len(specs), "flights", "sim", rates=True, done=results.resumed)
    t0 = time.monotonic()
    stopped, engine, flown = None, None, False

    def finished(rows: list[Any]) -> None:
        results.append(rows)  # as they finish: an interrupted campaign keeps them
        for row in rows:
            progress(row.outcome, failed=not row.in_window)

    with on_signals():
        try:
            engine = open_engine(cluster, args.jobs or default_jobs(len(todo)))
            results.begin()
            fly_campaign(CampaignJob(plan, cfg, spread, args.logs), todo, engine, finished)
            flown = True
        except Stopped as stop:
            stopped = stop
        finally:
            try:  # the engine first: a signal in the progress line's close leaves no worker
                close_quietly(engine, flown)
            finally:
                progress.close()
            where = {
                "engine": engine.name if engine else None,
                "resumed": results.resumed,
                "flown": len(results.rows) - results.resumed,
            }
            rows = results.finish(len(specs), {**where, "wall_s": time.monotonic() - t0})
    report(args, cfg, spread, rows, table, time.monotonic() - t0, stopped, len(specs), where)
    if stopped is not None:
        return stopped.exit_code
    return 0 if cp.summarize(rows).in_window == len(rows) else 1


def close_quietly(engine: Engine | None, flown: bool) -> None:
    """The engine closed with signals held off: a second Ctrl-C does not leave workers.
    Unless every unit was `flown` (a signal, an error), its workers are killed, not waited
    for: a unit mid-flight takes seconds, the command has 1 s to end (docs/contracts.md §6)."""
    if engine is None:
        return
    held = {s: signal.signal(s, signal.SIG_IGN) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        if flown:
            engine.close()
        else:
            engine.kill()
    finally:
        for s, handler in held.items():
            signal.signal(s, handler)


def report(
    args,
    cfg,
    spread,
    rows: list[Any],
    table: Path,
    wall: float,
    stopped: Stopped | None,
    planned: int,
    where: dict[str, Any],
) -> None:
    """The summary of the table's flights (all of them unless `stopped`)."""
    summary = cp.summarize(rows)
    if args.json:
        print(
            json.dumps(
                {
                    **asdict(summary),
                    "plan": args.campaign,
                    "policy": cfg.trigger.policy.value,
                    "spread": asdict(spread),
                    "table": str(table),
                    "wall_s": wall,
                    "interrupted": None if stopped is None else stopped.name,
                    "planned": planned,
                    **where,
                }
            )
        )
    else:
        print(summary_text(summary, table, wall))
    if stopped is not None:
        print(
            f"perchd sim: interrupted by {stopped.name} after {len(rows)} of {planned} "
            f"flights; the table holds those, and the same command flies the rest",
            file=sys.stderr,
        )


class Stopped(BaseException):
    """SIGINT/SIGTERM during a campaign: stop flying, keep what finished (docs/contracts.md §6)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.name = signal.Signals(signum).name
        self.exit_code = exit_code(signum)


@contextlib.contextmanager
def on_signals():
    """SIGINT and SIGTERM raise Stopped in the main thread while the campaign runs."""

    def stop(signum, _frame):
        for s in (signal.SIGINT, signal.SIGTERM):  # once: the first signal decides
            signal.signal(s, signal.SIG_IGN)
        raise Stopped(signum)

    previous = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def make_default_dir(table: Path) -> None:
    """The default ./campaigns is the one directory a campaign makes."""
    if table.parent == Path("campaigns"):
        table.parent.mkdir(exist_ok=True)
