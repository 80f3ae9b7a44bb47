"""What the flight knows of its vehicle's response along X, and what it feeds forward.

One object holds the identification (flight/lagid.py) through a flight: it records the
ticks, refits during the approach and identifies at the trigger; it logs each fit. The
supervisor decides when each happens and hands the feed-forward's steps over to its
integrals (docs/errata.md §10).
"""

from __future__ import annotations

from perchd.flight.config import LagIdGains, TauGains
from perchd.flight.control import FeedForward
from perchd.flight.lagid import LagFit, LagIdentifier, LagModel
from perchd.logs.flightlog import LogEvent


def feed_forward(m: LagModel) -> FeedForward:
    """The feed-forward of an identified response."""
    return FeedForward(m.lag_s, m.drag_per_s, m.bias_mps2, m.qdrag_per_m)


class VehicleResponse:
    """ff: the feed-forward flown now; model: the latest accepted fit (None: none yet or
    refused); identified: the trigger's fit, once made. events: where fits are logged."""

    def __init__(self, gains: TauGains, cfg: LagIdGains, events: list[LogEvent]) -> None:
        self.gains = gains
        self.lagid = LagIdentifier(cfg)
        self.ff = FeedForward(gains.ff_lead_s)
        self.model: LagModel | None = None
        self.identified: LagFit | None = None
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
