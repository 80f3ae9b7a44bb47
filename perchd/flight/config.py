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
    """Learning the hover thrust during the hold (flight/hover.py).

    learn: refine the hover thrust in HOLD and start the approach only once it settled.
    tau_s: [s] time constant of the low-pass on the measured hover thrust.
    settle_s: [s] the estimate must stay within rel_tol of itself this long, with the
        height within z_tol_m [m] of its reference and |zdot| below vz_tol_mps [m/s].
    rel_tol: relative spread of the estimate over settle_s that counts as converged.
    timeout_s: [s] in HOLD without convergence ends the flight HOVER_UNLEARNED.
    ratio_min, ratio_max: a learned hover outside this multiple of mass_kg * g is refused
        (a wrong mass or calibration by that much is not flown on).
    """

    learn: bool = True
    tau_s: float = setting(0.25, "s", 0.01, 5.0)
    settle_s: float = setting(0.4, "s", 0.0, 10.0)
    rel_tol: float = setting(0.01, "", 0.0, 0.5)
    z_tol_m: float = setting(0.15, "m", 0.01, 1.0)
    vz_tol_mps: float = setting(0.15, "m/s", 0.01, 1.0)
    timeout_s: float = setting(6.0, "s", 0.5, 60.0)
    ratio_min: float = setting(0.6, "", 0.1, 1.0)
    ratio_max: float = setting(1.6, "", 1.0, 10.0)


