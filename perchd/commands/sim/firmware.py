"""`perchd sim firmware`: a vehicle's real flight firmware in the loop (docs/firmware.md).

    perchd sim firmware --arducopter PATH [--instance N] [--stock-params] [--vision]
                        [--defaults FILE] [--frame nwu|enu] [--pose-out ...]
    perchd sim firmware --px4 BUILD_DIR [--instance N] [--stock-params] [--vision]
                        [--px4-param NAME=VALUE ...] [--ahead M] [--pose-out ...]
    perchd sim firmware --cf2 PATH [--pose-out zmq://127.0.0.1:0 | natnet://127.0.0.1[:PORT]]
                        [--link udp://127.0.0.1:19850] [--fw-port PORT] [--body cf1]
                        [--start X Y Z] [--surface X Y Z] [--normal NX NY NZ]
                        [--noise M] [--imu-noise GYRO ACC] [--mocap-rate HZ]
                        [--fw-log PATH] [--duration S] [--json]

Starts the Crazyflie SITL firmware (cf2) against perchd's physics (perchd.sim.firmware.cf2),
waits until it has calibrated, then prints one line on stderr, as `perchd sim` does:
    perchd sim: ready: mocap <URI for perchd fly --mocap> driver <URI for --driver>
and publishes the vehicle's true pose as mocap until SIGINT/SIGTERM or --duration. Then it
stops every process it started and prints a summary (text, or with --json one JSON object
on stdout: contact time [s] and speed [m/s], the IMU rate achieved, the launches), and
exits 0 after --duration, 130 / 143 after SIGINT / SIGTERM (docs/contracts.md §6).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from pathlib import Path
from typing import Any

from perchd.console.flightargs import surface_args
from perchd.core.clock import MonotonicClock
from perchd.core.errors import ConfigError, UriError
from perchd.core.interrupts import catching
from perchd.core.safefile import check_output, regular_file
from perchd.mocap.outputs import open_pose_output
from perchd.sim.firmware.ardupilot import (
    DEFAULT_PARAMS,
    ArduPilotParams,
    ArduPilotVehicle,
)
from perchd.sim.firmware.cf2 import Cf2Params, Cf2Vehicle, SensorNoise, Surface
from perchd.sim.firmware.harness import (
    Interrupted,
    ProcessGroup,
    TruthPublisher,
    ready_line,
)
from perchd.sim.firmware.px4 import Px4Params, Px4Vehicle
from perchd.sim.world import MocapParams


def register_under(sim_parser: argparse.ArgumentParser) -> None:
    """`firmware` as a subcommand of `perchd sim` (plain `perchd sim` is unchanged)."""
    register(
        sim_parser.add_subparsers(
            dest="sim_mode", metavar="{firmware}", parser_class=type(sim_parser)
        )
    )


def register(sub: argparse._SubParsersAction) -> None:
    """`firmware` among `perchd sim`'s subcommands."""
    p = sub.add_parser(
        "firmware",
        help="fly a vehicle's own firmware in the loop",
        description=__doc__.splitlines()[0],
    )
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument(
        "--cf2", metavar="PATH", help="the Crazyflie SITL firmware binary (docs/firmware.md)"
    )
    which.add_argument(
        "--arducopter",
        metavar="PATH",
        help="ArduCopter's SITL binary (docs/firmware.md, ArduPilot)",
    )
    which.add_argument(
        "--px4",
        metavar="BUILD_DIR",
        help="a PX4 SITL build folder with bin/px4 and etc/ (docs/firmware.md)",
    )
    p.add_argument(
        "--instance",
        "--px4-instance",
        dest="instance",
        type=int,
        default=0,
        help="SITL instance N, so several run side by side: PX4 ports 14540+N, "
        "19410+N, MAV_SYS_ID N+1; ArduCopter -I N (ports +10 N) (default 0)",
    )
    p.add_argument(
        "--stock-params",
        "--px4-stock-params",
        dest="stock_params",
        action="store_true",
        help="leave the autopilot's failsafe and angle-boost "
        "defaults (perchd's driver then refuses them, or sets them with configure=1)",
    )
    p.add_argument(
        "--vision",
        action="store_true",
        help="ArduCopter, PX4: GPS off, the EKF on the mocap perchd's driver "
        'forwards (docs/firmware.md, "Mocap to the autopilot"); the vehicle '
        "waits on the ground",
    )
    p.add_argument(
        "--px4-param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="PX4: a parameter set at boot (repeatable), e.g. SIH_KDV=0.1",
    )
    p.add_argument(
        "--ahead",
        type=float,
        default=4.5,
        help="[m] PX4: the surface this far ahead of the hover point (default 4.5)",
    )
    p.add_argument(
        "--heading",
        type=float,
        metavar="DEG",
        help="[deg] PX4: the compass heading (from north towards east) it turns to "
        "in Hold after its take-off; the surface lies ahead along it "
        "(default: the take-off's, north)",
    )
    p.add_argument(
        "--sim-speed",
        type=float,
        default=1.0,
        metavar="F",
        help="PX4: SIH's speed factor (PX4_SIM_SPEED_FACTOR): above 1 makes up "
        "for its clock falling behind the wall clock on a loaded machine; the "
        "summary's sim_clock_rate says how far it did (default 1)",
    )
    p.add_argument(
        "--defaults",
        metavar="FILE",
        help="ArduCopter: the defaults .parm (default: "
        "Tools/autotest/default_params/copter.parm of the binary's source tree)",
    )
    p.add_argument(
        "--frame",
        choices=("nwu", "enu"),
        default="nwu",
        help="ArduCopter: world frame of the truth (default nwu: X north, "
        "perchd's MAVLink driver's frame)",
    )
    p.add_argument(
        "--pose-out",
        default="zmq://127.0.0.1:0",
        help="natnet://HOST[:PORT] or zmq://HOST:PORT (default zmq://127.0.0.1:0)",
    )
    p.add_argument(
        "--link",
        default="udp://127.0.0.1:19850",
        help="where cflib's udp:// link connects (default udp://127.0.0.1:19850; "
        "port 0: a free one)",
    )
    p.add_argument(
        "--fw-port",
        type=int,
        default=0,
        help="UDP port the firmware sends to (default 0: a free one)",
    )
    p.add_argument("--body", default="cf1", help="rigid body name (default cf1)")
    p.add_argument(
        "--start",
        nargs=3,
        type=float,
        metavar=("X", "Y", "Z"),
        default=(-4.5, 0.0, 0.0),
        help="[m] start, on the floor at Z = 0 (default -4.5 0 0: 4.5 m before the surface)",
    )
    surface_args(p)
    p.add_argument("--noise", type=float, default=0.0, help="[m] mocap noise std per axis")
    p.add_argument(
        "--imu-noise",
        nargs=2,
        type=float,
        default=(0.0, 0.0),
        metavar=("GYRO", "ACC"),
        help="[rad/s] [m/s^2] IMU noise std per axis",
    )
    p.add_argument("--mocap-rate", type=float, default=100.0, help="[Hz] (default 100)")
    p.add_argument("--fw-log", help="the firmware's stdout (default /tmp/perchd-cf2-PID.log)")
    p.add_argument("--duration", type=float, help="[s] stop after this long once ready")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(run=run)


