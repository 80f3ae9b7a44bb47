"""`perchd fly P.json --driver URI --mocap URI [--config F] [--surface X Y Z]
[--normal NX NY NZ] [--log F] [--state F] [--vehicle NAME] [--json]`: fly one perch and
report it (docs/contracts.md §2).

`--log F.mcap` writes the flight log beside it as F.jsonl while flying and, when the flight
ends, F.mcap from it (`perchd log export`, needs perchd[mcap]); docs/contracts.md §5.
`--foxglove [HOST:]PORT` serves the same channels live (perchd.logs.foxglove, perchd[foxglove]).

What the flight learns of the vehicle (its hover thrust; its lag and drag, to be seen) is
kept in the vehicle's profile (--vehicle NAME, default the driver URI): --state F, default
$XDG_STATE_HOME/perchd/vehicles/NAME.json (flight/profile.py, flight/vehiclestate.py); the
hover is the next flight's guess. The summary names the profile each time (`perchd vehicle
show NAME`, `perchd vehicle forget NAME`).

While flying, a one-line status on stderr (phase, X, Xdot, tau vs tau_ref); afterwards a
summary (or with --json exactly one JSON object on stdout). Exit 0 on contact, 1 otherwise;
SIGINT or SIGTERM end the flight (SIGNAL, with the failsafe) and exit 130 or 143 (docs/contracts.md §6).
With `--driver sim:// --mocap sim://` the flight is simulated on a simulated clock.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from perchd.console.argcheck import numbers_as_values
from perchd.console.flightargs import load_config
from perchd.core import realtime
from perchd.core.errors import ConfigError, PerchdError
from perchd.core.extras import require
from perchd.core.interrupts import catching
from perchd.core.safefile import OutputError, check_output
from perchd.core.types import EndReason
from perchd.core.uriparams import params_help
from perchd.flight.planguard import check_flight_plan
from perchd.flight.run import FlightAbort, FlightResult
from perchd.flight.vehiclestate import VehicleStore, profile_path
from perchd.logs.flightlog import read_log
from perchd.logs.foxglove import ViewProcess, parse_address
from perchd.logs.mcapexport import export_mcap
from perchd.logs.summary import figure_lines
from perchd.session import open_links
from perchd.tau import load_plan

EPILOG = f"""URI query parameters, KEY [unit] (default); any other key is refused
(docs/contracts.md §7), e.g. --driver sim://?latency=0.02 --mocap sim://?noise=0.001;
sim:// is one world: the vehicle's keys on --driver, the mocap's on --mocap:
{params_help()}

The loop: by default each mocap frame releases a tick (`[flight] sync = "mocap"`, rate_hz
= the mocap rate), so a setpoint follows its pose by the compute time only; with no frame for
1.5 periods it ticks anyway (stale mocap still ends the flight; the Crazyflie and MAVLink
drivers repeat the last setpoint themselves after 100 ms). `sync = "fixed"` ticks at
rate_hz whatever the frames do (a pose then waits up to a period): for a link whose firmware
wants a steady setpoint rate, or a mocap much faster than the link should be commanded.
--realtime[=PRIO] runs the agent under SCHED_FIFO (needs CAP_SYS_NICE or ulimit -r PRIO).