@dataclass(frozen=True)
class TauGains:
    """Tau PID on e = 1 - tau_ref/tau (eq. 17) with gain scheduling (eq. 20); output [m/s^2].

    kp_fast: [m/s^2] used when tau_ref/tau > 1 (too fast: must brake).  kp_slow: when
             tau_ref/tau <= 1.  Defaults are half the paper's k_px1 = 77500 and k_px2 = 31000
             units (21.1 and 8.45 m/s^2), keeping its ratio 2.5: with the plan's acceleration
             fed forward the feedback only corrects, and the full gains turn 1 mm mocap noise
             into +-2 m/s^2 of command (measured: contact speed error 0.10 vs 0.04 m/s).
    ki: [m/s^2 per s]; paper 2500 units = 0.68, default 6.0: what the feed-forward's model
        misses in stage 1 (ArduCopter SITL: 0.1-0.3 m/s^2 from the trigger on) the paper's
        integral takes up over seconds, and the vehicle falls 0.06-0.08 m behind the plan
        within stage 1's 1.5 s; with stage 1 ended by place (end_by_position) that lateness
        is perch time (ArduCopter +2.4-3.3 %; +0.8-2.4 % at 6.0; docs/errata.md §10).
    kd: [m/s^2 s]; paper 2500 units = 0.68,
        default 0.2 (734 units): the derivative of a tau ratio amplifies mocap noise, and
        with 1 mm noise 0.2 halves the scatter of the contact speed over seeds.
    i_limit: [m/s^2] anti-windup clamp of the integral term's contribution.
    d_filter_s: [s] time constant of the low-pass on the error derivative.
    error_min, error_max: the error is clamped to this range (it grows without bound as
        tau -> 0 at contact).
    feedforward: add the plan's acceleration Xddot_ref(t + ff_lead_s) to the PID output.
    ff_lead_s: [s] look-ahead of the feed-forward: the vehicle reaches a commanded
        acceleration only after the command latency, the attitude response and the motor lag
        (about 0.1 s on a Crazyflie over Crazyradio), so the plan's acceleration is asked for
        that much early; most visibly, the stage-1 braking is released before the switch.
        With `identify` on, the lead flown is the lag identified in the hold and approach
        and this value is the fallback when the identification refuses.
    identify: identify the vehicle's lag and drag along the approach (flight/lagid.py,
        LagIdGains) and feed forward the plan's acceleration that lag early plus the
        identified drag times the plan's speed (docs/errata.md §10).
    predict: with a lag identified beyond ff_lead_s (the response these gains were made
        for), the tau PID acts on the state predicted the excess ahead from the commands
        still in flight, against the references then (a Smith predictor,
        LagIdentifier.predict); off: on the measured state.
    terminal_s: [s] in stage 2, once tau_ref is within this of 0 the tau feedback holds its
        last output and the speed is left alone: e = 1 - tau_ref/tau divides two vanishing
        numbers there, so millimetre noise becomes metres per second squared of command,
        while the stage-2 speed is already what contact will be.
    stage2_hold_speed: in stage 2 use tau_ref = X / V_c (so e = 1 - Xdot/V_c: the same tau
        PID now holds the plan's contact speed, docs/errata.md §9 "holds a constant speed"), rather
        than the paper's clock-indexed tau_s + (t - t_s) (eq. 6), which holds *whatever*
        speed the vehicle had at the switch: any stage-1 tracking error then reaches the
        surface unchanged. Both are the same reference when the switch happens on plan.
    v_contact_margin_mps: [m/s] with stage2_hold_speed, the speed held is the plan's V_c
        moved at least this far inside the contact window [V_l, V_u]: a minimum-time plan
        puts V_c on the window's edge (V_u), where any tracking error would leave it.
    scale_gain: gamma of stage 1's scale correction: tau is the same for every trajectory
        c times the plan's (X and Xdot scaled alike), so a vehicle a lag behind in X keeps
        tau by being faster and reaches the stage-2 switch c times too fast. Stage 1 aims
        at tau_ref c^-gamma, c = X / X_plan: c returns to 1 with time constant |tau|/gamma,
        never faster than twice the lag, faded out between three and two lags before the
        plan's switch (docs/errata.md §10). 0: the paper's tau reference alone.
    end_by_position: as the scale correction fades (three to two lags before the plan's
        switch), stage 1 aims at the plan's point where the vehicle is rather than where
        the clock is: tau_ref and the feed-forward of that point. A vehicle behind the plan
        in X (every lagging one is) then reaches the switch point nearer the plan's speed
        than c times it, and its braking ends where the plan's does; the time it is behind
        shows in the perch time rather than the contact speed (docs/errata.md §10).
        Off: the clock's references to the switch.
    switch_predicted: judge the stage-2 switch (tau reaching tau_s, docs/errata.md §9) on
        the tau the tau PID acts on, predicted over the lag (`predict`), not the measured
        one, which reaches tau_s a horizon later: the tau PID would fly that horizon past
        stage 1's end on stage 1's references (ArduCopter SITL: perch time +1.8 % median,
        2.35 % max, measured; docs/firmware.md, "The switch on the predicted tau"). Off:
        the measured tau, as the paper's experiment.
    """

    kp_fast: float = setting(from_paper_units(38750.0), "m/s^2", 0.0, 200.0)
    kp_slow: float = setting(from_paper_units(15500.0), "m/s^2", 0.0, 200.0)
    ki: float = setting(6.0, "m/s^3", 0.0, 100.0)
    kd: float = setting(from_paper_units(734.0), "m/s", 0.0, 20.0)
    i_limit: float = setting(1.0, "m/s^2", 0.0, 20.0)
    d_filter_s: float = setting(0.03, "s", 0.0, 1.0)
    error_min: float = setting(-1.5, "", -10.0, 0.0)
    error_max: float = setting(1.0, "", 0.0, 10.0)
    feedforward: bool = True
    ff_lead_s: float = setting(0.1, "s", 0.0, 1.0)
    terminal_s: float = setting(0.15, "s", 0.0, 1.0)
    stage2_hold_speed: bool = True
    v_contact_margin_mps: float = setting(0.015, "m/s", 0.0, 0.5)
    scale_gain: float = setting(3.0, "", 0.0, 10.0)
    end_by_position: bool = True
    switch_predicted: bool = True
    identify: bool = True
    predict: bool = True


