"""The simulated world: one plant, a surface that registers contact, and a mocap model.

The `sim://` driver and the `sim://` mocap source share one world through Runtime.sim
(perchd.session puts it there). The world is
lazy: it integrates the plant up to runtime.clock.now() whenever it is asked for a pose or
given a setpoint, so with a ManualClock the control loop's sleep_until drives simulated time
and a 3 s flight runs in a few hundred milliseconds of wall time.

URI options, each on the side that owns it (perchd.core.uriparams: the other side refuses
it). The driver's: latency [s] command delay, start=X,Y,Z [m], attitude_tau [s],
motor_tau [s], stall=AT,FOR [s] (perchd.sim.stall: a hung link), mass [kg] the simulated
vehicle's true mass (the flight config may disagree, as a real weight may), drag [1/s]
linear drag, qdrag [1/m] quadratic drag, draught=X,A a constant acceleration A [m/s^2]
along world X from world x = X [m] on (air off a wall). The mocap's: noise [m] std,
mocap_rate [Hz], mocap_latency [s], seed (of the noise), body.
"""

from __future__ import annotations

import heapq
import math
import random
import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace

from perchd.core.clock import Clock
from perchd.core.envelope import FAILSAFE_DESCENT_MPS, FAILSAFE_DROP_MAX_M
from perchd.core.errors import UriError
from perchd.core.ports import SourceStats
from perchd.core.runtime import Runtime
from perchd.core.types import EndReason, Phase, Pose, Setpoint, Vec3
from perchd.core.uri import Uri
from perchd.core.uriparams import SIM, check_known, check_params, float_param, names_of
from perchd.sim.faults import MocapFault, shape
from perchd.sim.plant import Plant, PlantParams, PlantState, Touch, quaternion
from perchd.sim.stall import Stall, stall_from_uri

DESCENT_GAIN_PER_S = 3.0
"""[1/s] the failsafe descent's sink-rate gain: m (g + k (v_ref - vz)) of thrust."""


@dataclass(frozen=True)
class MocapParams:
    """rate_hz [Hz]; latency_s [s] exposure to arrival; noise_m [m] Gaussian std per axis."""

    rate_hz: float = 120.0
    latency_s: float = 0.004
    noise_m: float = 0.0


@dataclass(frozen=True)
class WorldParams:
    """plant, mocap; start [m] world position, hovering there when start z > 0 (None: 4.5 m
    back from the surface point along the normal, 1 m above it);
    surface_point [m] and surface_normal (towards the surface, i.e. the approach direction);
    body: the mocap body name; seed for the noise; stall: a hung link (perchd.sim.stall)."""

    plant: PlantParams = PlantParams()
    mocap: MocapParams = MocapParams()
    start: Vec3 | None = None
    surface_point: Vec3 = (0.0, 0.0, 0.0)
    surface_normal: Vec3 = (1.0, 0.0, 0.0)
    body: str = "cf1"
    seed: int = 0
    stall: Stall | None = None


@dataclass(frozen=True, slots=True)
class Contact:
    """t [s] when the vehicle reached the surface; speed [m/s] along the normal then;
    p [m] world position of the contact."""

    t: float
    speed: float
    p: Vec3


@dataclass
class Faults:
    """Things a test can break: mocap outages [(t0, t1)] (no pose measured in between),
    link_ok (the driver's health), and `at`: (t, fn(world)) disturbances applied once when
    simulated time reaches t (a gust: fn changes plant.v; a knock: plant.att); mocap: frame
    faults (perchd.sim.faults) every measured frame passes through, in order."""

    mocap_outages: list[tuple[float, float]] = field(default_factory=list)
    link_ok: bool = True
    at: list[tuple[float, Callable[[SimWorld], None]]] = field(default_factory=list)
    mocap: list[MocapFault] = field(default_factory=list)


