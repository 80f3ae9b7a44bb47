"""The Crazyflie link keeper: a child process that owns the cflib link (docs/safety.md,
"When the agent dies").

The firmware holds the last thrust, levelled, for 2 s after the last setpoint
(COMMANDER_WDT_TIMEOUT_SHUTDOWN): a dead agent mid-approach would climb and then drop.
So the link lives in this process, and when the agent goes (EOF on the socket: the kernel
closes it on SIGKILL; or no message for SILENT_S) it flies the vehicle down itself: level
at once (during its first |v| / a, at most LEAN_MAX_S, leaning against the velocity the
driver last measured: the brake the driver keeps renewing, drivers/mavlink/brake.py), at a
sink speed held on the flight's own mocap, opened here at the death (drivers/cfsink.py
ClosedSink), or open loop about the hover thrust while the mocap is not there (OpenSink);
then the stop setpoint, then it closes the link and exits. A keeper whose link never
reached the vehicle (never heard it, never sent a thrust above zero: the agent's connect
failed) has nothing to land and exits at once, saying nothing.

Wire (a SOCK_SEQPACKET pair, one message per packet, little-endian):
  driver -> keeper: b"S" <fffHH> roll deg, pitch deg, yaw rate deg/s (cflib conventions),
                    thrust units, hold units (the thrust whose vertical part the last
                    command had, i.e. the level thrust that holds height);
                    b"P" <7f> extpose (x, y, z, qx, qy, qz, qw); b"B" <ffffd> the brake:
                    roll deg, pitch deg (cflib conventions), duration s, the thrust
                    units' factor that holds height at that tilt, time.monotonic() when
                    measured; b"Z" <ffd> height m, vertical speed m/s (up), time.monotonic()
                    when measured;
                    b"A" alive; b"X" stop;
                    b"U" leave the stop (the next flight's take-over; ignored once the
                    agent is gone); b"C" close (the keeper exits).
  keeper -> driver: b"R" link open; b"E" message: cflib could not open it; b"H" <dd> seconds since the vehicle was last heard
                    (-1: never), echo round trip median (-1: none), then a UTF-8 link error
                    ("" while the link is fine).

Run as `python -m perchd.service.cflink_main FD LINK_URI REPEAT_S HOVER_UNITS MASS_KG
[MOCAP_URI]` by drivers/crazyflie.py: that entry point opens the mocap (no driver imports
one) and hands it in (`main`'s `open_mocap`).
"""

from __future__ import annotations

import select
import signal
import socket
import struct
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from perchd.core.childproc import say
from perchd.core.ports import PoseSource
from perchd.drivers import cfsink
from perchd.drivers.cfsink import ClosedSink, Hover, OpenSink, hover_mean
from perchd.drivers.mavlink.brake import WILL_MAX_AGE_S
from perchd.drivers.thrust import CF_UNITS_MAX, CrazyflieThrust

CMD = struct.Struct("<fffHH")
POSE = struct.Struct("<7f")
BRAKE = struct.Struct("<ffffd")
STATUS = struct.Struct("<dd")
MOTION = struct.Struct("<ffd")

PING_S = 0.02
"""[s] period of CRTP link-echo pings and of status reports to the driver."""
KEEPALIVE_S = 0.1
"""[s] no setpoint this long: the hold thrust goes out levelled (the firmware levels at 0.5 s)."""
SILENT_S = 0.25
"""[s] no message from the driver (it sends one every PING_S) = the agent is hung: descend."""
LEAN_MAX_S = 0.5
"""[s] the longest brake: at the 1.5 m/s of a perch's approach, all of it."""
MOTION_MAX_AGE_S = 1.0
"""[s] an older height (and vertical speed) from the driver is not known (the open loop's
bound without one)."""
DESCENT_MAX_S = cfsink.DESCENT_MAX_S
"""[s] the keeper's longest descent: then the stop."""
HOVER_BAND = (0.5, 1.5)
"""hold thrusts outside this share of the model's weight (spool-up, a kick) teach no hover."""
FAILSAFE_REPEAT_S = 3.0
"""[s] the stop is repeated with every ping this long: one sent into a dead link is lost."""
PING_TAG = b"pd"
RTT_SAMPLES = 10
ECHO_HEADER = 0xFC
"""CRTP port 15 (link control) channel 0 (echo) with cflib's reserved bits 0b11."""


