"""`perchd log plot`: the paper's figure 6 layout for one or more flights.

One column per flight, three rows: distance X [m], velocity Xdot [m/s] and tau [s], each
measured (the estimator's, as logged) against the plan's reference, over time since the
trigger. Dotted lines mark the stage switch and the contact. The lines end at the contact:
after it the wall holds the vehicle while the logged estimate runs on past the surface
(0.17 m in the 0.2 s after a case-1 contact), which is no part of the perch. matplotlib is
imported here, lazily, through perchd.core.extras (extra "plot").
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from perchd.core.extras import require
from perchd.logs.figsave import save_figure
from perchd.logs.flightlog import FlightLog

PRE_TRIGGER_S = 0.5
"""[s] of the approach shown before the trigger."""
TAU_CLIP_S = 3.0
"""[s] |tau| beyond this is left off the plot (tau runs to infinity at low speed)."""
ROWS = (
    ("x", "x_plan", "distance X [m]"),
    ("xdot", "v_plan", "velocity Xdot [m/s]"),
    ("tau", "tau_ref", "tau [s]"),
)


def plot_flights(
    logs: Sequence[FlightLog],
    out: str | Path,
    titles: Sequence[str] | None = None,
    force: bool = False,
) -> Path:
    """The flights side by side, saved to `out` (an existing file only with `force`)."""

    mpl = require("matplotlib", "plot")
    mpl.use("Agg")
    plt = require("matplotlib.pyplot", "plot")
    fig, axes = plt.subplots(
        3, len(logs), figsize=(5.0 * len(logs), 8.0), sharex="col", squeeze=False
    )
    for col, log in enumerate(logs):
        title = titles[col] if titles else ""
        _column(axes[:, col], log, title)
    fig.tight_layout()
    try:
        return save_figure(fig, out, 110, "--out", force)
    finally:
        plt.close(fig)


def plot_flight(log: FlightLog, out: str | Path, title: str = "", force: bool = False) -> Path:
    return plot_flights([log], out, [title], force)


def shown_rows(log: FlightLog) -> tuple[float, list]:
    """(the trigger's time [s], the rows plotted): from PRE_TRIGGER_S before the trigger up
    to the contact, when there is one."""
    events = {e.kind: e.t for e in log.events}
    t0 = events.get("stage1", log.rows[0].t if log.rows else 0.0)
    end = events.get("contact", float("inf"))
    return t0, [r for r in log.rows if t0 - PRE_TRIGGER_S <= r.t <= end]


def _column(axes, log: FlightLog, title: str) -> None:
    events = {e.kind: e.t for e in log.events}
    t0, rows = shown_rows(log)
    t = [r.t - t0 for r in rows]
    for ax, (meas, ref, label) in zip(axes, ROWS):
        m = [_clip(getattr(r, meas), meas) for r in rows]
        p = [_clip(getattr(r, ref), meas) for r in rows]
        ax.plot(t, m, color="tab:red", lw=1.4, label="measured")
        ax.plot(t, p, color="k", lw=1.0, ls="--", label="reference (plan)")
        for kind, style in (("stage2", ":"), ("contact", "-.")):
            if kind in events:
                ax.axvline(
                    events[kind] - t0,
                    color="tab:blue",
                    ls=style,
                    lw=0.8,
                    label="stage switch" if kind == "stage2" else "contact",
                )
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    plan = log.header.get("plan") or {}
    outcome = (log.end or {}).get("outcome", "INCOMPLETE")
    axes[0].set_title(
        f"{title}\n{plan.get('strategy', '?').upper()} plan "
        f"{plan.get('duration', float('nan')):.2f} s: {outcome}",
        fontsize=10,
    )
    axes[0].legend(fontsize=8, loc="lower right")
    axes[-1].set_xlabel("time since trigger [s]")


def _clip(value: float | None, kind: str) -> float:
    if value is None or (kind == "tau" and abs(value) > TAU_CLIP_S):
        return float("nan")
    return value
