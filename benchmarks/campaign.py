"""Campaign throughput: flights per second per core on Dask LocalClusters of 1 and 2 worker
processes (perchd.campaign.dask_engine), and one flight's CPU cost in this process.

    python benchmarks/campaign.py [--flights N] [--repeat R] [--plan FILE] [--profile K]

Each cluster is started, warmed (every worker imports perchd and flies one unit), then flies
N flights (default 200) R times (default 3); the figures are medians of the R runs, the
cluster's start reported apart. flights/s/core = flights/s / workers; the ratio is 2
workers' flights/s over 1 worker's. Targets: 8 flights/s/core, ratio >= 1.8. --profile K:
cProfile one in-process unit and print its top K entries by internal time. Needs the
"cluster" extra (pip install 'perchd[cluster]').
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import statistics
import time
from pathlib import Path

from perchd.campaign import flights as cp
from perchd.campaign.batches import CampaignJob, fly_campaign, fly_unit
from perchd.campaign.dask_engine import DaskEngine
from perchd.flight.config import FlightConfig
from perchd.tau import load_plan

ROOT = Path(__file__).resolve().parents[1]
PLAN = ROOT / "plans" / "robust-n3-table2-box.json"
TARGET_PER_CORE, TARGET_RATIO = 8.0, 1.8


def job_and_specs(plan_file: Path, flights: int) -> tuple[CampaignJob, list[cp.FlightSpec]]:
    plan = load_plan(plan_file)
    x0, v0 = cp.default_ranges(plan)
    spread = cp.Spread(x0, v0, gust_mps=0.2, seed=0)
    cfg = cp.campaign_config(FlightConfig(), cp.default_policy(plan))
    return CampaignJob(plan, cfg, spread), cp.random_specs(spread, flights, plan.duration)


def in_process(job: CampaignJob, specs: list, repeat: int) -> float:
    """[CPU-s] per flight flown in this process (median of `repeat` units of 20)."""
    fly_unit(job, specs[:2])  # imports and caches: once per worker in a campaign
    costs = []
    for _ in range(repeat):
        t0 = time.process_time()
        fly_unit(job, specs[:20])
        costs.append((time.process_time() - t0) / 20)
    return statistics.median(costs)


def on_cluster(workers: int, job: CampaignJob, specs: list, repeat: int) -> dict:
    t0 = time.perf_counter()
    engine = DaskEngine.start(None, workers)
    try:
        started_s = time.perf_counter() - t0
        fly_campaign(job, specs[: 2 * workers], engine, lambda rows: None)  # warm every worker
        rates, cpu = [], []
        for _ in range(repeat):
            rows: list = []
            t0 = time.perf_counter()
            fly_campaign(job, specs, engine, rows.extend)
            rates.append(len(rows) / (time.perf_counter() - t0))
            cpu.append(sum(r.cpu_s for r in rows) / len(rows))
    finally:
        engine.close()
    rate = statistics.median(rates)
    return {
        "workers": workers,
        "start_s": started_s,
        "flights_per_s": rate,
        "per_core": rate / workers,
        "cpu_per_flight_s": statistics.median(cpu),
        "runs": rates,
    }


def profile(job: CampaignJob, specs: list, top: int) -> None:
    fly_unit(job, specs[:2])
    prof = cProfile.Profile()
    prof.runcall(fly_unit, job, specs[:20])
    pstats.Stats(prof).sort_stats("tottime").print_stats(top)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--plan", type=Path, default=PLAN)
    ap.add_argument("--profile", type=int, metavar="K")
    args = ap.parse_args()
    job, specs = job_and_specs(args.plan, args.flights)
    if args.profile:
        profile(job, specs, args.profile)
        return
    print(f"plan {args.plan.name}, {args.flights} flights x {args.repeat}, medians")
    cost = in_process(job, specs, args.repeat)
    print(f"in this process: {cost * 1e3:.1f} ms CPU per flight = {1 / cost:.1f} flights/s/core")
    found = [on_cluster(w, job, specs, args.repeat) for w in (1, 2)]
    for f in found:
        runs = " ".join(f"{r:.2f}" for r in f["runs"])
        print(
            f"LocalCluster {f['workers']}: {f['flights_per_s']:.2f} flights/s = "
            f"{f['per_core']:.2f} /core (target {TARGET_PER_CORE:g}); "
            f"{f['cpu_per_flight_s'] * 1e3:.1f} ms CPU per flight in the worker; "
            f"cluster up in {f['start_s']:.1f} s; runs {runs}"
        )
    ratio = found[1]["flights_per_s"] / found[0]["flights_per_s"]
    print(f"2 workers / 1: {ratio:.2f}x (target >= {TARGET_RATIO:g})")


if __name__ == "__main__":
    main()
