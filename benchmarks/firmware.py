"""Perches on the vehicles' own firmware, beside the same flights in perchd's simulator.

    python benchmarks/firmware.py [--flights N] [--noise M] [--only NAME ...] [--json]

For each firmware whose environment variable names a binary (PERCHD_CF2: the Crazyflie's
cf2; PERCHD_ARDUCOPTER: ArduCopter SITL; PERCHD_PX4: a PX4 SITL build folder; the others are
skipped with one line), N flights (default 10) of plans/case1-ipts-n3.json, each as a user
flies it: `perchd sim firmware ... --noise M` (the harness, perchd/sim/firmware, docs/firmware.md)
and `perchd fly` with the harness's mocap and driver URIs, no mass or hover in the URI (the
flight config names the vehicle, the hold learns its hover thrust), one vehicle profile
(`--state`) per firmware as a lab's vehicle flown N times has (its first flight knows nothing;
`--fresh-state`: every flight a first). Printed per firmware:
flights perched / flown (in the plan's window; on target: in it and within 0.03 m/s of the
speed its stage 2 held), the true contact speed (median, min, max) against the held speed,
perch time (median, % error against the plan flown: the trigger replans, TRIGGER), the true heading's largest departure from
the start heading (PX4: the harness's, at take-over; else the first of the flight) between the
flight's first and last control tick, the speed at the trigger against the plan's v0, the
lag and drag the flight identified (flight/lagid.py), PX4's simulation clock against the
wall clock and the push its attitude estimate put on the vehicle in the 0.5 s before
contact; beside it the same N flights in
perchd's simulator (sim:// with the same mocap noise, seeds 0..N-1: its Crazyflie plant and
the default flight config).

Flights run in real time: on a loaded machine a firmware or `perchd fly` descheduled for
tens of milliseconds changes the figures. The load average is printed with them.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "helpers"))  # the firmware tests' harness helpers
from stale import HARNESS_SAFETY  # noqa: E402  (the firmware tests' stale limit)

PLAN = ROOT / "plans" / "case1-ipts-n3.json"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
INSTANCE = os.environ.get("PERCHD_FW_INSTANCE")
"""The SITL instance (ports moved by N) as the firmware tests take it, for a machine shared
with other runs; None: the harness's default (0)."""
HEADING_DEG = "60"
"""[deg] PX4 turns to this compass heading before the flight, as the PX4 trial flies: a
heading off the world's axes (the frame's rotation) and both truth velocity components in
the contact speed (HIL_STATE_QUATERNION's are whole cm/s)."""
CONTACT_TOL_MPS = 0.03
"""[m/s] on target: in the plan's window and this close to the speed the flight's stage 2
held (its `v_hold_mps`: perchd.flight.references.hold_loop)."""
SIM_SPEED = os.environ.get("PERCHD_PX4_SIM_SPEED", "1.015")
"""SIH's speed factor: on this 2-core machine its lockstep clock ran at 0.984-0.990 of the
wall clock at 1 (with the harness's fine timer slack), 0.992-1.005 at 1.015; the summary
prints the rate each flight reached (docs/firmware.md, "PX4 SIH")."""
LIBRARY = ROOT / "plans" / "libraries" / PLAN.name
TRIGGER = {"policy": '"replan"', "library": json.dumps(str(LIBRARY))}
"""The trigger a campaign flies (benchmarks/family.py `base_config`), given to every firmware
flight: a vehicle that reaches x0 off the plan's v0 (the autopilots by up to 0.13 m/s) flies a
plan made from the state it measured, warm from the plan's library, instead of the plan made
for v0 (1 % of perch time early per 0.05 m/s too fast, measured on ArduCopter) or a refusal
(past `[trigger] v_tol_mps`). Its perch time is the new plan's (`plan_duration`)."""


def with_trigger(config: str) -> str:
    """The flight config with TRIGGER's keys in its [trigger] table (one added if it has none)."""
    keys = "".join(f"{k} = {v}\n" for k, v in TRIGGER.items())
    if "\n[trigger]\n" in config:
        return config.replace("\n[trigger]\n", "\n[trigger]\n" + keys, 1)
    return f"{config}\n[trigger]\n{keys}"