def params_from(args: argparse.Namespace) -> tuple[Cf2Params, MocapParams]:
    if not 0.0 <= args.noise <= 0.1:
        raise UriError(f"--noise {args.noise:g} m is outside 0..0.1 m")
    gyro, acc = args.imu_noise
    if not (0.0 <= gyro <= 1.0 and 0.0 <= acc <= 10.0):
        raise UriError(f"--imu-noise {gyro:g} {acc:g} is outside 0..1 rad/s, 0..10 m/s^2")
    if not 1.0 <= args.mocap_rate <= 1000.0:
        raise UriError(f"--mocap-rate {args.mocap_rate:g} Hz is outside 1..1000 Hz")
    if not 0 <= args.fw_port <= 65535:
        raise UriError(f"--fw-port {args.fw_port} is not a UDP port")
    cf2 = Cf2Params(
        binary=args.cf2,
        fw_port=args.fw_port,
        link=args.link,
        start=tuple(args.start),
        noise=SensorNoise(gyro, acc),
        surface=Surface(tuple(args.surface), tuple(args.normal)),
        log=Path(args.fw_log) if args.fw_log else None,
    )
    return cf2, MocapParams(rate_hz=args.mocap_rate, latency_s=0.0, noise_m=args.noise)


GIL_SWITCH_S = 0.0005
"""[s] Python's GIL hand-over interval (5 ms by default): the 1 kHz sim thread must not
wait a whole default interval behind another thread's Python code."""


