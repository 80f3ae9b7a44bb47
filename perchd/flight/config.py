"""Flight configuration: plain nested frozen dataclasses with SI defaults.

A TOML loader (service engineer) fills these; nothing here reads files. Every field carries
its unit in its name or docstring. Gains are SI (acceleration [m/s^2] per unit of error) and
their docstrings give the paper's Crazyflie thrust-unit equivalents (docs/errata.md §8: hover is about
36000 units for a 27-30 g CF2.0 at g = 9.81, so 1 unit of thrust is m*g/36000 N and produces
g/36000 = 2.725e-4 m/s^2 whatever the mass; SI gain = units gain * 9.81 / 36000).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from perchd.core.envelope import CEILING_ABOVE_FLOOR_M, MARGIN_M, TAKEOFF_HEIGHT_MAX_M
from perchd.core.errors import ConfigError
from perchd.core.vehicle import (
    CRAZYFLIE_HOVER_UNITS,
    CRAZYFLIE_MASS_KG,
    CRAZYFLIE_THRUST_MAX_N,
    CRAZYFLIE_THRUST_MIN_N,
    G_M_S2,
)
from perchd.flight.bounds import REQUIRED, check_bounds, setting

UNIT_ACCEL = G_M_S2 / CRAZYFLIE_HOVER_UNITS
"""[m/s^2] acceleration of one paper thrust unit (docs/errata.md §8)."""
THRUST_MAX_N = 2000.0
"""[N] the most thrust any setting may name: twice the weight of VehicleConfig's heaviest
vehicle (50 kg)."""
ROOM_M = 100.0
"""[m] the largest distance a geofence setting may name: no flying room is bigger."""
MAX_COORD_M = 1000.0
"""[m] largest |coordinate| of a surface point: no flying room is bigger; 1e300 is a typo."""


SOLVE_MAX_S = 0.25
"""[s] the longest the trigger waits for a replan from the measured state."""
AHEAD_V_TOL_MPS = 0.05
"""[m/s] the plan made ahead is flown when the speed at the trigger is this close to the
speed it was made for."""


def from_paper_units(units: float) -> float:
    """A paper gain in thrust units -> the SI gain in m/s^2 per unit of error."""
    return units * UNIT_ACCEL


@dataclass(frozen=True)
class VehicleConfig:
    """The one vehicle of a flight (drivers take its mass, Driver.bind_mass).

    mass_kg [kg]; g [m/s^2].
    thrust_min_n/thrust_max_n [N] collective limits while flying (the paper's eq. 26 clamps
        10000..65000 units). thrust_max_n is a cap: the flight saturates, and stops its
        integrators, at min(thrust_max_n, the driver's ceiling) (flight.run.fly asks
        Driver.thrust_ceiling_n: a Crazyflie's thrust model at the firmware's 60000-unit
        clamp, a MAVLink vehicle's full thrust, the simulated plant's maximum), so the
        controller never counts on thrust the vehicle will not give.
    hover_thrust_n [N]: the thrust that holds the vehicle level, in the driver's newtons;
        None: mass_kg * g, or what an earlier flight of this vehicle learned. It is the
        initial guess the hold phase refines (HoverConfig, flight/hover.py).
    """

    mass_kg: float = setting(CRAZYFLIE_MASS_KG, "kg", 1e-3, 50.0)
    thrust_min_n: float = setting(CRAZYFLIE_THRUST_MIN_N, "N", 0.0, THRUST_MAX_N)
    thrust_max_n: float = setting(CRAZYFLIE_THRUST_MAX_N, "N", 1e-3, THRUST_MAX_N)
    g: float = setting(G_M_S2, "m/s^2", 9.7, 9.9)
    hover_thrust_n: float | None = setting(None, "N", 1e-3, THRUST_MAX_N)

    @property
    def hover_guess_n(self) -> float:
        """[N] the configured hover thrust, or the weight."""
        return self.mass_kg * self.g if self.hover_thrust_n is None else self.hover_thrust_n


@dataclass(frozen=True)
class HoverConfig:
    """Learning the hover thrust during the hold (flight/hover.py, whose constants say when
    the estimate has settled and which hover thrusts are believed).

    learn: refine the hover thrust in HOLD and start the approach once it settled.
    timeout_s: [s] in HOLD without the estimate settling: a vehicle holding its height
        (within flight/hover.py's Z_TOL_M) flies on the estimate it has, an autopilot's
        height loop keeping its thrust moving by a few percent; one that does not hold its
        height, or whose estimate is outside RATIO x its weight, ends HOVER_UNLEARNED.
    """

    learn: bool = True
    timeout_s: float = setting(6.0, "s", 0.5, 60.0)


@dataclass(frozen=True)
class TauGains:
    """Tau PID on e = 1 - tau_ref/tau (eq. 17) with gain scheduling (eq. 20); output [m/s^2].
    Its integral clamp, derivative filter and error clamp are flight/control.py's constants.

    kp_fast: [m/s^2] used when tau_ref/tau > 1 (too fast: must brake).  kp_slow: when
             tau_ref/tau <= 1.  Defaults are half the paper's k_px1 = 77500 and k_px2 = 31000
             units (21.1 and 8.45 m/s^2), keeping its ratio 2.5: with the plan's acceleration
             fed forward the feedback only corrects, and the full gains turn 1 mm mocap noise
             into +-2 m/s^2 of command (measured: contact speed error 0.10 vs 0.04 m/s).
    ki: [m/s^2 per s]; paper 2500 units = 0.68, default 6.0: what the feed-forward's model
        misses in stage 1 the paper's integral takes up only over seconds, and the vehicle
        falls behind the plan within stage 1's 1.5 s (docs/controller.md).
    kd: [m/s^2 s]; paper 2500 units = 0.68,
        default 0.2 (734 units): the derivative of a tau ratio amplifies mocap noise, and
        with 1 mm noise 0.2 halves the scatter of the contact speed over seeds.
    feedforward: add the model's feed-forward (the plan's acceleration ff_lead_s early, the
        drag at the plan's speed, less the bias) to the PID output.
    ff_lead_s: [s] the lead flown when no lag is identified: the vehicle reaches a commanded
        acceleration only after the command latency, the attitude response and the motor
        lag (about 0.1 s on a Crazyflie over Crazyradio). With `identify` on, the lead flown
        is the lag identified in the hold and approach.
    identify: identify the vehicle's response along the approach (flight/lagid.py: delay,
        lag, linear and quadratic drag, bias) and feed it forward (docs/controller.md).
    wall_push_mps2: [m/s^2] the push near the wall (a draught, the wall's own air) stage 2
        keeps room for: a minimum-time plan puts V_c on the contact window's top edge, and
        stage 2's speed loop, met by this push, runs over the speed it holds by push V_c / kp
        (kp its gain) before it answers. So stage 2 holds V_c moved that far inside the
        window, at most MARGIN_MAX_MPS (flight/references.py `hold_loop`; docs/errata.md §9,
        docs/controller.md). 0: the plan's V_c held as planned.
    scale_gain: gamma of stage 1's scale correction: tau is the same for every trajectory
        c times the plan's (X and Xdot scaled alike), so a vehicle a lag behind in X keeps
        tau by being faster and reaches the stage-2 switch c times too fast. Stage 1 aims
        at tau_ref c^-gamma, c = X / X_plan: c returns to 1 with time constant |tau|/gamma,
        never faster than twice the lag, faded out between three and two lags before the
        plan's switch (docs/errata.md §10). 0: the paper's tau reference alone.
    """

    kp_fast: float = setting(from_paper_units(38750.0), "m/s^2", 0.0, 200.0)
    kp_slow: float = setting(from_paper_units(15500.0), "m/s^2", 0.0, 200.0)
    ki: float = setting(6.0, "m/s^3", 0.0, 100.0)
    kd: float = setting(from_paper_units(734.0), "m/s", 0.0, 20.0)
    feedforward: bool = True
    ff_lead_s: float = setting(0.1, "s", 0.0, 1.0)
    wall_push_mps2: float = setting(0.3, "m/s^2", 0.0, 5.0)
    scale_gain: float = setting(3.0, "", 0.0, 10.0)
    identify: bool = True


@dataclass(frozen=True)
class LagIdGains:
    """The identification of the vehicle's response (flight/lagid.py, whose constants bound
    its grid, window and acceptance).

    from_attitude: take the delay and the first-order lag from the attitude the mocap
        measures, answering the setpoints' (LagIdentifier.lean_response), and the drag from
        the acceleration that attitude makes; the positions' own fit when the lean swept too
        little or fits poorly. The attitude's fit finds one vehicle's lag within a few ms
        from flight to flight where the positions' scattered by 0.06 s (docs/firmware.md,
        "The attitude the mocap measures").
    """

    from_attitude: bool = True


@dataclass(frozen=True)
class AxisGains:
    """Position PID of one lateral axis (eq. 18); kp [m/s^2 per m], ki [m/s^2 per m s],
    kd [m/s^2 per m/s] (on the estimated velocity); its integral clamp is flight/control.py's
    AXIS_I_LIMIT_MPS2."""

    kp: float = setting(REQUIRED, "1/s^2", 0.0, 100.0)
    ki: float = setting(REQUIRED, "1/s^3", 0.0, 100.0)
    kd: float = setting(REQUIRED, "1/s", 0.0, 50.0)


@dataclass(frozen=True)
class LateralGains:
    """y: paper k_py, k_iy, k_dy = 14500, 2000, 4500 units = 3.95, 0.545, 1.23 SI.
    z: paper k_pz, k_iz, k_dz = 20000, 1500, 3500 units = 5.45, 0.409, 0.954 SI."""

    y: AxisGains = AxisGains(
        from_paper_units(14500.0), from_paper_units(2000.0), from_paper_units(4500.0)
    )
    z: AxisGains = AxisGains(
        from_paper_units(20000.0), from_paper_units(1500.0), from_paper_units(3500.0)
    )


@dataclass(frozen=True)
class ApproachConfig:
    """Before the trigger: hold, then accelerate along X to reach the plan's (x0, v0) (its
    speed loop's gains are flight/supervisor.py's APPROACH_* constants).

    takeoff_height_m: [m] world height climbed to when the flight starts lower than this
        minus 0.1 m (on the ground); takeoff_speed_mps [m/s] climb rate of the reference.
    hold_s: [s] hover at the start before the approach.
    accel_max_mps2: [m/s^2] the approach may not need more than this (else it is refused).
    """

    takeoff_height_m: float = setting(1.0, "m", 0.0, TAKEOFF_HEIGHT_MAX_M)
    takeoff_speed_mps: float = setting(0.5, "m/s", 0.05, 2.0)
    hold_s: float = setting(0.5, "s", 0.0, 30.0)
    accel_max_mps2: float = setting(1.4, "m/s^2", 0.1, 20.0)


class TriggerPolicy(enum.Enum):
    """What to do when the measured trigger state is not exactly the plan's (x0, v0).

    ROBUST: the plan must carry a robust box holding the state; fly it retargeted (k_0 = v/x).
    REPLAN: retarget (re-plan) the same strategy and limits from the measured state.
    REFUSE: fly the plan as made when within the tolerance, else end TRIGGER_REFUSED.
    """

    ROBUST = "robust"
    REPLAN = "replan"
    REFUSE = "refuse"


class TriggerFallback(enum.Enum):
    """What the trigger does when its replan is not in by the deadline (or failed).

    PLAN: fly the nearest plan made before the trigger (the one planned ahead, or the
        flight's own) if the measured trigger state is within x_tol_m/v_tol_mps of it, as
        REFUSE would, else end TRIGGER_REFUSED.  REFUSE: end TRIGGER_REFUSED.
    """

    PLAN = "plan"
    REFUSE = "refuse"


@dataclass(frozen=True)
class TriggerConfig:
    """policy: see TriggerPolicy.  x_tol_m [m], v_tol_mps [m/s]: largest |measured - plan|
    of x0 and v0 flown without a new plan (REFUSE, and the PLAN fallback).  library: a plan
    library file (`perchd plan library`) for the plan's order and limits: REPLAN then
    warm-starts from it (~2 ms) instead of a cold global solve (~60 ms at order 3, ~0.5 s
    at 7).

    ROBUST and REPLAN never solve on the loop thread in real time (docs/architecture.md,
    "Planning in flight"): a worker process plans ahead during the approach for the
    predicted trigger state, and the trigger flies that plan when the measured speed is
    within AHEAD_V_TOL_MPS of the speed it was made for. Otherwise the trigger asks
    for a plan from the measured state and holds that speed until it comes, for at most
    min(SOLVE_MAX_S, v_tol_mps / the plan's peak deceleration, sqrt(2 x_tol_m / that
    deceleration)): the time after which the held speed, or the distance flown, is further
    from the plan waited for than the tolerance. Past it (or if it fails): `fallback`.
    """

    policy: TriggerPolicy = TriggerPolicy.REFUSE
    x_tol_m: float = setting(0.05, "m", 0.0, 1.0)
    v_tol_mps: float = setting(0.10, "m/s", 0.0, 2.0)
    library: str | None = None
    fallback: TriggerFallback = TriggerFallback.PLAN

    def deadline_s(self, a_peak_mps2: float) -> float:
        """[s] longest wait for the trigger's replan, for a plan whose largest |acceleration|
        is a_peak_mps2 [m/s^2] (see the class docstring)."""
        if a_peak_mps2 <= 0.0:
            return SOLVE_MAX_S
        return min(
            SOLVE_MAX_S,
            self.v_tol_mps / a_peak_mps2,
            math.sqrt(2.0 * self.x_tol_m / a_peak_mps2),
        )


class LoopSync(enum.Enum):
    """What releases a control tick.

    MOCAP (the default): the arrival of each new pose (mocap-synchronous): the setpoint
        follows the pose by the compute time only. rate_hz is then the expected mocap rate:
        a tick overruns when it ends a period after it started, and runs anyway after 1.5
        periods without a pose, so stale mocap is still detected and the driver still gets
        a setpoint at least that often (every driver here also repeats the last one on its
        own after 100 ms: docs/safety.md). Set rate_hz to the mocap system's rate.
    FIXED: a clock at rate_hz; a pose waits up to one period for the tick that uses it. For
        a link whose firmware wants setpoints at a steady rate, or a mocap far faster than
        the link should be commanded.
    """

    FIXED = "fixed"
    MOCAP = "mocap"


class PostContact(enum.Enum):
    """After contact: CUT the motors, or IDLE at the vehicle's minimum thrust."""

    CUT = "cut"
    IDLE = "idle"