PX4_CONFIG = (
    """version = 1
[vehicle]
mass_kg = 1.0
thrust_min_n = 2.0
thrust_max_n = 18.0
"""
    + HARNESS_SAFETY
)
"""SIH's quadrotor (1 kg, 4 x 5 N)."""


@dataclass(frozen=True)
class Firmware:
    """name; env: the variable naming the binary; flag: `perchd sim firmware`'s option for it;
    extra: more harness options; config: the flight config (TOML text, None: the default
    Crazyflie)."""

    name: str
    env: str
    flag: str
    extra: tuple[str, ...] = ()
    config: str | None = None


FIRMWARES = (
    Firmware(
        "cf2",
        "PERCHD_CF2",
        "--cf2",
        ("--link", "udp://127.0.0.1:0"),
        config="version = 1\n" + HARNESS_SAFETY,
    ),
    Firmware(
        "arducopter",
        "PERCHD_ARDUCOPTER",
        "--arducopter",
        config=(ROOT / "tests" / "firmware" / "arducopter-3kg.toml").read_text(),
    ),  # has it
    Firmware(
        "px4",
        "PERCHD_PX4",
        "--px4",
        ("--ahead", "4.5", "--heading", HEADING_DEG, "--sim-speed", SIM_SPEED),
        config=PX4_CONFIG,
    ),
    # PX4's other start: on the ground, GPS off, EKF2 on the mocap perchd forwards;
    # perchd arms and takes off. The same 1.5 m run-up to x0 as in the air (with 4.5 m,
    # 4 of 10 reached x0 0.11-0.2 m/s fast and the trigger refused: docs/firmware.md).
    Firmware(
        "px4-ground",
        "PERCHD_PX4",
        "--px4",
        ("--vision", "--ahead", "4.5", "--sim-speed", SIM_SPEED),
        config=PX4_CONFIG,
    ),
)


def driver_uri(ready: str) -> str:
    """The ready line's driver URI without mass= or hover= (the flight config names the
    vehicle, the hold learns its hover thrust)."""
    base, _, query = ready.partition("?")
    kept = [kv for kv in query.split("&") if kv and kv.split("=")[0] not in ("mass", "hover")]
    return base + ("?" + "&".join(kept) if kept else "")


def start_harness(fw: Firmware, binary: str, noise: float, tmp: Path):
    """`perchd sim firmware`: its process, mocap URI, driver URI and surface options."""
    from fwharness import start_placed

    instance = ("--instance", INSTANCE) if INSTANCE and fw.name != "cf2" else ()
    proc, mocap, driver, surface = start_placed(
        fw.flag,
        binary,
        *fw.extra,
        *instance,
        "--noise",
        str(noise),
        "--fw-log",
        str(tmp / "fw.log"),
        env=ENV,
    )
    return proc, mocap, driver_uri(driver), surface


def stop_harness(proc: subprocess.Popen) -> dict:
    from fwharness import stop_harness as stop

    return stop(proc, 30.0)


def lag_event(log: Path) -> dict:
    from fwharness import lag_event as event

    return event(log)


def fly_argv(
    fw: Firmware,
    tmp: Path,
    mocap: str,
    driver: str,
    surface: list[str],
    config_add: str = "",
    driver_add: str = "",
    state: Path | None = None,
    replan: bool = True,
) -> list[str]:
    """`perchd fly` against a started harness, as a user flies it; its flight log is
    tmp/flight.jsonl. config_add: TOML appended to the flight config; driver_add: URI
    parameters appended to the driver's; state: the vehicle profile shared by the flights,
    named after the firmware (the harness's ports are ephemeral); None: tmp's own, a
    vehicle flown for the first time; replan: with TRIGGER, else the plan as made (the
    trigger's default)."""
    driver += ("&" if "?" in driver else "?") + driver_add if driver_add else ""
    config = (fw.config or "version = 1\n") + config_add
    (tmp / "flight.toml").write_text(with_trigger(config) if replan else config)
    return [
        sys.executable,
        "-m",
        "perchd",
        "fly",
        str(PLAN),
        "--driver",
        driver,
        "--mocap",
        mocap,
        "--config",
        str(tmp / "flight.toml"),
        *surface,
        "--log",
        str(tmp / "flight.jsonl"),
        "--state",
        str(state or tmp / "vehicle.json"),
        *(("--vehicle", fw.name) if state else ()),
        "--json",
    ]


