"""ArduCopter SITL in the loop: ArduPilot's own physics, its truth published as mocap.

SITL runs headless in a fresh temporary directory (it writes eeprom.bin, logs/ and
terrain/ into its cwd) with two MAVLink serials, both UDP clients on loopback (a TCP
serial would listen on 0.0.0.0 and block the start until a client connects):
  - SERIAL0 -> the harness: SIM_STATE (the simulator's true state) at truth_hz, status,
    parameters. perchd never sees this link.
  - SERIAL1 -> perchd's MAVLink driver (`mavlink:udpin:127.0.0.1:PORT`), its own link.
Start-up runs at boot_speedup until the vehicle is armable (the EKF needs ~42 s of sim
time before it uses GPS), then SIM_SPEEDUP goes back to 1: perchd flies in real time.

The world frame is perchd's (docs/architecture.md: Z up, metres): NED about the first
true position, rotated into NWU (default) or ENU, plus `start`. NWU is the frame
perchd's MAVLink driver assumes (drivers/mavlink/setpoints.py: rotating by pi about X maps perchd's
world onto NED, so yaw zero = north = world X); in ENU yaw zero would face world Y.
"""

from __future__ import annotations

import math
import shutil
import socket
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from perchd.core.clock import Clock, MonotonicClock
from perchd.core.errors import LinkError, UriError
from perchd.core.ned import world_quat, world_vec
from perchd.core.types import Vec3
from perchd.drivers.mavlink.link import (
    CMD_SET_MESSAGE_INTERVAL,
    MAV_PARAM_TYPE_REAL32,
    Connection,
    wait_for,
)
from perchd.sim.firmware.harness import (
    FirmwareVehicle,
    Interrupted,
    ProcessGroup,
    Truth,
    contact_json,
    default_log,
)
from perchd.sim.world import Contact

DEG7_M = 0.011131884502145034
"""[m] per 1e-7 degree of latitude (ArduPilot's LOCATION_SCALING_FACTOR)."""
SIM_STATE_ID, SYS_STATUS_ID, SYSTEM_TIME_ID = 108, 1, 2
VISION_BOOT_S = 40.0
"""[s] of simulated time after boot before a vision=True vehicle is ready: without GPS
nothing else says when the inertial checks settle ("Accels inconsistent" for ~30 s), and
the GPS start is ready at about this time too (docs/firmware.md)."""
STATUS_HZ = 2.0
"""[Hz] SYS_STATUS (its pre-arm health bit): SITL streams nothing on a bare serial."""
SITL_TARGET = (1, 1)  # ArduCopter SITL's system and component
ASK_S = 0.5
"""[s] a request awaited during start-up (a parameter, a message rate) is sent this often."""
RECEIVE_S = 0.05
"""[s] the receiving thread's longest block: how soon it sees close()."""
PREARM_BIT = 0x10000000
"""MAV_SYS_STATUS_PREARM_CHECK: SYS_STATUS health bit set when the pre-arm checks pass."""
EKF_GPS_TEXT = "is using GPS"
"""STATUSTEXT once EKF3 fuses GPS (ArduCopter 4.8-dev): from then on it can arm."""
FRAMES = ("nwu", "enu")
COPTER_MODES = {
    0: "STABILIZE",
    2: "ALT_HOLD",
    3: "AUTO",
    4: "GUIDED",
    5: "LOITER",
    6: "RTL",
    9: "LAND",
    17: "BRAKE",
    20: "GUIDED_NOGPS",
}
DEFAULT_PARAMS = (
    ("GUID_OPTIONS", 8.0),
    ("GUID_TIMEOUT", 0.5),
    ("FS_GCS_ENABLE", 5.0),
    ("FS_GCS_TIMEOUT", 2.0),
    ("ATC_ANGLE_BOOST", 0.0),
)
"""What perchd's driver checks (drivers/mavlink/ardupilot.py): GUID_OPTIONS bit 3 (thrust is thrust,
not a climb rate), the failsafe that levels and lands a dead agent's vehicle (docs/safety.md),
no second tilt compensation. stock_params leaves all but GUID_OPTIONS at copter.parm's."""
VISION_BOOT_PARAMS = (
    ("VISO_TYPE", 1.0),
    ("GPS1_TYPE", 0.0),
    ("EK3_SRC1_POSXY", 6.0),
    ("EK3_SRC1_VELXY", 0.0),
    ("EK3_SRC1_POSZ", 6.0),
    ("EK3_SRC1_VELZ", 0.0),
    ("EK3_SRC1_YAW", 6.0),
)
"""vision=True: no GPS, the EKF on perchd's mocap (drivers/mavlink/vision.py); in a defaults file
read at boot, as VISO_TYPE takes effect only then."""


