"""PX4 SITL with its own physics (SIH), headless, on loopback: a FirmwareVehicle.

PX4's simulator-in-hardware model flies inside the px4 process, so there is no physics
here: the harness starts `bin/px4 -d -i N -w TMPDIR BUILD/etc` (airframe sihsim_quadx) in a
fresh temporary working directory, asks SIH's display link (UDP 19410+N) for ground truth
(HIL_STATE_QUATERNION) at the mocap rate, takes off to PX4's own Hold, and from then on
converts every truth sample into perchd's world frame (ENU, Z up, metres, origin on the
ground where the vehicle started; truth_from_hil). perchd flies it over PX4's offboard link,
`mavlink:udpin:127.0.0.1:14540+N` (docs/firmware.md, "PX4 SIH").

PX4 is not part of perchd: the build folder is the user's (docs/firmware.md names the
version the tests were run with).
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from perchd.core.clock import Clock, MonotonicClock
from perchd.core.errors import LinkError, UriError
from perchd.core.extras import require
from perchd.core.ned import rotate, world_quat, world_vec
from perchd.core.types import Quat, Vec3
from perchd.core.vehicle import G_M_S2
from perchd.drivers.mavlink.link import Connection, wait_for
from perchd.flight.frame import body_z
from perchd.sim.firmware.cf2 import Surface
from perchd.sim.firmware.harness import (
    FirmwareVehicle,
    Interrupted,
    ProcessGroup,
    Truth,
    contact_json,
    default_log,
    fine_timer_slack,
    yaw_of,
)
from perchd.sim.world import Contact

EARTH_RADIUS_M = 6371000.0
"""[m] the radius PX4's map projection uses (CONSTANTS_RADIUS_OF_EARTH)."""
SIH_MASS_KG = 1.0
"""[kg] SIH_MASS of airframe 10040 (sihsim_quadx)."""
SIH_HOVER = SIH_MASS_KG * 9.81 / (4 * 5.0)
"""Normalised hover thrust: SIH's thrust is linear in the motor command, 4 rotors of
SIH_T_MAX = 5 N each (the driver's hover=, instead of MPC_THR_HOVER's 0.5)."""
OFFBOARD_PORT, DISPLAY_PORT = 14540, 19410
"""PX4 sends to these + instance: the offboard API link, SIH's display link (truth)."""
SAFE_PARAMS = {"COM_OF_LOSS_T": "0.3", "COM_OBL_RC_ACT": "4", "SDLOG_BACKEND": "0"}
"""Set at boot (PX4_PARAM_*): perchd's failsafe values (docs/safety.md), and no .ulg logs."""
VISION_PARAMS = {
    "EKF2_EV_CTRL": "11",
    "EKF2_HGT_REF": "3",
    "EKF2_GPS_CTRL": "0",
    "EKF2_EVP_NOISE": "0.01",
    "EKF2_EVA_NOISE": "0.02",
    "EKF2_BARO_CTRL": "0",
}
"""vision: EKF2 on the mocap perchd's driver forwards (position and yaw, vision height),
GPS off (drivers/mavlink/px4.py checks the first two); the noise floors down to the mocap's
(drivers/mavlink/vision.py: EKF2 takes the larger of its floor, 0.1 m and 0.1 rad by default,
and the covariance sent)."""
REFINE_GAIN = 0.02
"""Share of the gap to the quantised fix a refined truth position takes up per sample: ~50
samples (0.5 s at 100 Hz) average out the steps of HIL_STATE_QUATERNION's lat/lon. At 0.05
the fix's steps came through as speed: sd 0.005, up to 0.03 m/s in perchd's estimate on
synthetic SIH truth, against 0.002 and 0.019 now (docs/firmware.md, "PX4 SIH")."""
REFINE_MAX_DT_S = 0.02
"""[s] longest interval the truth velocity is integrated over: longer gaps are px4 held up
(lockstep: its vehicle froze with it), not flight."""
PUSH_WINDOW_S, PUSH_KEEP = 0.5, 100
"""[s] the summary's attitude_push_mps2 averages this long before contact (stage 2), of the
last PUSH_KEEP ATTITUDE messages (2 s at 50 Hz)."""
RECEIVE_S = 0.05
"""[s] the receiving thread's longest block: how soon it sees close()."""
RESEND_AFTER_S = 0.025
"""[s] a truth sample older than this is sent again stamped now (Px4Vehicle.truth)."""
HOLD, OFFBOARD = (4, 3), (6, 0)  # PX4 (main, sub) modes
BOOT_TIMEOUT_S, TAKEOFF_TIMEOUT_S, TURN_TIMEOUT_S = 30.0, 40.0, 30.0
TURN_TOL_RAD, TURN_STEADY_S = math.radians(2.0), 1.0
"""The turn in Hold is done once PX4's heading estimate has stayed this close to the heading
asked for this long (PX4 steers its estimate, not the truth: docs/firmware.md, "PX4 SIH")."""