@dataclass(frozen=True)
class Lean:
    """The brake (drivers/mavlink/brake.py): roll_deg, pitch_deg in cflib's conventions, held
    for duration_s [s], level thrust units times thrust_factor (the driver's thrust model:
    the units are not linear in force); measured (time.monotonic()) at t_s [s]."""

    roll_deg: float
    pitch_deg: float
    duration_s: float
    thrust_factor: float
    t_s: float

    def command(self, level_units: int) -> tuple[float, float, float, int]:
        """send_setpoint arguments: the lean, with the thrust whose vertical part is
        level_units' (the descent's at that moment)."""
        units = min(int(level_units * self.thrust_factor), CF_UNITS_MAX)
        return self.roll_deg, self.pitch_deg, 0.0, units


NO_LEAN = Lean(0.0, 0.0, 0.0, 1.0, 0.0)


class Descent:
    """The keeper's own flight after the agent is gone, from t0_s (time.monotonic()): the
    brake's lean first (its tilt compensated, for at most LEAN_MAX_S), level after; the
    level thrust from the closed loop while it has the mocap, else from the open loop."""

    def __init__(
        self, t0_s: float, open_sink: OpenSink, closed: ClosedSink | None, lean: Lean = NO_LEAN
    ) -> None:
        self.t0_s = t0_s
        self.open = open_sink
        self.closed = closed
        self.lean = lean
        self.units = open_sink.hold_units  # the last level thrust flown

    def command(self, now: float) -> tuple[float, float, float, int] | None:
        """send_setpoint arguments at `now`, None once the descent is over (send the stop)."""
        level = self._level(now)
        if level is None:
            return None
        self.units = level
        leaning = now - self.t0_s < min(self.lean.duration_s, LEAN_MAX_S)
        return self.lean.command(level) if leaning else (0.0, 0.0, 0.0, level)

    def _level(self, now: float) -> int | None:
        closed = self.closed
        if closed is not None and closed.flying(now):
            return closed.level_units(now)
        if closed is not None and closed.vz_mps is not None:  # the mocap is lost
            say("cflink", "the mocap is lost: the open-loop sink goes on")
            self.open, self.closed = closed.open_sink(now, self.units), None
        return self.open.level_units(now)


class _LinkPort:
    """The slice of cflib's Crazyflie that Commander and Localization use."""

    def __init__(self, link: Any) -> None:
        self.link = link
        self.lock = threading.Lock()

    def send_packet(self, pk: Any) -> None:
        with self.lock:
            self.link.send_packet(pk)

    def add_port_callback(self, port: int, cb: Any) -> None:
        """Incoming packets are drained by the keeper itself; nothing dispatches them."""


MocapOpener = Callable[[str], PoseSource]
"""Opens a mocap URI, not started (the mocap is no driver's to import)."""