# -- truth conversion (pure; the frames are perchd.core.ned) ---------------------
@dataclass(frozen=True, slots=True)
class GeoOrigin:
    """lat_e7, lon_e7 [1e-7 deg] and alt_m [m AMSL] of world position `start`."""

    lat_e7: int
    lon_e7: int
    alt_m: float


def ned_offset(lat_e7: int, lon_e7: int, alt_m: float, origin: GeoOrigin) -> Vec3:
    """[m] north, east, down of a position from the origin (ArduPilot's flat-earth
    Location::get_distance_NED: exact to mm over the few metres of a perch)."""
    north = (lat_e7 - origin.lat_e7) * DEG7_M
    east = (lon_e7 - origin.lon_e7) * DEG7_M * math.cos(math.radians(origin.lat_e7 * 1e-7))
    return (north, east, -(alt_m - origin.alt_m))


@dataclass(frozen=True, slots=True)
class SimState:
    """The fields of one SIM_STATE used: q (w, x, y, z) FRD -> NED; lat_e7, lon_e7
    [1e-7 deg] (lat_int/lon_int: the float lat/lon lose ~0.3 m); alt_m [m AMSL, 1 cm
    steps]; v_ned [m/s]; gyro [rad/s] body FRD."""

    q: tuple[float, float, float, float]
    lat_e7: int
    lon_e7: int
    alt_m: float
    v_ned: Vec3
    gyro: Vec3

    @classmethod
    def from_msg(cls, m: Any) -> SimState:
        lat = getattr(m, "lat_int", 0) or int(round(m.lat))  # MAVLink1 lacks the extension
        lon = getattr(m, "lon_int", 0) or int(round(m.lon))
        return cls(
            (m.q1, m.q2, m.q3, m.q4),
            int(lat),
            int(lon),
            float(m.alt),
            (m.vn, m.ve, m.vd),
            (m.xgyro, m.ygyro, m.zgyro),
        )


class TruthFilter:
    """SIM_STATE's position is quantised (1.1 cm lat/lon, 1 cm alt) and its velocity is
    not: integrate the velocity, pulled towards the position with time constant tau_s, so
    the mocap is smooth to sub-cm (the estimator expects mm noise: flight/config.py)."""

    def __init__(self, origin: GeoOrigin, start: Vec3, frame: str, tau_s: float = 0.5) -> None:
        self.origin, self.start, self.frame, self.tau_s = origin, start, frame, tau_s
        self._p: list[float] | None = None
        self._t: float | None = None

    def update(self, t: float, s: SimState) -> Truth:
        ned = ned_offset(s.lat_e7, s.lon_e7, s.alt_m, self.origin)
        meas = [a + b for a, b in zip(self.start, world_vec(ned, self.frame))]
        v = world_vec(s.v_ned, self.frame)
        if self._p is None or self._t is None or not 0.0 < t - self._t < 1.0:
            self._p = meas
        else:
            dt = t - self._t
            k = min(1.0, dt / self.tau_s)
            self._p = [p + vi * dt + k * (m - p - vi * dt) for p, vi, m in zip(self._p, v, meas)]
        self._t = t
        gx, gy, gz = s.gyro
        return Truth(
            t,
            tuple(self._p),
            v,
            world_quat(s.q, self.frame),  # type: ignore[arg-type]
            (gx, -gy, -gz),
        )


# -- options ---------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Home:
    """lat, lon [deg], alt [m AMSL], heading [deg]: SITL's --home. Heading 0: the vehicle
    starts facing north = world X in NWU, the yaw perchd flies (0)."""

    lat: float = -35.363261
    lon: float = 149.165230
    alt: float = 584.0
    heading: float = 0.0

    def arg(self) -> str:
        return f"{self.lat:.7f},{self.lon:.7f},{self.alt:g},{self.heading:g}"


