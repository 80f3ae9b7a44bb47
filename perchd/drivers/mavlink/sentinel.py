"""The MAVLink sentinel: a child process that lands the vehicle the moment the agent dies
(docs/safety.md, "When the agent dies").

An autopilot flies a dead agent's last attitude target until its own offboard-loss timeout
(PX4 COM_OF_LOSS_T, ArduPilot GUID_TIMEOUT), then its failsafe: PX4 SIH killed at 0.46 m/s
went 0.70 m further toward the wall, tilted for the timeout, then braking in Land. The
sentinel holds a copy of the driver's link (the same socket: the vehicle hears the partner
it knows) and one end of a socket pair whose other end only the driver holds. When that
closes without a release while perchd flies the vehicle (the kernel closes it on SIGKILL,
the OOM killer, a crash), the sentinel first flies the brake the agent left (brake.py:
leaning against the velocity until it is gone) and then commands the
autopilot's LAND, repeated LAND_REPEATS times, LAND_REPEAT_S apart (a lost datagram would
leave the vehicle flying). Given the flight's mocap URI, it also keeps the mocap flowing to
the autopilot's EKF from the death until the landing is over (relay.py), and
answers the autopilot's TIMESYNC meanwhile. An agent that dies with the vehicle no longer
its own (between a service's flights: landing in its failsafe's LAND, or a pilot's) gets the
relay alone: nothing is commanded, and the EKF keeps the mocap it was being fed.

Wire (SOCK_SEQPACKET), driver -> sentinel: b"F" perchd flies the vehicle (its offboard mode
was acknowledged); b"D" it does not any more (the driver has commanded LAND itself); b"B"
and a packed Brake: the brake to fly first, renewed from the mocap; b"Y" and a float64:
yaw0 [rad], the NED heading of world X the mocap is relayed in; b"R" release: exit
without acting; b"L" hand-over: the agent ends with the vehicle landing (its own LAND):
relay the mocap until the landing is over, command nothing.

Run as `python -m perchd.service.mavsentinel_main CTL_FD LINK_FD DEST SSYS SCOMP SYS COMP
MAIN SUB MOCAP FLIGHT` by the driver (driver.py; that entry point, outside the drivers,
opens the mocap): DEST is HOST:PORT[,HOST:PORT...] for a UDP link, "-" for a stream;
SSYS, SCOMP the driver's own ids; SYS, COMP the vehicle's; MAIN, SUB the LAND mode as
DO_SET_MODE's param2 and param3; MOCAP the mocap URI to relay, "-" for none; FLIGHT the
custom_mode of the offboard mode perchd flies in.
"""

from __future__ import annotations

import logging
import math
import os
import select
import signal
import socket
import struct
import threading
import time
from dataclasses import dataclass

from perchd.core import childproc
from perchd.core.childproc import say
from perchd.core.types import Vec3
from perchd.drivers.mavlink.brake import (
    BRAKE_ROUNDS,
    LEVEL_MAX_S,
    PACKED_SIZE,
    WILL_MAX_AGE_S,
    Brake,
)
from perchd.drivers.mavlink.link import (
    CMD_DO_SET_MODE,
    CMD_SET_MESSAGE_INTERVAL,
    CUSTOM_MODE_ENABLED,
    LOCAL_POSITION_NED_ID,
    Connection,
)
from perchd.drivers.mavlink.relay import DISARMED_GRACE_S, RELAY_MAX_S, PoseOpener, VisionRelay
from perchd.drivers.mavlink.setpoints import attitude_target
from perchd.drivers.mavlink.vision import timesync_reply

LAND_REPEATS = 10
LAND_REPEAT_S = 0.1
"""LAND goes out at once and then every LAND_REPEAT_S, LAND_REPEATS times in all (1 s)."""
BRAKE_PERIOD_S = 0.02
"""[s] the brake's attitude target is repeated this often while it is flown."""
ENTRY_MODULE = "perchd.service.mavsentinel_main"
"""The sentinel's process entry point, outside the drivers: it opens the mocap to relay."""
VELOCITY_INTERVAL_US = 20000
"""LOCAL_POSITION_NED at 50 Hz while braking (the driver asks for 10)."""
VEHICLE_SILENT_S = 2.0
"""[s] the relay ends when the vehicle has not been heard this long: it is gone, or another
process (a restarted agent) now receives on the link."""
FOLLOW_PERIOD_S = 0.05
"""[s] while relaying, the link is read this often (TIMESYNC answered, heartbeats read)."""
YAW0_WIRE = "<d"

