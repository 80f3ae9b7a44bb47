"""MAVLink autopilots over pymavlink: ArduPilot in GUIDED_NOGPS, PX4 in OFFBOARD (their
dialects: ardupilot.py, px4.py), both flown with SET_ATTITUDE_TARGET (setpoints.py); the
`mavlink:` URI and its options: uri.py.

connect() changes nothing on the vehicle: it hears its heartbeat, asks for the messages the
driver reads and checks its parameters (params.py, the dialect's rules): a vehicle that
would keep flying a dead agent's setpoint, or fly home (docs/safety.md, "Autopilot failsafe
parameters"), whose attitude controller boosts thrust with tilt again (ArduPilot
ATC_ANGLE_BOOST), or whose EKF does not take the mocap (docs/firmware.md, "Mocap to the
autopilot") is refused by name there. engage(), once per flight, takes it (takeover.py);
the flight's poses go to the EKF meanwhile. A failsafe before it commands nothing (the
vehicle is not perchd's to land); after it, LAND until the vehicle takes it (landing.py).
From the acknowledged mode switch on, a sentinel process (sentinel.py) holds a copy of the
link and commands LAND the moment this process dies, until the vehicle leaves the offboard
mode; with vision on it relays the flight's mocap (bind_mocap) to the EKF until the landing
is over. Each pose the flight uses goes to the autopilot as VISION_POSITION_ESTIMATE
(vision.py), so its own failsafe can hold or land in place.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from perchd.core.clock import MonotonicClock
from perchd.core.errors import ConfigError, LinkError
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, LinkHealth, Setpoint, Vec3
from perchd.drivers.base import DriverBase, PoseFeed, agreed_mass, no_poses
from perchd.drivers.mavlink.dialect import rules_for
from perchd.drivers.mavlink.guard import SentinelGuard
from perchd.drivers.mavlink.landing import LandRetry
from perchd.drivers.mavlink.link import (
    ATTITUDE_ID,
    ATTITUDE_TARGET_ID,
    CMD_SET_MESSAGE_INTERVAL,
    EXTENDED_SYS_STATE_ID,
    HEARTBEAT_S,
    LOCAL_POSITION_NED_ID,
    Connection,
    ParamIO,
    Waiter,
    open_connection,
)
from perchd.drivers.mavlink.params import check_params
from perchd.drivers.mavlink.px4 import OFFBOARD_PORT
from perchd.drivers.mavlink.rivals import RivalWatch
from perchd.drivers.mavlink.setpoints import KEEPALIVE_S, SetpointStream, ned_attitude, ned_yaw
from perchd.drivers.mavlink.takeover import Takeover
from perchd.drivers.mavlink.tilt import NO_TILT, TiltCorrection
from perchd.drivers.mavlink.vehicle import VehicleView
from perchd.drivers.mavlink.vision import timesync_reply, vision_estimate, vision_message
from perchd.drivers.mavlink.yaw0 import Yaw0
from perchd.drivers.targetlock import TargetLock, connect_holding
from perchd.drivers.thrust import NormalisedThrust
from perchd.drivers.ticker import Ticker

log = logging.getLogger(__name__)

RECEIVE_S = 0.05
"""[s] the receiving thread's longest block: how soon it sees close()."""
STATUS_HZ = 10.0
"""[Hz] LOCAL_POSITION_NED (the autopilot's own estimate: does it take the mocap?) and
ATTITUDE_TARGET (the thrust it applies: spooled up?) asked for: a spool-up seen 0.1 s late
costs nothing, and every message parsed is Python time beside the control loop."""
LANDED_STATE_HZ = 10.0
"""[Hz] EXTENDED_SYS_STATE: on the ground, or in the air (a take-over)."""
NO_HEARTBEAT_CAUSES = (
    "is the autopilot running and sending to this address? PX4 sends only to its fixed "
    f"offboard port: use mavlink:udpin:127.0.0.1:{OFFBOARD_PORT} (SITL instance N: "
    f"{OFFBOARD_PORT}+N); a PX4 that already heard a udpout: link from another source "
    "port answers only that one (restart it, use udpin:, or keep one port with ?sport=); "
    "ArduPilot SITL: mavlink:tcp:127.0.0.1:5760 or its --out udp port with udpin:"
)
RIVAL_LISTEN_S = 0.5
"""[s] connect() listens at least this long for another GCS's or companion's targets: an
offboard stream comes at 2 Hz or more (PX4 leaves OFFBOARD below it)."""