@dataclass(frozen=True, slots=True)
class ArduPilotParams:
    """binary: arducopter; defaults: the .parm file (None: found from the binary's source
    tree); model: SITL frame ("quad" = '+', as copter.parm's FRAME_TYPE=0); start [m] world
    position of the vehicle at start; frame: "nwu" | "enu"; surface (point, normal) of
    the virtual surface whose crossing is recorded as contact (SITL has no wall);
    truth_hz [Hz] SIM_STATE rate asked for; boot_speedup: SIM_SPEEDUP until ready;
    ready_timeout_s [s] wall; params: (NAME, value) set once booted; workdir: SITL's cwd
    (None: a fresh temporary one, removed on close); log: its stdout; instance: SITL's -I N
    (its own ports move by 10 N; the harness's links are free ports anyway); vision: GPS off
    and the EKF on the mocap the driver forwards (VISION_BOOT_PARAMS), ready without a
    position (arming then waits for perchd's mocap), the driver URI without vision=0."""

    binary: str
    defaults: str | None = None
    model: str = "quad"
    home: Home = Home()
    start: Vec3 = (-4.5, 0.0, 0.0)
    frame: str = "nwu"
    surface: tuple[Vec3, Vec3] | None = ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    truth_hz: float = 100.0
    boot_speedup: float = 10.0
    ready_timeout_s: float = 120.0
    params: tuple[tuple[str, float], ...] = DEFAULT_PARAMS
    workdir: str | None = None
    log: Path | None = None
    instance: int = 0
    vision: bool = False

    def __post_init__(self) -> None:
        if not 0 <= self.instance <= 9:
            raise UriError(f"ArduPilot instance {self.instance} is outside 0..9")
        if self.frame not in FRAMES:
            raise UriError(f"frame {self.frame!r} is not one of {', '.join(FRAMES)}")
        if not 1.0 <= self.truth_hz <= 400.0:
            raise UriError(f"truth rate {self.truth_hz:g} Hz is outside 1..400 Hz")
        if not 1.0 <= self.boot_speedup <= 50.0:
            raise UriError(f"boot speed-up {self.boot_speedup:g} is outside 1..50")


def find_defaults(binary: str) -> Path:
    """copter.parm in the source tree of a binary built in place
    (TREE/build/sitl/bin/arducopter -> TREE/Tools/autotest/default_params/copter.parm)."""
    exe = Path(binary).resolve()
    for root in exe.parents:
        parm = root / "Tools" / "autotest" / "default_params" / "copter.parm"
        if parm.is_file():
            return parm
    raise UriError(
        f"no Tools/autotest/default_params/copter.parm above {exe}: "
        f"give --defaults (docs/firmware.md)"
    )


def free_udp_port() -> int:
    """A loopback UDP port free now (the driver binds it later; a race we accept)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def sitl_argv(p: ArduPilotParams, defaults: str, harness_port: int, driver_port: int) -> list[str]:
    """SITL's command line: loopback UDP serials only (docs/firmware.md); defaults: one
    .parm file or several, comma-separated."""
    return [
        p.binary,
        "--model",
        p.model,
        "--speedup",
        f"{p.boot_speedup:g}",
        f"-I{p.instance}",
        "-w",
        "--defaults",
        defaults,
        "--home",
        p.home.arg(),
        "--serial0",
        f"udpclient:127.0.0.1:{harness_port}",
        "--serial1",
        f"udpclient:127.0.0.1:{driver_port}",
        "--serial2",
        "none:",  # else SERIAL2 listens on TCP 0.0.0.0:5763
        "--rc-in-port",
        str(free_udp_port()),
    ]  # not 5501: two harnesses can run


def in_dir(workdir: Path, argv: list[str]) -> list[str]:
    """argv run in workdir through coreutils' `env -C` (it execs: the pid is SITL's)."""
    return ["env", "-C", str(workdir), *argv]


def driver_uri_for(port: int, vision: bool = False) -> str:
    """perchd's driver listens where SERIAL1 sends; arm=1: nobody else arms it; vision=0
    unless the EKF is set up for mocap (with GPS it flies on its own position)."""
    return f"mavlink:udpin:127.0.0.1:{port}?arm=1" + ("" if vision else "&vision=0")


def boot_parm(workdir: Path, params: tuple[tuple[str, float], ...]) -> Path:
    """A defaults file SITL reads after copter.parm (later files win)."""
    path = workdir / "perchd-boot.parm"
    path.write_text("".join(f"{name} {value:g}\n" for name, value in params))
    return path


def crossing(surface: tuple[Vec3, Vec3], before: Truth, now: Truth) -> Contact | None:
    """Contact when the vehicle passed the surface plane between two truths."""
    point, normal = surface
    n = math.sqrt(sum(c * c for c in normal))
    gap = lambda p: sum((p[i] - point[i]) * normal[i] for i in range(3)) / n  # noqa: E731
    if gap(before.p) < 0.0 <= gap(now.p):
        return Contact(now.t, sum(now.v[i] * normal[i] for i in range(3)) / n, now.p)
    return None


# -- the vehicle -----------------------------------------------------------------------
@dataclass
class LinkState:
    """What the harness's own link has heard (written by its receive thread)."""

    mode: int | None = None
    armed: bool = False
    prearm_ok: bool = False
    ekf_gps: bool = False
    params: dict[str, float] = field(default_factory=dict)
    texts: list[tuple[float, str]] = field(default_factory=list)
    modes: list[tuple[float, str, bool]] = field(default_factory=list)
    sim_states: int = 0
    boot_s: float = 0.0  # [s] the autopilot's time since boot (SYSTEM_TIME)
    first_sim_t: float | None = None
    last_sim_t: float | None = None


