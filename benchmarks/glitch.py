"""Benchmark: the README flight in perchd's simulator with a one-frame mocap glitch every
N-th frame (a reflection tracked as the body), for glitch sizes under the outlier gate.

    python3 benchmarks/glitch.py [--sizes 0.01 0.02 0.03 0.04 0.05] [--every 29 31 37 41 43]
        [--no-hold] [--json]

Prints, per size [m on each axis], every flight's ending, true contact speed and the largest
|u_x| commanded [m/s^2]. --no-hold: the estimator fuses a frame off the track at once (the
outlier gate alone). Not a test: it asserts nothing (docs/safety.md, "Design rules").
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "helpers"))

from faultsim import fly  # noqa: E402

import perchd.flight.run as flight_run  # noqa: E402
from perchd.flight.estimator import EstimatorConfig  # noqa: E402
from perchd.sim.faults import Outliers  # noqa: E402


def flight(jump_m: float, every: int) -> dict:
    with tempfile.TemporaryDirectory() as d:
        f = fly(Path(d), Outliers(every=every, jump_m=jump_m))
        return {
            "every": every,
            "outcome": f.res.outcome.name,
            "contact_mps": f.res.true_contact_speed,
            "ux_max_mps2": max(abs(r.ux) for r in f.log.rows if r.ux is not None),
        }


def speed(mps: float | None) -> str:
    return "-" if mps is None else f"{mps:.3f} m/s"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[0.01, 0.02, 0.03, 0.04, 0.05])
    ap.add_argument("--every", type=int, nargs="+", default=[29, 31, 37, 41, 43])
    ap.add_argument("--no-hold", action="store_true", help="no frame waits: the outlier gate alone")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()
    if min(args.every) < 2 or not all(0.0 < s <= 1.0 for s in args.sizes):
        print("benchmarks/glitch.py: --every must be >= 2 and --sizes 0..1 m", file=sys.stderr)
        return 2
    if args.no_hold:
        flight_run.EstimatorConfig = functools.partial(EstimatorConfig, glitch_speed_mps=math.inf)
    out = {f"{s:g}": [flight(s, n) for n in args.every] for s in args.sizes}
    if args.json:
        print(json.dumps(out))
        return 0
    for size, flights in out.items():
        cells = [
            f"{f['outcome']} {speed(f['contact_mps'])} |ux| {f['ux_max_mps2']:.1f}" for f in flights
        ]
        print(f"{size} m: " + "; ".join(cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