@dataclass(frozen=True)
class SafetyConfig:
    """Abort thresholds, checked every tick (see perchd.flight.supervisor).

    stale_timeout_s: [s] mocap is stale when no valid pose arrived for this long; None:
        flight/endrules.py's STALE_PERIODS mocap periods.
    geofence: perching-frame box: x_min_m..x_max_m [m] along the normal (x_max_m > 0 means
        the vehicle went through the surface; the surface, X = 0, must lie inside),
        lateral_max_m [m] from the approach line, floor_m [m] lowest world height after
        take-off, ceiling_m [m] highest world height (at most
        core.envelope.CEILING_ABOVE_FLOOR_M above the floor, whatever is set). Height
        references stay core.envelope.MARGIN_M inside floor and ceiling.
    tilt_max_rad: [rad] measured tilt that ends the flight.
    speed_max_mps: [m/s] measured speed that ends the flight.
    link_rtt_max_s: [s] a link round trip (LinkHealth.rtt_s, where the driver measures one)
        above this ends the flight LOST_LINK: commands that late land the perch too fast
        (tests/faults: 100 ms one way still perches in the window, 200 ms lands at 1.3 m/s).
    timeout_s: [s] longest flight.
    The tau divergence, overrun, plan-grace and contact rules' thresholds are
    flight/endrules.py's constants.
    """

    stale_timeout_s: float | None = setting(None, "s", 0.005, 5.0)
    x_min_m: float = setting(-8.0, "m", -ROOM_M, 0.0)
    x_max_m: float = setting(0.3, "m", 0.0, ROOM_M)
    lateral_max_m: float = setting(1.0, "m", 0.01, ROOM_M)
    floor_m: float = setting(0.1, "m", -ROOM_M, ROOM_M)
    ceiling_m: float = setting(3.0, "m", -ROOM_M, ROOM_M + CEILING_ABOVE_FLOOR_M)
    tilt_max_rad: float = setting(math.radians(45.0), "rad", math.radians(1.0), math.radians(80.0))
    speed_max_mps: float = setting(3.5, "m/s", 0.1, 20.0)
    link_rtt_max_s: float = setting(0.25, "s", 1e-3, 10.0)
    timeout_s: float = setting(30.0, "s", 0.1, 3600.0)


