"""Crazyflie 2.x over cflib: a Crazyradio (`radio://0/80/2M/E7E7E7E7E7`) or cflib's `udp://`
link (software-in-the-loop, and the tests' CRTP responder).

The link lives in a child process, the keeper (drivers/cflink.py): when this process dies
it flies the brake this driver keeps renewing from the mocap, a descent at a held sink speed
on the flight's mocap (bind_mocap), and stops the motors (docs/safety.md, "When the agent
dies").
It speaks the low-level CRTP link (cflib.crtp.get_link_driver) with cflib's own
Commander and Localization encoders, not the full `Crazyflie` object: that one downloads the
log/param TOCs and memories on connect, which the attitude stream does not need.

Conversions (perchd SI -> cflib send_setpoint):
- roll [rad] -> degrees, same sign: the firmware's roll is right-handed about body x.
- pitch [rad] -> degrees, same sign: cflib's `pitch` argument is positive nose-down
  (right-handed about y with z up), and cflib puts -pitch on the wire because the
  firmware's legacy attitude is positive nose-up (commander.py packs `-pitch`; the sign
  is flown against the firmware in tests/firmware/test_fw_cf2_signs.py).
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
import socket
import subprocess
import threading
import time
from dataclasses import dataclass

from perchd.core import childproc
from perchd.core.errors import ConfigError, LinkError, UriError
from perchd.core.extras import require
from perchd.core.ned import ned_vec
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, LinkHealth, Pose, Setpoint
from perchd.core.uri import Uri
from perchd.core.uriparams import bool_param, float_param, without_query
from perchd.core.vehicle import CRAZYFLIE_HOVER_UNITS, CRAZYFLIE_MASS_KG
from perchd.drivers import cflink
from perchd.drivers.base import DriverBase, PoseFeed, agreed_mass, no_poses
from perchd.drivers.mavlink.brake import WillSchedule, lean_for
from perchd.drivers.targetlock import TargetLock, connect_holding
from perchd.drivers.thrust import CF_UNITS_MAX, CrazyflieThrust
from perchd.drivers.ticker import Ticker

PING_S = cflink.PING_S
"""[s] period of CRTP link-echo pings (the keeper's) and of the driver's alive messages."""
FAILSAFE_REPEAT_S = cflink.FAILSAFE_REPEAT_S
"""[s] after failsafe() the keeper repeats the stop with every ping this long (or until
close()): one sent into a dead link is lost. Past it the firmware has cut the motors."""
KEEPER_MODULE = "perchd.service.cflink_main"
"""The keeper's entry point: it opens the flight's mocap, which no driver imports."""
KEEPER_START_S = 15.0
"""[s] for the keeper process to start and open the link (python + cflib imports, loaded
machine); the connect's wait= for the echo counts from then."""
K_YAW = 2.0
"""[1/s] yaw-rate gain on the yaw error when a measured yaw is known."""
YAW_RATE_MAX = 90.0
"""[deg/s] clamp on the commanded yaw rate."""


@dataclass(frozen=True)
class KeeperStatus:
    """The keeper's last report on the link."""

    at: float  # [s] time.monotonic() it arrived
    heard_age_s: float  # [s] since the vehicle was last heard when sent; < 0: never
    rtt_s: float | None  # [s] echo round trip (median of the last 10)
    error: str  # cflib's link error, "" while fine


def open_crazyflie(uri: Uri, runtime: Runtime) -> CrazyflieDriver:
    """Factory for `radio://` and `udp://` (not connected yet)."""
    require("cflib", "crazyflie")
    if uri.scheme == "radio":
        _check_radio(uri)
    hover = float_param(uri, "hover", CRAZYFLIE_HOVER_UNITS, 1000, 60000, " units")
    mass = float_param(uri, "mass", None, 0.010, 0.100, " kg")
    timeout = float_param(uri, "timeout", 0.5, 0.01, 10.0, " s")
    model = CrazyflieThrust(hover_units=hover, mass_kg=mass or CRAZYFLIE_MASS_KG)
    driver = CrazyflieDriver(
        uri.raw,
        without_query(uri),
        runtime,
        model,
        timeout,
        extpose=bool_param(uri, "extpose"),
        wait=float_param(uri, "wait", 2.0, 0.05, 60.0, " s"),
    )
    driver.uri_mass = mass
    return driver


def _check_radio(uri: Uri) -> None:
    """radio://DONGLE/CHANNEL/RATE[/ADDRESS], checked here: cflib would only say "connection
    failed" at connect time for a typo."""
    parts = uri.path.strip("/").split("/") if uri.path.strip("/") else []
    ok = (
        (uri.host.isdigit() or uri.host == "*")
        and len(parts) in (2, 3)
        and parts[0].isdigit()
        and 0 <= int(parts[0]) <= 125
        and parts[1] in ("250K", "1M", "2M")
    )
    if ok and len(parts) == 3:
        ok = len(parts[2]) == 10 and all(c in "0123456789abcdefABCDEF" for c in parts[2])
    if not ok:
        raise UriError(
            f"{uri.raw}: expected radio://DONGLE/CHANNEL/RATE[/ADDRESS], e.g. "
            "radio://0/80/2M/E7E7E7E7E7 (channel 0..125, rate 250K, 1M or 2M, "
            "address 10 hex digits)"
        )


def wrap_angle(a: float) -> float:
    """[rad] into [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def yaw_of(q: tuple[float, float, float, float]) -> float:
    """[rad] Z-Y-X yaw of an (x, y, z, w) quaternion."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class CrazyflieDriver(DriverBase):
    """Converts SI setpoints; the link itself lives in the keeper process (drivers/cflink.py)."""

    def __init__(
        self,
        uri: str,
        link_uri: str,
        runtime: Runtime,
        model: CrazyflieThrust,
        timeout: float,
        extpose: bool = False,
        wait: float = 2.0,
    ) -> None:
        self.uri = uri
        self.link_uri = link_uri
        self.clock = runtime.clock
        self.model = model
        self.timeout = timeout
        self.extpose = extpose
        self.wait = wait
        self._sock: socket.socket | None = None
        self._keeper: subprocess.Popen | None = None
        self._tickers: list[Ticker] = []
        self._status: KeeperStatus | None = None
        self._echoed = threading.Event()
        self._opened = threading.Event()
        self._link_error = ""
        self._yaw: float | None = None
        self._stopped = False
        self._wire = threading.Lock()  # "stopped?" and the send that follows, as one step
        self.failsafe_reasons: list[EndReason] = []
        self.uri_mass: float | None = None  # [kg] the URI's mass=, checked by bind_mass
        self._will = WillSchedule()  # the keeper's brake, renewed from the mocap
        self._hold_n = 0.0  # [N] the last setpoint's vertical thrust (the keeper's hold)
        self._lock = TargetLock(uri)  # one agent per vehicle on this machine
        self.mocap_uri: str | None = None  # the flight's mocap, the keeper's descent

    # -- Driver protocol ---------------------------------------------------------------
    def connect(self) -> None:
        connect_holding(self._lock, self._open_link, self._close_link)

    def _open_link(self) -> None:
        self._stopped = False
        self._start_keeper()
        if not self._opened.wait(KEEPER_START_S) or self._link_error:
            why = self._link_error or f"link keeper did not start within {KEEPER_START_S:g} s"
            raise LinkError(f"{self.uri}: connection failed: {why}")
        if not self._echoed.wait(self.wait) or self._link_error:
            why = self._link_error or f"no answer to a link echo within {self.wait:g} s"
            raise LinkError(f"{self.uri}: connection failed: {why}")
        self._send(b"S" + cflink.CMD.pack(0.0, 0.0, 0.0, 0, 0))  # unlocks the thrust lock

    def send(self, setpoint: Setpoint) -> None:
        if self._stopped or self._sock is None:
            return  # after a failsafe nothing may re-arm thrust
        roll, pitch, yawrate, units = self.command(setpoint)
        self._hold_n = setpoint.thrust * math.cos(setpoint.roll) * math.cos(setpoint.pitch)
        hold = self.model.units(self._hold_n)
        with self._wire:
            if not self._stopped:  # a failsafe from another thread may have come between
                self._send(b"S" + cflink.CMD.pack(roll, pitch, yawrate, units, hold))

    def engage(self, poses: PoseFeed = no_poses) -> None:
        """A flight after a failsafe on the same link (perchd serve): the keeper leaves its
        stop and the thrust lock is opened again with a zero-thrust setpoint, as at connect.
        Without a failsafe before, connect was the take-over: nothing to do."""
        if not self._stopped or self._sock is None:
            return
        with self._wire:
            self._send(b"U")
            self._send(b"S" + cflink.CMD.pack(0.0, 0.0, 0.0, 0, 0))
            self._stopped = False

    def failsafe(self, reason: EndReason) -> None:
        self.failsafe_reasons.append(reason)
        self._stop()

    def health(self) -> LinkHealth:
        if self._sock is None:
            return LinkHealth(False, 0.0, "not connected")
        st = self._status
        if st is None or st.heard_age_s < 0:
            age = 0.0
        else:
            age = st.heard_age_s + time.monotonic() - st.at
        if self._link_error:
            return LinkHealth(False, age, f"connection lost: {self._link_error}")
        if st is not None and time.monotonic() - st.at > self.timeout:
            return LinkHealth(
                False,
                age,
                f"connection lost: link keeper silent for {time.monotonic() - st.at:.3f} s",
            )
        if age > self.timeout:
            return LinkHealth(False, age, f"connection lost: silent for {age:.3f} s")
        return LinkHealth(True, age, rtt_s=st.rtt_s if st else None)

    def close(self, hand_over: bool = True) -> None:  # nothing outlives the link
        if self._sock is None:
            return
        if not self._stopped:
            self._stop()
        self._send(b"C")
        self._close_link()

    def bind_mass(self, mass_kg: float) -> None:
        """Recalibrate the thrust model to the flight's mass: hover= units hold mass_kg."""
        mass = agreed_mass(self.uri, self.uri_mass, mass_kg)
        try:
            self.model = CrazyflieThrust(hover_units=self.model.hover_units, mass_kg=mass)
        except ValueError as err:
            raise ConfigError(f"{self.uri}: vehicle.mass_kg: {err}") from None

    def bind_mocap(self, uri: str) -> None:
        """The flight's mocap: the keeper opens it itself to land a vehicle whose agent died."""
        self.mocap_uri = uri

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
        return (
            math.degrees(sp.roll),
            math.degrees(sp.pitch),
            -yawrate,  # clockwise-positive
            self.model.units(sp.thrust),
        )

    def observe_pose(self, pose: Pose) -> None:
        """The newest mocap pose: its yaw closes the yaw-rate loop; with extpose=1 it also
        goes to the on-board estimator (cflib's send_extpose, in the keeper)."""
        if not pose.valid:
            return
        self._yaw = yaw_of(pose.q)
        self._renew_will(pose)
        if self.extpose and not self._stopped:
            self._send(b"P" + cflink.POSE.pack(*pose.p, *pose.q))

    def _renew_will(self, pose: Pose) -> None:
        """Every WILL_PERIOD_S, the brake the keeper is to fly should this process die:
        against the mocap's velocity (drivers/mavlink/brake.py; world X taken as north, so FRD
        roll is the world's and its pitch the world's negated: cflib's degrees)."""
        now = time.monotonic()
        v = self._will.due(pose, now)
        if v is None or self._stopped:
            return
        self._send(b"Z" + cflink.MOTION.pack(pose.p[2], v[2], now))
        roll, pitch, duration = lean_for(ned_vec(v, 0.0), -self._yaw)
        level = self.model.units(self._hold_n)
        factor = (
            self.model.units(self._hold_n / (math.cos(roll) * math.cos(pitch))) / level
            if level > 0
            else 1.0
        )
        self._send(
            b"B"
            + cflink.BRAKE.pack(math.degrees(roll), -math.degrees(pitch), duration, factor, now)
        )

    # -- the keeper ------------------------------------------------------------------
    def _start_keeper(self) -> None:
        """`python -m KEEPER_MODULE FD URI REPEAT_S HOVER_UNITS MASS_KG [MOCAP_URI]` on one
        end of a socket pair; this very perchd first on its path, so the keeper runs the
        same code."""
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        args = [
            str(theirs.fileno()),
            self.link_uri,
            repr(FAILSAFE_REPEAT_S),
            repr(self.model.hover_units),
            repr(self.model.mass_kg),
        ]
        try:
            self._keeper = childproc.start(
                KEEPER_MODULE, args + [self.mocap_uri or ""], (theirs.fileno(),)
            )
        finally:
            theirs.close()
        ours.settimeout(0.05)
        self._sock = ours
        self._echoed.clear()
        self._opened.clear()
        self._link_error = ""
        self._status = None
        # receive: recv blocks up to 50 ms, so a zero period is no busy loop
        self._tickers = [
            Ticker(0.0, self._receive, "crazyflie-receive").start(),
            Ticker(PING_S, lambda: self._send(b"A"), "crazyflie-alive").start(),
        ]

    def _send(self, msg: bytes) -> None:
        sock = self._sock
        if sock is None:
            return
        try:
            sock.send(msg)
        except OSError as err:
            self._keeper_gone(f"send failed: {err}")

    def _stop(self) -> None:
        with self._wire:  # no setpoint can follow the stop
            self._stopped = True
            self._send(b"X")

    def _receive(self) -> None:
        sock = self._sock
        if sock is None:
            return
        try:
            msg = sock.recv(512)
        except TimeoutError:
            return
        except OSError as err:
            msg = b""
            if sock.fileno() < 0:
                return  # closed by close()
            self._keeper_gone(str(err))
        if not msg:
            self._keeper_gone("its socket closed")
        elif msg[:1] == b"R":
            self._opened.set()
        elif msg[:1] == b"E":
            self._link_error = msg[1:].decode(errors="replace")
            self._opened.set()
        elif msg[:1] == b"H":
            age, rtt = cflink.STATUS.unpack_from(msg, 1)
            error = msg[1 + cflink.STATUS.size :].decode(errors="replace")
            self._status = KeeperStatus(time.monotonic(), age, rtt if rtt >= 0 else None, error)
            if error:
                self._link_error = error
            if age >= 0:
                self._echoed.set()

    def _keeper_gone(self, why: str) -> None:
        """The keeper is the link: without it the link is lost, and named so."""
        if not self._link_error:
            code = self._keeper.poll() if self._keeper else None
            self._link_error = f"link keeper exited ({why}" + (
                f", exit code {code})" if code is not None else ")"
            )
        self._opened.set()
        time.sleep(0.05)  # the receive ticker would spin on a closed socket

    def _close_link(self) -> None:
        for ticker in self._tickers:
            ticker.stop()
        sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()
        keeper, self._keeper = self._keeper, None
        if keeper is not None:  # reaped in the background: it exits after its stop
            childproc.reap_later(keeper, cflink.DESCENT_MAX_S + 2.0, "crazyflie-reap")
        self._lock.release()
