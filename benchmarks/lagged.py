"""Perches in perchd's simulator made to answer like the firmwares: late and through a filter.

    python benchmarks/lagged.py [--seeds N] [--set SECTION.KEY=VALUE ...] [--json]

The firmware flights (benchmarks/firmware.py) are the judge but take minutes each; these
take a second. Each plant is sim:// with link latency and an attitude time constant that
together make the 0.13-0.35 s lag the firmwares were identified with (docs/firmware.md, "Lag
and drag"), and the drag they meet, linear or growing with speed. Plan case1-ipts-n3; per
plant over N noise seeds (1 mm): true contact speed (min..max), speed at the stage-2 switch,
perch time error, and how many touched within 0.03 m/s of the speed its stage 2 held (hold_loop) inside the window.
`--set tau_gains.scale_gain=0` (any FlightConfig field, repeatable) flies a variant.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "helpers"))

from simflight import Sim, case1

from perchd.flight.config import FlightConfig
from perchd.logs.flightlog import read_log

PLANTS = {
    "lag 0.25 s, drag 0.3/s": "latency=0.1&attitude_tau=0.15&drag=0.3",
    "lag 0.25 s, drag 0.2|v|v": "latency=0.1&attitude_tau=0.15&qdrag=0.2",
    "lag 0.13 s, drag 0.2/s": "latency=0.05&attitude_tau=0.05&drag=0.2",
    "lag 0.25 s, drag 1/s": "latency=0.1&attitude_tau=0.1&drag=1.0",
    "lag 0.35 s, drag 0.5/s": "latency=0.1&attitude_tau=0.2&drag=0.5",
    "lag 0.13 s, push -0.2 in stage 2": "latency=0.05&attitude_tau=0.05&drag=0.2&draught=-0.7,-0.2",
    "perchd's own (20 ms)": "latency=0.02",
}
"""name -> sim:// query (docs/contracts.md §7); the lags are what the flight identifies."""


def configured(sets: list[str]) -> FlightConfig:
    """FlightConfig with SECTION.KEY=VALUE overrides (VALUE as JSON: numbers, true/false)."""
    cfg = FlightConfig()
    for item in sets:
        path, _, raw = item.partition("=")
        section, _, key = path.partition(".")
        part = getattr(cfg, section)
        cfg = dataclasses.replace(
            cfg, **{section: dataclasses.replace(part, **{key: json.loads(raw)})}
        )
    return cfg


def fly(query: str, seed: int, cfg: FlightConfig) -> dict:
    plan = case1("ipts")
    log = Path(tempfile.mkdtemp()) / "flight.jsonl"
    res = Sim(f"sim://?{query}&noise=0.001&seed={seed}").fly(plan, log, cfg)
    rows = [r for r in read_log(log).rows if r.phase == "stage2"]
    lo, hi = plan.limits.v_contact
    v = res.true_contact_speed
    return {
        "outcome": res.outcome.name,
        "contact": v,
        "switch_speed": rows[0].xdot if rows else None,
        "perch_pct": 100 * (res.true_perch_time / plan.duration - 1) if v else None,
        "on_target": v is not None
        and res.v_hold_mps is not None
        and lo <= v <= hi
        and abs(v - res.v_hold_mps) <= 0.03,
    }


def report(out: dict[str, list[dict]], sets: list[str]) -> None:
    """One line per plant: contact, switch speed and perch time ranges over its seeds."""
    hits = sum(f["on_target"] for runs in out.values() for f in runs)
    total = sum(len(runs) for runs in out.values())
    print(f"on target {hits}/{total}  {' '.join(sets)}")
    for name, runs in out.items():
        ok = [f for f in runs if f["contact"] is not None]
        c = [f["contact"] for f in ok]
        sw = [f["switch_speed"] for f in ok if f["switch_speed"]]
        pt = [f["perch_pct"] for f in ok]
        print(
            f"  {name:34s} contact {min(c):.3f}..{max(c):.3f}  switch "
            f"{min(sw):.2f}..{max(sw):.2f} m/s  perch {min(pt):+.1f}..{max(pt):+.1f} %"
            f"  {len(ok)}/{len(runs)} perched"
        )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4, help="noise seeds per plant (4)")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    cfg = configured(args.set)
    out = {name: [fly(q, s, cfg) for s in range(args.seeds)] for name, q in PLANTS.items()}
    if args.json:
        print(json.dumps(out))
    else:
        report(out, args.set)
    return 0


if __name__ == "__main__":
    sys.exit(main())