def fly_firmware(
    fw: Firmware,
    binary: str,
    noise: float,
    seed: int,
    tmp: Path,
    config_add: str = "",
    driver_add: str = "",
    state: Path | None = None,
    replan: bool = True,
) -> dict:
    proc, mocap, driver, surface = start_harness(fw, binary, noise, tmp)
    from fwharness import YawWatch, flight_window, heading_error

    watch = YawWatch(mocap)
    try:
        done = subprocess.run(
            fly_argv(fw, tmp, mocap, driver, surface, config_add, driver_add, state, replan),
            check=False,
            capture_output=True,
            text=True,
            timeout=180,
            env=ENV,
        )
    finally:
        watch.close()
        sim = stop_harness(proc)
    fly = (
        json.loads(done.stdout)
        if done.stdout.strip()
        else {"outcome": "NO_RESULT", "detail": done.stderr.strip()[-300:]}
    )
    yaws = watch.between(*flight_window(tmp / "flight.jsonl"))
    heading = sim.get("start_heading_rad")
    heading = yaws[0] if heading is None and yaws else heading or 0.0
    return {
        "outcome": fly["outcome"],
        "detail": fly.get("detail"),
        "contact_speed": (sim.get("contact") or {}).get("speed"),
        "agent_contact_speed": fly.get("contact_speed"),
        "held": fly.get("v_hold_mps"),
        "perch_time": fly.get("perch_time"),
        "plan_duration": fly.get("plan_duration"),
        "trigger_v": (fly.get("trigger") or {}).get("v"),
        "yaw_dev_deg": math.degrees(heading_error(yaws, heading)) if yaws else None,
        "lag": lag_event(tmp / "flight.jsonl"),
        "sim_clock_rate": sim.get("sim_clock_rate"),
        "attitude_push": sim.get("attitude_push_mps2"),
    }


def fly_sim(noise: float, seed: int, tmp: Path) -> dict:
    """The same flight in perchd's own simulator (its Crazyflie, the default flight config),
    in process on a simulated clock."""
    from simflight import Sim

    from perchd.tau.planfile import load_plan

    res = Sim(f"sim://?noise={noise}&seed={seed}").fly(load_plan(PLAN), tmp / "sim.jsonl")
    return {
        "outcome": res.outcome.name,
        "contact_speed": res.true_contact_speed,
        "held": res.v_hold_mps,
        "perch_time": res.true_perch_time,
        "plan_duration": res.plan_duration,
        "trigger_v": res.trigger and res.trigger.v,
        "yaw_dev_deg": 0.0,
        "lag": lag_event(tmp / "sim.jsonl"),
    }


def perch_error_pct(flight: dict) -> float:
    """[%] the flight's perch time against the plan it flew (the trigger's, if it replanned)."""
    return 100.0 * (flight["perch_time"] / flight["plan_duration"] - 1.0)


