"""`perchd sim`: the loopback plant as a process of its own, for hardware-in-the-loop runs.

    perchd sim --pose-out natnet://127.0.0.1[:PORT] | zmq://127.0.0.1:5555
               --setpoint-in zmq://127.0.0.1:5556 [--body cf1] [--start X Y Z]
               [--latency S] [--noise M] [--surface X Y Z] [--normal NX NY NZ]
               [--watchdog LEVEL_S CUT_S] [--duration S] [--exit-on-stop] [--json]

The simulated world (perchd.sim.world) runs in real time. Poses go out at the mocap rate
through a NatNet server emulator or a ZMQ publisher (perchd.mocap.outputs); setpoints come
in on a ZMQ SUB socket bound at --setpoint-in (docs/contracts.md §3 topics `setpoint` and `stop`),
which `perchd fly --driver zmq://...` connects to. A `stop` cuts the motors.

The vehicle has the Crazyflie firmware's setpoint watchdog (perchd.sim.watchdog): once
setpoints have come, LEVEL_S (0.5 s) without one levels it out at its last thrust and
CUT_S (2 s) cuts the motors and locks the thrust until a zero-thrust setpoint; so an agent
killed mid-flight leaves a vehicle that comes down, as a real one would.

Port 0 picks a free port. Once serving, one line on stderr says where:
    perchd sim: ready: mocap <URI for perchd fly --mocap> driver <URI for --driver>
On exit (SIGINT/SIGTERM, --duration, or --exit-on-stop) a summary: text, or with --json
exactly one JSON object on stdout (contact time [s] and speed [m/s], counts). Exit 0 after
--duration or --exit-on-stop, 130 / 143 after SIGINT / SIGTERM (docs/contracts.md §6).

`perchd sim --campaign P.json ...` flies many simulated flights in this process instead
(no sockets; see perchd.commands.sim.campaign): --pose-out and --setpoint-in are then not wanted.
`perchd sim report TABLE [--plots DIR]` reads a campaign's table back (perchd.commands.sim.report).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from typing import Any

from perchd.commands.sim import campaign as campaign_cli
from perchd.commands.sim import firmware as sim_firmware
from perchd.commands.sim import report as sim_report
from perchd.commands.sim.campaign import add_arguments
from perchd.console.argcheck import numbers_as_values, within
from perchd.console.flightargs import check_geometry, surface_args
from perchd.core.clock import MonotonicClock
from perchd.core.errors import LinkError, UriError
from perchd.core.interrupts import catching
from perchd.core.netbind import port_error
from perchd.flight.config import MAX_COORD_M
from perchd.mocap.outputs import natnet_options_help, open_pose_output
from perchd.sim.plant import PlantParams
from perchd.sim.receiver import Counts, SetpointInbox
from perchd.sim.watchdog import SetpointWatchdog, WatchdogParams
from perchd.sim.world import MocapParams, SimWorld, WorldParams

EPILOG = f"""--pose-out natnet:// options, KEY [unit] (default) meaning; any other key is refused
(docs/contracts.md §7), e.g. natnet://127.0.0.1?multicast=1&data_port=1511:
{natnet_options_help()}"""

STOP_GRACE_S = 0.5
"""[s] --exit-on-stop keeps serving this long after a stop (the agent's last messages)."""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "sim",
        help="run the simulated vehicle as its own process",
        description=__doc__.splitlines()[0],
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    numbers_as_values(p)
    p.add_argument(
        "--pose-out",
        help="natnet://HOST[:PORT][?KEY=VALUE&...] (options below) or "
        "zmq://HOST:PORT (required without --campaign)",
    )
    p.add_argument(
        "--setpoint-in", help="zmq://HOST:PORT to bind for setpoints (required without --campaign)"
    )
    p.add_argument("--body", default="cf1", help="rigid body name (default cf1)")
    p.add_argument(
        "--start",
        nargs=3,
        type=float,
        metavar=("X", "Y", "Z"),
        help="[m] start position, hovering when Z > 0 (default 4.5 m before the "
        "surface, 1 m above it)",
    )
    p.add_argument("--latency", type=float, default=0.0, help="[s] setpoint-to-vehicle delay")
    p.add_argument("--noise", type=float, default=0.0, help="[m] mocap noise std per axis")
    surface_args(p)
    p.add_argument(
        "--watchdog",
        nargs=2,
        type=float,
        metavar=("LEVEL_S", "CUT_S"),
        default=(0.5, 2.0),
        help="[s] without a setpoint: level out after LEVEL_S, "
        "cut the motors and lock after CUT_S (default 0.5 2, the Crazyflie's)",
    )
    p.add_argument("--duration", type=float, help="[s] stop serving after this long")
    p.add_argument(
        "--exit-on-stop",
        action="store_true",
        help="exit once the agent has sent `stop` (the flight ended)",
    )
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    add_arguments(p)
    p.set_defaults(run=run)
    sub = p.add_subparsers(dest="sim_mode", metavar="{firmware,report}", parser_class=type(p))
    sim_firmware.register(sub)  # `perchd sim firmware ...` (docs/firmware.md)
    sim_report.register(sub)  # `perchd sim report TABLE`: a campaign's summary and plots


def make_world(args: argparse.Namespace) -> Any:
    if not 0.0 <= args.latency <= 1.0:
        raise UriError(f"--latency {args.latency:g} s is outside 0..1 s")
    if not 0.0 <= args.noise <= 0.1:
        raise UriError(f"--noise {args.noise:g} m is outside 0..0.1 m")
    check_geometry(args.surface, args.normal, "--surface", "--normal")
    within("--start", args.start, -MAX_COORD_M, MAX_COORD_M, "m")
    params = WorldParams(
        plant=PlantParams(latency_s=args.latency),
        mocap=MocapParams(noise_m=args.noise),
        start=tuple(args.start) if args.start else None,
        surface_point=tuple(args.surface),
        surface_normal=tuple(args.normal),
        body=args.body,
    )
    return SimWorld(params, MonotonicClock())


def serve(
    world: Any,
    output: Any,
    counts: Counts,
    done: threading.Event,
    until: float | None,
    exit_on_stop: bool,
) -> None:
    """Publish each pose as it arrives, in real time, until told to stop."""
    last = -1
    while not done.is_set():
        pose = world.latest_pose()
        if pose is not None and pose.seq != last:
            output.publish(pose)
            counts.poses, last = counts.poses + 1, pose.seq
        now = time.monotonic()
        if until is not None and now >= until:
            return
        if exit_on_stop and counts.stop_at is not None and now >= counts.stop_at + STOP_GRACE_S:
            return
        done.wait(max(0.0, min(world.next_arrival() - world.clock.now(), 0.05)))


def summary(
    world: Any,
    counts: Counts,
    mocap_uri: str,
    driver_uri: str,
    watchdog: SetpointWatchdog | None = None,
) -> dict[str, Any]:
    c = world.contact
    st = world.state()
    out = {
        "contact": c is not None,
        "contact_t": c.t - world.t0 if c else None,
        "contact_speed": c.speed if c else None,
        "setpoints": counts.setpoints,
        "stops": counts.stops,
        "rejected": counts.rejected,
        "foreign": counts.foreign,
        "poses": counts.poses,
        "mocap": mocap_uri,
        "driver": driver_uri,
        "vehicle": {"z_m": st.p[2], "thrust_n": st.thrust},
    }
    if watchdog is not None:  # the silences [s] at which it acted
        out["watchdog"] = {
            "level_s": watchdog.params.level_s,
            "cut_s": watchdog.params.cut_s,
            "levelled_after_s": watchdog.levels,
            "cut_after_s": watchdog.cuts,
            "locked": watchdog.locked,
            "refused": watchdog.refused,
        }
    return out


def run(args: argparse.Namespace) -> int:

    campaign_cli.check_mode(args)
    if args.campaign:
        return campaign_cli.run(args)
    watchdog = WatchdogParams(*args.watchdog)
    world = make_world(args)
    counts = Counts()
    output = open_pose_output(args.pose_out, [args.body], world.clock)
    try:
        inbox = SetpointInbox(args.setpoint_in, world, args.body, counts, watchdog)
    except LinkError as err:
        output.close()
        raise port_error(f"--setpoint-in {args.setpoint_in}", err) from None
    except BaseException:
        output.close()
        raise
    done = threading.Event()
    mocap_uri = output.uri(args.body)
    until = None if args.duration is None else time.monotonic() + args.duration
    with catching(done.set) as caught:  # before "ready": a signal from then on is caught
        print(
            f"perchd sim: ready: mocap {mocap_uri} driver {inbox.uri}", file=sys.stderr, flush=True
        )
        try:
            serve(world, output, counts, done, until, args.exit_on_stop)
        finally:
            inbox.close()
            output.close()
    result = summary(world, counts, mocap_uri, inbox.uri, inbox.watchdog)
    if args.json:
        print(json.dumps(result))
    else:
        contact = (
            f"contact at {result['contact_speed']:.3f} m/s, {result['contact_t']:.3f} s after start"
            if result["contact"]
            else "no contact"
        )
        print(
            f"{contact}; {counts.setpoints} setpoints, {counts.stops} stops, "
            f"{counts.rejected} rejected, {counts.foreign} from a second sender, "
            f"{counts.poses} poses; watchdog: "
            f"{len(inbox.watchdog.levels)} levels, {len(inbox.watchdog.cuts)} cuts"
        )
    caught.say("sim", "stopped serving; the summary covers the run so far")
    return caught.exit_code(0)
