"""Crazyflie 2.x over cflib: a Crazyradio (`radio://0/80/2M/E7E7E7E7E7`) or cflib's `udp://`
link (software-in-the-loop, and the tests' CRTP responder).

The driver speaks the low-level CRTP link (cflib.crtp.get_link_driver) with cflib's own
Commander and Localization encoders, not the full `Crazyflie` object: that one downloads the
log/param TOCs and memories on connect, which the attitude stream does not need.

Conversions (perchd SI -> cflib send_setpoint):
- roll [rad] -> degrees, same sign: the firmware's roll is right-handed about body x.
- pitch [rad] -> degrees, same sign: cflib's `pitch` argument is positive nose-down
  (right-handed about y with z up), and cflib puts -pitch on the wire because the
  firmware's legacy attitude is positive nose-up (commander.py packs `-pitch`; see
  bitcraze/crazyflie-firmware#884 and crazyflie-lib-rs#7 on that legacy sign).
- yaw [rad] -> a yaw *rate* [deg/s]: the RPYT packet commands yaw rate. With a measured
  yaw (observe_pose) it is K_YAW * wrap(yaw_sp - yaw), clamped to YAW_RATE_MAX;
  without one it is 0 (hold the heading the vehicle has). It goes on the wire negated:
  the firmware's legacy RPYT takes the yaw rate positive clockwise
  (crtp_commander_rpyt.c sets attitudeRate.yaw = -yaw), so a counter-clockwise
  correction is sent negative; sent as is, the yaw loop runs away (docs/firmware.md).
- thrust [N] -> 0..60000 through drivers.thrust.CrazyflieThrust (the firmware clamps
  RPYT thrust at 60000).

URI options (removed before cflib sees the URI): hover=UNITS (thrust model calibration:
the command that holds the flight's vehicle.mass_kg; the mass itself comes from the flight,
bind_mass; a mass=KG here must agree with it, else the flight is refused before it starts), timeout=S (link silent this long = lost, default 0.5), wait=S (connect
waits this long for the echo, default 2), extpose=1 (forward observed poses to the
on-board estimator).
"""

from __future__ import annotations

import math
import struct
import threading
import time
from collections import deque
from typing import Any

from perchd.drivers.base import DriverBase, agreed_mass
from perchd.drivers.thrust import CF_UNITS_MAX, CrazyflieThrust
from perchd.drivers.ticker import Ticker

from perchd.core.errors import ConfigError, LinkError, UriError
from perchd.core.extras import require
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, LinkHealth, Pose, Setpoint
from perchd.core.uri import Uri
from perchd.core.uriparams import bool_param, float_param, without_query
from perchd.core.vehicle import CRAZYFLIE_HOVER_UNITS, CRAZYFLIE_MASS_KG

KEEPALIVE_S = 0.1
"""[s] silence after which the keep-alive re-sends (the firmware levels at 0.5 s, cuts at 2 s)."""
PING_S = 0.02
"""[s] period of CRTP link-echo pings, the proof of life on links without acks (udp)."""
PING_TAG = b"pd"  # our echoes, told apart from anything else echoed on the link
RTT_SAMPLES = 10  # the round trip is the median of the last 10 echoes (200 ms)
FAILSAFE_REPEAT_S = 3.0
"""[s] after failsafe() the stop goes out again with every ping for this long (or until
close()): one sent into a dead link is lost, and a link back within this window still
delivers it. Past it the firmware has cut the motors itself (2 s without a setpoint)."""
K_YAW = 2.0
"""[1/s] yaw-rate gain on the yaw error when a measured yaw is known."""
YAW_RATE_MAX = 90.0
"""[deg/s] clamp on the commanded yaw rate."""

ECHO_HEADER = 0xFC
"""CRTP port 15 (link control) channel 0 (echo) with cflib's reserved bits 0b11."""

_crtp_ready = False