class MavlinkDriver(DriverBase):
    """The Driver (drivers/base.py) of a MAVLink autopilot; options as uri.py reads them."""

    def __init__(
        self,
        uri: str,
        device: str,
        runtime: Runtime,
        *,
        mass_kg: float | None,
        hover: float | None,
        arm: bool,
        timeout: float,
        stream_hz: float,
        wait: float,
        yaw0: float | None = 0.0,
        configure: bool = False,
        sport: int | None = None,
        vision: bool = True,
        tilt: bool = True,
    ) -> None:
        self.uri, self.device, self.clock = uri, device, runtime.clock
        self.mass_kg = self.uri_mass = mass_kg  # uri_mass: the URI's mass=, for bind_mass
        self.hover, self.arm, self.timeout = hover, arm, timeout
        self.stream_hz, self.wait = stream_hz, wait
        self.configure, self.sport, self.vision = configure, sport, vision
        self.vision_sent = 0  # VISION_POSITION_ESTIMATEs sent
        self.tilt: TiltCorrection | None = TiltCorrection() if tilt else None
        self.model: NormalisedThrust | None = None
        self.vehicle = VehicleView()
        self.failsafe_reasons: list[EndReason] = []
        self.mocap_uri: str | None = None  # the flight's mocap, relayed after a death
        self._yaw0 = Yaw0(yaw0, uri)
        self._link: Connection | None = None
        self._params: ParamIO | None = None  # once the vehicle is known
        self._stream: SetpointStream | None = None  # once the vehicle is known
        self._takeover: Takeover | None = None  # once the vehicle is known
        self._refused = ""  # why the vehicle refused a command, once it has
        self._tickers: list[Ticker] = []
        self._landing = LandRetry(self._command_land)
        self._last_heartbeat = 0.0  # time.monotonic() of our last heartbeat
        self._stopped = False
        self._armed_at_land = False
        self._airborne_before_arm = False
        self._engaged = False  # the offboard mode has been asked for: the vehicle is ours
        self._engaging = False  # engage() is under way: a failsafe meanwhile ends it
        self._poses: PoseFeed = no_poses  # engage()'s pose feed, read while it waits
        self._pumped_seq: int | None = None  # the newest pose engage() forwarded
        self._guard = SentinelGuard(uri)  # lands the vehicle if this process dies
        self._vision_seq: int | None = None  # the newest pose sent to the EKF: each goes once
        self._lock = TargetLock(uri)  # one agent per vehicle on this machine
        self._rivals = RivalWatch()  # one on the link: another GCS or companion steering
        self._listen_from = 0.0  # [s] on self.clock: connect() began to hear the link

    @property
    def yaw0(self) -> float | None:
        """[rad] the autopilot's heading of world X; None while yaw0=auto knows none."""
        return self._yaw0.value

    @property
    def autopilot(self) -> int | None:
        return self.vehicle.autopilot

    @property
    def ekf_position_ned(self) -> Vec3 | None:
        """[m] the autopilot's own position estimate (LOCAL_POSITION_NED), newest."""
        return self.vehicle.ekf_position_ned

    # -- Driver protocol ---------------------------------------------------------------
    def connect(self) -> None:
        connect_holding(self._lock, self._open, self._release)

    def _open(self) -> None:
        self._rivals, self._listen_from = RivalWatch(), self.clock.now()
        self._link = open_connection(self.device, self.uri, self.sport, self._on_refused)
        self._refused = ""
        self.vehicle = VehicleView()
        self._stopped = self._engaged = False
        if self.tilt is not None:  # another link, maybe another boot: its clock learnt anew
            self.tilt = TiltCorrection()
        self._tickers = [
            Ticker(0.0, self._receive, "mavlink-receive").start(),
            Ticker(KEEPALIVE_S / 2, self._keepalive, "mavlink-keepalive").start(),
        ]
        try:
            self._setup(Waiter(self._link, self.uri, self.wait, MonotonicClock(), self._pump))
        except BaseException:
            self._release()
            raise

    def engage(self, poses: PoseFeed = no_poses) -> None:
        """Take the vehicle for one flight (takeover.py); each new pose from `poses` goes
        to the EKF while it waits. A failsafe's LAND still repeating is called off: a new
        flight was asked for."""
        steps, model = self._takeover, self.model
        if self._link is None or steps is None or model is None:
            raise LinkError(f"{self.uri}: engage() before connect()")
        self._poses, self._stopped, self._engaging = poses, False, True
        self._landing.cancel()
        try:
            self._airborne_before_arm = steps.prestream(model.hover_fraction)
            self._engaged = True
            steps.switch_mode()
            self._guard.flying(
                self._link,
                self.vehicle.target,
                steps.dialect.land,
                self.mocap_uri if self.vision else None,
                self.vehicle.flight_mode or 0,
            )
            if self.arm:
                steps.arm(self.vision, self._fed)
                if steps.dialect.spools_up and not self._airborne_before_arm:
                    steps.spool_up(model.hover_fraction)
        finally:
            self._poses, self._engaging = no_poses, False

    def send(self, setpoint: Setpoint) -> None:
        if self._stopped or self._link is None or self._stream is None or self.model is None:
            return
        if self.yaw0 is None:  # auto, and no pose yet: it faces where it is told to
            self._yaw0.align((self.vehicle.yaw_ned or 0.0) + setpoint.yaw)
        self._stream.level_yaw = ned_yaw(setpoint.yaw, self.yaw0)
        tilt = NO_TILT if self.tilt is None else self.tilt.correction(self.clock.now())
        self._stream.send(
            ned_attitude(setpoint, self.yaw0, tilt), self.model.fraction(setpoint.thrust)
        )

    def observe_pose(self, pose: Any) -> None:
        """Each pose goes to the autopilot's EKF once (vision.py) unless vision=0, and is
        paired with its attitude estimates for the tilt correction unless tilt=0."""
        link = self._link
        if not getattr(pose, "valid", True) or link is None:
            return
        self._yaw0.track(self.vehicle.yaw_ned, pose)
        self._renew_will(pose)
        if self.yaw0 is None or not (self.vision or self.tilt):
            return
        v = vision_estimate(pose, self.yaw0)
        if self.tilt is not None:
            self.tilt.on_pose(pose.t, v.rpy[0], v.rpy[1])
        if self.vision and pose.seq != self._vision_seq:  # the loop may see a pose twice
            self._vision_seq = pose.seq
            link.send(vision_message(link.mav, v))
            self.vision_sent += 1

    def failsafe(self, reason: EndReason) -> None:
        self.failsafe_reasons.append(reason)
        self._land()

    def health(self) -> LinkHealth:
        v = self.vehicle
        if self._link is None or v.heard_s is None:
            return LinkHealth(False, 0.0, "not connected")
        age = self.clock.now() - v.heard_s
        if self._refused:
            return LinkHealth(False, age, f"connection lost: {self._refused}")
        if age > self.timeout:
            return LinkHealth(
                False, age, f"connection lost: no message from the vehicle for {age:.2f} s"
            )
        if not self._stopped and v.left_flight_mode():
            return LinkHealth(False, age, f"vehicle left the offboard mode (custom mode {v.mode})")
        return LinkHealth(True, age)

    def close(self, hand_over: bool = True) -> None:
        if self._link is None:
            return
        if not self._stopped and self._engaged:
            self._land()
        # an EKF on mocap alone would dead-reckon the rest of the landing (docs/safety.md,
        # "The mocap relayed after the death"): the sentinel relays it until the end,
        # unless new links to this vehicle feed it from now on
        self._release(handover=hand_over and self._engaged and self.vehicle.armed and self.vision)

    def bind_mass(self, mass_kg: float) -> None:
        """The flight's mass for the thrust model (rebuilt if connect() already made it)."""
        self.mass_kg = agreed_mass(self.uri, self.uri_mass, mass_kg)
        if self.model is not None:
            self.model = NormalisedThrust(self.mass_kg, self.model.hover_fraction)

    def bind_mocap(self, uri: str) -> None:
        """The flight's mocap URI: with vision on, the sentinel relays it to the EKF after
        a death (relay.py)."""
        self.mocap_uri = uri

    def thrust_ceiling_n(self) -> float | None:
        """[N] full normalised thrust (1.0) in this model; known once connected."""
        return None if self.model is None else self.model.newtons(1.0)

    # -- connection setup --------------------------------------------------------------
    def _setup(self, waiter: Waiter) -> None:
        if self.mass_kg is None:
            raise ConfigError(
                f"{self.uri}: the vehicle mass is unknown: fly with a flight "
                f"config ([vehicle] mass_kg) or add ?mass=KG"
            )
        v = self.vehicle
        waiter.until(
            ("HEARTBEAT",),
            lambda: v.heard_s is not None,
            "a heartbeat from the vehicle",
            causes=NO_HEARTBEAT_CAUSES,
        )
        dialect = v.dialect
        if dialect is None:
            raise LinkError(
                f"{self.uri}: autopilot type {v.autopilot} is neither ArduPilot nor PX4"
            )
        self._params = params = ParamIO(waiter, v.target)
        self._stream = SetpointStream(waiter.link, v.target, self.clock)
        self._takeover = Takeover(waiter.link, waiter, v, self._stream, dialect, self.uri)
        self._ask_streams(waiter.link, v.target)
        dialect.check_setup(self.uri, params.read)
        check_params(
            self.uri,
            rules_for(dialect, self.vision),
            params.read,
            lambda name, value: params.write(name, *dialect.param_wire(name, value)),
            self.configure,
        )
        hover = self.hover if self.hover is not None else params.read(dialect.hover_param)
        try:
            self.model = NormalisedThrust(self.mass_kg, hover)
        except ValueError as err:
            raise ConfigError(f"{self.uri}: {err}") from None
        self.clock.sleep_until(self._listen_from + RIVAL_LISTEN_S)
        self._rivals.check(self.uri, v, dialect, self._lock.shared)

    def _ask_streams(self, link: Connection, target: tuple[int, int]) -> None:
        """The messages the driver reads, at the rates it needs them."""
        for msg_id, hz in (
            (ATTITUDE_ID, self.stream_hz),
            (EXTENDED_SYS_STATE_ID, LANDED_STATE_HZ),
            (ATTITUDE_TARGET_ID, STATUS_HZ),
            (LOCAL_POSITION_NED_ID, STATUS_HZ),
        ):
            link.command(target, CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)

    # -- engaging ----------------------------------------------------------------------
    def _fed(self) -> str:
        """What went to the EKF while arming was asked for, for its refusal."""
        if not self.vision:
            return ""
        return f" for {self.wait:g} s while {self.vision_sent} poses went to its EKF"

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

    def _renew_will(self, pose: Any) -> None:
        """While perchd flies, the brake the sentinel is to fly should this process die:
        against the mocap's velocity, at the heading flown (guard.py)."""
        level = self._stream.level_yaw if self._stream is not None else None
        heading = level if level is not None else self.vehicle.yaw_ned or 0.0
        hover = None if self._stopped or self.model is None else self.model.hover_fraction
        self._guard.renew(pose, self.yaw0, heading, hover)  # stopped: no brake to fly

    # -- the link's threads ------------------------------------------------------------
    def _receive(self) -> None:
        link = self._link
        if link is not None:
            link.pump(RECEIVE_S, self._on_message)

    def _on_message(self, msg: Any) -> None:
        self._rivals.on_message(msg)
        v = self.vehicle
        if not v.on_message(msg, self.clock.now()):
            return
        kind = msg.get_type()
        if kind == "PARAM_VALUE" and self._params is not None and v.dialect is not None:
            self._params.on_value(msg.param_id, v.dialect.param_value(msg))
        elif kind == "ATTITUDE" and self.tilt is not None:
            self.tilt.on_estimate(
                msg.time_boot_ms * 1e-3, v.heard_s, float(msg.roll), float(msg.pitch)
            )
        elif kind == "TIMESYNC" and msg.tc1 == 0 and self._link is not None:
            link = self._link
            link.send(link.mav.timesync_encode(*timesync_reply(msg.ts1, self.clock.now())))

    def _keepalive(self) -> None:
        """Heartbeat at 2 Hz; repeat the last attitude target, levelled, if the loop is silent;
        after a failsafe, LAND every LAND_RETRY_S until the vehicle takes it."""
        link, now = self._link, time.monotonic()
        if link is None:
            return
        if now - self._last_heartbeat >= HEARTBEAT_S:
            self._last_heartbeat = now
            link.heartbeat()
        if not self._stopped and self._stream is not None:
            self._stream.keep_alive()
        if self._stopped:
            taken = self._land_taken()
            self._landing.tick(taken)
            if taken:
                self._guard.not_flying()

    def _on_refused(self) -> None:
        if self.vehicle.heard_s is not None:  # before the first heartbeat, connect() waits
            self._refused = "the vehicle's port refused our datagrams (it has gone away)"

    # -- landing -----------------------------------------------------------------------
    def _land(self) -> None:
        """Stop streaming and hand the vehicle to the autopilot's own landing mode; the
        keep-alive repeats the command until the vehicle shows it took it. A vehicle never
        engaged is not perchd's: nothing is commanded."""
        self._stopped = True
        if self._link is None or self.vehicle.dialect is None or not self._engaged:
            return
        self._armed_at_land = self.vehicle.armed
        self._landing.start()

    def _command_land(self) -> None:
        link, dialect = self._link, self.vehicle.dialect
        if link is not None and dialect is not None:
            link.set_mode(self.vehicle.target, dialect.land.main, dialect.land.sub)

    def _land_taken(self) -> bool:
        """The vehicle's heartbeat shows it no longer flies our setpoints: it left the mode
        we flew in (LAND, or a mode the pilot or its own failsafe chose), or disarmed."""
        v = self.vehicle
        return v.mode != v.flight_mode or (self._armed_at_land and not v.armed)

    def _release(self, handover: bool = False) -> None:
        self._guard.end(handover)
        for ticker in self._tickers:
            ticker.stop()
        link, self._link = self._link, None
        if link is not None:
            link.close()
        self._lock.release()
