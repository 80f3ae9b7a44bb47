"""MAVLink autopilots over pymavlink: ArduPilot in GUIDED_NOGPS, PX4 in OFFBOARD, both flown
with SET_ATTITUDE_TARGET (attitude quaternion + normalised thrust).

`mavlink:DEVICE[?mass=KG&arm=1&hover=F&timeout=S&stream=HZ&wait=S&yaw0=DEG&configure=1&sport=P]`
DEVICE: `udpin:127.0.0.1:14540` for PX4 (SITL instance N: 14540+N; PX4 sends to that fixed
port and ignores anyone else), `udpin:`/`udpout:HOST:PORT`/`tcp:HOST:PORT` for ArduPilot, or a
serial device. A `udpout:` link speaks from one source port; a vehicle that locks onto its
first partner (PX4) answers only that one: give it a fixed one with `sport=` (or use udpin).
- mass: the thrust model's mass (drivers.thrust.NormalisedThrust) comes from the flight
  config (`[vehicle] mass_kg`, bind_mass); a mass= here must agree with it, else the flight
  is refused before the mode switch or arming. Only a driver never bound uses it alone.
- hover: normalised hover thrust; default: read MOT_THST_HOVER (ArduPilot) or
  MPC_THR_HOVER (PX4) from the vehicle.
- arm=1: arm after the mode switch (default: never arm; the pilot does).
- timeout [s, default 1.5]: no message from the vehicle this long = link lost. The driver
  asks for ATTITUDE at `stream` Hz (default 50) so a short timeout is usable.
- wait [s, default 5]: how long connect() waits for each answer.
- yaw0 [deg, default 0]: the autopilot's heading (NED yaw, from north) of the world X axis:
  0 when its yaw zero faces mocap X, 90 for an ENU world on a north-referenced autopilot.
  `yaw0=auto`: measured from every pose (the autopilot's heading from ATTITUDE plus the
  mocap yaw, low-passed over YAW0_TRACK_S), for an autopilot whose heading comes from its
  compass and drifts off the mocap's (PX4 SIH: `perchd sim firmware --px4`, degrees per
  second in hover). Tracking the offset closes the heading loop on the mocap.
- configure=1: set the parameters below to perchd's values (PARAM_SET, read back, logged)
  instead of refusing to fly.
- vision=0: do not forward mocap to the autopilot nor check its external-navigation setup
  (a vehicle that has its own position source, e.g. GPS outdoors or in SITL).
- tilt=0: send the setpoints as they are. By default (tilt=1) each is rotated by the change
  in the autopilot's tilt error, its attitude estimate (ATTITUDE) less the mocap's
  (drivers/mavtilt.py): the autopilot flies its estimate, and an estimate a degree off
  leans the vehicle a degree off what perchd asked for.

connect() changes nothing on the vehicle: it hears its heartbeat, asks for the messages the
driver reads and checks its parameters (drivers/mavparams.py): a vehicle that would keep
flying a dead agent's setpoint, or fly home (docs/safety.md, "Autopilot failsafe
parameters"), whose attitude controller boosts thrust with tilt again (ArduPilot
ATC_ANGLE_BOOST), or whose EKF does not take the mocap (docs/firmware.md, "Mocap to the
autopilot") is refused by name there. engage(), once per flight, takes it: level at its
heading, the offboard mode, arming (arm=1), the spool-up; the flight's poses go to the EKF
meanwhile. Until then perchd's heartbeat is all the vehicle hears, and a failsafe before
it commands nothing (the vehicle is not perchd's to land). From the acknowledged mode switch
on, a sentinel process (drivers/mavsentinel.py) holds a copy of the link and commands LAND
the moment this process dies, until the vehicle leaves the offboard mode; with vision on it
relays the flight's mocap (bind_mocap) to the EKF until the landing is over.
Each pose the flight uses goes to the autopilot as VISION_POSITION_ESTIMATE
(drivers/mavvision.py), so its own failsafe can hold or land in place; an EKF on mocap alone
refuses to arm until it has some, so engage() asks again every ARM_RETRY_S within `wait`.
ArduCopter armed on the ground is held at a fraction of the hover thrust until its motors
have spooled up (ATTITUDE_TARGET shows the thrust applied); engage() returns then.
Taking over a vehicle in the air (armed, not landed) streams level at its current heading
with the hover thrust, never zero thrust, and flies as soon as the mode switch is
acknowledged (COMMAND_ACK ACCEPTED), not at the next 1 Hz heartbeat.

Frames: perchd's world is Z-up with Z-Y-X Euler angles; autopilots want the body FRD
attitude in NED. Rotating by pi about X maps one onto the other: roll stays, pitch and
yaw change sign (yaw then measured from yaw0). The quaternion goes out w-first. Yaw is relative to the autopilot's own
heading reference, so its yaw zero must face the mocap X axis (as the paper's does).

ArduPilot reads the thrust field as a climb rate unless GUID_OPTIONS bit 3 (value 8) is
set; the driver reads the parameter and refuses to fly without it.
"""

from __future__ import annotations

import logging
import math
import socket
import struct
import threading
import time
from typing import Any, Callable