@dataclass(frozen=True, slots=True)
class Px4Params:
    """build: PX4's build folder (bin/px4, etc/); instance N moves every port by N and
    makes MAV_SYS_ID N+1; takeoff: climb to MIS_TAKEOFF_ALT (2.5 m) and hold before ready;
    surface_ahead_m [m]: the surface is put this far ahead of the hover point along the
    heading (None: no surface); stock_params: leave PX4's failsafe defaults (to try the
    driver's refusal or ?configure=1); extra_params: more PX4 parameters set at boot, e.g.
    (("SIH_KDV", "0.1"),) (SIH's linear drag, 1.0 N/(m/s) by default); vision: GPS off and
    EKF2 on the mocap perchd's driver forwards (VISION_PARAMS; no take-off then: without
    mocap it has no position); heading_deg [deg]: the compass heading (NED: from north
    towards east) PX4 turns to in Hold after its take-off, before ready (None: the
    take-off's, north on SIH); sim_speed: SIH's PX4_SIM_SPEED_FACTOR, above 1 to make up
    for its lockstep loop falling behind the wall clock on a loaded machine (the summary's
    sim_clock_rate says how far it did); log: PX4's console output."""

    build: str
    instance: int = 0
    takeoff: bool = True
    surface_ahead_m: float | None = 4.5
    stock_params: bool = False
    extra_params: tuple[tuple[str, str], ...] = ()
    log: Path | None = None
    vision: bool = False
    heading_deg: float | None = None
    sim_speed: float = 1.0


def enu_from_geodetic(
    lat_deg: float, lon_deg: float, alt_m: float, origin: tuple[float, float, float]
) -> Vec3:
    """[m] east, north, up of a point from the origin (lat [deg], lon [deg], alt [m]):
    equirectangular, exact to well under a millimetre over a room."""
    lat0, lon0, alt0 = origin
    north = math.radians(lat_deg - lat0) * EARTH_RADIUS_M
    east = math.radians(lon_deg - lon0) * EARTH_RADIUS_M * math.cos(math.radians(lat0))
    return (east, north, alt_m - alt0)


def enu_quat(q_ned_wxyz: tuple[float, float, float, float]) -> Quat:
    """PX4's body FRD -> NED attitude (w, x, y, z) as perchd's body FLU -> ENU (x, y, z, w)."""
    return world_quat(q_ned_wxyz, "enu")


def truth_from_hil(msg: Any, t: float, origin: tuple[float, float, float]) -> Truth:
    """HIL_STATE_QUATERNION (lat/lon 1e-7 deg, alt mm AMSL, NED velocity cm/s, FRD rates)
    -> Truth in perchd's world: ENU from `origin`, Z up, metres; t [s] of receipt
    (PX4 sends time_usec = 0)."""
    p = enu_from_geodetic(msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3, origin)
    v = (cm_s(msg.vy), cm_s(msg.vx), -cm_s(msg.vz))
    w = (msg.rollspeed, -msg.pitchspeed, -msg.yawspeed)
    return Truth(t, p, v, enu_quat(tuple(msg.attitude_quaternion)), w)


def cm_s(c: int) -> float:
    """[m/s] a HIL_STATE_QUATERNION velocity component: PX4 casts m/s x 100 to an integer,
    which truncates towards zero, so a count c stands for [c, c + 1) cm/s away from zero;
    the centre of that step, 0 for 0 (docs/firmware.md, "PX4 SIH")."""
    return 0.01 * (c + 0.5 * ((c > 0) - (c < 0)))