def arducopter_params(args: argparse.Namespace) -> ArduPilotParams:
    params = DEFAULT_PARAMS[:1] if args.stock_params else DEFAULT_PARAMS
    return ArduPilotParams(
        binary=args.arducopter,
        defaults=args.defaults,
        start=tuple(args.start),
        frame=args.frame,
        instance=args.instance,
        vision=args.vision,
        params=params,
        surface=(tuple(args.surface), tuple(args.normal)),
        truth_hz=max(args.mocap_rate, 50.0),
        log=Path(args.fw_log) if args.fw_log else None,
    )


def px4_params(args: argparse.Namespace) -> Px4Params:
    if not 0.5 <= args.ahead <= 50.0:
        raise UriError(f"--ahead {args.ahead:g} m is outside 0.5..50 m")
    if args.heading is not None and not -360.0 <= args.heading <= 360.0:
        raise UriError(f"--heading {args.heading:g} deg is outside -360..360 deg")
    if args.heading is not None and args.vision:
        raise UriError(
            "--heading turns PX4 after its own take-off; with --vision it waits "
            "on the ground (no take-off): leave --heading out"
        )
    if not 0.5 <= args.sim_speed <= 2.0:
        raise UriError(f"--sim-speed {args.sim_speed:g} is outside 0.5..2")
    extra = tuple(px4_param(a) for a in args.px4_param)
    return Px4Params(
        args.px4,
        instance=args.instance,
        surface_ahead_m=args.ahead,
        stock_params=args.stock_params,
        vision=args.vision,
        takeoff=not args.vision,
        extra_params=extra,
        heading_deg=args.heading,
        sim_speed=args.sim_speed,
        log=Path(args.fw_log) if args.fw_log else None,
    )


def px4_param(text: str) -> tuple[str, str]:
    name, sep, value = text.partition("=")
    if not (sep and name and value and name.replace("_", "").isalnum()):
        raise UriError(f"--px4-param {text!r}: expected NAME=VALUE")
    return name.upper(), value


def open_vehicle(args: argparse.Namespace, clock: MonotonicClock) -> Any:
    """The FirmwareVehicle the command line names."""
    if args.arducopter:
        return ArduPilotVehicle(arducopter_params(args), clock)
    if args.px4:
        return Px4Vehicle(px4_params(args), clock)
    return Cf2Vehicle(params_from(args)[0], clock)


def check_files(args: argparse.Namespace) -> None:
    """The files the command line names, checked before any firmware starts: a binary that
    is not an executable regular file would be launched and waited for in vain, and a FIFO
    as --fw-log would block its opening."""
    for flag, binary in (("--cf2", args.cf2), ("--arducopter", args.arducopter)):
        if binary:
            regular_file(binary, flag, ConfigError, executable=True)
    if args.defaults:
        regular_file(args.defaults, "--defaults", ConfigError)
    if args.fw_log:
        check_output(args.fw_log, "--fw-log", force=True)