from perchd.core.errors import ConfigError, LinkError, UriError
from perchd.core.extras import require
from perchd.core.ned import ned_vec, quaternion_wxyz
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, LinkHealth, Setpoint
from perchd.core.uri import Uri
from perchd.core.uriparams import bool_param, float_param, split_query
from perchd.drivers.base import DriverBase, PoseFeed, agreed_mass, no_poses
from perchd.drivers.mavbrake import WillSchedule, brake_for
from perchd.drivers.mavparams import (
    ARDUPILOT,
    PX4,
    PX4_INT_PARAMS,
    check_params,
    rules_for,
)
from perchd.drivers.mavsentinel import (
    CMD_DO_SET_MODE,
    CMD_SET_MESSAGE_INTERVAL,
    CUSTOM_MODE_ENABLED,
    IGNORE_BODY_RATES,
    LOCAL_POSITION_NED_ID,
    Sentinel,
)
from perchd.drivers.mavtilt import NO_TILT, Tilt, TiltCorrection
from perchd.drivers.mavvision import timesync_reply, vision_estimate, vision_message
from perchd.drivers.thrust import NormalisedThrust
from perchd.drivers.ticker import Ticker

log = logging.getLogger("perchd.drivers.mavlink")

HEARTBEAT_S = 0.5
"""[s] our heartbeat period (MAVLink asks for at least 1 Hz)."""
KEEPALIVE_S = 0.1
"""[s] a silent loop gets its last attitude target repeated after this long (PX4 leaves
OFFBOARD after COM_OF_LOSS_T = 0.5 s without one; ArduPilot levels after 1 s)."""
PX4_PRESTREAM_S = 1.2
"""[s] setpoints streamed before asking PX4 for OFFBOARD (it wants > 1 s of them)."""
LAND_RETRY_S = 0.25
"""[s] after failsafe() LAND is commanded again this often until a heartbeat shows the
vehicle took it: a command sent into a dead link is lost, a link back still delivers it."""
FAILSAFE_REPEAT_S = 10.0
"""[s] at most this long (or until close()); ArduPilot's GUIDED timeout only levels the
vehicle, so it is worth landing it well after its own watchdog has acted."""
GUIDED_THRUST_BIT = 8
"""ArduPilot GUID_OPTIONS bit 3: SET_ATTITUDE_TARGET thrust is thrust, not climb rate."""

ARDUPILOT_GUIDED_NOGPS, ARDUPILOT_LAND = 20, 9
PX4_OFFBOARD = (6, 0)  # (main mode, sub mode)
PX4_AUTO_LAND = (4, 6)
HOVER_PARAM = {ARDUPILOT: "MOT_THST_HOVER", PX4: "MPC_THR_HOVER"}
ATTITUDE_MSG_ID, ATTITUDE_TARGET_MSG_ID = 30, 83
EXTENDED_SYS_STATE_MSG_ID = 245
STATUS_HZ = 10.0
"""[Hz] LOCAL_POSITION_NED (the autopilot's own estimate: does it take the mocap?) and
ATTITUDE_TARGET (the thrust it applies: spooled up?) asked for: a spool-up seen 0.1 s late
costs nothing, and every message parsed is Python time beside the control loop."""
CMD_ARM = 400
MAV_RESULT_ACCEPTED, MAV_RESULT_IN_PROGRESS = 0, 5
LANDED_ON_GROUND = 1  # MAV_LANDED_STATE
SPOOL_FRACTION = 0.25
"""ArduCopter on the ground: after arming, level at this fraction of the hover thrust (well
below lift-off) until ATTITUDE_TARGET shows the thrust applied, i.e. the motors have spooled
up (MOT_SAFE_TIME + MOT_SPOOL_TIME, ~1.5 s) and it left its landed state. Before that it
flies thrust 0 whatever is sent, and a take-off ramp started meanwhile winds up."""
ARM_RETRY_S = 0.5
"""[s] an arming refused while mocap flows to an EKF that needs it is asked again this often
(ArduPilot on ExternalNav alone has no position or heading until the poses come)."""
MODE_CONFIRM_S = 1.5
"""[s] after an acknowledged mode switch a heartbeat still showing the old mode is one sent
before the switch (heartbeats come at 1 Hz); past this the vehicle really is elsewhere."""
YAW0_TRACK_S = 0.1
"""[s] time constant of yaw0=auto's offset tracking: ten mocap frames, against one frame's
jitter; and fast, because the autopilot steers its own heading estimate, which PX4 SIH's
EKF2 moves by 10-14 deg within a perch: at 0.5 s the true heading strayed 3.7-13 deg over
eight flights, at 0.1 s at most 2.2 deg over six (docs/firmware.md)."""
PX4_OFFBOARD_PORT = 14540
NO_HEARTBEAT_CAUSES = (
    "is the autopilot running and sending to this address? PX4 sends only to its fixed "
    f"offboard port: use mavlink:udpin:127.0.0.1:{PX4_OFFBOARD_PORT} (SITL instance N: "
    f"{PX4_OFFBOARD_PORT}+N); a PX4 that already heard a udpout: link from another source "
    "port answers only that one (restart it, use udpin:, or keep one port with ?sport=); "
    "ArduPilot SITL: mavlink:tcp:127.0.0.1:5760 or its --out udp port with udpin:")