def summary(flights: list[dict], plan: dict) -> dict:
    ok = [f for f in flights if f["outcome"] == "CONTACT" and f["contact_speed"] is not None]
    lo, hi = plan["limits"]["v_contact"]
    speeds = [f["contact_speed"] for f in ok]
    held = [(f["contact_speed"], f["held"]) for f in ok if f.get("held") is not None]
    errs = [v - h for v, h in held]
    times = [f["perch_time"] for f in ok if f["perch_time"] is not None]
    errs_pct = [perch_error_pct(f) for f in ok if f["perch_time"] is not None]
    trig = [f["trigger_v"] - plan["v0"] for f in flights if f["trigger_v"] is not None]
    yaws = [f["yaw_dev_deg"] for f in flights if f["yaw_dev_deg"] is not None]
    lags = [f["lag"].get("lag_s") for f in flights if f["lag"].get("lag_s") is not None]
    drags = [f["lag"].get("drag_per_s") for f in flights if f["lag"].get("drag_per_s") is not None]
    rates = [f["sim_clock_rate"] for f in flights if f.get("sim_clock_rate") is not None]
    pushes = [f["attitude_push"] for f in flights if f.get("attitude_push") is not None]
    med = statistics.median
    return {
        "flights": len(flights),
        "perched": len(ok),
        "in_window": sum(lo <= s <= hi for s in speeds),
        "on_target": sum(lo <= v <= hi and abs(v - h) <= CONTACT_TOL_MPS for v, h in held),
        "outcomes": sorted({f["outcome"] for f in flights}),
        "contact_median": med(speeds) if speeds else None,
        "contact_min": min(speeds, default=None),
        "contact_max": max(speeds, default=None),
        "held_speed": med(h for _, h in held) if held else None,
        "contact_err_maxabs": max((abs(e) for e in errs), default=None),
        "perch_time_median": med(times) if times else None,
        "perch_time_err_pct": med(errs_pct) if errs_pct else None,
        "perch_time_err_pct_maxabs": max(map(abs, errs_pct), default=None),
        "within_2pct": sum(abs(e) <= 2.0 for e in errs_pct),
        "yaw_dev_deg_max": max(yaws, default=None),
        "trigger_v_err_median": med(trig) if trig else None,
        "trigger_v_err_maxabs": max(map(abs, trig), default=None),
        "lag_s": [round(x, 3) for x in lags],
        "drag_per_s": [round(x, 3) for x in drags],
        "sim_clock_rate": [round(x, 4) for x in rates],
        "attitude_push_mps2": [round(x, 3) for x in pushes],
    }