log = logging.getLogger("perchd.drivers.mavlink.sentinel")


def command_frame(
    source: tuple[int, int], target: tuple[int, int], command: int, *params: float
) -> bytes:
    """COMMAND_LONG from `source` (the driver's system and component), framed in the
    MAVLink version pymavlink speaks here (the driver's own)."""
    from pymavlink import mavutil

    mav = mavutil.mavlink.MAVLink(None, *source)
    p = (*params, *[0.0] * (7 - len(params)))
    return mav.command_long_encode(*target, command, 0, *p).pack(mav)


def land_frame(source: tuple[int, int], target: tuple[int, int], main: int, sub: int) -> bytes:
    """DO_SET_MODE to the LAND mode."""
    return command_frame(source, target, CMD_DO_SET_MODE, CUSTOM_MODE_ENABLED, main, sub)


def attitude_frame(
    source: tuple[int, int],
    target: tuple[int, int],
    q: tuple[float, float, float, float],
    thrust: float,
) -> bytes:
    """SET_ATTITUDE_TARGET of an attitude (w, x, y, z; FRD in NED) and normalised thrust."""
    from pymavlink import mavutil

    mav = mavutil.mavlink.MAVLink(None, *source)
    return attitude_target(mav, 0, target, q, thrust).pack(mav)


@dataclass(frozen=True)
class Death:
    """The agent died flying the vehicle, or handed over a landing one, or died after the
    vehicle stopped being its own (handover: the LAND, if any, was its own, so only the
    relay is left to do); brake: the newest it left, if any; yaw0 [rad]: the newest NED
    heading of world X it told, if any (the relay's frame); said: the line it gets."""

    brake: Brake | None = None
    yaw0: float | None = None
    handover: bool = False
    said: str = "the agent died flying the vehicle: brake, LAND"


def agent_death(ctl: socket.socket) -> Death | None:
    """Wait for the driver: a Death when it handed over, or its end closed after it had
    flown the vehicle (flying it still, or not); None on a release or a death before."""
    flying, flown, brake, yaw0 = False, False, None, None
    while True:
        try:
            msg = ctl.recv(64)
        except OSError:
            msg = b""
        if not msg and flying:
            return Death(brake, yaw0)
        if not msg:
            return (
                Death(
                    None,
                    yaw0,
                    handover=True,
                    said="the agent died between flights: relaying the mocap, commanding nothing",
                )
                if flown
                else None
            )
        if msg == b"R":
            return None
        if msg == b"L":
            return Death(
                None,
                yaw0,
                handover=True,
                said="the agent handed over its landing vehicle: relaying the mocap",
            )
        if msg in (b"F", b"D"):
            flying = msg == b"F"
            flown = flown or flying
        elif msg[:1] == b"B" and len(msg) == 1 + PACKED_SIZE:
            brake = Brake.unpack(msg[1:])
        elif msg[:1] == b"Y" and len(msg) == 1 + struct.calcsize(YAW0_WIRE):
            (yaw0,) = struct.unpack(YAW0_WIRE, msg[1:])


def fly_brake(
    link: SentinelLink, source: tuple[int, int], target: tuple[int, int], brake: Brake
) -> None:
    """Fly the brake if it is fresh (one left before the agent's mocap stopped is not):
    its lean for its duration, then level until the autopilot's own velocity says the
    vehicle has stopped (brake.py)."""
    if brake.duration_s <= 0.0:
        return
    if time.monotonic() - brake.t_s > WILL_MAX_AGE_S:
        say("mavsentinel", "the brake left is stale: LAND at once")
        return
    link.send(
        command_frame(
            source, target, CMD_SET_MESSAGE_INTERVAL, LOCAL_POSITION_NED_ID, VELOCITY_INTERVAL_US
        )
    )
    for _ in range(BRAKE_ROUNDS):
        v = brake_round(link, source, target, brake)
        if v is None or brake.stopped(v):
            return
        brake = brake.again(v)