def _check_network_port(raw: str, device: str) -> None:
    """udpout:/udpin:/udp:/tcp: devices end in :PORT; pymavlink would raise a bare
    ValueError at connect time for anything else."""
    if device.startswith(("/dev/", "COM")):
        return
    port = device.rsplit(":", 1)[1] if device.count(":") >= 2 else ""
    if not (port.isdigit() and 0 < int(port) < 65536):
        raise UriError(f"{raw}: {device!r} needs HOST:PORT with a port 1..65535, got {port!r}")


def open_mavlink(uri: Uri, runtime: Runtime) -> "MavlinkDriver":
    require("pymavlink", "mavlink")
    device, query = split_query(uri.path)
    if not device.startswith(("udpout:", "udpin:", "udp:", "tcp:", "/dev/", "COM")):
        raise UriError(f"{uri.raw}: expected mavlink:udpin:HOST:PORT (PX4: udpin:127.0.0.1:"
                       f"{PX4_OFFBOARD_PORT}; or udpout:, tcp:, a serial device)")
    _check_network_port(uri.raw, device)
    opts = Uri(uri.raw, uri.scheme, "", None, device, query)
    mass = float_param(opts, "mass", None, 0.01, 50.0, " kg")
    return MavlinkDriver(
        uri.raw, device, runtime, mass_kg=mass,
        hover=float_param(opts, "hover", None, 0.05, 0.95),
        arm=bool_param(opts, "arm"),
        timeout=float_param(opts, "timeout", 1.5, 0.01, 30.0, " s"),
        stream_hz=float_param(opts, "stream", 50.0, 1.0, 500.0, " Hz"),
        wait=float_param(opts, "wait", 5.0, 0.1, 60.0, " s"),
        yaw0=heading_offset(opts),
        configure=bool_param(opts, "configure"),
        sport=source_port(opts, device),
        vision=bool_param(opts, "vision", True),
        tilt=bool_param(opts, "tilt", True))


def heading_offset(opts: Uri) -> float | None:
    """?yaw0=DEG [rad], or None for yaw0=auto."""
    if (opts.param("yaw0") or "").lower() == "auto":
        return None
    return math.radians(float_param(opts, "yaw0", 0.0, -360.0, 360.0, " deg"))


def pose_yaw(q: tuple[float, float, float, float]) -> float:
    """[rad] Z-Y-X yaw of an (x, y, z, w) quaternion."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def source_port(opts: Uri, device: str) -> int | None:
    """?sport=PORT: the fixed local port of a udpout: link (None: an ephemeral one)."""
    port = float_param(opts, "sport", None, 1, 65535)
    if port is None:
        return None
    if not device.startswith("udpout:") or port != int(port):
        raise UriError(f"{opts.raw}: sport= is a whole port number, for udpout: links only")
    return int(port)


def ned_attitude(sp: Setpoint, yaw0: float = 0.0, tilt: Tilt = NO_TILT
                 ) -> tuple[float, float, float, float]:
    """perchd's Z-up attitude as the FRD-in-NED quaternion an autopilot takes, its roll and
    pitch moved by `tilt` (FRD in NED)."""
    return quaternion_wxyz(sp.roll + tilt.roll_rad, -sp.pitch + tilt.pitch_rad,
                           ned_yaw(sp.yaw, yaw0))


def ned_yaw(yaw: float, yaw0: float) -> float:
    """[rad] autopilot heading of a world (Z-up) yaw, yaw0 the heading of world X."""
    return yaw0 - yaw


def level_ned(yaw_ned: float) -> tuple[float, float, float, float]:
    """Roll 0, pitch 0 at an autopilot heading: level, never "level facing north"."""
    return quaternion_wxyz(0.0, 0.0, yaw_ned)


def px4_param_float(value: int) -> float:
    """An integer as PX4 carries it in PARAM_SET/PARAM_VALUE's float (bytewise)."""
    return struct.unpack("<f", struct.pack("<i", int(value)))[0]


def px4_param_int(value: float) -> int:
    return struct.unpack("<i", struct.pack("<f", value))[0]


def watch_refusals(conn: Any, on_refused: Callable[[], None]) -> None:
    """Make a pymavlink `udpout` link report a vehicle that has gone away.

    pymavlink's mavudp swallows ECONNREFUSED, and an unconnected socket never sees it
    anyway. Connected to the vehicle's address, the kernel turns the ICMP port-unreachable
    that answers a datagram to a closed port into ECONNREFUSED on the next call, so the
    loss is known one datagram later instead of after the heartbeat timeout. This
    replaces the link's recv/write with the same socket calls, minus the swallowing."""
    sock = conn.port
    dest = (socket.gethostbyname(conn.destination_addr[0]), conn.destination_addr[1])
    sock.connect(dest)

    def recv(n: int | None = None) -> bytes | str:
        try:
            return sock.recv(65535)
        except (BlockingIOError, InterruptedError):
            return ""
        except ConnectionRefusedError:
            on_refused()
            return ""

    def write(buf: bytes) -> None:
        try:
            sock.send(buf)
        except ConnectionRefusedError:
            on_refused()
        except OSError:
            pass  # as pymavlink: a full buffer or a transient error drops one datagram

    conn.recv, conn.write = recv, write