def fmt(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def print_row(name: str, s: dict, plan: dict) -> None:
    print(
        f"  {name:9s} perched {s['perched']}/{s['flights']} (in window {s['in_window']}, "
        f"on target {s['on_target']}); "
        f"contact {fmt(s['contact_median'], '.3f')} [{fmt(s['contact_min'], '.3f')}.."
        f"{fmt(s['contact_max'], '.3f')}] vs {fmt(s['held_speed'], '.3f')} m/s held "
        f"(plan V_c {plan['v_contact']:.3f}) "
        f"(max |err| {fmt(s['contact_err_maxabs'], '.3f')}); perch time "
        f"{fmt(s['perch_time_median'], '.3f')} s (plan {plan['duration']:.4f} s; against the "
        f"plan flown {fmt(s['perch_time_err_pct'], '+.2f')} %, max |err| "
        f"{fmt(s['perch_time_err_pct_maxabs'], '.2f')} %, within +-2 % {s['within_2pct']}/"
        f"{s['perched']}); yaw within "
        f"{fmt(s['yaw_dev_deg_max'], '.2f')} deg; trigger v err median "
        f"{fmt(s['trigger_v_err_median'], '+.3f')} (max |err| "
        f"{fmt(s['trigger_v_err_maxabs'], '.3f')}) m/s"
    )
    if s["lag_s"]:
        print(
            f"            identified lag {min(s['lag_s'])}..{max(s['lag_s'])} s, drag "
            f"{min(s['drag_per_s'])}..{max(s['drag_per_s'])} 1/s"
        )
    if s["sim_clock_rate"]:
        print(
            f"            simulation clock {min(s['sim_clock_rate'])}.."
            f"{max(s['sim_clock_rate'])} s per wall-clock s"
        )
    if s["attitude_push_mps2"]:
        print(
            f"            the autopilot's attitude estimate's push in stage 2 "
            f"{min(s['attitude_push_mps2'])}..{max(s['attitude_push_mps2'])} m/s^2"
        )
    if set(s["outcomes"]) - {"CONTACT"}:
        print(f"            outcomes: {', '.join(s['outcomes'])}")


def add_selection(ap: argparse.ArgumentParser, what: str) -> None:
    """--only, --keep and --json, as every firmware benchmark takes them."""
    ap.add_argument(
        "--only", nargs="*", choices=[f.name for f in FIRMWARES], help="these firmwares only"
    )
    ap.add_argument("--keep", metavar="DIR", help=f"keep each {what}'s logs under DIR")
    ap.add_argument("--json", action="store_true", help="print one JSON object")


def selected(only: list[str] | None):
    """(firmware, its binary) for each firmware asked for whose environment variable names
    a binary; one line on stderr for each skipped."""
    for fw in FIRMWARES:
        binary = os.environ.get(fw.env, "")
        if only and fw.name not in only:
            continue
        if not binary:
            print(f"{fw.name}: skipped ({fw.env} is not set)", file=sys.stderr)
            continue
        yield fw, binary


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=10, help="flights per firmware (10)")
    ap.add_argument("--noise", type=float, default=0.001, help="[m] mocap noise std (0.001)")
    add_selection(ap, "flight")
    ap.add_argument(
        "--config-add",
        default="",
        metavar="TOML",
        help="TOML tables appended to every firmware flight's config, e.g. "
        "'[tau_gains]\\npredict = false' (the sim:// flights keep the default)",
    )
    ap.add_argument(
        "--driver-add",
        default="",
        metavar="PARAMS",
        help="URI parameters appended to every firmware flight's driver, e.g. 'tilt=0'",
    )
    ap.add_argument(
        "--fresh-state",
        action="store_true",
        help="every flight a vehicle flown for the first time (default: one "
        "vehicle profile per firmware, empty at its first flight)",
    )
    ap.add_argument(
        "--as-made",
        action="store_true",
        help="fly the plan as made for v0 (the trigger's default: refused past "
        "[trigger] v_tol_mps), not replanned from the state at x0",
    )
    args = ap.parse_args()
    if args.flights < 1 or not 0.0 <= args.noise <= 0.1:
        print(
            "benchmarks/firmware.py: --flights must be >= 1 and --noise 0..0.1 m", file=sys.stderr
        )
        return 2
    plan = json.loads(PLAN.read_text())
    out: dict = {
        "plan": {"duration": plan["duration"], "v_contact": plan["v_contact"], "v0": plan["v0"]},
        "noise_m": args.noise,
        "firmwares": {},
    }
    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="perchd-fwbench-"))
    for fw, binary in selected(args.only):
        runs: dict[str, list[dict]] = {"firmware": [], "sim": []}
        state = None if args.fresh_state else root / fw.name / "vehicle.json"
        if state is not None:
            state.unlink(missing_ok=True)
        for i in range(args.flights):
            tmp = root / fw.name / str(i)
            tmp.mkdir(parents=True, exist_ok=True)
            runs["firmware"].append(
                fly_firmware(
                    fw,
                    binary,
                    args.noise,
                    i,
                    tmp,
                    args.config_add.replace("\\n", "\n") + "\n",
                    args.driver_add,
                    state,
                    not args.as_made,
                )
            )
            runs["sim"].append(fly_sim(args.noise, i, tmp))
            if not args.json:
                f = runs["firmware"][-1]
                print(
                    f"{fw.name} flight {i + 1}: {f['outcome']} contact "
                    f"{fmt(f['contact_speed'], '.3f')} m/s, perch time "
                    f"{fmt(f['perch_time'], '.3f')} s of {fmt(f['plan_duration'], '.3f')} s, lag {fmt(f['lag'].get('lag_s'), '.3f')} s "
                    f"drag {fmt(f['lag'].get('drag_per_s'), '.3f')} 1/s, stage 2 held "
                    f"{fmt(f['held'], '.3f')} m/s",
                    file=sys.stderr,
                )
        out["firmwares"][fw.name] = {
            "load_avg": os.getloadavg(),
            "firmware": summary(runs["firmware"], plan),
            "sim": summary(runs["sim"], plan),
            "flights": runs,
        }
        if not args.json:
            res = out["firmwares"][fw.name]
            print(
                f"{fw.name} (load average {res['load_avg'][0]:.2f}, mocap noise {args.noise:g} m):"
            )
            print_row("firmware", res["firmware"], plan)
            print_row("sim://", res["sim"], plan)
    if args.json:
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