@dataclass(frozen=True)
class SurfaceConfig:
    """point [m] on the surface and its normal (the approach direction), world frame."""

    point: tuple[float, float, float] = setting((0.0, 0.0, 0.0), "m", -MAX_COORD_M, MAX_COORD_M)
    normal: tuple[float, float, float] = setting((1.0, 0.0, 0.0), "", -1e6, 1e6)


@dataclass(frozen=True)
class FlightConfig:
    """Everything one flight needs besides the plan and the two links.

    rate_hz: [Hz] control loop rate, 20..500 (with sync MOCAP, the default: the mocap rate).
    sync: what releases a tick (LoopSync: a fixed-rate clock, or each mocap frame).
    tilt_limit_rad: [rad] setpoint saturation
    (eq. 25, 25 deg).
    idle_thrust_n: [N] thrust of PostContact.IDLE (None: the vehicle's thrust_min_n).
    """

    vehicle: VehicleConfig = VehicleConfig()
    hover: HoverConfig = HoverConfig()
    tau_gains: TauGains = TauGains()
    lag_id: LagIdGains = LagIdGains()
    lateral: LateralGains = LateralGains()
    approach: ApproachConfig = ApproachConfig()
    trigger: TriggerConfig = TriggerConfig()
    safety: SafetyConfig = SafetyConfig()
    surface: SurfaceConfig = SurfaceConfig()
    rate_hz: float = setting(100.0, "Hz", 20.0, 500.0)
    sync: LoopSync = LoopSync.MOCAP
    tilt_limit_rad: float = setting(math.radians(25.0), "rad", 0.01, math.radians(60.0))
    post_contact: PostContact = PostContact.CUT
    idle_thrust_n: float | None = setting(None, "N", 0.0, THRUST_MAX_N)

    def __post_init__(self) -> None:
        validate(self)


