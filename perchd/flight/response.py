"""What the flight knows of its vehicle's response along X, and what it feeds forward.

One object holds the identification (flight/lagid.py) through a flight: it records the
ticks, refits during the approach, identifies at the trigger, takes the lag again from
stage 1's attitude and refits the bias at the stage-2 switch; it logs each fit. The supervisor decides when each
happens and hands the feed-forward's steps over to its integrals (docs/errata.md §10).
"""

from __future__ import annotations

from dataclasses import replace

from perchd.flight.config import LagIdGains, TauGains
from perchd.flight.control import FeedForward
from perchd.flight.lagid import LagFit, LagIdentifier, LagModel
from perchd.logs.flightlog import LogEvent

RELAG_MAX = 0.25
"""Stage 1's attitude lag replaces the approach's if within this share of it (the firmwares:
3-15 %)."""


def feed_forward(m: LagModel) -> FeedForward:
    """The feed-forward of an identified response."""
    return FeedForward(m.lag_s, m.drag_per_s, m.bias_mps2, m.qdrag_per_m)


class VehicleResponse:
    """ff: the feed-forward flown now; model: the latest accepted fit (None: none yet or
    refused); identified: the trigger's fit, once made; departure_mps2: stage 1's refit
    bias less the approach's, once refitted (this flight's own: never carried over). events:
    where fits are logged."""

    def __init__(self, gains: TauGains, cfg: LagIdGains, events: list[LogEvent]) -> None:
        self.gains, self.cfg = gains, cfg
        self.lagid = LagIdentifier(cfg)
        self.ff = FeedForward(gains.ff_lead_s)
        self.model: LagModel | None = None
        self.identified: LagFit | None = None
        self.departure_mps2: float | None = None  # stage 1's bias less the approach's
        self._events = events

    def record(self, t: float, u_x: float, x: float, xdot: float) -> None:
        """One tick: t [s], u_x [m/s^2] the command sent, x [m], xdot [m/s] measured."""
        self.lagid.record(t, u_x, x, xdot)

    def record_lean(self, t: float, sent: float, t_measured: float, measured: float) -> None:
        """One tick's lean along X: sent at t [s], measured at t_measured [s]."""
        self.lagid.record_lean(t, sent, t_measured, measured)

    def refit(self) -> LagModel | None:
        """An approach refit, None when refused; the caller hands its feed-forward's step
        over to its integral, then `adopt`s it."""
        return self.lagid.fit().model

    def adopt(self, m: LagModel) -> None:
        """Fly m from now on."""
        self.model, self.ff = m, feed_forward(m)

    def identify(self, t: float) -> None:
        """The trigger's fit of the hold and approach just flown, fed forward from here on;
        a refused fit keeps the configured lead and no drag term."""
        self.identified = fit = self.lagid.fit()
        self.model = m = fit.model
        if m is None:
            self.ff = FeedForward(self.gains.ff_lead_s)
            self._events.append(
                LogEvent(
                    t,
                    "lag-unidentified",
                    (
                        f"{fit.why}: flying the configured lead {self.ff.lead_s:g} s and no drag term"
                    ),
                    {"lead_s": self.ff.lead_s},
                )
            )
            return
        self.ff = feed_forward(m)
        self._events.append(
            LogEvent(
                t,
                "lag-identified",
                (
                    f"lag {m.lag_s:.3f} s ({m.time_constant_s:.3f} s of it first-order) from the "
                    f"{'attitude' if m.from_attitude else 'positions'}, drag {m.drag_per_s:.3f} 1/s "
                    f"+ {m.qdrag_per_m:.3f} 1/m x v|v| "
                    f"from the {'lean measured' if m.drag_from_attitude else 'commands'}"
                ),
                {
                    "lag_s": m.lag_s,
                    "time_constant_s": m.time_constant_s,
                    "from_attitude": m.from_attitude,
                    "drag_from_attitude": m.drag_from_attitude,
                    "drag_per_s": m.drag_per_s,
                    "qdrag_per_m": m.qdrag_per_m,
                    "bias_mps2": m.bias_mps2,
                    "rms_mps": m.rms_mps,
                    "samples": m.samples,
                    "speed_span_mps": m.speed_span_mps,
                },
            )
        )

    def refit_stage2(self, t: float, since_t: float, v_hold: float) -> float:
        """At the stage-2 switch: the bias again from stage 1 (since since_t [s]), lag and
        drag kept, is flown from here on (LagIdentifier.refit_bias). Returns the step [m/s^2] this adds
        at the held speed v_hold [m/s] (0 when refused, logged, or nothing was identified)."""
        if self.model is None or not self.cfg.stage2_refit:
            return 0.0
        self._relag(t, since_t)
        fit = self.lagid.refit_bias(self.model, since_t)
        if fit.model is None:
            self._events.append(
                LogEvent(
                    t,
                    "bias-unrefitted",
                    f"{fit.why}: stage 2 keeps bias {self.ff.bias_mps2:.3f} m/s^2",
                )
            )
            return 0.0
        fitted, approach = fit.model.bias_mps2, self.model.bias_mps2
        self.departure_mps2 = fitted - approach
        m = fit.model
        ff = feed_forward(m)
        step = ff.step_from(self.ff, 0.0, v_hold)
        self.ff, self.model = ff, m
        self._log_refit(t, approach, fitted, step)
        return step

    def _log_refit(self, t: float, approach: float, fitted: float, step: float) -> None:
        """The bias-refit event: approach and fitted biases [m/s^2], the feed-forward's step
        [m/s^2] (docs/contracts.md)."""
        m, own = self.model, fitted - approach
        self._events.append(
            LogEvent(
                t,
                "bias-refit",
                (
                    f"stage 2: bias {m.bias_mps2:.3f} m/s^2 = the approach's {approach:.3f} + "
                    f"stage 1's {own:+.3f}"
                ),
                {
                    "bias_mps2": m.bias_mps2,
                    "fitted_mps2": fitted,
                    "departure_mps2": own,
                    "rms_mps": m.rms_mps,
                    "samples": m.samples,
                    "step_mps2": step,
                },
            )
        )

    def _relag(self, t: float, since_t: float) -> None:
        """A lag taken from the attitude is taken again from stage 1's alone (drag and bias
        kept): an autopilot's shaping answers stage 1's faster swings 0.01-0.05 s sooner
        than the hold's and the approach's (docs/firmware.md, "The attitude the mocap
        measures"), and stage 2 is decided by the last of them."""
        m = self.model
        lean = self.lagid.lean_response(since_t) if m.from_attitude else None
        if lean is None or abs(sum(lean) - m.lag_s) > RELAG_MAX * m.lag_s:
            return  # stage 1 alone too short or too odd to overrule the approach's
        # The lead changes where the plan's acceleration no longer does (stage 2 holds
        # its speed from the switch on), so the feed-forward does not step.
        self.model = replace(m, lag_s=lean[0] + lean[1], time_constant_s=lean[1])
        self.ff = feed_forward(self.model)
        self._events.append(
            LogEvent(
                t,
                "lag-refit",
                (
                    f"stage 2: lag {self.model.lag_s:.3f} s ({lean[1]:.3f} s of it first-order) "
                    f"from stage 1's attitude, {m.lag_s:.3f} s before"
                ),
                {"lag_s": self.model.lag_s, "time_constant_s": lean[1], "was_lag_s": m.lag_s},
            )
        )