@dataclass(frozen=True)
class LagIdGains:
    """The identification of lag and drag (flight/lagid.py) and its bounds.

    window_s: [s] the last this many seconds of the hold and the approach are fitted.
    refit_s: [s] period of the refits during the approach (its own feed-forward uses
        the drag found so far); the fit at the trigger is the one logged and flown.
    lag_max_s, lag_step_s: [s] the delays tried (0..lag_max_s); a best delay at the bound
        is refused (the vehicle is slower than any tried). lag_max_s also bounds the lag
        (delay + T) fitted to the attitude (from_attitude).
    time_constant_max_s: [s] when the lag is fitted to the positions (no attitude, or
        from_attitude off): the first-order lags tried behind the delay (0 up to this, in
        lag_step_s). 0 (the default): one pure delay. Above, the lead flown is delay + T.
    drag_max_per_s: [1/s] an identified drag above this is refused.
    speed_span_min_mps: [m/s] the fitted ticks must cover this speed range (the approach).
    rms_max_mps: [m/s] a fit with a larger residual is refused.
    stage2_refit: at the stage-2 switch, fit the bias again from stage 1 alone (lag and
        drag kept) and feed it forward in stage 2: a push the approach never met
        (LagIdentifier.refit_bias).
    stage2_refit_share: how much of that refit's departure from the approach's bias stage
        2 flies (1: all of it; 0: the approach's bias). Stage 1's push reaches stage 2 in
        part only, and differently from flight to flight: on PX4 SIH the contact followed
        the refit's step (r 0.91 over 40 flights) and touched 0.961-0.999 m/s with all of
        it, 0.975-0.999 with half (docs/firmware.md, "How much of stage 1's push stage 2
        meets"). A push is this flight's own: no earlier flight's is carried over.
    from_attitude: take the delay and the first-order lag from the attitude the mocap
        measures, answering the setpoints' (LagIdentifier.lean_response), drag and bias
        from the positions as before; the positions' own lag fit when the lean swept too
        little or the fit is poor. The attitude's fit finds one vehicle's lag within a few
        ms from flight to flight where the positions' scattered by 0.06 s (docs/firmware.md,
        "The attitude the mocap measures"). With stage2_refit, stage 2 flies the lag of
        stage 1's attitude alone (VehicleResponse.refit_stage2).
    drag_from_attitude: with from_attitude, fit the drag to the acceleration the measured
        lean makes rather than the one the setpoints ask for (LagIdentifier.lean_drag):
        an autopilot's attitude estimate that errs with speed reads as drag otherwise.
    """

    window_s: float = setting(8.0, "s", 1.0, 60.0)
    refit_s: float = setting(0.25, "s", 0.02, 3600.0)
    lag_max_s: float = setting(0.5, "s", 0.01, 2.0)
    lag_step_s: float = setting(0.02, "s", 0.005, 0.1)
    time_constant_max_s: float = setting(0.0, "s", 0.0, 1.0)
    drag_max_per_s: float = setting(2.0, "1/s", 0.0, 20.0)
    speed_span_min_mps: float = setting(0.5, "m/s", 0.0, 5.0)
    rms_max_mps: float = setting(0.1, "m/s", 1e-3, 1.0)
    stage2_refit: bool = True
    stage2_refit_share: float = setting(1.0, "", 0.0, 1.0)
    from_attitude: bool = True
    drag_from_attitude: bool = True