def envelope_checks(cfg: FlightConfig) -> list[tuple[str, float, float, float]]:
    """(key, value, low, high) of the hard envelope (perchd.core.envelope): the ceiling, the
    take-off height and the surface inside the geofence (x_max_m's own range is 0 up, so
    x_min_m < x_max_m)."""
    s = cfg.safety
    return [
        (
            "[safety] ceiling_m",
            s.ceiling_m,
            s.floor_m + 2 * MARGIN_M,
            s.floor_m + CEILING_ABOVE_FLOOR_M,
        ),
        (
            f"[approach] takeoff_height_m ({MARGIN_M:g} m inside floor and ceiling, at most "
            f"{TAKEOFF_HEIGHT_MAX_M:g} m)",
            cfg.approach.takeoff_height_m,
            s.floor_m + MARGIN_M,
            min(s.ceiling_m - MARGIN_M, TAKEOFF_HEIGHT_MAX_M),
        ),
        (
            "[safety] x_min_m (the surface, X = 0, inside the geofence)",
            s.x_min_m,
            -math.inf,
            -MARGIN_M,
        ),
    ]


def _below(
    low: tuple[str, float | None], high: tuple[str, float], unit: str, strict: bool = True
) -> str | None:
    """The fault of a (key, value) pair that must be below (strict) or at most the other."""
    (lo_key, lo), (hi_key, hi) = low, high
    if lo is None or lo < hi or (not strict and lo == hi):
        return None
    return (
        f"{lo_key} = {lo:g}{unit} must be {'below' if strict else 'at most'} "
        f"{hi_key} = {hi:g}{unit}"
    )