class SimWorld:
    def __init__(self, params: WorldParams, clock: Clock) -> None:
        self.params = params
        self.clock = clock
        sp, n = params.surface_point, params.surface_normal
        norm = math.sqrt(sum(c * c for c in n))
        self.start = params.start or (
            sp[0] - 4.5 * n[0] / norm,
            sp[1] - 4.5 * n[1] / norm,
            sp[2] + 1.0,
        )
        self.t0 = clock.now()
        self.plant = Plant(params.plant, self.start, self.t0)
        self.faults = Faults()
        if params.stall is not None:
            self.faults.at.append((self.t0 + params.stall.at_s, params.stall))
        self.contact: Contact | None = None
        self.sent: list[Setpoint] = []
        self.failsafes: list[EndReason] = []
        self._descending = False  # the failsafe descends before it cuts (failsafe)
        n = params.surface_normal
        norm = math.sqrt(sum(c * c for c in n))
        self._n: Vec3 = (n[0] / norm, n[1] / norm, n[2] / norm)
        self._rng = random.Random(params.seed)
        self._lock = threading.RLock()
        period = 1.0 / params.mocap.rate_hz
        self._period = period
        self._next_frame = 0  # index k of the next exposure at t0 + k * period
        self._in_flight: list[tuple[float, int, Pose]] = []  # heap by arrival: not arrived yet
        self._sent = 0  # tie-break of the heap
        self._latest: Pose | None = None
        self._seq = 0
        self._advanced_to: float | None = None  # [s] the last advance's time

    @property
    def pristine(self) -> bool:
        """Nothing measured, commanded or integrated yet: its parameters may still change."""
        return self._next_frame == 0 and not self.sent and self.clock.now() == self.t0

    # --- time -----------------------------------------------------------------------------
    def advance(self, t: float | None = None) -> None:
        """Integrate up to `t` (default clock.now()), measuring mocap frames on the way."""
        t = self.clock.now() if t is None else t
        with self._lock:
            if t == self._advanced_to:  # nothing to integrate, measure or deliver
                if self.faults.at:
                    self._disturb(t)
                return
            plant = self.plant
            while True:
                t_frame = self.t0 + self._next_frame * self._period
                if t_frame > t:
                    break
                plant.step_to(t_frame, self._touch())
                self._measure(t_frame)
                self._next_frame += 1
                if self._descending:  # the failsafe's descent, at the mocap's rate
                    self._descend(t_frame)
            plant.step_to(t, self._touch())
            if self._in_flight:
                self._deliver(t)
            if self.faults.at:
                self._disturb(t)
            self._advanced_to = t

    def _disturb(self, t: float) -> None:
        due = [item for item in self.faults.at if item[0] <= t]
        if due:
            self.faults.at = [item for item in self.faults.at if item[0] > t]
            for _, fn in due:
                fn(self)

    def state(self) -> PlantState:
        self.advance()
        return self.plant.state()

    def gap(self, p: Vec3) -> float:
        """[m] signed distance along the normal: < 0 before the surface."""
        sp = self.params.surface_point
        return sum((p[i] - sp[i]) * self._n[i] for i in range(3))

    def _touch(self) -> Touch | None:
        """What the plant's steps report reaching: the surface, until contact."""
        if self.contact is not None:
            return None
        return self.params.surface_point, self._n, self._check_contact

    def _check_contact(self, t_prev: float, p_prev: Vec3, t: float) -> None:
        if self.contact is not None:
            return
        g1 = self.gap(self.plant.p)
        if g1 < 0.0:
            return
        g0 = self.gap(p_prev)
        frac = -g0 / (g1 - g0) if g1 > g0 else 1.0
        speed = sum(self.plant.v[i] * self._n[i] for i in range(3))
        self.contact = Contact(t_prev + frac * (t - t_prev), speed, tuple(self.plant.p))
        self.plant.freeze()

    # --- the driver side --------------------------------------------------------------------
    @property
    def link_ok(self) -> bool:
        """The simulated radio link is up (tests cut it through faults.link_ok)."""
        return self.faults.link_ok

    @property
    def command_latency_s(self) -> float:
        """[s] from a setpoint's sending to its reaching the vehicle."""
        return self.params.plant.latency_s

    def failsafe(self, reason: EndReason) -> None:
        """The driver's failsafe: recorded, and the motors stopped; from higher than
        core.envelope.FAILSAFE_DROP_MAX_M above the ground the vehicle first descends, level,
        at FAILSAFE_DESCENT_MPS to that height (docs/safety.md "Hard envelope")."""
        with self._lock:
            self.failsafes.append(reason)
            self.advance()
            self._descending = self.plant.p[2] > FAILSAFE_DROP_MAX_M
            self._descend(self.clock.now())

    def _descend(self, t: float) -> None:
        """One step of the failsafe's descent (level, thrust on the sink rate), or the cut."""
        if not self._descending or self.plant.p[2] <= FAILSAFE_DROP_MAX_M:
            self._descending = False
            self._queue_command(Setpoint.stop(t), t)
            return
        pp = self.plant.params
        lift = pp.mass_kg * (pp.g + DESCENT_GAIN_PER_S * (-FAILSAFE_DESCENT_MPS - self.plant.v[2]))
        self._queue_command(
            Setpoint(t, 0.0, 0.0, 0.0, min(max(lift, 0.0), pp.thrust_max_n), -1, Phase.ABORT), t
        )

    def command(self, sp: Setpoint) -> None:
        with self._lock:
            self.advance()
            self._queue_command(sp, self.clock.now())

    def _queue_command(self, sp: Setpoint, t: float) -> None:
        """Sent at t [s] (the world integrated up to t already)."""
        self.sent.append(sp)
        self.plant.command(sp, t)

    def applied(self) -> Setpoint | None:
        """The newest setpoint that has reached the vehicle."""
        self.advance()
        return self.plant.applied

    # --- the mocap side ---------------------------------------------------------------------
    def _measure(self, t: float) -> None:
        faults = self.faults
        if faults.mocap_outages and any(a <= t < b for a, b in faults.mocap_outages):
            return
        mocap, (x, y, z) = self.params.mocap, self.plant.p
        noise = mocap.noise_m
        if noise > 0:
            gauss = self._rng.gauss
            p = (x + gauss(0.0, noise), y + gauss(0.0, noise), z + gauss(0.0, noise))
        else:
            p = (x + 0.0, y + 0.0, z + 0.0)
        self._seq += 1
        pose = Pose(
            self.params.body, self._seq, t, p, quaternion(*self.plant.att), True, mocap.latency_s
        )
        arrivals = (
            shape(faults.mocap, t + pose.latency, pose)
            if faults.mocap
            else ((t + pose.latency, pose),)
        )
        for arrive, out in arrivals:
            self._sent += 1
            heapq.heappush(self._in_flight, (arrive, self._sent, out))

    def _deliver(self, t: float) -> None:
        while self._in_flight and self._in_flight[0][0] <= t + 1e-12:
            self._latest = heapq.heappop(self._in_flight)[2]

    def latest_pose(self) -> Pose | None:
        with self._lock:
            self.advance()
            return self._latest

    def next_arrival(self) -> float:
        """[s] when the next pose will arrive (assuming no outage)."""
        with self._lock:
            if self._in_flight:
                return self._in_flight[0][0]
            return self.t0 + self._next_frame * self._period + self.params.mocap.latency_s