class PositionRefiner:
    """SIH's truth position at mocap resolution. HIL_STATE_QUATERNION gives lat/lon in
    1e-7 deg: steps of 1.1 cm north and ~0.75 cm east, i.e. +-1 m/s between two samples
    10 ms apart, which perchd's estimator (trusting millimetre mocap) turns into +-0.1 m/s of
    speed noise. Its truth velocity (1 cm/s steps) is integrated between samples and pulled
    towards the fix by REFINE_GAIN per sample (docs/firmware.md, "PX4 SIH")."""

    def __init__(self, gain: float = REFINE_GAIN, max_dt_s: float = REFINE_MAX_DT_S) -> None:
        self.gain, self.max_dt_s = gain, max_dt_s
        self._last: Truth | None = None

    def update(self, truth: Truth) -> Truth:
        last = self._last
        if last is not None:
            dt = min(max(0.0, truth.t - last.t), self.max_dt_s)
            pred = [last.p[i] + dt * 0.5 * (last.v[i] + truth.v[i]) for i in range(3)]
            p = tuple(pred[i] + self.gain * (truth.p[i] - pred[i]) for i in range(3))
            truth = replace(truth, p=p)
        self._last = truth
        return truth


def surface_ahead(p: Vec3, yaw: float, distance_m: float) -> Surface:
    """A wall `distance_m` ahead of p along the horizontal heading yaw [rad, ENU]."""
    n = (math.cos(yaw), math.sin(yaw), 0.0)
    return Surface(tuple(p[i] + distance_m * n[i] for i in range(3)), n)  # type: ignore[arg-type]


def px4_mode(custom_mode: int) -> tuple[int, int]:
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