def open_crazyflie(uri: Uri, runtime: Runtime) -> "CrazyflieDriver":
    """Factory for `radio://` and `udp://` (not connected yet)."""
    require("cflib", "crazyflie")
    if uri.scheme == "radio":
        _check_radio(uri)
    hover = float_param(uri, "hover", CRAZYFLIE_HOVER_UNITS, 1000, 60000, " units")
    mass = float_param(uri, "mass", None, 0.010, 0.100, " kg")
    timeout = float_param(uri, "timeout", 0.5, 0.01, 10.0, " s")
    model = CrazyflieThrust(hover_units=hover, mass_kg=mass or CRAZYFLIE_MASS_KG)
    driver = CrazyflieDriver(uri.raw, without_query(uri), runtime, model, timeout,
                             extpose=bool_param(uri, "extpose"),
                             wait=float_param(uri, "wait", 2.0, 0.05, 60.0, " s"))
    driver.uri_mass = mass
    return driver


def _check_radio(uri: Uri) -> None:
    """radio://DONGLE/CHANNEL/RATE[/ADDRESS], checked here: cflib would only say "connection
    failed" at connect time for a typo."""
    parts = uri.path.strip("/").split("/") if uri.path.strip("/") else []
    ok = ((uri.host.isdigit() or uri.host == "*") and len(parts) in (2, 3) and parts[0].isdigit()
          and 0 <= int(parts[0]) <= 125 and parts[1] in ("250K", "1M", "2M"))
    if ok and len(parts) == 3:
        ok = len(parts[2]) == 10 and all(c in "0123456789abcdefABCDEF" for c in parts[2])
    if not ok:
        raise UriError(f"{uri.raw}: expected radio://DONGLE/CHANNEL/RATE[/ADDRESS], e.g. "
                       "radio://0/80/2M/E7E7E7E7E7 (channel 0..125, rate 250K, 1M or 2M, "
                       "address 10 hex digits)")


def _init_cflib() -> Any:
    """cflib.crtp.init_drivers() once: it appends to a global driver list on every call."""
    global _crtp_ready
    import cflib.crtp
    if not _crtp_ready:
        cflib.crtp.init_drivers()
        _crtp_ready = True
    return cflib.crtp


def wrap_angle(a: float) -> float:
    """[rad] into [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def yaw_of(q: tuple[float, float, float, float]) -> float:
    """[rad] Z-Y-X yaw of an (x, y, z, w) quaternion."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class _LinkPort:
    """The slice of cflib's Crazyflie that Commander and Localization use."""

    def __init__(self, link: Any) -> None:
        self.link = link
        self.lock = threading.Lock()

    def send_packet(self, pk: Any) -> None:
        with self.lock:
            if self.link is not None:
                self.link.send_packet(pk)

    def add_port_callback(self, port: int, cb: Any) -> None:
        """Incoming packets are drained by the driver itself; nothing dispatches them."""