class ArduPilotVehicle(FirmwareVehicle):
    name = "arducopter"

    def __init__(self, params: ArduPilotParams, clock: Clock | None = None) -> None:
        self.params = params
        self.clock = clock or MonotonicClock()
        self.defaults = Path(params.defaults) if params.defaults else find_defaults(params.binary)
        if not self.defaults.is_file():
            raise UriError(f"--defaults {self.defaults}: no such file")
        self.log = params.log or default_log("arducopter")
        self.state = LinkState()
        self._own_dir = params.workdir is None
        self.workdir = Path(params.workdir or tempfile.mkdtemp(prefix="perchd-sitl-"))
        self._truth: Truth | None = None
        self._contact: Contact | None = None
        self._filter: TruthFilter | None = None
        self._halt = threading.Event()
        self._lock = threading.Lock()
        self._t0 = self.clock.now()
        self.driver_port = free_udp_port()
        self._link = self._open_link()
        self._thread = threading.Thread(target=self._receive_loop, name="sitl-link", daemon=True)
        self._thread.start()

    def _open_link(self) -> Connection:
        from perchd.core.extras import require

        require("pymavlink", "mavlink")
        from pymavlink import mavutil

        conn = mavutil.mavlink_connection(
            "udpin:127.0.0.1:0", source_system=250, source_component=190
        )
        self.harness_port = conn.port.getsockname()[1]
        return Connection(conn)

    # -- FirmwareVehicle ----------------------------------------------------------------
    def start(self, procs: ProcessGroup, cancel: threading.Event) -> None:
        defaults = str(self.defaults)
        if self.params.vision:
            defaults += "," + str(boot_parm(self.workdir, VISION_BOOT_PARAMS))
        argv = sitl_argv(self.params, defaults, self.harness_port, self.driver_port)
        self.proc = procs.launch(in_dir(self.workdir, argv), self.log)
        deadline = time.monotonic() + self.params.ready_timeout_s
        self._wait(
            ("SIM_STATE",),
            lambda: self.state.sim_states > 0,
            "SIM_STATE",
            deadline,
            cancel,
            ask=self._ask_truth,
        )
        for name, value in self.params.params:
            self._set_param(name, value, deadline, cancel)
        if self.params.vision:  # no position before perchd's mocap: no pre-arm pass either
            self._wait(
                ("SYSTEM_TIME",),
                lambda: self.state.boot_s >= VISION_BOOT_S,
                f"{VISION_BOOT_S:g} s since boot",
                deadline,
                cancel,
            )
        else:
            self._wait(
                ("STATUSTEXT", "SYS_STATUS"),
                lambda: self.state.ekf_gps and self.state.prearm_ok,
                "the EKF to use GPS and the pre-arm checks to pass",
                deadline,
                cancel,
            )
        self._set_param("SIM_SPEEDUP", 1.0, deadline, cancel)
        self._ask_truth()  # the rate is per wall second: ask again at speed-up 1
        self.state.sim_states, self.state.first_sim_t = 0, None  # the summary's rate: at 1x

    def truth(self) -> Truth | None:
        return self._truth

    def driver_uri(self) -> str:
        return driver_uri_for(self.driver_port, self.params.vision)

    def contact(self) -> Contact | None:
        return self._contact

    def summary(self) -> dict[str, Any]:
        s = self.state
        span = (s.last_sim_t or 0.0) - (s.first_sim_t or 0.0)
        return {
            "contact": contact_json(self._contact, self._t0),
            "truth": {
                "sim_states": s.sim_states,
                "rate_hz": (s.sim_states - 1) / span if span > 0 else None,
            },
            "mode": COPTER_MODES.get(s.mode, str(s.mode)) if s.mode is not None else None,
            "armed": s.armed,
            "modes": [{"t": t - self._t0, "mode": m, "armed": a} for t, m, a in s.modes],
            "texts": [{"t": t - self._t0, "text": x} for t, x in s.texts[-40:]],
            "t0": self._t0,  # [s] the harness clock (monotonic) the t above count from
            "workdir": str(self.workdir),
            "log": str(self.log),
            "defaults": str(self.defaults),
        }

    def close(self) -> None:
        self._halt.set()
        self._thread.join(timeout=1.0)
        self._link.close()
        if self._own_dir:
            shutil.rmtree(self.workdir, ignore_errors=True)

    # -- start-up ------------------------------------------------------------------------
    def _wait(
        self,
        types: tuple[str, ...],
        done: Callable[[], bool],
        what: str,
        deadline: float,
        cancel: threading.Event,
        ask: Callable[[], None] | None = None,
    ) -> None:
        """Until done(), checked on each message of `types`; ask() every ASK_S meanwhile;
        LinkError past `deadline` (time.monotonic()) or when arducopter exits."""

        def idle() -> None:
            if cancel.is_set():
                raise Interrupted()
            if self.proc.poll() is not None:
                raise LinkError(
                    f"arducopter exited ({self.proc.returncode}) while waiting "
                    f"for {what}; see {self.log}"
                )

        clock = MonotonicClock()
        if (
            not done()
            and wait_for(
                self._link,
                types,
                lambda _msg: done(),
                deadline - clock.now(),
                clock,
                ask=ask,
                ask_every_s=ASK_S,
                idle=idle,
            )
            is None
        ):
            raise LinkError(
                f"arducopter: no {what} within {self.params.ready_timeout_s:g} s; see {self.log}"
            )

    def _ask_truth(self) -> None:
        for msg_id, hz in (
            (SIM_STATE_ID, self.params.truth_hz),
            (SYS_STATUS_ID, STATUS_HZ),
            (SYSTEM_TIME_ID, STATUS_HZ),
        ):
            self._link.command(SITL_TARGET, CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)

    def _set_param(self, name: str, value: float, deadline: float, cancel: threading.Event) -> None:
        def send() -> None:
            self._link.send(
                self._link.mav.param_set_encode(
                    *SITL_TARGET, name.encode(), value, MAV_PARAM_TYPE_REAL32
                )
            )

        self.state.params.pop(name, None)
        self._wait(
            ("PARAM_VALUE",),
            lambda: self.state.params.get(name) == value,
            f"{name}={value:g}",
            deadline,
            cancel,
            ask=send,
        )

    # -- receiving -----------------------------------------------------------------------
    def _receive_loop(self) -> None:
        while not self._halt.is_set():
            try:
                self._link.pump(RECEIVE_S, self._on_message)
            except (OSError, ValueError):
                return  # closed under us

    def _on_message(self, msg: Any) -> None:
        kind, s, now = msg.get_type(), self.state, self.clock.now()
        if kind == "SIM_STATE":
            self._on_sim_state(now, SimState.from_msg(msg))
        elif kind == "HEARTBEAT" and msg.autopilot == 3:
            armed = bool(msg.base_mode & 128)
            if (msg.custom_mode, armed) != (s.mode, s.armed):
                s.modes.append(
                    (now, COPTER_MODES.get(msg.custom_mode, str(msg.custom_mode)), armed)
                )
            s.mode, s.armed = msg.custom_mode, armed
        elif kind == "SYSTEM_TIME":
            s.boot_s = msg.time_boot_ms * 1e-3
        elif kind == "SYS_STATUS":
            s.prearm_ok = bool(msg.onboard_control_sensors_health & PREARM_BIT)
        elif kind == "STATUSTEXT":
            s.texts.append((now, msg.text))
            s.ekf_gps = s.ekf_gps or EKF_GPS_TEXT in msg.text
        elif kind == "PARAM_VALUE":
            s.params[msg.param_id] = float(msg.param_value)

    def _on_sim_state(self, now: float, sim: SimState) -> None:
        s = self.state
        s.sim_states += 1
        s.first_sim_t = s.first_sim_t if s.first_sim_t is not None else now
        s.last_sim_t = now
        if self._filter is None:
            origin = GeoOrigin(sim.lat_e7, sim.lon_e7, sim.alt_m)
            self._filter = TruthFilter(origin, self.params.start, self.params.frame)
        before, self._truth = self._truth, self._filter.update(now, sim)
        surface = self.params.surface
        if surface is not None and before is not None and self._contact is None:
            self._contact = crossing(surface, before, self._truth)