def cross_faults(cfg: FlightConfig) -> list[str | None]:
    """The rules between settings (each within its own range): min below max, the thrust
    lifts the vehicle; None where one holds."""
    v = cfg.vehicle
    top = ("[vehicle] thrust_max_n", v.thrust_max_n)
    weight = v.mass_kg * v.g
    return [
        _below(("[vehicle] thrust_min_n", v.thrust_min_n), top, " N"),
        None
        if v.thrust_max_n > weight
        else (
            f"[vehicle] thrust_max_n = {v.thrust_max_n:g} N must lift [vehicle] mass_kg = "
            f"{v.mass_kg:g} kg: more than its weight {weight:.4g} N"
        ),
        _below(("[vehicle] hover_thrust_n", v.hover_thrust_n), top, " N", strict=False),
        _below(("[flight] idle_thrust_n", cfg.idle_thrust_n), top, " N", strict=False),
    ]


def validate(cfg: FlightConfig) -> None:
    """Raise ConfigError naming the first setting out of its range (flight/bounds.py), then
    the first rule between settings broken (cross_faults, the hard envelope, the surface)."""
    check_bounds(cfg)
    for fault in cross_faults(cfg):
        if fault is not None:
            raise ConfigError(fault)
    for name, value, lo, hi in envelope_checks(cfg):
        if not lo <= value <= hi:
            side = (
                f"below {lo:g} by {lo - value:g}"
                if value < lo
                else f"above {hi:g} by {value - hi:g}"
            )
            raise ConfigError(f"{name} = {value:g} is {side}")
    if cfg.trigger.library is not None and cfg.trigger.policy is not TriggerPolicy.REPLAN:
        raise ConfigError(
            f"[trigger] library is used by policy 'replan' only, not {cfg.trigger.policy.value!r}"
        )
    n = cfg.surface.normal
    horizontal = math.hypot(n[0], n[1])
    if horizontal < 1e-6 or abs(n[2]) > horizontal:
        raise ConfigError(
            f"[surface] normal {n} must point more sideways than up or down "
            f"(a wall): |nz| = {abs(n[2]):g} > {horizontal:g}"
        )