class Keeper:
    def __init__(
        self,
        sock: socket.socket,
        link_uri: str,
        repeat_s: float,
        model: CrazyflieThrust | None = None,
        mocap: PoseSource | None = None,
    ) -> None:
        self.sock = sock
        self.link_uri = link_uri
        self.repeat_s = repeat_s
        self.model = model or CrazyflieThrust()
        self.hover_n = self.model.newtons(self.model.hover_units)  # the hold thrusts' mean
        self.hold_at: float | None = None  # time.monotonic() of the last hold thrust
        self.motion: tuple[float, float, float] | None = None  # z [m], vz [m/s] up, measured at
        self.mocap = mocap  # the flight's mocap, opened, started at the death
        self.mocap_seq = -1
        self.error = ""
        self.heard: float | None = None  # time.monotonic() the vehicle was last heard
        self.thrust_sent = False  # a setpoint with thrust above zero went out
        self.rtts: deque[float] = deque(maxlen=RTT_SAMPLES)
        self.last_cmd = (0.0, 0.0, 0.0, 0)
        self.hold_units = 0
        self.last_sent = 0.0
        self.last_msg = time.monotonic()  # last message from the driver
        self.stop_until: float | None = None  # set once stopped
        self.descent: Descent | None = None
        self.lean = NO_LEAN  # the newest brake the driver left
        self.agent_gone = False
        self.running = True
        self.status_lock = threading.Lock()

    # -- link --------------------------------------------------------------------------
    def open(self) -> None:
        import cflib.crtp
        from cflib.crazyflie.commander import Commander
        from cflib.crazyflie.localization import Localization

        cflib.crtp.init_drivers()
        link = cflib.crtp.get_link_driver(self.link_uri, None, self._on_link_error)
        if link is None:
            raise RuntimeError(f"cflib has no link driver for {self.link_uri!r}")
        self.link = link
        self.port = _LinkPort(link)
        self.commander = Commander(self.port)
        self.loc = Localization(self.port)

    def _on_link_error(self, message: str) -> None:
        lines = [ln.strip() for ln in message.strip().splitlines() if ln.strip()]
        self.error = ": ".join(lines[:2]) or "link error"
        self.report()  # at once: the supervisor reads health every tick

    def _receive(self) -> None:
        while self.running:
            pk = self.link.receive_packet(0.05)
            if pk is not None:
                self.heard = time.monotonic()
                data = bytes(pk.data)
                if pk.header == ECHO_HEADER and len(data) == 10 and data.startswith(PING_TAG):
                    self.rtts.append(time.monotonic() - struct.unpack_from("<d", data, 2)[0])

    def ping(self) -> None:
        from cflib.crtp.crtpstack import CRTPPacket

        self.port.send_packet(
            CRTPPacket(ECHO_HEADER, PING_TAG + struct.pack("<d", time.monotonic()))
        )

    # -- to the driver -----------------------------------------------------------------
    def report(self) -> None:
        age = -1.0 if self.heard is None else time.monotonic() - self.heard
        rtt = sorted(self.rtts)[len(self.rtts) // 2] if self.rtts else -1.0
        with self.status_lock:
            try:
                self.sock.send(b"H" + STATUS.pack(age, rtt) + self.error.encode()[:400])
            except OSError:
                pass  # the agent is gone: the socket's EOF says so on the next read

    # -- setpoints ---------------------------------------------------------------------
    def send_cmd(self, cmd: tuple[float, float, float, int]) -> None:
        self.last_cmd = cmd
        self.thrust_sent = self.thrust_sent or cmd[3] > 0
        self.last_sent = time.monotonic()
        self.commander.send_setpoint(*cmd)

    def stop(self) -> None:
        if self.stop_until is None:
            self.stop_until = time.monotonic() + self.repeat_s
        for _ in range(2):  # on udp a pending ICMP error from an earlier datagram eats one
            self.commander.send_stop_setpoint()

    def on_message(self, msg: bytes) -> None:
        self.last_msg = time.monotonic()
        kind, body = msg[:1], msg[1:]
        if kind == b"S" and self.stop_until is None and self.descent is None:
            roll, pitch, yawrate, thrust, hold = CMD.unpack(body)
            self.hold_units = hold
            self.learn_hover(hold)
            self.send_cmd((roll, pitch, yawrate, thrust))
        elif kind == b"B" and len(body) == BRAKE.size:
            self.lean = Lean(*BRAKE.unpack(body))
        elif kind == b"Z" and len(body) == MOTION.size:
            self.motion = MOTION.unpack(body)
        elif kind == b"P" and self.stop_until is None:
            vals = POSE.unpack(body)
            self.loc.send_extpose(list(vals[:3]), list(vals[3:]))
        elif kind == b"X":
            self.stop()
        elif kind == b"U" and not self.agent_gone:
            self.stop_until = None
        elif kind == b"C":
            if self.stop_until is None:
                self.stop()
            self.running = False

    def learn_hover(self, hold_units: int) -> None:
        """The hold thrusts' mean, in newtons: the hover the agent's own hold learned."""
        now, newtons = time.monotonic(), self.model.newtons(hold_units)
        weight = self.model.newtons(self.model.hover_units)
        if HOVER_BAND[0] * weight <= newtons <= HOVER_BAND[1] * weight:
            dt = 0.0 if self.hold_at is None else now - self.hold_at
            self.hover_n = hover_mean(self.hover_n, newtons, dt)
            self.hold_at = now

    def reached_vehicle(self) -> bool:
        """A vehicle that may be flying: heard on the link, or sent a thrust above zero. A
        link that never reached one (the driver's connect failed: no echo) has only sent
        the zero-thrust keep-alives."""
        return self.heard is not None or self.thrust_sent

    def agent_lost(self, now: float) -> None:
        """EOF or silence: brake and descend unless already stopped (then only the repeats
        remain). A brake older than WILL_MAX_AGE_S is not flown: the mocap had stopped.
        Without a vehicle ever reached there is nothing to land: it exits at once, silent
        (the agent's connect said why in its one line)."""
        self.agent_gone = True
        if not self.reached_vehicle():
            self.running = False
            return
        if self.stop_until is None and self.descent is None:
            fresh = time.monotonic() - self.lean.t_s <= WILL_MAX_AGE_S
            hover = Hover(self.model, self.hover_n)
            opened = self.start_mocap()
            self.descent = Descent(
                now,
                OpenSink(now, self.hold_units, hover, *self.known_motion(now)),
                ClosedSink(now, hover) if opened else None,
                self.lean if fresh else NO_LEAN,
            )

    def known_motion(self, now: float) -> tuple[float | None, float]:
        """[m] above the floor (None: unknown) and [m/s] sink (> 0 down; a climb below zero,
        for the open loop's brake), from the driver's last height if recent."""
        if self.motion is None or now - self.motion[2] > MOTION_MAX_AGE_S:
            return None, 0.0
        return self.motion[0] - cfsink.FLOOR_Z_M, -self.motion[1]

    def start_mocap(self) -> bool:
        """The flight's mocap, its sockets opened now (never beside the agent's own)."""
        if self.mocap is None:
            return False
        try:
            self.mocap.start()
        except Exception as err:  # noqa: BLE001 - the open loop flies without it
            say("cflink", f"the mocap cannot be opened: {err}; open-loop sink")
            self.mocap = None
            return False
        return True

    def feed_mocap(self, now: float) -> None:
        """The newest pose, if new, to the closed loop."""
        closed = self.descent.closed if self.descent is not None else None
        pose = self.mocap.latest() if self.mocap is not None and closed is not None else None
        if pose is not None and pose.seq != self.mocap_seq:
            self.mocap_seq = pose.seq
            closed.observe(pose, now)

    def tick(self, now: float) -> None:
        """Every PING_S: ping, report, and keep the vehicle commanded."""
        self.ping()
        if not self.agent_gone:
            self.report()
            if now - self.last_msg > SILENT_S:
                self.agent_lost(now)
        if self.stop_until is not None:
            if now < self.stop_until:
                self.commander.send_stop_setpoint()
            elif self.agent_gone:
                self.running = False  # stopped, repeated, nobody left to tell
        elif self.descent is not None:
            self.feed_mocap(now)
            cmd = self.descent.command(now)
            if cmd is None:
                self.end_descent()
                self.stop()
                self.running = False  # the stop went twice; the agent is gone
            else:
                self.send_cmd(cmd)
        elif now - self.last_sent >= KEEPALIVE_S:
            # levelled at the hold thrust: the tilted thrust, levelled, would climb
            self.send_cmd((0.0, 0.0, 0.0, self.hold_units))

    def end_descent(self) -> None:
        closed = self.descent.closed if self.descent is not None else None
        how = "open loop" if closed is None else "touchdown" if closed.landed else "its bound"
        say("cflink", f"descent over ({how}): motors stopped")
        if self.mocap is not None:
            self.mocap.close()
            self.mocap = None

    def read_driver(self, timeout: float) -> None:
        if self.agent_gone:
            time.sleep(max(0.0, timeout))
            return
        ready, _, _ = select.select([self.sock], [], [], max(0.0, timeout))
        while ready:
            try:
                msg = self.sock.recv(64, socket.MSG_DONTWAIT)
            except BlockingIOError:
                return
            except OSError:
                msg = b""
            if not msg:
                self.agent_lost(time.monotonic())
                return
            self.on_message(msg)
            if not self.running:
                return

    def run(self) -> None:
        threading.Thread(target=self._receive, name="cflink-receive", daemon=True).start()
        self.sock.send(b"R")
        next_tick = time.monotonic()
        while self.running:
            self.read_driver(next_tick - time.monotonic())
            now = time.monotonic()
            if self.running and now >= next_tick:
                self.tick(now)
                next_tick = max(next_tick + PING_S, now)


def open_mocap_or_none(uri: str | None, open_mocap: MocapOpener | None) -> PoseSource | None:
    """The flight's mocap, opened (imports done, no sockets yet), or None: the open loop."""
    if not uri or open_mocap is None:
        return None
    try:
        return open_mocap(uri)
    except Exception as err:  # noqa: BLE001 - the keeper's link matters more
        say("cflink", f"the mocap {uri} cannot be opened: {err}")
        return None


def main(argv: list[str], open_mocap: MocapOpener | None = None) -> int:
    """FD LINK_URI REPEAT_S [HOVER_UNITS MASS_KG [MOCAP_URI]]."""
    # the agent's Ctrl-C, a service stop, systemd's watchdog signal and a terminal's hang-up
    # reach the whole group: the keeper outlives them and ends when the agent's socket closes
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGABRT, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)
    sock = socket.socket(fileno=int(argv[0]))
    model = CrazyflieThrust(float(argv[3]), float(argv[4])) if len(argv) > 4 else None
    mocap = open_mocap_or_none(argv[5] if len(argv) > 5 else None, open_mocap)
    keeper = Keeper(sock, argv[1], float(argv[2]), model, mocap)
    try:
        keeper.open()
    except Exception as err:  # cflib raises bare Exceptions (no dongle, link open)
        sock.send(b"E" + str(err).encode()[:400])
        return 1
    try:
        keeper.run()
    finally:
        keeper.running = False
        if keeper.mocap is not None:
            keeper.mocap.close()
        # cflib's udp close waits up to 1 s for its receive thread; the stop is out already
        closer = threading.Thread(target=keeper.link.close, daemon=True)
        closer.start()
        closer.join(0.3)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