@dataclass(frozen=True)
class AxisGains:
    """Position PID of one lateral axis (eq. 18); kp [m/s^2 per m], ki [m/s^2 per m s],
    kd [m/s^2 per m/s], i_limit [m/s^2] anti-windup clamp, d_filter_s [s] derivative
    low-pass (the derivative is taken of the estimated velocity, which is already smooth)."""

    kp: float = setting(REQUIRED, "1/s^2", 0.0, 100.0)
    ki: float = setting(REQUIRED, "1/s^3", 0.0, 100.0)
    kd: float = setting(REQUIRED, "1/s", 0.0, 50.0)
    i_limit: float = setting(1.0, "m/s^2", 0.0, 20.0)
    d_filter_s: float = setting(0.0, "s", 0.0, 1.0)


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
    """Before the trigger: hold, then accelerate along X to reach the plan's (x0, v0).

    takeoff_height_m: [m] world height climbed to when the flight starts lower than this
        minus 0.1 m (on the ground); takeoff_speed_mps [m/s] climb rate of the reference.
    hold_s: [s] hover at the start before the approach.
    accel_max_mps2: [m/s^2] the approach may not need more than this (else it is refused).
    kv: [1/s] speed-tracking gain along X during the approach.
    ki_v: [1/s^2] integral gain on the approach's speed error: drag and the attitude lag
        otherwise leave the speed at the trigger ~0.09 m/s short of v0 on the Crazyflie
        firmware. i_limit_mps2: [m/s^2] clamp of its contribution; it does not
        integrate while the mapping saturates, and is reset when the approach begins.
    lead_into_plan: the approach's references continue past x0 as the plan's own, so that
        a vehicle answering a lag late is already commanded the plan's first acceleration
        when it crosses x0 (off: the plan's acceleration is first asked for at the
        trigger, and the vehicle starts stage 1 a lag behind it; docs/errata.md §10).
    """

    takeoff_height_m: float = setting(1.0, "m", 0.0, TAKEOFF_HEIGHT_MAX_M)
    takeoff_speed_mps: float = setting(0.5, "m/s", 0.05, 2.0)
    hold_s: float = setting(0.5, "s", 0.0, 30.0)
    accel_max_mps2: float = setting(1.4, "m/s^2", 0.1, 20.0)
    kv: float = setting(3.0, "1/s", 0.0, 50.0)
    ki_v: float = setting(8.0, "1/s^2", 0.0, 100.0)
    i_limit_mps2: float = setting(1.0, "m/s^2", 0.0, 20.0)
    lead_into_plan: bool = True


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
    within ahead_v_tol_mps [m/s] of the speed it was made for. Otherwise the trigger asks
    for a plan from the measured state and holds that speed until it comes, for at most
    min(solve_max_s [s], v_tol_mps / the plan's peak deceleration, sqrt(2 x_tol_m / that
    deceleration)): the time after which the held speed, or the distance flown, is further
    from the plan waited for than the tolerance. Past it (or if it fails): `fallback`.
    """

    policy: TriggerPolicy = TriggerPolicy.REFUSE
    x_tol_m: float = setting(0.05, "m", 0.0, 1.0)
    v_tol_mps: float = setting(0.10, "m/s", 0.0, 2.0)
    library: str | None = None
    fallback: TriggerFallback = TriggerFallback.PLAN
    solve_max_s: float = setting(0.25, "s", 0.0, 5.0)
    ahead_v_tol_mps: float = setting(0.05, "m/s", 0.0, 1.0)

    def deadline_s(self, a_peak_mps2: float) -> float:
        """[s] longest wait for the trigger's replan, for a plan whose largest |acceleration|
        is a_peak_mps2 [m/s^2] (see the class docstring)."""
        if a_peak_mps2 <= 0.0:
            return self.solve_max_s
        return min(
            self.solve_max_s,
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

    stale_periods / stale_timeout_s: mocap is stale when no valid pose arrived for more than
        this many mocap periods, or for stale_timeout_s [s] when that is set.
    geofence: perching-frame box: x_min_m..x_max_m [m] along the normal (x_max_m > 0 means
        the vehicle went through the surface; the surface, X = 0, must lie inside),
        lateral_max_m [m] from the approach line, floor_m [m] lowest world height after
        take-off, ceiling_m [m] highest world height (at most
        core.envelope.CEILING_ABOVE_FLOOR_M above the floor, whatever is set). Height
        references stay core.envelope.MARGIN_M inside floor and ceiling.
    tilt_max_rad: [rad] measured tilt that ends the flight.
    speed_max_mps: [m/s] measured speed that ends the flight.
    tau_error_max / tau_error_s: |tau - tau_ref| [s] beyond max(tau_error_max,
        tau_error_rel * |tau_ref|) for tau_error_s [s], or tau undefined that long, diverges.
    overrun_streak: consecutive missed loop deadlines that end the flight.
    link_rtt_max_s: [s] a link round trip (LinkHealth.rtt_s, where the driver measures one)
        above this ends the flight LOST_LINK: commands that late land the perch too fast
        (tests/faults: 100 ms one way still perches in the window, 200 ms lands at 1.3 m/s).
    timeout_s: [s] longest flight; plan_grace_s: [s] after the plan's duration without contact.
    contact_margin_m: [m] contact is declared within one tick of travel plus this of X = 0.
    """

    stale_periods: float = setting(3.0, "", 1.0, 100.0)
    stale_timeout_s: float | None = setting(None, "s", 0.005, 5.0)
    x_min_m: float = setting(-8.0, "m", -ROOM_M, 0.0)
    x_max_m: float = setting(0.3, "m", 0.0, ROOM_M)
    lateral_max_m: float = setting(1.0, "m", 0.01, ROOM_M)
    floor_m: float = setting(0.1, "m", -ROOM_M, ROOM_M)
    ceiling_m: float = setting(3.0, "m", -ROOM_M, ROOM_M + CEILING_ABOVE_FLOOR_M)
    tilt_max_rad: float = setting(math.radians(45.0), "rad", math.radians(1.0), math.radians(80.0))
    speed_max_mps: float = setting(3.5, "m/s", 0.1, 20.0)
    tau_error_max: float = setting(0.5, "s", 0.01, 100.0)
    tau_error_rel: float = setting(0.5, "", 0.0, 10.0)
    tau_error_s: float = setting(0.3, "s", 0.01, 100.0)
    overrun_streak: int = setting(10, "", 1, 10000)
    link_rtt_max_s: float = setting(0.25, "s", 1e-3, 10.0)
    timeout_s: float = setting(30.0, "s", 0.1, 3600.0)
    plan_grace_s: float = setting(1.0, "s", 0.0, 60.0)
    contact_margin_m: float = setting(0.005, "m", 0.0, 0.5)