def brake_round(
    link: SentinelLink, source: tuple[int, int], target: tuple[int, int], brake: Brake
) -> tuple[float, float, float] | None:
    """Lean for the brake's duration, then level until stopped (LEVEL_MAX_S at most):
    the autopilot's newest velocity [m/s, NED] then, None if it sent none."""
    leaned = hold(link, attitude_frame(source, target, brake.q_ned, brake.thrust), brake.duration_s)
    heard: list[tuple[float, float, float]] = []

    def stopped() -> bool:
        v = link.poll()
        heard.extend([v] if v is not None else [])
        return bool(heard) and brake.stopped(heard[-1])

    level = hold(link, attitude_frame(source, target, *brake.level), LEVEL_MAX_S, stopped)
    v = heard[-1] if heard else None
    why = (
        "no velocity heard"
        if v is None
        else "stopped"
        if brake.stopped(v)
        else f"still at {math.hypot(*v[:2]):.2f} m/s"
    )
    say(
        "mavsentinel",
        f"braked {leaned:.2f} s against {math.hypot(*brake.v_ne):.2f} m/s, "
        f"level {level:.2f} s ({why})",
    )
    return v


def hold(link: SentinelLink, frame: bytes, longest_s: float, done=lambda: False) -> float:
    """Send `frame` every BRAKE_PERIOD_S for longest_s [s] or until done(); [s] held."""
    start = time.monotonic()
    while time.monotonic() - start < longest_s and not done():
        link.send(frame)
        time.sleep(BRAKE_PERIOD_S)
    return time.monotonic() - start


class SentinelLink:
    """The dead agent's link to the vehicle, from the sentinel's side: `fd` and DEST
    (module docstring), the driver's ids `source` and the vehicle's `target`; sends may
    come from two threads (the relay's and the main one); what the vehicle sent since is
    read without blocking (poll)."""

    def __init__(
        self, fd: int, dest: str, source: tuple[int, int], target: tuple[int, int]
    ) -> None:
        self.fd, self.dest, self.target = fd, dest, target
        from pymavlink import mavutil

        self._parser = mavutil.mavlink.MAVLink(None)
        self._parser.robust_parsing = True
        self._mav = mavutil.mavlink.MAVLink(None, *source)
        self._lock = threading.Lock()
        self.heard_s: float | None = None  # time.monotonic() of the vehicle's last message
        self.armed: bool | None = None  # from its heartbeat, once heard
        self.mode: int | None = None  # custom_mode from its heartbeat, once heard

    def send(self, frame: bytes) -> None:
        with self._lock:
            if self.dest == "-":
                os.write(self.fd, frame)
                return
            with socket.socket(fileno=os.dup(self.fd)) as sock:
                for addr in self.dest.split(","):
                    host, _, port = addr.rpartition(":")
                    sock.sendto(frame, (host, int(port)))

    def poll(self) -> Vec3 | None:
        """Read what the vehicle sent since: its heartbeat's state kept, its TIMESYNC
        requests answered (on time.monotonic(), the clock the relayed poses are stamped
        on, as the driver answered them); [m/s, NED] of its newest LOCAL_POSITION_NED."""
        newest = None
        for msg in self._parser.parse_buffer(self._drain()) or []:
            if msg.get_srcSystem() != self.target[0]:
                continue
            self.heard_s, kind = time.monotonic(), msg.get_type()
            if kind == "LOCAL_POSITION_NED":
                newest = (msg.vx, msg.vy, msg.vz)
            elif kind == "HEARTBEAT" and msg.get_srcComponent() == self.target[1]:
                self.armed, self.mode = bool(msg.base_mode & 128), msg.custom_mode
            elif kind == "TIMESYNC" and msg.tc1 == 0:
                reply = self._mav.timesync_encode(*timesync_reply(msg.ts1, time.monotonic()))
                self.send(reply.pack(self._mav))
        return newest

    def _drain(self) -> bytes:
        chunks = []
        while select.select([self.fd], [], [], 0.0)[0]:
            try:
                chunk = os.read(self.fd, 65536)
            except (BlockingIOError, ConnectionRefusedError):  # refused: the vehicle's
                break  # port closed (a udpout link is connected); its silence ends the relay
            if not chunk:
                break
            chunks.append(chunk)
        return b"".join(chunks)