class CrazyflieDriver(DriverBase):
    def __init__(self, uri: str, link_uri: str, runtime: Runtime, model: CrazyflieThrust,
                 timeout: float, extpose: bool = False, wait: float = 2.0) -> None:
        self.uri = uri
        self.link_uri = link_uri
        self.clock = runtime.clock
        self.model = model
        self.timeout = timeout
        self.extpose = extpose
        self.wait = wait
        self._port: _LinkPort | None = None
        self._commander: Any = None
        self._loc: Any = None
        self._tickers: list[Ticker] = []
        self._echoed = threading.Event()
        self._rtts: deque[float] = deque(maxlen=RTT_SAMPLES)  # [s] recent echo round trips
        self._rtt_s: float | None = None  # their median, kept by the receive thread
        self._link_error = ""
        self._last_heard: float | None = None
        self._last_sent = 0.0  # time.monotonic() of the last setpoint on the wire
        self._last_cmd = (0.0, 0.0, 0.0, 0)  # (roll deg, pitch deg, yawrate deg/s, units)
        self._yaw: float | None = None
        self._stopped = False
        self._stop_until = 0.0  # time.monotonic() until which the stop is repeated
        self._wire = threading.Lock()  # "stopped?" and the send that follows, as one step
        self.failsafe_reasons: list[EndReason] = []
        self.uri_mass: float | None = None  # [kg] the URI's mass=, checked by bind_mass

    # -- Driver protocol ---------------------------------------------------------------
    def connect(self) -> None:
        crtp = _init_cflib()
        from cflib.crazyflie.commander import Commander
        from cflib.crazyflie.localization import Localization
        try:
            link = crtp.get_link_driver(self.link_uri, None, self._on_link_error)
        except Exception as err:  # cflib raises bare Exceptions (no dongle, link open)
            raise LinkError(f"{self.uri}: connection failed: {err}") from None
        if link is None:
            raise LinkError(f"{self.uri}: cflib has no link driver for {self.link_uri!r}")
        self._port = _LinkPort(link)
        self._commander = Commander(self._port)
        self._loc = Localization(self._port)
        self._stopped = False
        self._start_threads()
        self._ping()
        if not self._echoed.wait(self.wait) or self._link_error:
            why = self._link_error or f"no answer to a link echo within {self.wait:g} s"
            self._close_link()
            raise LinkError(f"{self.uri}: connection failed: {why}")
        self._send_cmd((0.0, 0.0, 0.0, 0))  # thrust 0 unlocks the firmware's thrust lock

    def send(self, setpoint: Setpoint) -> None:
        if self._stopped or self._port is None:
            return  # after a failsafe nothing may re-arm thrust
        cmd = self.command(setpoint)
        with self._wire:
            if not self._stopped:  # a failsafe from another thread may have come between
                self._send_cmd(cmd)

    def failsafe(self, reason: EndReason) -> None:
        self.failsafe_reasons.append(reason)
        self._stop()

    def health(self) -> LinkHealth:
        if self._port is None:
            return LinkHealth(False, 0.0, "not connected")
        age = 0.0 if self._last_heard is None else self.clock.now() - self._last_heard
        if self._link_error:
            return LinkHealth(False, age, f"connection lost: {self._link_error}")
        if age > self.timeout:
            return LinkHealth(False, age, f"connection lost: silent for {age:.3f} s")
        return LinkHealth(True, age, rtt_s=self._rtt_s)

    def close(self) -> None:
        if self._port is None:
            return
        if not self._stopped:
            self._stop()
        self._close_link()

    def bind_mass(self, mass_kg: float) -> None:
        """Recalibrate the thrust model to the flight's mass: hover= units hold mass_kg."""
        mass = agreed_mass(self.uri, self.uri_mass, mass_kg)
        try:
            self.model = CrazyflieThrust(hover_units=self.model.hover_units, mass_kg=mass)
        except ValueError as err:
            raise ConfigError(f"{self.uri}: vehicle.mass_kg: {err}") from None

    def thrust_ceiling_n(self) -> float:
        """[N] what CF_UNITS_MAX (the firmware's RPYT clamp) gives in this model."""
        return self.model.newtons(CF_UNITS_MAX)

    # -- conversions -----------------------------------------------------------------
    def command(self, sp: Setpoint) -> tuple[float, float, float, int]:
        """send_setpoint arguments for an SI setpoint: (roll deg, pitch deg, yaw rate
        deg/s, thrust units), in cflib's conventions (see the module docstring)."""
        yawrate = 0.0
        if self._yaw is not None:
            err = math.degrees(wrap_angle(sp.yaw - self._yaw))
            yawrate = max(-YAW_RATE_MAX, min(YAW_RATE_MAX, K_YAW * err))
        return (math.degrees(sp.roll), math.degrees(sp.pitch), -yawrate,  # clockwise-positive
                self.model.units(sp.thrust))

    def observe_pose(self, pose: Pose) -> None:
        """The newest mocap pose: its yaw closes the yaw-rate loop; with extpose=1 it also
        goes to the on-board estimator (cflib's send_extpose)."""
        if not pose.valid:
            return
        self._yaw = yaw_of(pose.q)
        if self.extpose and self._loc is not None and not self._stopped:
            self._loc.send_extpose(list(pose.p), list(pose.q))

    # -- wire ------------------------------------------------------------------------
    def _send_cmd(self, cmd: tuple[float, float, float, int]) -> None:
        self._last_cmd = cmd
        self._last_sent = time.monotonic()
        self._commander.send_setpoint(*cmd)

    def _stop(self) -> None:
        with self._wire:  # no keep-alive setpoint can follow the stop
            self._stop_until = time.monotonic() + FAILSAFE_REPEAT_S
            self._stopped = True
            if self._commander is not None:
                # twice: on udp a pending ICMP error from an earlier datagram eats one send
                for _ in range(2):
                    self._commander.send_stop_setpoint()

    def _ping(self) -> None:
        """A CRTP echo stamped with its send time: the echo's return gives the round trip."""
        from cflib.crtp.crtpstack import CRTPPacket
        if self._port is not None:
            stamp = struct.pack("<d", time.monotonic())
            self._port.send_packet(CRTPPacket(ECHO_HEADER, PING_TAG + stamp))

    def _on_link_error(self, message: str) -> None:
        """cflib's link error: connection_failed before the echo, connection_lost after."""
        lines = [ln.strip() for ln in message.strip().splitlines() if ln.strip()]
        self._link_error = ": ".join(lines[:2]) or "link error"

    def _start_threads(self) -> None:
        self._echoed.clear()
        self._link_error = ""
        self._rtts.clear()  # a new link's round trip, not the last one's
        self._rtt_s = None
        # receive: receive_packet blocks up to 50 ms, so a zero period is no busy loop
        self._tickers = [Ticker(0.0, self._receive, "crazyflie-receive").start(),
                         Ticker(PING_S, self._keepalive, "crazyflie-keepalive").start()]

    def _receive(self) -> None:
        link = self._port.link if self._port else None
        pk = link.receive_packet(0.05) if link is not None else None
        if pk is not None:
            self._last_heard = self.clock.now()
            if pk.header == ECHO_HEADER:
                self._echoed.set()
                self._note_round_trip(bytes(pk.data))

    def _note_round_trip(self, data: bytes) -> None:
        if len(data) == len(PING_TAG) + 8 and data.startswith(PING_TAG):
            (sent,) = struct.unpack_from("<d", data, len(PING_TAG))
            self._rtts.append(time.monotonic() - sent)
            self._rtt_s = sorted(self._rtts)[len(self._rtts) // 2]

    def _keepalive(self) -> None:
        """Ping, and never let KEEPALIVE_S pass without a setpoint: a stalled loop gets the
        last thrust, levelled (a held tilt would keep accelerating the vehicle at the wall).
        After a failsafe, repeat the stop (FAILSAFE_REPEAT_S) so a link back delivers it."""
        self._ping()
        with self._wire:
            now = time.monotonic()
            if self._commander is None:
                return
            if self._stopped:
                if now < self._stop_until:
                    self._commander.send_stop_setpoint()
            elif now - self._last_sent >= KEEPALIVE_S:
                self._send_cmd((0.0, 0.0, 0.0, self._last_cmd[3]))

    def _close_link(self) -> None:
        for ticker in self._tickers:
            ticker.stop()
        port, self._port = self._port, None
        if port is None or port.link is None:
            return
        with port.lock:
            link, port.link = port.link, None
        # cflib's udp receive thread blocks in recv for up to 1 s before it sees the stop
        # flag; release the link in the background rather than stall the caller.
        threading.Thread(target=link.close, name="crazyflie-close", daemon=True).start()
