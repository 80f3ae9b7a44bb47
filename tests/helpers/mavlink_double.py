"""A MAVLink vehicle double on loopback UDP, built on pymavlink, for tests.

It behaves like the slice of ArduPilot or PX4 the driver talks to:
- HEARTBEAT every heartbeat_s (1 s), and at once on every mode or arming change unless
  prompt=False (PX4 waits for its next 1 Hz beat), type quadrotor, autopilot ArduPilot (3)
  or PX4 (12), custom_mode and the armed flag in base_mode;
- PARAM_REQUEST_READ -> PARAM_VALUE for the parameters it holds (unknown ones unanswered),
  PARAM_SET -> stored and echoed; PX4's integer parameters travel bytewise, as PX4 sends them;
- airborne=True: armed, in the air (EXTENDED_SYS_STATE landed_state 2), at heading yaw_deg;
- lock_partner=True: answers only the first address it heard from (PX4's offboard link);
- COMMAND_LONG DO_SET_MODE (176): ArduPilot takes param2 as the custom mode; PX4 takes
  param2/param3 as main/sub mode and refuses OFFBOARD (MAV_RESULT_DENIED) unless attitude
  targets have streamed for more than 1 s and the last is under 0.5 s old;
- COMMAND_LONG COMPONENT_ARM_DISARM (400), SET_MESSAGE_INTERVAL (511) for ATTITUDE and
  EXTENDED_SYS_STATE, acknowledged; those are then streamed at the asked rate; ATTITUDE
  holds its attitude estimate (roll, pitch, yaw: settable) and its boot time, time.monotonic()
  less boot_s;
- SET_ATTITUDE_TARGET recorded with its arrival time; ATTITUDE_TARGET (83) streamed when
  asked, its thrust the one applied: 0 until spool_s after the first positive thrust once
  armed on the ground (ArduCopter's MOT_SAFE_TIME + MOT_SPOOL_TIME), then the last target's;
- VISION_POSITION_ESTIMATE recorded with its arrival time; vision_to_arm=N: arming is refused
  (MAV_RESULT_FAILED) until N of them have arrived, as ArduCopter on ExternalNav alone has no
  position or heading before the mocap flows;
- mavlink2=True: speaks MAVLink 2 (pymavlink's peer switches to it on the first frame);
- timesync=True: TIMESYNC requests (tc1 = 0) every 0.1 s, as PX4 sends them; the answers
  recorded.
mute() stops all sending (a hung autopilot), unmute() resumes it; die() closes the socket.
"""

from __future__ import annotations

import math
import struct
import subprocess
import sys
import threading
import time
from dataclasses import dataclass

from pymavlink import mavutil
from ticks import wait_for

from perchd.core.runtime import Runtime
from perchd.drivers.base import open_driver

ARDUPILOT, PX4 = 3, 12
ACCEPTED, DENIED, FAILED = 0, 2, 4
SAFE_PARAMS = {
    ARDUPILOT: {
        "GUID_OPTIONS": 8.0,
        "MOT_THST_HOVER": 0.35,
        "GUID_TIMEOUT": 0.5,
        "FS_GCS_ENABLE": 5.0,
        "FS_GCS_TIMEOUT": 2.0,
        "ATC_ANGLE_BOOST": 0.0,
        "VISO_TYPE": 1.0,
        "EK3_SRC1_POSXY": 6.0,
        "EK3_SRC1_POSZ": 6.0,
        "EK3_SRC1_YAW": 6.0,
    },
    PX4: {
        "MPC_THR_HOVER": 0.42,
        "COM_OF_LOSS_T": 0.3,
        "COM_OBL_RC_ACT": 4.0,
        "EKF2_EV_CTRL": 11.0,
        "EKF2_HGT_REF": 3.0,
    },
}
"""Parameters with perchd's values: failsafe (docs/safety.md), mocap to the EKF
(docs/firmware.md)."""
PX4_INTS = {"COM_OBL_RC_ACT", "NAV_DLL_ACT", "EKF2_EV_CTRL", "EKF2_HGT_REF"}


def connected(vehicle: VehicleDouble, query: str = "", mass_kg: float = 0.5, engage: bool = True):
    """perchd's MAVLink driver, connected to the double (query: more URI parameters) and,
    unless engage=False, engaged as a flight engages it (no poses)."""
    drv = open_driver(f"{vehicle.uri}?mass={mass_kg}{query}", Runtime.real())
    drv.connect()
    if engage:
        try:
            drv.engage()
        except BaseException:
            drv.close()
            raise
    return drv