@dataclass(frozen=True)
class EstimatorConfig:
    """Kalman filter (perchd.flight.estimator).

    jerk_psd: [m^2/s^5] white-jerk spectral density of the constant-acceleration model.
    meas_std_m: [m] mocap position noise.
    outlier_speed_mps: [m/s] a jump implying more than this speed is rejected.
    outlier_max_rejects: consecutive rejections after which the filter re-initialises.
    min_speed_mps: [m/s] tau is undefined (None) when Xdot is at or below this.
    """

    jerk_psd: float = setting(2.0, "m^2/s^5", 1e-3, 1e4)
    meas_std_m: float = setting(0.001, "m", 1e-6, 0.5)
    outlier_speed_mps: float = setting(10.0, "m/s", 0.5, 1000.0)
    outlier_max_rejects: int = setting(5, "", 1, 1000)
    min_speed_mps: float = setting(0.05, "m/s", 0.0, 1.0)


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
    (eq. 25, 25 deg).  post_contact_s: [s] the post-contact action is held this long.
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
    estimator: EstimatorConfig = EstimatorConfig()
    surface: SurfaceConfig = SurfaceConfig()
    rate_hz: float = setting(100.0, "Hz", 20.0, 500.0)
    sync: LoopSync = LoopSync.MOCAP
    tilt_limit_rad: float = setting(math.radians(25.0), "rad", 0.01, math.radians(60.0))
    post_contact: PostContact = PostContact.CUT
    post_contact_s: float = setting(0.2, "s", 0.0, 10.0)
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
    lifts the vehicle, a lag grid of two steps at least; None where one holds."""
    v, h, lag = cfg.vehicle, cfg.hover, cfg.lag_id
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
        _below(("[hover] ratio_min", h.ratio_min), ("[hover] ratio_max", h.ratio_max), ""),
        _below(
            ("[tau_gains] error_min", cfg.tau_gains.error_min),
            ("[tau_gains] error_max", cfg.tau_gains.error_max),
            "",
        ),
        _below(
            ("2 x [lag_id] lag_step_s", 2.0 * lag.lag_step_s),
            ("[lag_id] lag_max_s", lag.lag_max_s),
            " s",
            strict=False,
        ),
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