def world_params_from_uri(
    uri: Uri, base: WorldParams | None = None, kind: str | None = None
) -> WorldParams:
    """Apply a sim:// URI's options to `base` (defaults); bad values and unknown keys are one
    UriError. kind "driver" or "mocap": that side's keys only (the other side's are refused
    naming where they belong); None: a whole world's (perchd.core.uriparams.SIM,
    docs/contracts.md §7)."""
    if kind is None:
        check_known(uri, names_of(SIM))
    else:
        check_params(kind, uri)

    wp = base or WorldParams()
    plant = replace(
        wp.plant,
        latency_s=float_param(uri, "latency", wp.plant.latency_s, 0.0, 1.0, " s"),
        attitude_tau_s=float_param(uri, "attitude_tau", wp.plant.attitude_tau_s, 0.005, 1.0, " s"),
        motor_tau_s=float_param(uri, "motor_tau", wp.plant.motor_tau_s, 0.001, 1.0, " s"),
        mass_kg=float_param(uri, "mass", wp.plant.mass_kg, 0.005, 50.0, " kg"),
        drag_per_s=float_param(uri, "drag", wp.plant.drag_per_s, 0.0, 5.0, " 1/s"),
        qdrag_per_m=float_param(uri, "qdrag", wp.plant.qdrag_per_m, 0.0, 5.0, " 1/m"),
    )
    mocap = replace(
        wp.mocap,
        rate_hz=float_param(uri, "mocap_rate", wp.mocap.rate_hz, 1.0, 1000.0, " Hz"),
        latency_s=float_param(uri, "mocap_latency", wp.mocap.latency_s, 0.0, 0.5, " s"),
        noise_m=float_param(uri, "noise", wp.mocap.noise_m, 0.0, 0.1, " m"),
    )
    start = _floats(uri, "start", 3, "X,Y,Z in metres") or wp.start
    draught = _floats(uri, "draught", 2, "X,A: from world x = X [m] on, A [m/s^2] along X")
    if draught is not None:
        plant = replace(plant, draught_x_m=draught[0], draught_mps2=draught[1])
    seed = int(float_param(uri, "seed", float(wp.seed), 0, 2**31, ""))
    return replace(
        wp,
        plant=plant,
        mocap=mocap,
        start=start,
        seed=seed,
        body=uri.param("body", wp.body) or wp.body,
        stall=stall_from_uri(uri) or wp.stall,
    )