def follow_landing(link: SentinelLink, relay: VisionRelay, flight_mode: int, died_s: float) -> str:
    """Relay until the landing is over: the vehicle disarmed (DISARMED_GRACE_S later), or
    back in the offboard mode `flight_mode` after it left it (a new agent has it: two
    streams must not feed one EKF), or silent for VEHICLE_SILENT_S, or the relay stopped,
    or RELAY_MAX_S after the death; why it ended. A pilot's mode keeps the relay going: a
    vehicle on mocap alone has no other position."""
    left_flight, disarmed_s = False, None
    while True:
        try:
            link.poll()
        except OSError as err:  # a TIMESYNC answer refused: the vehicle's port is closed
            return f"the link is gone ({err})"
        now = time.monotonic()
        left_flight = left_flight or (link.mode is not None and link.mode != flight_mode)
        if left_flight and link.mode == flight_mode:
            return f"the vehicle is back in the offboard mode (custom mode {flight_mode})"
        disarmed_s = (disarmed_s or now) if link.armed is False else None
        if disarmed_s is not None and now - disarmed_s >= DISARMED_GRACE_S:
            return "the vehicle disarmed"
        if now - (link.heard_s or died_s) > VEHICLE_SILENT_S:
            return f"the vehicle silent for {VEHICLE_SILENT_S:g} s"
        if not relay.alive:
            return "the mocap relay stopped"
        if now - died_s > RELAY_MAX_S:
            return f"{RELAY_MAX_S:g} s after the death"
        select.select([link.fd], [], [], FOLLOW_PERIOD_S)  # TIMESYNC answered on arrival


def land(link: SentinelLink, frame: bytes) -> int:
    """LAND_REPEATS times, LAND_REPEAT_S apart; 1 when the link itself is gone (or not one
    went out). A full send buffer costs one repeat, not the rest."""
    sent = 0
    for i in range(LAND_REPEATS):
        try:
            link.send(frame)
            sent += 1
        except (BlockingIOError, InterruptedError):
            pass
        except OSError as err:  # the link itself is gone: nothing more to do
            say("mavsentinel", f"LAND not sent: {err}")
            return 1
        if i + 1 < LAND_REPEATS:
            time.sleep(LAND_REPEAT_S)
    return 0 if sent else 1


def prepared_relay(
    mocap: str, source: tuple[int, int], link: SentinelLink, open_poses: PoseOpener | None
) -> VisionRelay | None:
    """The relay of the mocap URI (opened by open_poses, not started), or None: none given,
    or it cannot be opened (said on stderr: the brake and LAND still act)."""
    if mocap == "-" or open_poses is None:
        return None
    try:
        return VisionRelay(open_poses(mocap), source, link.send)
    except Exception as err:  # noqa: BLE001 - a relay that cannot be must not cost the LAND
        say("mavsentinel", f"no mocap relay ({err})")
        return None


def start_relay(relay: VisionRelay | None, yaw0: float | None) -> bool:
    """Start the relay at the death; False (said) when there is none to start."""
    if relay is None:
        return False
    if yaw0 is None:
        say("mavsentinel", "no mocap relayed: the agent never told its yaw0 (no brake left)")
        return False
    try:
        relay.start(yaw0)
    except Exception as err:  # noqa: BLE001 - the brake and LAND come first
        say("mavsentinel", f"mocap relay not started ({err!r})")
        return False
    return True


def brake_and_land(
    link: SentinelLink,
    source: tuple[int, int],
    target: tuple[int, int],
    mode: tuple[int, int],
    brake: Brake | None,
) -> int:
    """The brake left, if any, then LAND (land's result)."""
    if brake is not None:
        try:
            fly_brake(link, source, target, brake)
        except Exception as err:  # noqa: BLE001 - whatever failed, LAND must still go out
            say("mavsentinel", f"brake abandoned ({err!r}): LAND")
    return land(link, land_frame(source, target, *mode))


