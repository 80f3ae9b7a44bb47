"""What each layer of the controller earns: the vehicle family flown with each layer off.

    python benchmarks/ablation.py [--n N] [--seed S] [--jobs J] [--layers NAME ...]
                                  [--json OUT]

Flies the same N members of the vehicle family (perchd/sim/family.py, each on its first
flight, perchd/campaign/familyrun.py: fly_member) with the baseline config (benchmarks/family.py:
base_config, the defaults with the trigger replanning) and with each variant of VARIANTS:
one layer turned off by its config switches, or a group of them. A variant changes the
FlightConfig (dataclasses.replace) and, for a layer with no setting, a module constant
(Variant.patches, set in the worker for its flights). Prints one table, a row a variant:

    in-window  CONTACT inside the plan's window (the simulator's contact speed) [%]
    err mean   mean contact speed less the plan's V_c over the contacts [m/s]
    |err| p95  95th percentile of |contact speed - V_c| (nearest rank) [m/s]
    on-time    perch time within +-3 % of the plan's [%]
    unst       unstable endings (familyrun.UNSTABLE)
    d win, d on-time  the variant less the baseline [percentage points] +- its standard
               error, paired over the same members: sqrt(b + c - (b - c)^2 / N) / N with b,
               c the members only one of the two counts; `*` where |d| > 2 SE.
    d err      the mean contact error's change [m/s] +- its paired standard error over the
               members both touched

then the default sim:// perch (plans/case1-ipts-n3.json on the default simulated Crazyflie,
the README's `perchd fly plans/case1-ipts-n3.json --driver sim:// --mocap sim://` with the
default config) per variant: its contact speed and perch time error. --layers: the
variants flown (besides the baseline); --json OUT: the summary and every row.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib.util
import json
import math
import sys
import tempfile
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from perchd.campaign.familyrun import FamilyRow, fly_member
from perchd.flight.config import FlightConfig
from perchd.session import open_session
from perchd.sim.family import FamilyVehicle, sample
from perchd.tau import load_plan
from perchd.tau.plan import Plan

ROOT = Path(__file__).resolve().parents[1]
PLAN = ROOT / "plans" / "case1-ipts-n3.json"


def _family_bench() -> Any:
    """benchmarks/family.py as a module (its base_config: the trigger a campaign flies)."""
    name = "perchd_bench_family"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / "family.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


Change = tuple[str, str, Any]
"""(section, key, value): FlightConfig.<section>.<key> = value, as `[section] key = value`;
as a patch, (module, constant, value): a module constant the variant flies with."""


@dataclass(frozen=True)
class Variant:
    """name; what: the layer (or group) turned off, in words; changes: its switches."""

    name: str
    what: str
    changes: tuple[Change, ...] = ()
    patches: tuple[Change, ...] = ()

    def apply(self, cfg: FlightConfig) -> FlightConfig:
        """cfg with the changes (each section replaced once, so validation sees them all)."""
        sections: dict[str, dict[str, Any]] = {}
        for section, key, value in self.changes:
            sections.setdefault(section, {})[key] = value
        return dataclasses.replace(
            cfg, **{s: dataclasses.replace(getattr(cfg, s), **kv) for s, kv in sections.items()}
        )

    def config_toml(self) -> str:
        """The changes as TOML tables, appended to a flight config file."""
        sections: dict[str, list[str]] = {}
        for section, key, value in self.changes:
            sections.setdefault(section, []).append(f"{key} = {_toml(value)}")
        return "".join(f"\n[{s}]\n" + "\n".join(kv) + "\n" for s, kv in sections.items())

    def toml(self) -> str:
        return "; ".join(
            [f"[{s}] {k} = {_toml(v)}" for s, k, v in self.changes]
            + [f"{m}.{k} = {_toml(v)}" for m, k, v in self.patches]
        )

    @contextlib.contextmanager
    def patched(self) -> Iterator[None]:
        """The module constants of `patches` set while inside (restored after)."""
        saved = []
        try:
            for module, key, value in self.patches:
                mod = importlib.import_module(module)
                saved.append((mod, key, getattr(mod, key)))
                setattr(mod, key, value)
            yield
        finally:
            for mod, key, value in reversed(saved):
                setattr(mod, key, value)


def _toml(v: Any) -> str:
    return str(v).lower() if isinstance(v, bool) else format(v, "g")


LAYERS: tuple[Variant, ...] = (
    Variant("hover", "hover learning in the hold (flight/hover.py)", (("hover", "learn", False),)),
    Variant(
        "feedforward",
        "the tau PID's feed-forward (plan acceleration, drag, bias)",
        (("tau_gains", "feedforward", False),),
    ),
    Variant(
        "ff-lead",
        "the configured lead (0: no lead without an identified lag)",
        (("tau_gains", "ff_lead_s", 0.0),),
    ),
    Variant(
        "identify",
        "the response's identification (and all that uses it)",
        (("tau_gains", "identify", False),),
    ),
    Variant(
        "qdrag",
        "the quadratic drag in the model (one linear drag)",
        patches=(("perchd.flight.lagid", "QUADRATIC_DRAG", False),),
    ),
    Variant(
        "refits",
        "the approach's refits (one fit at the trigger)",
        patches=(("perchd.flight.supervisor", "REFIT_S", 3600.0),),
    ),
    Variant(
        "lag-attitude", "the lag from the measured attitude", (("lag_id", "from_attitude", False),)
    ),
    Variant("scale", "stage 1's scale correction", (("tau_gains", "scale_gain", 0.0),)),
    Variant(
        "margin",
        "the stage-2 margin inside the window (no wall push: V_c held as planned)",
        (("tau_gains", "wall_push_mps2", 0.0),),
    ),
    Variant(
        "hold-ki",
        "stage 2's integral from its gain (the configured ki throughout)",
        patches=(("perchd.flight.references", "KI_SHARE", 0.0),),
    ),
)
"""One layer off each: the switches (config changes, module constants) that turn it off."""

_BY_NAME = {v.name: v for v in LAYERS}


def _group(name: str, what: str, *layers: str) -> Variant:
    picked = [_BY_NAME[n] for n in layers]
    return Variant(
        name,
        what,
        tuple(c for v in picked for c in v.changes),
        tuple(p for v in picked for p in v.patches),
    )


GROUPS: tuple[Variant, ...] = (
    _group(
        "no-ident",
        "all identification",
        "identify",
        "qdrag",
        "refits",
        "lag-attitude",
    ),
    _group(
        "paper-only",
        "every layer: the paper's tau PID with the plan's acceleration fed "
        "forward at once, its Y/Z PID, stage 2 holding the plan's V_c",
        *(v.name for v in LAYERS if v.name != "feedforward"),
    ),
)
"""Groups of layers off together."""

BASELINE = Variant("baseline", "nothing (today's defaults)", ())
VARIANTS: tuple[Variant, ...] = LAYERS + GROUPS


def pick(names: list[str] | None) -> list[Variant]:
    """The baseline, then the named variants (all when None) in VARIANTS' order."""
    known = {v.name for v in VARIANTS}
    unknown = sorted(set(names or ()) - known)
    if unknown:
        raise SystemExit(f"unknown layer(s) {', '.join(unknown)}; known: {', '.join(known)}")
    return [BASELINE] + [v for v in VARIANTS if names is None or v.name in names]