def _floats(uri: Uri, key: str, n: int, form: str) -> tuple[float, ...] | None:
    """The URI's `key` as n comma-separated finite numbers, None when absent; anything
    else is one UriError saying the `form` wanted."""
    text = uri.param(key)
    if text is None:
        return None
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise UriError(f"{uri.raw}: {key}={text!r} must be {form}")
    return values


def world_for(uri: Uri, runtime: Runtime, kind: str) -> SimWorld:
    """The runtime's world, created from this URI's options (the `kind` side's) if it has
    none yet; a world made already (by the other link, or perchd.session from both URIs)
    must be what this URI's options make of it, or they are refused: never ignored."""
    if uri.host:
        raise UriError(
            f"{uri.raw}: sim:// takes no host; its options go in the query "
            "(--driver sim://?latency=0.02 --mocap sim://?noise=0.001)"
        )
    if runtime.sim is None:
        runtime.sim = SimWorld(world_params_from_uri(uri, kind=kind), runtime.clock)
        return runtime.sim
    wanted = world_params_from_uri(uri, runtime.sim.params, kind)
    if wanted != runtime.sim.params:
        if not runtime.sim.pristine:
            raise UriError(
                f"{uri.raw}: the simulated world has run already without this "
                f"--{kind} link's options; open both links before it runs"
            )
        runtime.sim.__init__(wanted, runtime.clock)  # in place: the other link holds it
    return runtime.sim


class SimMocap:
    """PoseSource over a SimWorld: poses at the mocap rate, delayed and noisy as configured."""

    def __init__(self, world: SimWorld) -> None:
        self.world = world
        self.body = world.params.body
        self._started = False
        self._served = 0

    def start(self) -> None:
        self._started = True

    def latest(self) -> Pose | None:
        if not self._started:
            return None
        return self.world.latest_pose()

    def wait(self, after_seq: int, timeout: float) -> Pose | None:
        """Sleep on the world's clock until a newer pose arrives (ManualClock: at once)."""
        deadline = self.world.clock.now() + max(0.0, timeout)
        while True:
            pose = self.latest()
            if pose is not None and pose.seq > after_seq:
                return pose
            now = self.world.clock.now()
            if now >= deadline:
                return None
            self.world.clock.sleep_until(min(max(self.world.next_arrival(), now + 1e-4), deadline))

    def stats(self) -> SourceStats:
        pose = self.world.latest_pose()
        n = pose.seq if pose else 0
        return SourceStats(n, n, 0)

    def close(self) -> None:
        self._started = False


def open_sim_mocap(uri: Uri, runtime: Runtime) -> SimMocap:
    return SimMocap(world_for(uri, runtime, "mocap"))