def run(args: argparse.Namespace) -> int:
    check_files(args)
    if args.cf2:
        _, mocap = params_from(args)
    else:
        mocap = MocapParams(rate_hz=args.mocap_rate, latency_s=0.0, noise_m=args.noise)
    sys.setswitchinterval(GIL_SWITCH_S)
    clock = MonotonicClock()
    done = threading.Event()
    with catching(done.set) as caught:
        try:
            with ProcessGroup() as procs:
                vehicle = open_vehicle(args, clock)
                try:
                    output = open_pose_output(args.pose_out, [args.body], clock)
                    try:
                        result = serve(
                            vehicle, procs, output, mocap, args.body, done, args.duration
                        )
                    finally:
                        output.close()
                finally:
                    vehicle.close()
        except Interrupted:
            caught.say("sim", "stopped before the firmware was ready")
            return caught.exit_code(130)
    if args.json:
        print(json.dumps(result))
    else:
        text = arducopter_text if args.arducopter else px4_text if args.px4 else summary_text
        print(text(result))
    caught.say("sim", "stopped every process it started; the summary covers the run so far")
    return caught.exit_code(0)


def serve(
    vehicle: Any,
    procs: ProcessGroup,
    output: Any,
    mocap: MocapParams,
    body: str,
    done: threading.Event,
    duration: float | None,
) -> dict[str, Any]:
    vehicle.start(procs, done)
    if (line := surface_line(vehicle)) is not None:
        print(line, file=sys.stderr, flush=True)
    mocap_uri, driver_uri = output.uri(body), vehicle.driver_uri()
    print(ready_line(mocap_uri, driver_uri), file=sys.stderr, flush=True)
    publisher = TruthPublisher(vehicle, output, mocap, vehicle.clock, body)
    until = None if duration is None else time.monotonic() + duration
    publisher.run(done, until)
    out = vehicle.summary()
    out.update(
        {
            "mocap": mocap_uri,
            "driver": driver_uri,
            "poses": publisher.poses,
            "yaw_range_rad": publisher.yaw_range,
        }
    )
    return out


def surface_line(vehicle: Any) -> str | None:
    """PX4 places the surface ahead of where it hovers: say where, for `perchd fly`."""
    s = getattr(vehicle, "surface", None)
    if s is None or vehicle.name != "px4":
        return None
    fmt = lambda v: " ".join(f"{c:.3f}" for c in v)  # noqa: E731
    return f"perchd sim: px4: surface {fmt(s.point)} normal {fmt(s.normal)}"


def px4_text(r: dict[str, Any]) -> str:
    c = r["contact"]
    contact = f"contact at {c['speed']:.3f} m/s" if c else "no contact"
    return (
        f"{contact}; modes {' -> '.join(r['modes'])}; {r['truth_samples']} truth samples; "
        f"{r['poses']} poses; PX4 log {r['log']}"
    )


def summary_text(r: dict[str, Any]) -> str:
    c = r["contact"]
    contact = f"contact at {c['speed']:.3f} m/s, {c['t']:.3f} s after start" if c else "no contact"
    imu = r["imu"]
    rate = "n/a" if imu["rate_hz"] is None else f"{imu['rate_hz']:.1f} Hz"
    return (
        f"{contact}; IMU {imu['sent']} samples at {rate} (late max "
        f"{imu['late_max_ms']:.1f} ms, {imu['skipped_late']} skipped); "
        f"{r['motor_packets']} motor packets; {len(r['launches'])} launch(es); "
        f"{r['poses']} poses; firmware log {r['log']}"
    )


def arducopter_text(r: dict[str, Any]) -> str:
    c = r["contact"]
    contact = f"contact at {c['speed']:.3f} m/s, {c['t']:.3f} s after start" if c else "no contact"
    rate = r["truth"]["rate_hz"]
    return (
        f"{contact}; SIM_STATE {r['truth']['sim_states']} at "
        f"{'n/a' if rate is None else f'{rate:.1f} Hz'}; mode {r['mode']}, "
        f"{'armed' if r['armed'] else 'disarmed'}; {r['poses']} poses; log {r['log']}"
    )
