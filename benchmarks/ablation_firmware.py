"""What each layer of the controller earns on the vehicles' own firmware.

    python benchmarks/ablation_firmware.py [--flights N] [--only NAME ...] [--layers NAME ...]
                                           [--json]

The ablation's variants (benchmarks/ablation.py) flown on each firmware whose environment
variable names a binary (benchmarks/firmware.py: PERCHD_CF2, PERCHD_ARDUCOPTER, PERCHD_PX4),
N flights each (default 3) of plans/case1-ipts-n3.json, one vehicle profile per firmware and
variant (empty at its first flight), each variant's switches appended to the flight config
as TOML. A variant that sets a module constant is not flown here: the flight is `perchd fly`
in its own process, and nothing but its config may change it. Prints one table, a row a
variant and firmware:

    in-window   flights touching inside the plan's window (the simulator's truth) / flown
    contact     median true contact speed [min..max] [m/s]
    perch       median perch time error against the plan flown [%] (largest |error|; the
                trigger replans: benchmarks/firmware.py TRIGGER)
    +-2 %       flights within +-2 % of the plan's perch time
    unst        flights ending otherwise than in CONTACT
    d contact, d perch  the median's change against the baseline on the same firmware

Flights run in real time: fly on a quiet machine (the load average is printed).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def bench_module(name: str) -> Any:
    """benchmarks/<name>.py as a module."""
    key = f"perchd_bench_{name}"
    if key not in sys.modules:
        spec = importlib.util.spec_from_file_location(key, ROOT / "benchmarks" / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[key] = module
        spec.loader.exec_module(module)
    return sys.modules[key]


def figures(flights: list[dict], plan: dict) -> dict[str, Any]:
    """One variant's figures on one firmware."""
    lo, hi = plan["limits"]["v_contact"]
    speeds = [f["contact_speed"] for f in flights if f["contact_speed"] is not None]
    errs = [
        bench_module("firmware").perch_error_pct(f)
        for f in flights
        if f["outcome"] == "CONTACT" and f["perch_time"] is not None
    ]
    return {
        "flights": len(flights),
        "in_window": sum(lo <= s <= hi for s in speeds),
        "contact": [statistics.median(speeds), min(speeds), max(speeds)] if speeds else None,
        "perch_pct": statistics.median(errs) if errs else None,
        "perch_pct_maxabs": max(map(abs, errs)) if errs else None,
        "within_2pct": sum(abs(e) <= 2.0 for e in errs),
        "unstable": sum(f["outcome"] != "CONTACT" for f in flights),
        "outcomes": sorted({f["outcome"] for f in flights}),
    }


def row(name: str, fw: str, s: dict[str, Any], base: dict[str, Any] | None) -> str:
    c = s["contact"]
    contact = "-" if c is None else f"{c[0]:.3f} [{c[1]:.3f}..{c[2]:.3f}]"
    perch = (
        "-" if s["perch_pct"] is None else f"{s['perch_pct']:+.2f} ({s['perch_pct_maxabs']:.2f})"
    )
    d_c = d_p = ""
    if base is not None and c is not None and base["contact"] is not None:
        d_c = f"{c[0] - base['contact'][0]:+.3f}"
    if base is not None and s["perch_pct"] is not None and base["perch_pct"] is not None:
        d_p = f"{s['perch_pct'] - base['perch_pct']:+.2f}"
    return (
        f"| {name} | {fw} | {s['in_window']}/{s['flights']} | {contact} | {perch} | "
        f"{s['within_2pct']}/{s['flights']} | {s['unstable']} | {d_c} | {d_p} |"
    )


HEAD = (
    "| layer off | firmware | in-window | contact [m/s] | perch [%] (max) | +-2 % | unst "
    "| d contact [m/s] | d perch [pp] |"
)


def fly_variant(fw: Any, binary: str, variant: Any, home: Path, args: Any) -> list[dict]:
    """args.flights flights of the variant on one firmware under home/, one vehicle profile
    (empty at the first)."""
    home.mkdir(parents=True, exist_ok=True)
    state = home / "vehicle.json"
    state.unlink(missing_ok=True)
    add = variant.config_toml()
    flights = []
    for i in range(args.flights):
        (home / str(i)).mkdir(exist_ok=True)
        flights.append(
            bench_module("firmware").fly_firmware(
                fw, binary, args.noise, i, home / str(i), add, "", state
            )
        )
    return flights


def main(argv: list[str] | None = None) -> int:
    fwb, abl = bench_module("firmware"), bench_module("ablation")
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=3, help="flights per variant and firmware")
    ap.add_argument("--noise", type=float, default=0.001, help="[m] mocap noise std (0.001)")
    fwb.add_selection(ap, "flight")
    ap.add_argument("--layers", nargs="+", metavar="NAME", help="variants besides the baseline")
    args = ap.parse_args(argv)
    if args.flights < 1:
        print("benchmarks/ablation_firmware.py: --flights must be >= 1", file=sys.stderr)
        return 2
    variants = abl.pick(args.layers)
    for v in [v for v in variants if v.patches]:
        print(f"{v.name}: not flown (it sets a module constant: {v.toml()})", file=sys.stderr)
    variants = [v for v in variants if not v.patches]
    plan = json.loads(fwb.PLAN.read_text())
    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="perchd-fwablation-"))
    out: dict[str, dict[str, Any]] = {}
    lines = [HEAD, "|" + "---|" * (HEAD.count(" | ") + 1)]
    for fw, binary in fwb.selected(args.only):
        out[fw.name] = {"load_avg": os.getloadavg()}
        for v in variants:
            flights = fly_variant(fw, binary, v, root / fw.name / v.name, args)
            out[fw.name][v.name] = figures(flights, plan)
            base = None if v is variants[0] else out[fw.name][variants[0].name]
            lines.append(row(v.name, fw.name, out[fw.name][v.name], base))
            if not args.json:
                print(lines[-1], file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps(out))
        return 0
    loads = ", ".join(f"{k} {v['load_avg'][0]:.2f}" for k, v in out.items())
    print(f"{args.flights} flights per variant and firmware (load average at the end: {loads})")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