sim:// flies on a simulated clock, faster than real time. In real time: run
`perchd sim --pose-out natnet://127.0.0.1:0 --setpoint-in zmq://127.0.0.1:0` and fly
against the URIs it prints, or use sim:// links under `perchd serve`."""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "fly",
        help="fly a perch along a plan",
        description="Fly a perch along a plan file, e.g. "
        "perchd fly plans/case1-ipts-n3.json "
        "--driver sim:// --mocap sim://",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    numbers_as_values(p)
    p.add_argument("plan", help="plan file (perchd.plan/1 JSON)")
    p.add_argument("--driver", required=True, help="vehicle URI (sim://, radio://..., ...)")
    p.add_argument("--mocap", required=True, help="mocap URI (sim://, natnet://..., ...)")
    p.add_argument("--config", help="flight configuration file (TOML)")
    p.add_argument(
        "--surface",
        nargs=3,
        type=float,
        metavar=("X", "Y", "Z"),
        help="[m] a point on the surface, world frame (default 0 0 0)",
    )
    p.add_argument(
        "--normal",
        nargs=3,
        type=float,
        metavar=("NX", "NY", "NZ"),
        help="surface normal along the approach, world frame (default 1 0 0)",
    )
    p.add_argument(
        "--log",
        help="flight log path; its directory must exist "
        "(default ./flightlogs/<time>-<strategy>.jsonl, directory made). "
        "F.mcap: the log is written as F.jsonl beside it during the "
        "flight and exported to F.mcap at its end (perchd[mcap])",
    )
    p.add_argument("--force", action="store_true", help="overwrite an existing --log file(s)")
    p.add_argument(
        "--state",
        help="the vehicle's profile, what flights learned of it (JSON; "
        "default $XDG_STATE_HOME/perchd/vehicles/NAME.json, i.e. "
        "~/.local/state/perchd/vehicles/NAME.json)",
    )
    p.add_argument(
        "--vehicle",
        metavar="NAME",
        help="the vehicle's name, which names its profile (default: the driver URI; "
        "name it when its URI changes between flights, e.g. an ephemeral port)",
    )
    p.add_argument(
        "--realtime",
        nargs="?",
        type=int,
        const=realtime.DEFAULT_PRIORITY,
        default=0,
        metavar="PRIO",
        help="run the agent under SCHED_FIFO at priority PRIO (1..99, default "
        f"{realtime.DEFAULT_PRIORITY}) with its memory locked; refused in one "
        "line, nothing flown, if the system does not permit it "
        "(CAP_SYS_NICE or ulimit -r; docs/safety.md)",
    )
    p.add_argument(
        "--cpu", type=int, default=-1, metavar="N", help="with --realtime: pin the agent to CPU N"
    )
    p.add_argument(
        "--foxglove",
        metavar="[HOST:]PORT",
        help="serve the flight live over the Foxglove WebSocket protocol (the MCAP "
        "export's channels, docs/contracts.md §5) on HOST (default 127.0.0.1), "
        "PORT 0 for any free one; needs perchd[foxglove]",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object with the outcome")
    p.set_defaults(run=run)


class StatusLine:
    """The live status on stderr: rewritten in place on a terminal, else a line per 0.5 s."""

    def __init__(self, stream=None) -> None:
        self.stream = sys.stderr if stream is None else stream  # looked up now, not at import
        self.tty = self.stream.isatty()
        self.every = 0.1 if self.tty else 0.5
        self._next = 0.0

    def __call__(self, st) -> None:
        if st.t < self._next:
            return
        self._next = st.t + self.every
        fmt = lambda v, f: "  --  " if v is None else format(v, f)  # noqa: E731
        line = (
            f"t {st.t:6.2f} s  {st.phase.value:<8} X {fmt(st.x, '+7.3f')} m  "
            f"Xdot {fmt(st.xdot, '+6.3f')} m/s  tau {fmt(st.tau, '+7.3f')} / "
            f"ref {fmt(st.tau_ref, '+7.3f')} s"
        )
        self.stream.write(("\r" + line) if self.tty else line + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")


def summary_text(res: FlightResult) -> str:
    """The flight's summary: logs/summary.py's head, then what only a live flight knows."""
    lines = figure_lines(
        res.outcome.name,
        res.detail,
        res.contact_speed,
        res.v_contact_plan,
        res.perch_time,
        res.plan_duration,
    )
    if res.true_contact_speed is not None:
        lines.append(
            f"simulator: contact at {res.true_contact_speed:.3f} m/s"
            + (
                f", {res.true_perch_time:.3f} s after the trigger"
                if res.true_perch_time is not None
                else ""
            )
        )
    if res.hover_n is not None:
        lines.append(f"hover thrust learned: {res.hover_n:.4f} N (guess {res.hover_guess_n:.4f} N)")
    if res.trigger is not None:
        lines.append(
            f"trigger: x {res.trigger.x:.3f} m, v {res.trigger.v:.3f} m/s; {res.trigger.action}"
        )
    lp = res.loop
    lines.append(
        f"loop: {lp.ticks} ticks, compute median {lp.compute_median_s * 1e6:.0f} us "
        f"(p99 {lp.compute_p99_s * 1e6:.0f} us), {lp.overruns} overruns"
    )
    lines.append(f"log: {res.log}" + (f" (LOST: {res.log_lost})" if res.log_lost else ""))
    return "\n".join(lines)


def log_path(args: argparse.Namespace, strategy: str) -> Path:
    """--log checked (nothing overwritten without --force, no directory made), or the default
    in ./flightlogs, the one directory a flight creates."""
    if args.log:
        return check_output(args.log, "--log", args.force, inputs=inputs(args))
    log = Path("flightlogs") / f"{time.strftime('%Y%m%d-%H%M%S')}-{strategy}.jsonl"
    try:
        log.parent.mkdir(exist_ok=True)
    except OSError as err:
        raise OutputError(f"--log {log}: cannot make {log.parent} ({err.strerror})") from None
    return check_output(log, "--log", args.force)


def inputs(args: argparse.Namespace) -> tuple[str, ...]:
    """What the flight reads, which no output may be: the plan, --config, --state."""
    return tuple(p for p in (args.plan, args.config, args.state) if p)


def state_store(args: argparse.Namespace) -> VehicleStore:
    """The vehicle's profile (--state, or the default for --vehicle), refused now unless
    missing or a profile of perchd's own (it is rewritten after the flight)."""
    name = args.vehicle or args.driver
    path = Path(args.state) if args.state else profile_path(name)
    store = VehicleStore(path, name, _warn)
    store.check()
    return store


def mcap_path(args: argparse.Namespace) -> Path | None:
    """--log F.mcap checked, with the extra, before anything flies; None for a JSONL --log."""
    if not (args.log and args.log.endswith(".mcap")):
        return None
    require("mcap.writer", "mcap")
    return check_output(args.log, "--log", args.force, inputs=inputs(args))


def live_view(address: str | None, log: Path):
    """The --foxglove server, a process following `log` once it is written
    (perchd.logs.foxglove); bound and announced on stderr before anything flies. None
    without --foxglove."""
    if address is None:
        return None
    view = ViewProcess(parse_address(address), log)
    _warn(f"foxglove: serving {view.url}")
    return view


def write_mcap(log: Path, out: Path, force: bool) -> bool:
    """The flown log exported to `out`; a failure is a warning: the flight and its JSONL stand."""
    try:
        export_mcap(read_log(log), out, force, "--log")
        return True
    except (PerchdError, OSError) as err:
        _warn(f"{out} not written ({err}); the flight log is {log}")
        return False


def run(args: argparse.Namespace) -> int:
    plan = load_plan(args.plan)
    store = state_store(args)
    cfg, visit = store.with_learned_guess(load_config(args))
    check_flight_plan(plan, cfg)  # before any link opens: exit 2 naming the field
    mcap = mcap_path(args)
    if mcap is not None:
        args.log = str(mcap.with_suffix(".jsonl"))
    log = log_path(args, plan.strategy)
    rt = realtime_config(args)
    realtime.apply(rt)  # before the links and the view start their threads: they inherit it
    view = live_view(args.foxglove, log)
    abort = FlightAbort()
    status = StatusLine()
    with catching(lambda: abort.request(EndReason.SIGNAL)) as caught:
        try:
            links = open_links(args.driver, args.mocap, cfg.surface, mass_kg=cfg.vehicle.mass_kg)
            res = links.fly(
                plan,
                log,
                cfg,
                abort,
                status,
                header={
                    "plan_file": str(args.plan),
                    "mocap": args.mocap,
                    "scheduling": rt.describe(),
                },
                log_force=args.force,
            )
        finally:
            status.close()
            if view is not None:
                view.close()
    visit = store.remember_flight(cfg, res, visit)
    out = res.to_json()
    out["vehicle_profile"] = {
        "path": str(visit.path),
        "written": visit.written,
        "read": visit.read.to_doc() if visit.read else None,
    }
    if mcap is not None and write_mcap(log, mcap, args.force):
        out["mcap"] = str(mcap)
    text = "\n".join(
        [summary_text(res), visit.describe()] + ([f"mcap: {mcap}"] if "mcap" in out else [])
    )
    print(json.dumps(out) if args.json else text)
    caught.say("fly", f"the flight ended {res.outcome.name}; log {log}")
    return caught.exit_code(0 if res.outcome is EndReason.CONTACT else 1)


def realtime_config(args: argparse.Namespace) -> realtime.RealtimeConfig:
    """--realtime and --cpu as a RealtimeConfig (ConfigError for values out of range)."""
    if args.cpu >= 0 and not args.realtime:
        raise ConfigError(f"--cpu {args.cpu}: only with --realtime")
    return realtime.RealtimeConfig(args.realtime, args.cpu)


def _warn(line: str) -> None:
    print(f"perchd fly: {line}", file=sys.stderr)
