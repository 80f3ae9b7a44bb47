"""The failsafe after the service is gone (`perchd failsafe`, the units' ExecStopPost=):
what each driver can still do for a vehicle whose agent has stopped or died.

Each action is bounded by a deadline and returns an Outcome, one line on what it did or
why there was nothing to do; a link it cannot open is a LinkError. Per driver
(docs/safety.md, "When the service stops or dies"):
- sim://: the simulated vehicle lived in the service's process; nothing to do.
- zmq://: the stop message (docs/contracts.md §3), end reason SIGNAL, to the subscriber.
- mavlink: LAND, if the vehicle is armed in perchd's offboard mode (GUIDED_NOGPS, OFFBOARD),
  repeated until a heartbeat shows it; a vehicle disarmed, already landing, or in a mode
  the pilot or its own failsafe chose is left alone.
- radio://, udp:// (Crazyflie): a link keeper (drivers/cflink.py) still holding the link
  flies its own descent and stop: nothing to do. Without one, the stop setpoint.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from perchd.core.errors import LinkError
from perchd.core.extras import require
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason
from perchd.core.uri import parse_uri
from perchd.core.uriparams import without_query
from perchd.drivers.base import open_driver

STOP_REPEATS = 3
"""Crazyflie stop setpoints sent, PERIOD_S apart: one may be lost (the keeper sends two)."""
PERIOD_S = 0.05
"""[s] between repeated stop setpoints, and the MAVLink receive poll."""
KEEPER_MODULE = "perchd.drivers.cflink"


@dataclass(frozen=True)
class Outcome:
    acted: bool  # something was sent to the vehicle
    text: str  # one line: what was done, or why nothing was


def failsafe(uri: str, deadline: float) -> Outcome:
    """The failsafe for driver `uri`, done by `deadline` (time.monotonic() [s])."""
    scheme = parse_uri(uri).scheme
    action = ACTIONS.get(scheme)
    if action is None:  # the registry names the schemes it knows
        open_driver(uri, Runtime.real())
        raise LinkError(f"{uri}: no failsafe for the {scheme}: driver")
    return action(uri, deadline)


def _in_process(uri: str, deadline: float) -> Outcome:
    return Outcome(
        False, f"{uri}: the simulated vehicle lived in the service's process; nothing to do"
    )


def _zmq(uri: str, deadline: float) -> Outcome:
    driver: Any = open_driver(uri, Runtime.real())
    driver.wait = round(max(0.0, min(driver.wait, deadline - time.monotonic())), 1)
    driver.connect()  # LinkError when no subscriber is there within the wait
    try:
        driver.failsafe(EndReason.SIGNAL)
    finally:
        driver.close()  # lingers until the stop is out (zmq LINGER)
    return Outcome(True, f"{uri}: stop published (end reason {EndReason.SIGNAL.name})")


# --- MAVLink --------------------------------------------------------------------------------
def _mavlink(uri: str, deadline: float) -> Outcome:
    from perchd.drivers import mavlink as mav

    driver: Any = open_driver(uri, Runtime.real())  # the URI checked; never connected
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(driver.device, source_system=255, source_component=191)
    try:
        if driver.sport is not None:
            mav.bind_source_port(conn, driver.sport, uri)
        return _land(uri, _Vehicle(conn, mav), deadline)
    finally:
        conn.close()


class _Vehicle:
    """The autopilot as its heartbeats show it; our own heartbeat goes out meanwhile."""

    def __init__(self, conn: Any, mav: Any) -> None:
        self.conn, self.mav = conn, mav
        self.system: int | None = None
        self.autopilot = self.mode = 0
        self.armed = False
        self.accepted = False  # the LAND command's COMMAND_ACK
        self._beat = 0.0

    def poll(self) -> None:
        now = time.monotonic()
        if now - self._beat >= self.mav.HEARTBEAT_S:
            self._beat = now
            self.conn.mav.heartbeat_send(18, 8, 0, 0, 4)  # onboard controller, as the driver
        msg = self.conn.recv_match(blocking=True, timeout=PERIOD_S)
        if msg is None or (self.system is not None and msg.get_srcSystem() != self.system):
            return
        kind = msg.get_type()
        if kind == "HEARTBEAT" and msg.autopilot != 8 and msg.type not in (6, 18):
            self.system, self.autopilot = msg.get_srcSystem(), msg.autopilot
            self.mode, self.armed = msg.custom_mode, bool(msg.base_mode & 128)
        elif kind == "COMMAND_ACK" and msg.command == self.mav.CMD_DO_SET_MODE:
            self.accepted = msg.result == self.mav.MAV_RESULT_ACCEPTED

    def modes(self) -> tuple[int, int, tuple[int, int]]:
        """(perchd's offboard custom mode, LAND's, LAND as main/sub) for this autopilot."""
        d = self.mav.dialect_for(self.autopilot) or self.mav.ARDUPILOT
        return d.flight.custom, d.land.custom, (d.land.main, d.land.sub)

    def command_land(self, main_sub: tuple[int, int]) -> None:
        self.conn.mav.command_long_send(
            self.system, 1, self.mav.CMD_DO_SET_MODE, 0, 1, *main_sub, 0, 0, 0, 0
        )


def _land(uri: str, v: _Vehicle, deadline: float) -> Outcome:
    while v.system is None:
        if time.monotonic() > deadline:
            raise LinkError(f"{uri}: no heartbeat from the vehicle")
        v.poll()
    offboard, land, main_sub = v.modes()
    if not v.armed:
        return Outcome(False, f"{uri}: the vehicle is disarmed; nothing to do")
    if v.mode == land:
        return Outcome(False, f"{uri}: the vehicle is landing already; nothing to do")
    if v.mode != offboard:
        return Outcome(
            False,
            f"{uri}: armed in custom mode {v.mode}, not perchd's offboard "
            "mode: left to the pilot and the autopilot's own failsafe",
        )
    sent = 0.0
    while v.mode != land:
        now = time.monotonic()
        if now > deadline:
            why = "acknowledged" if v.accepted else "not acknowledged"
            raise LinkError(f"{uri}: LAND {why}, no heartbeat in LAND mode before the deadline")
        if now - sent >= v.mav.LAND_RETRY_S:  # UDP: a lost command would leave it hovering
            sent = now
            v.command_land(main_sub)
        v.poll()
    return Outcome(
        True,
        f"{uri}: LAND commanded from perchd's offboard mode; the vehicle "
        f"took it (custom mode {land})",
    )


# --- Crazyflie ------------------------------------------------------------------------------
def keeper_pids(link_uri: str) -> list[int]:
    """Live link keepers holding `link_uri`, found by command line (`python -m
    perchd.drivers.cflink FD LINK_URI REPEAT_S`, drivers/crazyflie.py); a zombie has none."""
    pids = []
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            argv = Path(entry.path, "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue  # gone meanwhile, or not ours to read
        args = [a.decode(errors="replace") for a in argv if a]
        if KEEPER_MODULE in args and len(args) >= 2 and args[-2] == link_uri:
            pids.append(int(entry.name))
    return pids


def _crazyflie(uri: str, deadline: float) -> Outcome:
    link_uri = without_query(parse_uri(uri))
    pids = keeper_pids(link_uri)
    if pids:
        return Outcome(
            False,
            f"{uri}: the link keeper (pid {', '.join(map(str, pids))}) "
            "still holds the link and flies its own descent and stop; "
            "nothing to do",
        )
    require("cflib", "crazyflie")
    sent = _send_stops(link_uri, deadline)
    return Outcome(True, f"{uri}: no link keeper left; stop setpoint sent {sent} times")


def _send_stops(link_uri: str, deadline: float) -> int:
    import cflib.crtp
    from cflib.crazyflie.commander import Commander

    from perchd.drivers.cflink import _LinkPort

    errors: list[str] = []
    cflib.crtp.init_drivers()
    try:
        link = cflib.crtp.get_link_driver(link_uri, None, errors.append)
    except Exception as err:  # noqa: BLE001 - cflib raises bare Exceptions (no dongle, busy)
        raise LinkError(f"{link_uri}: cannot open the link: {err}") from None
    if link is None:
        raise LinkError(f"{link_uri}: cflib has no link driver for it")
    commander, sent = Commander(_LinkPort(link)), 0
    try:
        while sent < STOP_REPEATS and time.monotonic() < deadline and not errors:
            commander.send_stop_setpoint()
            sent += 1
            time.sleep(PERIOD_S)
    finally:
        _close_soon(link.close)
    if errors or not sent:
        raise LinkError(
            f"{link_uri}: "
            + (errors[0].strip().splitlines()[0] if errors else "no time left to send the stop")
        )
    return sent


def _close_soon(close: Callable[[], None], wait_s: float = 0.3) -> None:
    """cflib's close may wait a second for its receive thread: the stop is out already."""
    closer = threading.Thread(target=close, daemon=True)
    closer.start()
    closer.join(wait_s)


ACTIONS: dict[str, Callable[[str, float], Outcome]] = {
    "sim": _in_process,
    "zmq": _zmq,
    "mavlink": _mavlink,
    "radio": _crazyflie,
    "udp": _crazyflie,
}