def _fly(
    job: tuple[Plan, FlightConfig, tuple[Change, ...], FamilyVehicle, str, int],
) -> tuple[int, FamilyRow]:
    plan, base, patches, member, log_dir, k = job
    with Variant("", "", patches=patches).patched():
        return k, fly_member(plan, member, base, Path(log_dir) / f"v{k}-m{member.index:05d}.jsonl")


def fly_variants(
    plan: Plan, base: FlightConfig, variants: list[Variant], members: list[FamilyVehicle], jobs: int
) -> Iterator[tuple[int, FamilyRow]]:
    """(variant index, row) for every variant and member, member-major (each member flown
    by every variant before the next), in `jobs` processes."""
    with tempfile.TemporaryDirectory(prefix="perchd-ablation-") as logs:
        work = [
            (plan, v.apply(base), v.patches, m, logs, k)
            for m in members
            for k, v in enumerate(variants)
        ]
        if jobs == 1:
            yield from map(_fly, work)
            return
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            yield from pool.map(_fly, work, chunksize=max(1, len(work) // (jobs * 32)))


def fly_default(plan: Plan, variant: Variant) -> dict[str, float | str | None]:
    """The README's sim:// perch with the variant: outcome, true contact speed [m/s], perch
    time error [% of the plan's duration]."""
    with tempfile.TemporaryDirectory(prefix="perchd-ablation-") as d, variant.patched():
        res = open_session("sim://").fly(
            plan, Path(d) / "flight.jsonl", variant.apply(FlightConfig())
        )
    err = (
        None
        if res.true_perch_time is None
        else 100.0 * (res.true_perch_time - res.plan_duration) / res.plan_duration
    )
    return {
        "outcome": res.outcome.name,
        "contact_speed": res.true_contact_speed,
        "v_contact_plan": res.v_contact_plan,
        "perch_error_pct": err,
    }


def paired_se(mine: list[bool], base: list[bool]) -> float:
    """[share] standard error of the difference of two rates over the same members."""
    n = len(mine)
    b = sum(x and not y for x, y in zip(mine, base, strict=True))
    c = sum(y and not x for x, y in zip(mine, base, strict=True))
    return math.sqrt(max(b + c - (b - c) ** 2 / n, 0.0)) / n if n else math.nan


def _err(r: FamilyRow) -> float | None:
    return None if r.contact_speed is None else r.contact_speed - r.plan_v_contact


def summarize(rows: list[FamilyRow], base: list[FamilyRow]) -> dict[str, Any]:
    """One variant's figures, and its deltas against the baseline's rows (same members)."""
    n = len(rows)
    errs = [e for e in map(_err, rows) if e is not None]
    absd = sorted(abs(e) for e in errs)
    win, on = [r.in_window for r in rows], [r.on_time for r in rows]
    bwin, bon = [r.in_window for r in base], [r.on_time for r in base]
    both = [
        (e, f)
        for e, f in zip(map(_err, rows), map(_err, base), strict=True)
        if e is not None and f is not None
    ]
    diffs = [e - f for e, f in both]
    mean_d = sum(diffs) / len(diffs) if diffs else math.nan
    sd_d = (
        math.sqrt(sum((d - mean_d) ** 2 for d in diffs) / (len(diffs) - 1))
        if len(diffs) > 1
        else math.nan
    )
    return {
        "n": n,
        "contacts": len(errs),
        "in_window_pct": 100.0 * sum(win) / n,
        "on_time_pct": 100.0 * sum(on) / n,
        "err_mean_mps": sum(errs) / len(errs) if errs else math.nan,
        "err_abs_p95_mps": absd[min(len(absd) - 1, round(0.95 * (len(absd) - 1)))]
        if absd
        else math.nan,
        "unstable": sum(r.unstable for r in rows),
        "outcomes": {
            o: sum(r.outcome == o for r in rows) for o in sorted({r.outcome for r in rows})
        },
        "d_in_window_pp": 100.0 * (sum(win) - sum(bwin)) / n,
        "se_in_window_pp": 100.0 * paired_se(win, bwin),
        "d_on_time_pp": 100.0 * (sum(on) - sum(bon)) / n,
        "se_on_time_pp": 100.0 * paired_se(on, bon),
        "d_err_mps": mean_d,
        "se_err_mps": sd_d / math.sqrt(len(diffs)) if diffs else math.nan,
    }


def _delta(d: float, se: float, spec: str) -> str:
    if math.isnan(d):
        return "-"
    star = "*" if se > 0 and abs(d) > 2 * se or se == 0 and d != 0 else " "
    if math.isnan(se):
        return f"{d:{spec}}"
    return f"{d:{spec}} +-{se:{spec.lstrip('+')}}{star}"


HEAD = (
    "| layer off | in-window | err mean | \\|err\\| p95 | on-time | unst "
    "| d win [pp] | d on-time [pp] | d err mean [m/s] | sim:// V [m/s] | sim:// perch |"
)


def table_lines(variants: list[Variant], summaries: list[dict], defaults: list[dict]) -> list[str]:
    """The Markdown table: a row a variant."""
    lines = [HEAD, "|" + "---|" * (HEAD.count(" | ") + 1)]
    for v, s, d in zip(variants, summaries, defaults, strict=True):
        speed = "-" if d["contact_speed"] is None else f"{d['contact_speed']:.3f}"
        perch = "-" if d["perch_error_pct"] is None else f"{d['perch_error_pct']:+.2f} %"
        base = v is variants[0]
        lines.append(
            f"| {v.name} | {s['in_window_pct']:.1f} % | {s['err_mean_mps']:+.3f} | "
            f"{s['err_abs_p95_mps']:.3f} | {s['on_time_pct']:.1f} % | {s['unstable']} | "
            + (
                " | | "
                if base
                else f"{_delta(s['d_in_window_pp'], s['se_in_window_pp'], '+.1f')} | "
                f"{_delta(s['d_on_time_pp'], s['se_on_time_pp'], '+.1f')} | "
            )
            + ("" if base else _delta(s["d_err_mps"], s["se_err_mps"], "+.3f"))
            + f" | {speed} | {perch} |"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="members flown by each variant")
    ap.add_argument("--seed", type=int, default=0, help="the family's draw")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument(
        "--layers",
        nargs="+",
        metavar="NAME",
        help=f"variants flown besides the baseline: {' '.join(v.name for v in VARIANTS)}",
    )
    ap.add_argument("--json", type=Path, metavar="OUT", help="write summary and rows here")
    args = ap.parse_args(argv)
    variants = pick(args.layers)
    plan = load_plan(PLAN)
    base = _family_bench().base_config(PLAN, plan)
    members = sample(args.n, args.seed)
    t0 = time.perf_counter()
    rows: list[list[FamilyRow | None]] = [[None] * args.n for _ in variants]
    done, total = 0, len(variants) * args.n
    for k, row in fly_variants(plan, base, variants, members, max(1, args.jobs)):
        rows[k][row.index] = row
        done += 1
        if done % max(1, total // 10) == 0:
            print(
                f"{done} of {total} flown ({time.perf_counter() - t0:.0f} s)",
                file=sys.stderr,
                flush=True,
            )
    flown: list[list[FamilyRow]] = [[r for r in rs if r is not None] for rs in rows]
    summaries = [summarize(rs, flown[0]) for rs in flown]
    defaults = [fly_default(plan, v) for v in variants]
    wall = time.perf_counter() - t0
    print(
        f"{args.n} members (seed {args.seed}) x {len(variants)} variants, {wall:.0f} s; "
        f"contact errors against the plan's V_c; deltas +- paired SE, * beyond 2 SE"
    )
    for line in table_lines(variants, summaries, defaults):
        print(line)
    print()
    for v in variants[1:]:
        print(f"  {v.name:<12} {v.toml()}")
    if args.json:
        args.json.write_text(
            json.dumps(
                {
                    "command": sys.argv,
                    "n": args.n,
                    "seed": args.seed,
                    "wall_s": wall,
                    "variants": [
                        {
                            "name": v.name,
                            "what": v.what,
                            "changes": v.changes,
                            "summary": s,
                            "default_perch": d,
                            "rows": [dataclasses.asdict(r) for r in rs],
                        }
                        for v, s, d, rs in zip(variants, summaries, defaults, flown, strict=True)
                    ],
                },
                indent=1,
            )
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
