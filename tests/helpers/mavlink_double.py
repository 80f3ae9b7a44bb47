"""A MAVLink vehicle double on loopback UDP, built on pymavlink, for tests.

It behaves like the slice of ArduPilot or PX4 the driver talks to:
- HEARTBEAT at 1 Hz (and at once on every mode or arming change), type quadrotor,
  autopilot ArduPilot (3) or PX4 (12), custom_mode and the armed flag in base_mode;
- PARAM_REQUEST_READ -> PARAM_VALUE for the parameters it holds (unknown ones unanswered);
- COMMAND_LONG DO_SET_MODE (176): ArduPilot takes param2 as the custom mode; PX4 takes
  param2/param3 as main/sub mode and refuses OFFBOARD (MAV_RESULT_DENIED) unless attitude
  targets have streamed for more than 1 s and the last is under 0.5 s old;
- COMMAND_LONG COMPONENT_ARM_DISARM (400), SET_MESSAGE_INTERVAL (511) for ATTITUDE,
  both acknowledged; ATTITUDE is then streamed at the asked rate;
- SET_ATTITUDE_TARGET recorded with its arrival time.
mute() stops all sending (a hung autopilot), unmute() resumes it; die() closes the socket.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

from pymavlink import mavutil
from ticks import wait_for

ARDUPILOT, PX4 = 3, 12
ACCEPTED, DENIED = 0, 2


@dataclass(frozen=True)
class Target:
    t: float  # [s] time.monotonic() at arrival
    q: tuple[float, float, float, float]  # (w, x, y, z)
    thrust: float
    type_mask: int
    target: tuple[int, int]


class VehicleDouble:
    def __init__(self, autopilot: int = ARDUPILOT, params: dict[str, float] | None = None,
                 refuse_arm: bool = False) -> None:
        self.autopilot = autopilot
        default = {"GUID_OPTIONS": 8.0, "MOT_THST_HOVER": 0.35} if autopilot == ARDUPILOT \
            else {"MPC_THR_HOVER": 0.42}
        self.params = default if params is None else params
        self.refuse_arm = refuse_arm
        self.conn = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=1,
                                               source_component=1)
        self.port = self.conn.port.getsockname()[1]
        self.uri = f"mavlink:udpout:127.0.0.1:{self.port}"
        self.custom_mode = 0 if autopilot == ARDUPILOT else (3 << 16)  # STABILIZE / POSCTL
        self.armed = False
        self.targets: list[Target] = []
        self.commands: list[tuple[float, int, tuple[float, ...]]] = []
        self.modes: list[tuple[float, int]] = []
        self.gcs_heartbeats: list[float] = []
        self.attitude_interval: float | None = None
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
                self._send(lambda m: m.attitude_send(int(now * 1000) & 0xFFFFFFFF, 0, 0, 0, 0, 0, 0))

    def _send(self, fn) -> None:
        if self._sending and self._alive and self.conn.clients:
            fn(self.conn.mav)

    def _heartbeat(self) -> None:
        self._next_heartbeat = time.monotonic() + 1.0
        base = 1 | (128 if self.armed else 0)
        self._send(lambda m: m.heartbeat_send(2, self.autopilot, base, self.custom_mode, 4))

    def _handle(self, msg) -> None:
        kind, now = msg.get_type(), time.monotonic()
        if kind == "HEARTBEAT":
            self.gcs_heartbeats.append(now)
            if len(self.gcs_heartbeats) == 1:
                self._heartbeat()  # a new client hears from us at once (saves test time)
        elif kind == "PARAM_REQUEST_READ" and msg.param_id in self.params:
            value = self.params[msg.param_id]
            self._send(lambda m: m.param_value_send(msg.param_id.encode(), value, 9, len(self.params), 0))
        elif kind == "SET_ATTITUDE_TARGET":
            self.targets.append(Target(now, tuple(msg.q), msg.thrust, msg.type_mask,
                                       (msg.target_system, msg.target_component)))
        elif kind == "COMMAND_LONG":
            params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
            self.commands.append((now, msg.command, params))
            self._ack(msg.command, self._command(msg.command, params, now))

    def _command(self, command: int, p: tuple[float, ...], now: float) -> int:
        if command == 176:
            mode = int(p[1]) if self.autopilot == ARDUPILOT else (int(p[1]) << 16) | (int(p[2]) << 24)
            if self.autopilot == PX4 and int(p[1]) == 6 and not self._offboard_ready(now):
                return DENIED
            self.custom_mode = mode
            self.modes.append((now, mode))
        elif command == 400:
            if self.refuse_arm:
                return DENIED
            self.armed = p[0] == 1
        elif command == 511 and int(p[0]) == 30:
            self.attitude_interval = p[1] / 1e6 if p[1] > 0 else None
        self._heartbeat()
        return ACCEPTED

    def _offboard_ready(self, now: float) -> bool:
        return bool(self.targets) and now - self.targets[0].t > 1.0 and now - self.targets[-1].t < 0.5

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