def main(argv: list[str], open_poses: PoseOpener | None = None) -> int:
    """The sentinel's process (module docstring: argv); open_poses opens the MOCAP URI to
    relay (None: nothing is relayed)."""
    # The agent's Ctrl-C, a service stop, systemd's watchdog signal and a terminal's hang-up
    # reach the whole group: the sentinel outlives them and acts only on its socket's closing.
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGABRT, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)
    ctl_fd, link_fd, dest = int(argv[0]), int(argv[1]), argv[2]
    source, target, mode = (tuple(map(int, argv[i : i + 2])) for i in (3, 5, 7))
    link = SentinelLink(link_fd, dest, source, target)
    relay = prepared_relay(argv[9], source, link, open_poses)
    death = agent_death(socket.socket(fileno=ctl_fd))
    if death is None or (death.handover and relay is None):
        return 0  # nothing to command, nothing to relay
    died_s = time.monotonic()
    say("mavsentinel", death.said)
    relaying = start_relay(relay, death.yaw0)
    rc = 0 if death.handover else brake_and_land(link, source, target, mode, death.brake)
    if relaying:
        say("mavsentinel", "relaying the mocap until the landing is over")
        childproc.let_go_of_pipes()  # a pipe's reader is not kept waiting for the landing
        try:
            why = "the link is gone" if rc else follow_landing(link, relay, int(argv[10]), died_s)
        finally:
            relay.stop()
        say("mavsentinel", f"mocap relay ended: {why}")
    return rc


class Sentinel:
    """The driver's side: starts the sentinel on the driver's connection `link` for the
    vehicle `target` (system, component) with its LAND `mode` (main, sub), the `mocap` URI
    to relay after a death (None: none) and the offboard `flight_mode` (custom_mode);
    flying(True/False) tells it whether perchd flies the vehicle; release() ends it
    without acting."""

    def __init__(
        self,
        link: Connection,
        target: tuple[int, int],
        mode: tuple[int, int],
        mocap: str | None = None,
        flight_mode: int = 0,
    ) -> None:
        link_fd, dest = link.endpoint()
        self._sock, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        argv = [
            str(theirs.fileno()),
            str(link_fd),
            dest,
            *map(str, (*link.source, *target, *mode)),
            mocap or "-",
            str(flight_mode),
        ]
        try:
            self._proc = childproc.start(ENTRY_MODULE, argv, (theirs.fileno(), link_fd))
        finally:
            theirs.close()
        self._lock = threading.Lock()
        self._flying: bool | None = None

    def flying(self, on: bool) -> None:
        if on != self._flying:
            self._flying = on
            self._send(b"F" if on else b"D")

    def will(self, brake: Brake) -> None:
        """The brake to fly first should the agent die now (brake.py)."""
        self._send(b"B" + brake.pack())

    def yaw0(self, yaw0: float) -> None:
        """[rad] the NED heading of world X, the frame the mocap is to be relayed in."""
        self._send(b"Y" + struct.pack(YAW0_WIRE, yaw0))

    def hand_over(self) -> None:
        """The agent ends with the vehicle landing: the sentinel relays the mocap until the
        landing is over (module docstring), then exits on its own."""
        self._end(b"L", RELAY_MAX_S + 5.0)

    def release(self) -> None:
        """Normal end: the sentinel exits without a word to the vehicle."""
        self._end(b"R", 2.0)

    def _end(self, last: bytes, reap_s: float) -> None:
        self._send(last)
        with self._lock:
            sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()
        childproc.reap_later(self._proc, reap_s, "mavsentinel-reap")

    def _send(self, msg: bytes) -> None:
        with self._lock:
            if self._sock is None:
                return
            try:
                self._sock.send(msg)
            except OSError as err:
                log.warning(
                    "the MAVLink sentinel is gone (%s): if the agent dies, only the "
                    "autopilot's own failsafe acts",
                    err,
                )
                self._sock.close()
                self._sock = None