def agent_process(code: str) -> subprocess.Popen:
    """A Python process running `code`, returned once it prints "ready" (an agent that has
    taken the vehicle, for the tests that kill it)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, stderr=subprocess.DEVNULL
    )
    assert proc.stdout.readline().strip() == "ready"
    return proc


def bytewise(value: float) -> float:
    return struct.unpack("<f", struct.pack("<i", int(value)))[0]


def from_bytewise(value: float) -> int:
    return struct.unpack("<i", struct.pack("<f", value))[0]


@dataclass(frozen=True)
class Target:
    t: float  # [s] time.monotonic() at arrival
    q: tuple[float, float, float, float]  # (w, x, y, z)
    thrust: float
    type_mask: int
    target: tuple[int, int]


class VehicleDouble:
    def __init__(
        self,
        autopilot: int = ARDUPILOT,
        params: dict[str, float] | None = None,
        refuse_arm: bool = False,
        *,
        airborne: bool = False,
        yaw_deg: float = 0.0,
        prompt: bool = True,
        heartbeat_s: float = 1.0,
        lock_partner: bool = False,
        spool_s: float = 0.0,
        timesync: bool = False,
        mavlink2: bool = False,
        vision_to_arm: int = 0,
    ) -> None:
        self.autopilot = autopilot
        self.params = dict(SAFE_PARAMS[autopilot]) if params is None else params
        self.refuse_arm = refuse_arm
        self.vision_to_arm = vision_to_arm
        self.prompt, self.heartbeat_s = prompt, heartbeat_s
        self.yaw = math.radians(yaw_deg)  # [rad] NED heading
        self.roll = self.pitch = 0.0  # [rad] its attitude estimate's, FRD in NED (ATTITUDE)
        self.boot_s = 0.0  # [s] time.monotonic() at its boot: ATTITUDE's time_boot_ms
        self.landed_state = 2 if airborne else 1  # MAV_LANDED_STATE_IN_AIR / ON_GROUND
        self.partner = None  # lock_partner: the first address heard
        self.conn = mavutil.mavlink_connection(
            "udpin:127.0.0.1:0", source_system=1, source_component=1
        )
        if mavlink2:  # as ArduPilot and PX4 speak; the driver follows (extension fields)
            self.conn.auto_mavlink_version(b"\xfd")
        self.port = self.conn.port.getsockname()[1]
        self.uri = f"mavlink:udpout:127.0.0.1:{self.port}"
        self.custom_mode = 0 if autopilot == ARDUPILOT else (3 << 16)  # STABILIZE / POSCTL
        if airborne:
            self.custom_mode = (
                5 if autopilot == ARDUPILOT else (4 << 16) | (3 << 24)
            )  # LOITER / HOLD
        self.armed = airborne
        self.param_sets: list[tuple[str, float]] = []
        self.sys_state_interval: float | None = None
        self._next_sys_state = 0.0
        if lock_partner:
            self._lock_partner()
        self.targets: list[Target] = []
        self.visions: list[tuple[float, object]] = []  # (arrival, the message)
        self.timesync_replies: list[tuple[float, int, int]] = []  # (arrival, tc1, ts1)
        self.spool_s, self.timesync = spool_s, timesync
        self._spool_start: float | None = 0.0 if airborne else None
        self.target_interval: float | None = None
        self._next_target = self._next_timesync = 0.0
        self.commands: list[tuple[float, int, tuple[float, ...]]] = []
        self.modes: list[tuple[float, int]] = []
        self.gcs_heartbeats: list[float] = []
        self.attitude_interval: float | None = None
        self.velocity_ned: tuple[float, float, float] | None = None
        """[m/s] LOCAL_POSITION_NED's velocity, streamed when asked for; None: not sent."""
        self.position_interval: float | None = None
        self._next_position = 0.0
        self._sending = True
        self._alive = True
        self._next_heartbeat = 0.0
        self._next_attitude = 0.0
        self._thread = threading.Thread(target=self._serve, name="mavlink-double", daemon=True)
        self._thread.start()

    # -- the vehicle ---------------------------------------------------------------------
    def _serve(self) -> None:
        while self._alive:
            try:
                msg = self.conn.recv_match(blocking=True, timeout=0.005)
            except OSError:
                return
            if msg is not None:
                self._handle(msg)
            now = time.monotonic()
            if now >= self._next_heartbeat:
                self._heartbeat()
            if self.attitude_interval and now >= self._next_attitude:
                self._next_attitude = now + self.attitude_interval
                boot_ms = int((now - self.boot_s) * 1000) & 0xFFFFFFFF
                self._send(
                    lambda m: m.attitude_send(boot_ms, self.roll, self.pitch, self.yaw, 0, 0, 0)
                )
            if self.target_interval and now >= self._next_target:
                self._next_target = now + self.target_interval
                applied = self.applied_thrust(now)
                self._send(lambda m: m.attitude_target_send(0, 0, [1, 0, 0, 0], 0, 0, 0, applied))
            if self.position_interval and self.velocity_ned and now >= self._next_position:
                self._next_position = now + self.position_interval
                v = self.velocity_ned
                self._send(lambda m: m.local_position_ned_send(0, 0, 0, -1, *v))
            if self.timesync and now >= self._next_timesync:
                self._next_timesync = now + 0.1
                self._send(lambda m: m.timesync_send(0, int(now * 1e9)))
            if self.sys_state_interval and now >= self._next_sys_state:
                self._next_sys_state = now + self.sys_state_interval
                self._send(lambda m: m.extended_sys_state_send(0, self.landed_state))

    def _lock_partner(self) -> None:
        """Drop datagrams from all but the first sender, as PX4's offboard link does."""
        sock, conn = self.conn.port, self.conn

        def recv(n=None):
            try:
                data, addr = sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return ""
            self.partner = self.partner or addr
            if addr != self.partner:
                return ""
            conn.clients = {addr}
            return data

        conn.recv = recv

    def _send(self, fn) -> None:
        if self._sending and self._alive and self.conn.clients:
            fn(self.conn.mav)

    def _heartbeat(self) -> None:
        self._next_heartbeat = time.monotonic() + self.heartbeat_s
        base = 1 | (128 if self.armed else 0)
        self._send(lambda m: m.heartbeat_send(2, self.autopilot, base, self.custom_mode, 4))

    def _handle(self, msg) -> None:
        kind, now = msg.get_type(), time.monotonic()
        if kind == "HEARTBEAT":
            self.gcs_heartbeats.append(now)
            if len(self.gcs_heartbeats) == 1:
                self._heartbeat()  # a new client hears from us at once (saves test time)
        elif kind == "PARAM_REQUEST_READ" and msg.param_id in self.params:
            self._param_value(msg.param_id)
        elif kind == "PARAM_SET" and msg.param_id in self.params:
            value = msg.param_value
            if self.autopilot == PX4 and msg.param_id in PX4_INTS:
                value = float(from_bytewise(value))
            self.params[msg.param_id] = value
            self.param_sets.append((msg.param_id, value))
            self._param_value(msg.param_id)
        elif kind == "SET_ATTITUDE_TARGET":
            self.targets.append(
                Target(
                    now,
                    tuple(msg.q),
                    msg.thrust,
                    msg.type_mask,
                    (msg.target_system, msg.target_component),
                )
            )
            if self.armed and msg.thrust > 0 and self._spool_start is None:
                self._spool_start = now
        elif kind == "VISION_POSITION_ESTIMATE":
            self.visions.append((now, msg))
        elif kind == "TIMESYNC" and msg.tc1 != 0:
            self.timesync_replies.append((now, msg.tc1, msg.ts1))
        elif kind == "COMMAND_LONG":
            params = (
                msg.param1,
                msg.param2,
                msg.param3,
                msg.param4,
                msg.param5,
                msg.param6,
                msg.param7,
            )
            self.commands.append((now, msg.command, params))
            self._ack(msg.command, self._command(msg.command, params, now))

    def _param_value(self, name: str) -> None:
        value, kind = self.params[name], 9  # MAV_PARAM_TYPE_REAL32
        if self.autopilot == PX4 and name in PX4_INTS:
            value, kind = bytewise(value), 6  # INT32, bytewise as PX4 sends it
        self._send(lambda m: m.param_value_send(name.encode(), value, kind, len(self.params), 0))

    def _command(self, command: int, p: tuple[float, ...], now: float) -> int:
        if command == 176:
            mode = (
                int(p[1]) if self.autopilot == ARDUPILOT else (int(p[1]) << 16) | (int(p[2]) << 24)
            )
            if self.autopilot == PX4 and int(p[1]) == 6 and not self._offboard_ready(now):
                return DENIED
            self.custom_mode = mode
            self.modes.append((now, mode))
        elif command == 400:
            if self.refuse_arm:
                return DENIED
            if p[0] == 1 and len(self.visions) < self.vision_to_arm:
                return FAILED  # pre-arm: the EKF has no position yet
            self.armed = p[0] == 1
        elif command == 511 and int(p[0]) == 30:
            self.attitude_interval = p[1] / 1e6 if p[1] > 0 else None
        elif command == 511 and int(p[0]) == 83:
            self.target_interval = p[1] / 1e6 if p[1] > 0 else None
        elif command == 511 and int(p[0]) == 32:
            self.position_interval = p[1] / 1e6 if p[1] > 0 else None
        elif command == 511 and int(p[0]) == 245:
            self.sys_state_interval = p[1] / 1e6 if p[1] > 0 else None
        if self.prompt:
            self._heartbeat()
        return ACCEPTED

    def applied_thrust(self, now: float) -> float:
        """The thrust the motors give: none before they have spooled up."""
        start = self._spool_start
        if not self.armed or start is None or now - start < self.spool_s or not self.targets:
            return 0.0
        return self.targets[-1].thrust

    def _offboard_ready(self, now: float) -> bool:
        return (
            bool(self.targets) and now - self.targets[0].t > 1.0 and now - self.targets[-1].t < 0.5
        )

    def _ack(self, command: int, result: int) -> None:
        self._send(lambda m: m.command_ack_send(command, result))

    # -- the test's hand on it -----------------------------------------------------------
    def switch_mode_by_pilot(self, custom_mode: int) -> None:
        self.custom_mode = custom_mode
        self._heartbeat()

    wait_for = staticmethod(wait_for)

    def mute(self) -> None:
        self._sending = False

    def unmute(self) -> None:
        self._sending = True

    def die(self) -> None:
        if self._alive:
            self._alive = False
            self._thread.join(timeout=1.0)
            self.conn.close()

    close = die