def bind_source_port(conn: Any, port: int, uri: str) -> None:
    """Give a udpout: link a fixed source port, so a vehicle that answers only the first
    port it heard from (PX4) still answers the next run."""
    sock = conn.port
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(("0.0.0.0", port))
    except OSError as err:
        conn.close()
        raise LinkError(f"{uri}: cannot bind source port {port}: {err.strerror or err}") from None


def px4_custom_mode(main: int, sub: int) -> int:
    return (main << 16) | (sub << 24)


class MavlinkDriver(DriverBase):
    def __init__(self, uri: str, device: str, runtime: Runtime, *, mass_kg: float | None,
                 hover: float | None, arm: bool, timeout: float, stream_hz: float,
                 wait: float, yaw0: float | None = 0.0, configure: bool = False,
                 sport: int | None = None, vision: bool = True, tilt: bool = True) -> None:
        self.uri = uri
        self.device = device
        self.clock = runtime.clock
        self.mass_kg = mass_kg
        self.uri_mass = mass_kg  # [kg] the URI's mass=, checked by bind_mass
        self.hover = hover
        self.arm = arm
        self.timeout = timeout
        self.stream_hz = stream_hz
        self.wait = wait
        self.yaw0 = yaw0
        self._yaw0_auto = yaw0 is None
        self._yaw0_t: float | None = None  # [s] pose time of the last yaw0=auto update
        self.configure = configure
        self.sport = sport
        self.vision = vision
        self.vision_sent = 0  # VISION_POSITION_ESTIMATEs sent
        self.tilt: TiltCorrection | None = TiltCorrection() if tilt else None
        self._ap_thrust: float | None = None  # ATTITUDE_TARGET thrust the vehicle applies
        self.ekf_position_ned: tuple[float, float, float] | None = None
        """[m] the autopilot's own position estimate (LOCAL_POSITION_NED), newest."""
        self.model: NormalisedThrust | None = None
        self.autopilot: int | None = None
        self._conn: Any = None
        self._refused = ""  # why the vehicle refused a command, once it has
        self._lock = threading.Lock()
        self._tickers: list[Ticker] = []
        self._target = (0, 0)
        self._heard: float | None = None  # clock time of the vehicle's last message
        self._mode: int | None = None  # custom_mode from its last heartbeat
        self._armed = False
        self._landed_state: int | None = None  # EXTENDED_SYS_STATE, once heard
        self._yaw_ned: float | None = None  # [rad] from ATTITUDE
        self._level_yaw: float | None = None  # [rad] NED heading to level out at
        self._mode_seen = False  # a heartbeat has shown the flight mode
        self._switched_at = 0.0  # time.monotonic() of the acknowledged switch
        self._params: dict[str, float] = {}
        self._acks: dict[int, int] = {}
        self._flight_mode: int | None = None  # the custom mode we fly in
        self._last_target: tuple[tuple[float, float, float, float], float] | None = None
        self._last_sent = 0.0
        self._last_heartbeat = 0.0
        self._stopped = False
        self._land_until = 0.0  # time.monotonic() until which LAND is repeated
        self._land_sent = 0.0
        self._armed_at_land = False
        self.failsafe_reasons: list[EndReason] = []
        self._airborne_before_arm = False
        self._engaged = False  # the offboard mode has been asked for: the vehicle is ours
        self._engaging = False  # engage() is under way: a failsafe meanwhile ends it
        self._poses: PoseFeed = no_poses  # engage()'s pose feed, read while it waits
        self._pumped_seq: int | None = None  # the newest pose engage() forwarded
        self._sentinel: Sentinel | None = None  # lands the vehicle if this process dies
        self._will = WillSchedule()  # the sentinel's brake, renewed from the mocap
        self._yaw0_told: float | None = None  # the yaw0 the sentinel last heard
        self.mocap_uri: str | None = None  # the flight's mocap, relayed after a death
        self._vision_seq: int | None = None  # the newest pose sent to the EKF: each goes once

    # -- Driver protocol ---------------------------------------------------------------
    def connect(self) -> None:
        from pymavlink import mavutil
        self._conn = mavutil.mavlink_connection(self.device, source_system=255,
                                                source_component=191)  # onboard computer
        self._refused = ""
        if self.sport is not None:
            bind_source_port(self._conn, self.sport, self.uri)
        if self.device.startswith("udpout:"):
            watch_refusals(self._conn, self._on_refused)
        self._stopped = self._engaged = False
        if self.tilt is not None:  # another link, maybe another boot: its clock learnt anew
            self.tilt = TiltCorrection()
        self._tickers = [Ticker(0.0, self._receive, "mavlink-receive").start(),
                         Ticker(KEEPALIVE_S / 2, self._keepalive, "mavlink-keepalive").start()]
        try:
            self._setup()
        except BaseException:
            self._release()
            raise

    def engage(self, poses: PoseFeed = no_poses) -> None:
        """Take the vehicle for one flight: level at its heading, the offboard mode, arming
        (arm=1) and, on the ground, the spool-up; each new pose from `poses` goes to the EKF
        while it waits. A failsafe's LAND still repeating is called off: a new flight was
        asked for."""
        if self._conn is None or self.model is None:
            raise LinkError(f"{self.uri}: engage() before connect()")
        self._poses, self._stopped, self._land_until = poses, False, 0.0
        self._engaging = True
        try:
            self._prestream()
            self._engaged = True
            self._switch_mode()
            self._guard()
            if self.arm:
                self._arm()
                if self.autopilot == ARDUPILOT and not self._airborne_before_arm:
                    self._spool_up()
        finally:
            self._poses, self._engaging = no_poses, False

    def send(self, setpoint: Setpoint) -> None:
        if self._stopped or self._conn is None or self.model is None:
            return
        if self.yaw0 is None:  # auto, and no pose yet: it faces where it is told to
            self._align_heading((self._yaw_ned or 0.0) + setpoint.yaw)
        self._level_yaw = ned_yaw(setpoint.yaw, self.yaw0)
        tilt = NO_TILT if self.tilt is None else self.tilt.correction(self.clock.now())
        self._send_target(ned_attitude(setpoint, self.yaw0, tilt),
                          self.model.fraction(setpoint.thrust))

    def observe_pose(self, pose: Any) -> None:
        """Each pose goes to the autopilot's EKF once (drivers/mavvision.py) unless vision=0,
        and is paired with its attitude estimates for the tilt correction unless tilt=0."""
        if not getattr(pose, "valid", True) or self._conn is None:
            return
        self._track_yaw0(pose)
        self._renew_will(pose)
        if self.yaw0 is None or not (self.vision or self.tilt):
            return
        v = vision_estimate(pose, self.yaw0)
        if self.tilt is not None:
            self.tilt.on_pose(pose.t, v.rpy[0], v.rpy[1])
        if self.vision and pose.seq != self._vision_seq:  # the loop may see a pose twice
            self._vision_seq = pose.seq
            with self._lock:
                self._conn.mav.send(vision_message(self._conn.mav, v))
            self.vision_sent += 1

    def _renew_will(self, pose: Any) -> None:
        """Every WILL_PERIOD_S while perchd flies, the brake the sentinel is to fly should
        this process die: against the mocap's velocity (drivers/mavbrake.py)."""
        now = time.monotonic()
        v = self._will.due(pose, now)
        if (v is None or self._sentinel is None or self._stopped or self.yaw0 is None
                or self.model is None):
            return
        heading = self._level_yaw if self._level_yaw is not None else self._yaw_ned or 0.0
        self._sentinel.will(brake_for(ned_vec(v, self.yaw0), heading,
                                      self.model.hover_fraction, now))
        if self.yaw0 != self._yaw0_told:
            self._yaw0_told = self.yaw0
            self._sentinel.yaw0(self.yaw0)

    def _track_yaw0(self, pose: Any) -> None:
        """yaw0=auto: each pose with the autopilot's newest heading measures the offset
        between its heading and the mocap's; yaw0 follows it through a first-order lag."""
        if not self._yaw0_auto or self._yaw_ned is None:
            return
        measured = self._yaw_ned + pose_yaw(pose.q)
        if self.yaw0 is None or self._yaw0_t is None:
            self._align_heading(measured)
        else:
            gain = min(1.0, max(0.0, pose.t - self._yaw0_t) / YAW0_TRACK_S)
            self.yaw0 += gain * math.remainder(measured - self.yaw0, math.tau)
        self._yaw0_t = pose.t

    def _align_heading(self, yaw0: float) -> None:
        self.yaw0 = yaw0
        log.info("%s: yaw0=auto: world X is at autopilot heading %.1f deg", self.uri,
                 math.degrees(yaw0))

    def failsafe(self, reason: EndReason) -> None:
        self.failsafe_reasons.append(reason)
        self._land()

    def health(self) -> LinkHealth:
        if self._conn is None or self._heard is None:
            return LinkHealth(False, 0.0, "not connected")
        age = self.clock.now() - self._heard
        if self._refused:
            return LinkHealth(False, age, f"connection lost: {self._refused}")
        if age > self.timeout:
            return LinkHealth(False, age, f"connection lost: no message from the vehicle for {age:.2f} s")
        if not self._stopped and self._flight_mode is not None and self._left_flight_mode():
            return LinkHealth(False, age, f"vehicle left the offboard mode (custom mode {self._mode})")
        return LinkHealth(True, age)

    def close(self, hand_over: bool = True) -> None:
        if self._conn is None:
            return
        if not self._stopped and self._engaged:
            self._land()
        # an EKF on mocap alone would dead-reckon the rest of the landing (docs/safety.md,
        # "The mocap relayed after the death"): the sentinel relays it until the end,
        # unless new links to this vehicle feed it from now on
        self._release(handover=hand_over and self._engaged and self._armed and self.vision)

    def bind_mass(self, mass_kg: float) -> None:
        """The flight's mass for the thrust model (rebuilt if connect() already made it)."""
        self.mass_kg = agreed_mass(self.uri, self.uri_mass, mass_kg)
        if self.model is not None:
            self.model = NormalisedThrust(self.mass_kg, self.model.hover_fraction)

    def bind_mocap(self, uri: str) -> None:
        """The flight's mocap URI: with vision on, the sentinel relays it to the EKF after
        a death (drivers/mavrelay.py)."""
        self.mocap_uri = uri

    def thrust_ceiling_n(self) -> float | None:
        """[N] full normalised thrust (1.0) in this model; known once connected."""
        return None if self.model is None else self.model.newtons(1.0)

    # -- connection setup --------------------------------------------------------------
    def _setup(self) -> None:
        if self.mass_kg is None:
            raise ConfigError(f"{self.uri}: the vehicle mass is unknown: fly with a flight "
                              f"config ([vehicle] mass_kg) or add ?mass=KG")
        self._await(lambda: self._heard is not None, "a heartbeat from the vehicle",
                    NO_HEARTBEAT_CAUSES)
        if self.autopilot not in (ARDUPILOT, PX4):
            raise LinkError(f"{self.uri}: autopilot type {self.autopilot} is neither ArduPilot nor PX4")
        self._command(CMD_SET_MESSAGE_INTERVAL, ATTITUDE_MSG_ID, 1e6 / self.stream_hz)
        self._command(CMD_SET_MESSAGE_INTERVAL, EXTENDED_SYS_STATE_MSG_ID, 1e5)  # landed state
        for msg_id in (ATTITUDE_TARGET_MSG_ID, LOCAL_POSITION_NED_ID):
            self._command(CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / STATUS_HZ)
        if self.autopilot == ARDUPILOT:
            options = int(self._param("GUID_OPTIONS"))
            if not options & GUIDED_THRUST_BIT:
                raise ConfigError(
                    f"{self.uri}: GUID_OPTIONS={options} lacks bit 3 (thrust as thrust); "
                    f"set GUID_OPTIONS={options | GUIDED_THRUST_BIT} on the vehicle")
        check_params(self.uri, rules_for(self.autopilot, self.vision), self._param,
                     self._write_param, self.configure)
        hover = self.hover if self.hover is not None else self._param(HOVER_PARAM[self.autopilot])
        try:
            self.model = NormalisedThrust(self.mass_kg, hover)
        except ValueError as err:
            raise ConfigError(f"{self.uri}: {err}") from None

    def _prestream(self) -> None:
        """Level at the vehicle's current heading until the loop runs: in the air with the
        hover thrust (zero thrust would drop it for as long as the switch takes), on the
        ground with none. PX4 wants > 1 s of setpoints before OFFBOARD."""
        self._await(lambda: self._yaw_ned is not None, "the vehicle's attitude (ATTITUDE)")
        self._level_yaw = self._yaw_ned
        airborne = self._airborne_before_arm = self._airborne()
        thrust = self.model.hover_fraction if airborne else 0.0
        log.info("%s: taking over %s, streaming level at heading %.1f deg, thrust %.3f",
                 self.uri, "in the air" if airborne else "on the ground",
                 math.degrees(self._level_yaw), thrust)
        self._send_target(level_ned(self._level_yaw), thrust)
        if self.autopilot == PX4:
            self._pause(PX4_PRESTREAM_S)  # the keep-alive streams meanwhile

    def _airborne(self) -> bool:
        """Armed and not known to be on the ground (EXTENDED_SYS_STATE, when it streams)."""
        return self._armed and self._landed_state != LANDED_ON_GROUND

    def _switch_mode(self) -> None:
        """Ask for the offboard mode; its COMMAND_ACK ACCEPTED is the confirmation (the
        heartbeat that shows it may be a second away), a refusal is named."""
        if self.autopilot == PX4:
            mode, main_sub = px4_custom_mode(*PX4_OFFBOARD), PX4_OFFBOARD
        else:
            mode, main_sub = ARDUPILOT_GUIDED_NOGPS, (ARDUPILOT_GUIDED_NOGPS, 0)
        self._acks.pop(CMD_DO_SET_MODE, None)
        self._mode_seen = False
        self._set_mode(*main_sub)
        result = lambda: self._acks.get(CMD_DO_SET_MODE, MAV_RESULT_IN_PROGRESS)  # noqa: E731
        self._await(lambda: self._mode == mode or result() != MAV_RESULT_IN_PROGRESS,
                    f"the switch to custom mode {mode}")
        if self._mode != mode and result() != MAV_RESULT_ACCEPTED:
            raise LinkError(f"{self.uri}: the vehicle refused custom mode {mode} "
                            f"(MAV_RESULT {result()})")
        self._switched_at = time.monotonic()
        self._flight_mode = mode
        self._mode_seen = self._mode == mode

    def _guard(self) -> None:
        """From the acknowledged mode switch on, the sentinel (drivers/mavsentinel.py)
        lands the vehicle if this process dies."""
        if self._sentinel is None:
            try:
                mocap = self.mocap_uri if self.vision else None
                self._sentinel = Sentinel(self._conn, self._target, self._land_mode(), mocap,
                                          self._flight_mode or 0)
                self._yaw0_told = None
            except (OSError, ValueError) as err:
                log.warning("%s: no MAVLink sentinel (%s): if this process dies, only the "
                            "autopilot's own failsafe acts", self.uri, err)
                return
        self._sentinel.flying(True)

    def _land_mode(self) -> tuple[int, int]:
        return PX4_AUTO_LAND if self.autopilot == PX4 else (ARDUPILOT_LAND, 0)

    def _left_flight_mode(self) -> bool:
        if self._mode == self._flight_mode:
            return False
        return self._mode_seen or time.monotonic() - self._switched_at > MODE_CONFIRM_S

    def _arm(self) -> None:
        """Arm; with vision on, a refusal is asked again every ARM_RETRY_S until `wait` has
        passed, while the poses flow (an EKF on mocap alone cannot arm before it has them)."""
        deadline = time.monotonic() + self.wait
        while True:
            self._acks.pop(CMD_ARM, None)
            self._command(CMD_ARM, 1)
            self._await(lambda: self._armed or self._acks.get(CMD_ARM, 0) not in (0, 5),
                        "arming")
            if self._armed:
                return
            if not self.vision or time.monotonic() + ARM_RETRY_S > deadline:
                break
            self._pause(ARM_RETRY_S)
        fed = f" for {self.wait:g} s while {self.vision_sent} poses went to its EKF" \
            if self.vision else ""
        raise LinkError(f"{self.uri}: the vehicle refused to arm "
                        f"(MAV_RESULT {self._acks.get(CMD_ARM)}){fed}")

    def _spool_up(self) -> None:
        """Hold the vehicle on the ground at a fraction of the hover thrust until it applies
        it (ATTITUDE_TARGET thrust > 0): only then does the loop's take-off start, so the
        ramp and the height integral do not wind up against motors still spooling."""
        thrust = SPOOL_FRACTION * self.model.hover_fraction
        self._ap_thrust = None
        self._send_target(level_ned(self._level_yaw or 0.0), thrust)
        self._await(lambda: (self._ap_thrust or 0.0) > 0.0,
                    "the motors to spool up (ATTITUDE_TARGET thrust above 0)")
        log.info("%s: spooled up (ATTITUDE_TARGET thrust %.3f)", self.uri, self._ap_thrust)

    def _write_param(self, name: str, value: float) -> float:
        """PARAM_SET, then the value read back."""
        is_int = self.autopilot == PX4 and name in PX4_INT_PARAMS
        wire = px4_param_float(int(value)) if is_int else float(value)
        kind = 6 if is_int else 9  # MAV_PARAM_TYPE_INT32 / REAL32
        self._params.pop(name, None)
        with self._lock:
            self._conn.mav.param_set_send(*self._target, name.encode(), wire, kind)
        return self._param(name)

    def _await(self, done: Callable[[], bool], what: str, causes: str = "") -> None:
        deadline = time.monotonic() + self.wait
        while not done():
            if time.monotonic() > deadline:
                hint = f": {causes}" if causes else ""
                raise LinkError(f"{self.uri}: waited {self.wait:g} s for {what} in vain{hint}")
            self._pump()
            time.sleep(0.005)

    def _pause(self, seconds: float) -> None:
        """Wait `seconds`, forwarding engage()'s poses meanwhile."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self._pump()
            time.sleep(0.005)

    def _pump(self) -> None:
        """While engage() waits: each new pose of the flight to the EKF, as the loop will;
        a failsafe from another thread meanwhile (a service stopping) ends the engage, or
        it would take the vehicle back out of the LAND just commanded."""
        if self._engaging and self._stopped:
            raise LinkError(f"{self.uri}: failsafe while engaging; the vehicle was not taken")
        pose = self._poses()
        if pose is not None and pose.seq != self._pumped_seq:
            self._pumped_seq = pose.seq
            self.observe_pose(pose)

    def _param(self, name: str) -> float:
        """Read one parameter, asking again every 0.5 s (PARAM_REQUEST_READ can be lost)."""
        asked = 0.0

        def answered() -> bool:
            nonlocal asked
            if name not in self._params and time.monotonic() - asked > 0.5:
                asked = time.monotonic()
                with self._lock:
                    self._conn.mav.param_request_read_send(*self._target, name.encode(), -1)
            return name in self._params
        self._await(answered, f"parameter {name}")
        return self._params[name]

    def _set_mode(self, main: int, sub: int) -> None:
        self._command(CMD_DO_SET_MODE, CUSTOM_MODE_ENABLED, main, sub)

    def _command(self, command: int, *params: float) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        with self._lock:
            self._conn.mav.command_long_send(*self._target, command, 0, *p)

    # -- streaming ---------------------------------------------------------------------
    def _send_target(self, q: tuple[float, float, float, float], thrust: float) -> None:
        self._last_target = (q, thrust)
        self._last_sent = time.monotonic()
        boot_ms = int(self.clock.now() * 1000) & 0xFFFFFFFF
        with self._lock:
            self._conn.mav.set_attitude_target_send(
                boot_ms, *self._target, IGNORE_BODY_RATES, list(q), 0.0, 0.0, 0.0, thrust)

    def _keepalive(self) -> None:
        """Heartbeat at 2 Hz; repeat the last attitude target, levelled, if the loop is silent;
        after a failsafe, LAND every LAND_RETRY_S until the vehicle takes it."""
        now = time.monotonic()
        if now - self._last_heartbeat >= HEARTBEAT_S:
            self._last_heartbeat = now
            with self._lock:
                self._conn.mav.heartbeat_send(18, 8, 0, 0, 4)  # onboard controller, no autopilot, active
        if not self._stopped and self._last_target and now - self._last_sent >= KEEPALIVE_S:
            self._send_target(level_ned(self._level_yaw or 0.0), self._last_target[1])
        if (self._stopped and now < self._land_until and now - self._land_sent >= LAND_RETRY_S
                and not self._land_taken()):
            self._command_land(repeats=1)
        if self._stopped and self._sentinel is not None and self._land_taken():
            self._sentinel.flying(False)  # landing, or the pilot's: no longer ours to land

    def _land(self) -> None:
        """Stop streaming and hand the vehicle to the autopilot's own landing mode; the
        keep-alive repeats the command until the vehicle shows it took it. A vehicle never
        engaged is not perchd's: nothing is commanded."""
        self._stopped = True
        if self._conn is None or self.autopilot is None or not self._engaged:
            return
        self._armed_at_land = self._armed
        self._land_until = time.monotonic() + FAILSAFE_REPEAT_S
        self._command_land(repeats=2)  # UDP: a lost command would leave the vehicle hovering

    def _command_land(self, repeats: int) -> None:
        self._land_sent = time.monotonic()
        for _ in range(repeats):
            self._set_mode(*self._land_mode())

    def _land_taken(self) -> bool:
        """The vehicle's heartbeat shows it no longer flies our setpoints: it left the mode
        we flew in (LAND, or a mode the pilot or its own failsafe chose), or disarmed."""
        return self._mode != self._flight_mode or (self._armed_at_land and not self._armed)

    # -- receiving ---------------------------------------------------------------------
    def _receive(self) -> None:
        conn = self._conn
        msg = conn.recv_match(blocking=True, timeout=0.05) if conn is not None else None
        if msg is None or msg.get_type() == "BAD_DATA":
            return
        if msg.get_type() == "HEARTBEAT":
            self._on_heartbeat(msg)
        if self._heard is None or msg.get_srcSystem() != self._target[0]:
            return
        self._heard = self.clock.now()
        kind = msg.get_type()
        if kind == "PARAM_VALUE":
            self._params[msg.param_id] = self._param_value(msg)
        elif kind == "COMMAND_ACK":
            self._acks[msg.command] = msg.result
        elif kind == "ATTITUDE":
            self._yaw_ned = float(msg.yaw)
            if self.tilt is not None:
                self.tilt.on_estimate(msg.time_boot_ms * 1e-3, self._heard, float(msg.roll),
                                      float(msg.pitch))
        elif kind == "EXTENDED_SYS_STATE":
            self._landed_state = int(msg.landed_state)
        elif kind == "LOCAL_POSITION_NED":
            self.ekf_position_ned = (float(msg.x), float(msg.y), float(msg.z))
        elif kind == "ATTITUDE_TARGET":
            self._ap_thrust = float(msg.thrust)
        elif kind == "TIMESYNC" and msg.tc1 == 0:
            with self._lock:
                conn.mav.timesync_send(*timesync_reply(msg.ts1, self.clock.now()))

    def _param_value(self, msg: Any) -> float:
        """PX4 carries integer parameters bytewise; ArduPilot casts them to float."""
        if self.autopilot == PX4 and 1 <= msg.param_type <= 8:
            return float(px4_param_int(msg.param_value))
        return float(msg.param_value)

    def _on_refused(self) -> None:
        if self._heard is not None:  # before the first heartbeat, connect() waits it out
            self._refused = "the vehicle's port refused our datagrams (it has gone away)"

    def _on_heartbeat(self, msg: Any) -> None:
        if msg.autopilot == 8 or msg.type in (6, 18):  # no autopilot, a GCS or a companion
            return
        if self._heard is None:
            self._target = (msg.get_srcSystem(), msg.get_srcComponent())
            self.autopilot = msg.autopilot
            self._heard = self.clock.now()
        if msg.get_srcSystem() == self._target[0]:
            self._mode = msg.custom_mode
            self._mode_seen = self._mode_seen or (
                self._flight_mode is not None and self._mode == self._flight_mode)
            self._armed = bool(msg.base_mode & 128)  # MAV_MODE_FLAG_SAFETY_ARMED

    def _release(self, handover: bool = False) -> None:
        sentinel, self._sentinel = self._sentinel, None
        if sentinel is not None:
            if handover:
                sentinel.hand_over()
            else:
                sentinel.release()
        for ticker in self._tickers:
            ticker.stop()
        conn, self._conn = self._conn, None
        if conn is not None:
            conn.close()