class Px4Vehicle(FirmwareVehicle):
    name = "px4"

    def __init__(self, params: Px4Params, clock: Clock | None = None) -> None:
        self.params = params
        self.clock = clock or MonotonicClock()
        build = Path(params.build)
        self.binary, self.etc = build / "bin" / "px4", build / "etc"
        if not (os.access(self.binary, os.X_OK) and self.etc.is_dir()):
            raise UriError(f"{build}: not a PX4 SITL build folder (needs bin/px4 and etc/)")
        if not 0 <= params.instance <= 9:
            raise UriError(f"PX4 instance {params.instance} is outside 0..9")
        self.log = params.log or default_log("px4")
        self.workdir: Path | None = None
        self.surface: Surface | None = None
        self.start_heading: float | None = None  # [rad] ENU yaw when ready
        self._link: Connection | None = None
        self._truth: Truth | None = None
        self._refiner = PositionRefiner()
        self._origin: tuple[float, float, float] | None = None
        self._mode: tuple[int, int] | None = None
        self._armed = False
        self._contact: Contact | None = None
        self._modes_seen: list[str] = []
        self._samples = 0
        self._truth_acked = False  # PX4 took the 100 Hz truth rate (25 Hz before)
        self._heading_errors: list[tuple[float, float]] = []  # (t [s], EKF - true [rad])
        self._ekf_heading: float | None = None  # [rad] NED, PX4's estimate (ATTITUDE)
        # (arrival [s], PX4's time [s]) of the first ATTITUDE since ready and of the last
        self._clock_span: tuple[tuple[float, float], tuple[float, float]] | None = None
        # (t [s], attitude push [m/s^2]) up to contact, PUSH_KEEP of them
        self._pushes: deque[tuple[float, float]] = deque(maxlen=PUSH_KEEP)
        self._ready_t: float | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._proc: Any = None

    # -- FirmwareVehicle ---------------------------------------------------------------
    def start(self, procs: ProcessGroup, cancel: threading.Event) -> None:
        require("pymavlink", "mavlink")
        from pymavlink import mavutil

        self.workdir = Path(tempfile.mkdtemp(prefix="perchd-px4-"))
        port = DISPLAY_PORT + self.params.instance
        self._link = Connection(
            mavutil.mavlink_connection(
                f"udpin:127.0.0.1:{port}", source_system=246, source_component=190
            )
        )
        self._launch(procs)
        self._thread = threading.Thread(target=self._receive, name="px4-truth", daemon=True)
        self._thread.start()
        self._wait(
            ("HIL_STATE_QUATERNION", "COMMAND_ACK"),
            lambda: self._origin is not None and self._truth_acked,
            BOOT_TIMEOUT_S,
            cancel,
            "ground truth (HIL_STATE_QUATERNION) from PX4 SIH",
            self._ask_truth,
        )
        if self.params.takeoff:
            self._take_off(cancel)
            if self.params.heading_deg is not None:
                self._turn(math.radians(self.params.heading_deg), cancel)
        truth = self._truth
        self._ready_t = truth.t
        self.start_heading = yaw_of(truth.q)
        if self.params.surface_ahead_m is not None:
            self.surface = surface_ahead(truth.p, self.start_heading, self.params.surface_ahead_m)

    def truth(self) -> Truth | None:
        """The newest sample, stamped when it arrived (the publisher sends each once: a
        publish time would put its own jitter into the speed perchd measures). One older
        than RESEND_AFTER_S is stamped now: SIH runs in lockstep, so while px4 is held up
        (a loaded machine) its vehicle is frozen too and the last sample is still its state;
        its age would run into perchd's stale-mocap rule for nothing."""
        truth, now = self._truth, self.clock.now()
        if truth is None or now - truth.t <= RESEND_AFTER_S:
            return truth
        return replace(truth, t=now)

    def driver_uri(self) -> str:
        port = OFFBOARD_PORT + self.params.instance
        # yaw0=auto: SIH's EKF heading comes from its compass, degrees off the truth
        # vision: on the ground, nobody else arms it; else it flies on its GPS
        vision = "&arm=1" if self.params.vision else "&vision=0"
        return (
            f"mavlink:udpin:127.0.0.1:{port}?mass={SIH_MASS_KG:g}&hover={SIH_HOVER:.4f}"
            f"&yaw0=auto{vision}"
        )

    def contact(self) -> Contact | None:
        return self._contact

    def summary(self) -> dict[str, Any]:
        s = self.surface
        return {
            "firmware": "px4",
            "instance": self.params.instance,
            "log": str(self.log),
            "workdir": str(self.workdir),
            "truth_samples": self._samples,
            "start_heading_rad": self.start_heading,
            "modes": self._modes_seen,
            "heading_estimate_error_deg": self._heading_span_deg(),
            "sim_clock_rate": self.sim_clock_rate(),
            "attitude_push_mps2": self.attitude_push(),
            "surface": None if s is None else {"point": list(s.point), "normal": list(s.normal)},
            "contact": contact_json(self._contact, 0.0),
        }

    def _heading_span_deg(self) -> list[float] | None:
        """[deg] PX4's heading estimate - true heading, smallest and largest since ready."""
        span = self.heading_error_span(self._ready_t) if self._ready_t is not None else None
        return None if span is None else [round(math.degrees(e), 2) for e in span]

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        if self._link is not None:
            self._link.close()
        if self.workdir is not None:
            shutil.rmtree(self.workdir, ignore_errors=True)

    # -- start-up ----------------------------------------------------------------------
    def _launch(self, procs: ProcessGroup) -> None:
        """px4 through env(1) (it execs, so the pid is px4's): the simulator, the airframe
        and the parameters PX4's rcS applies after the airframe (PX4_PARAM_<NAME>)."""
        params = {"SDLOG_BACKEND": "0"} if self.params.stock_params else dict(SAFE_PARAMS)
        params.update(VISION_PARAMS if self.params.vision else {})
        params.update(self.params.extra_params)
        env = [
            "PX4_SIMULATOR=sihsim",
            "PX4_SIM_MODEL=sihsim_quadx",
            f"PX4_SIM_SPEED_FACTOR={self.params.sim_speed:g}",
            *(f"PX4_PARAM_{k}={v}" for k, v in params.items()),
        ]
        with fine_timer_slack():
            self._proc = procs.launch(
                [
                    "env",
                    *env,
                    str(self.binary),
                    "-d",
                    "-i",
                    str(self.params.instance),
                    "-w",
                    str(self.workdir),
                    str(self.etc),
                ],
                self.log,
            )

    def _ask_truth(self) -> None:
        """HIL_STATE_QUATERNION at 100 Hz (sim time), and the display link's
        HIL_ACTUATOR_CONTROLS (~200 Hz) off: parsing it in Python starves the publisher."""
        if self._link.conn.clients:
            self._command(511, 115, 10000)
            self._command(511, 93, -1)
            self._command(511, 30, 20000)  # ATTITUDE at 50 Hz: its attitude estimate

    def _take_off(self, cancel: threading.Event) -> None:
        """NAV_TAKEOFF then ARM (PX4's own take-off to MIS_TAKEOFF_ALT); ready once PX4
        is back in Hold above 2 m: the flight starts in the air, as a take-over does."""

        def send() -> None:
            if not self._armed:  # arming is refused until PX4's health checks pass
                nan = float("nan")
                self._command(22, 0, 0, 0, nan, nan, nan, nan)
                self._command(400, 1)

        self._wait(
            ("HIL_STATE_QUATERNION", "HEARTBEAT"),
            lambda: self._armed and self._mode == HOLD and self._truth.p[2] > 2.0,
            TAKEOFF_TIMEOUT_S,
            cancel,
            "PX4's take-off to Hold above 2 m",
            send,
            2.0,
        )

    def _turn(self, heading: float, cancel: threading.Event) -> None:
        """DO_REPOSITION in Hold with only a yaw (radians on PX4; position and height
        kept), until PX4's heading estimate has held within TURN_TOL_RAD of `heading`
        [rad, NED] for TURN_STEADY_S."""
        nan, since = float("nan"), None

        def steady() -> bool:
            nonlocal since
            est, now = self._ekf_heading, time.monotonic()
            near = est is not None and abs(math.remainder(est - heading, math.tau)) < TURN_TOL_RAD
            since = (since or now) if near else None
            return since is not None and now - since >= TURN_STEADY_S

        self._wait(
            ("ATTITUDE",),
            steady,
            TURN_TIMEOUT_S,
            cancel,
            f"PX4's turn to heading {math.degrees(heading):.0f} deg in Hold",
            lambda: self._command(192, -1, 0, 0, heading, nan, nan, nan),
            2.0,
        )

    def _command(self, command: int, *params: float) -> None:
        self._link.command((self.params.instance + 1, 1), command, *params)

    def _wait(
        self,
        types: tuple[str, ...],
        done: Callable[[], bool],
        timeout_s: float,
        cancel: threading.Event,
        what: str,
        poke: Callable[[], None] | None = None,
        every_s: float = 0.5,
    ) -> None:
        """Until done(), checked on each message of `types`; poke() every every_s [s]
        meanwhile; LinkError after timeout_s [s] or when px4 exits."""

        def idle() -> None:
            if cancel.is_set():
                raise Interrupted()
            if self._proc is not None and self._proc.poll() is not None:
                # e.g. another px4 holds this instance's lock: its ports would answer for it
                raise LinkError(
                    f"PX4 instance {self.params.instance} exited "
                    f"({self._proc.returncode}) while waiting for {what} (is "
                    f"another px4 running as instance {self.params.instance}? "
                    f"log: {self.log})"
                )

        if (
            not done()
            and wait_for(
                self._link,
                types,
                lambda _msg: done(),
                timeout_s,
                MonotonicClock(),
                ask=poke,
                ask_every_s=every_s,
                idle=idle,
            )
            is None
        ):
            raise LinkError(
                f"PX4 instance {self.params.instance}: no {what} within "
                f"{timeout_s:g} s (log: {self.log})"
            )

    # -- truth -------------------------------------------------------------------------
    def _receive(self) -> None:
        while not self._stop.is_set():
            try:
                self._link.pump(RECEIVE_S, self._on_message)
            except OSError:
                return

    def _on_message(self, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "HIL_STATE_QUATERNION":
            self._on_truth(msg)
        elif kind == "ATTITUDE" and self._truth is not None:
            self._on_attitude(msg)
        elif kind == "COMMAND_ACK" and msg.command == 511 and msg.result == 0:
            self._truth_acked = True
        elif (
            kind == "HEARTBEAT"
            and msg.get_srcSystem() == self.params.instance + 1
            and msg.get_srcComponent() == 1
        ):
            self._on_heartbeat(msg)

    def _on_truth(self, msg: Any) -> None:
        if self._origin is None:  # on the ground at boot: that is the world origin
            self._origin = (msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3)
        truth = self._refiner.update(truth_from_hil(msg, self.clock.now(), self._origin))
        previous, self._truth = self._truth, truth
        self._samples += 1
        if self._contact is None and self.surface is not None and previous is not None:
            if self.surface.gap(previous.p) < 0 <= self.surface.gap(truth.p):
                self._contact = Contact(truth.t, self.surface.speed(truth.v), truth.p)

    def _on_attitude(self, msg: Any) -> None:
        """PX4's heading estimate against the truth: SIH's EKF2 heading wanders ~10 deg
        during a flight, and PX4 steers it (docs/firmware.md, "PX4 SIH")."""
        self._ekf_heading = msg.yaw
        if self._ready_t is not None:
            pair = (self.clock.now(), msg.time_boot_ms * 1e-3)
            self._clock_span = (self._clock_span[0] if self._clock_span else pair, pair)
        if self.surface is not None and self._contact is None:
            self._pushes.append((self._truth.t, self._push(msg)))
        true_ned = math.pi / 2 - yaw_of(self._truth.q)  # ENU yaw -> NED heading
        error = math.remainder(msg.yaw - true_ned, math.tau)
        self._heading_errors = [*self._heading_errors[-600:], (self._truth.t, error)]

    def _push(self, msg: Any) -> float:
        """[m/s^2] along the surface normal, g times the true thrust direction less the one
        PX4's attitude estimate (ATTITUDE) holds: what PX4, flying its estimate, puts on
        the vehicle beyond what it was sent (docs/firmware.md, "The harness's clock, the
        heading and the ground start")."""
        est = world_vec(tuple(-c for c in body_z(msg.roll, msg.pitch, msg.yaw)), "enu")
        x, y, z, w = self._truth.q
        true = rotate((w, x, y, z), (0.0, 0.0, 1.0))
        return G_M_S2 * self.surface.speed([true[i] - est[i] for i in range(3)])

    def attitude_push(self) -> float | None:
        """[m/s^2] the mean push (_push) over the PUSH_WINDOW_S before contact; None without
        a contact or ATTITUDE then."""
        c = self._contact
        pushes = (
            []
            if c is None
            else [p for t, p in list(self._pushes) if c.t - PUSH_WINDOW_S <= t <= c.t]
        )
        return sum(pushes) / len(pushes) if pushes else None

    def sim_clock_rate(self) -> float | None:
        """PX4's seconds per wall-clock second since ready, from ATTITUDE's time_boot_ms (SIH
        runs in lockstep: its time is the simulation's) against arrival: below 1 the
        vehicle lives slower than perchd's clock, and speeds perchd measures in wall time
        are that much below SIH's own (docs/firmware.md, "PX4 SIH"). None: under 5 s."""
        span = self._clock_span
        if span is None or span[1][0] - span[0][0] < 5.0:
            return None
        (wall0, px40), (wall1, px41) = span
        return (px41 - px40) / (wall1 - wall0)

    def heading_error_span(self, since: float) -> tuple[float, float] | None:
        """[rad] smallest and largest PX4 heading estimate - true heading since `since` [s]."""
        errors = [e for t, e in self._heading_errors if t >= since]
        return (min(errors), max(errors)) if errors else None

    def _on_heartbeat(self, msg: Any) -> None:
        self._armed = bool(msg.base_mode & 128)
        mode = px4_mode(msg.custom_mode)
        if mode != self._mode:
            self._modes_seen.append(mode_name(mode))
        self._mode = mode


def mode_name(mode: tuple[int, int]) -> str:
    return {
        HOLD: "AUTO.LOITER",
        (4, 5): "AUTO.RTL",
        (4, 6): "AUTO.LAND",
        (4, 2): "AUTO.TAKEOFF",
        OFFBOARD: "OFFBOARD",
    }.get(mode, f"{mode[0]}.{mode[1]}")
