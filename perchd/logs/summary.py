"""`perchd log summary`: a flight's figures re-derived from its log rows and events.

Outcome (the end record, or INCOMPLETE for a log cut short), contact speed [m/s] against the
plan's, perch time [s, trigger to contact] against the plan's duration, tau tracking RMS [s]
over the two tau stages, and the loop's timing: tick-to-tick period and the per-tick jitter
the loop recorded, as median, 99th percentile and maximum.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import asdict, dataclass
from typing import Any

from perchd.core.types import EndReason
from perchd.logs.flightlog import FlightLog, LogRow

TAU_STAGES = ("stage1", "stage2")


@dataclass(frozen=True)
class Spread:
    """median, p99, max of a series [s]."""

    median: float
    p99: float
    max: float

    @classmethod
    def of(cls, values: list[float]) -> Spread | None:
        if not values:
            return None
        ordered = sorted(values)
        return cls(
            statistics.median(ordered),
            ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))],
            ordered[-1],
        )


@dataclass(frozen=True)
class LogSummary:
    """outcome: EndReason name or INCOMPLETE; detail: its words. contact_speed and
    v_contact_plan [m/s]; perch_time and plan_duration [s] (the flight's own figures from
    the end record; for a log cut short, from the trigger and contact events' tick times); tau_rms [s] RMS of tau - tau_ref
    over rows with both defined in stage 1 and 2 (tau_rows of them), tau_rms_stage1 [s] the
    same over stage 1 alone; ticks; rate_hz configured; period: spacing of rows [s];
    jitter: the loop's tick start minus deadline [s]; duration_s: first to last row."""

    outcome: str
    detail: str
    contact_speed: float | None
    v_contact_plan: float | None
    perch_time: float | None
    plan_duration: float | None
    tau_rms: float | None
    tau_rms_stage1: float | None
    tau_rows: int
    ticks: int
    rate_hz: float | None
    sync: str | None
    period: Spread | None
    jitter: Spread | None
    duration_s: float

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def _rms(rows: list[LogRow]) -> float | None:
    errs = [(r.tau - r.tau_ref) ** 2 for r in rows]
    return math.sqrt(sum(errs) / len(errs)) if errs else None


def summarize(log: FlightLog) -> LogSummary:
    events = {e.kind: e for e in log.events}
    contact, trigger = events.get("contact"), events.get("stage1")
    plan = log.header.get("plan") or {}
    config = log.header.get("config") or {}
    tracked = [
        r for r in log.rows if r.phase in TAU_STAGES and r.tau is not None and r.tau_ref is not None
    ]
    ts = [r.t for r in log.rows]
    end = log.end or {}
    flown = end.get("summary") or {}  # the flight's own figures (trigger and contact interpolated)
    return LogSummary(
        outcome=end.get("outcome", "INCOMPLETE"),
        detail=end.get("detail", "no end record: the flight was cut short"),
        contact_speed=flown.get("contact_speed", contact.values.get("speed") if contact else None),
        v_contact_plan=plan.get("v_contact"),
        perch_time=flown.get("perch_time", contact.t - trigger.t if contact and trigger else None),
        plan_duration=plan.get("duration"),
        tau_rms=_rms(tracked),
        tau_rms_stage1=_rms([r for r in tracked if r.phase == "stage1"]),
        tau_rows=len(tracked),
        ticks=len(log.rows),
        rate_hz=config.get("rate_hz"),
        sync=config.get("sync"),
        period=Spread.of([b - a for a, b in zip(ts, ts[1:])]),
        jitter=Spread.of([r.jitter_s for r in log.rows[1:]]),  # row 0 has no previous tick
        duration_s=ts[-1] - ts[0] if ts else 0.0,
    )


def _ms(s: Spread | None) -> str:
    return (
        "--"
        if s is None
        else f"median {s.median * 1e3:.2f} ms, p99 {s.p99 * 1e3:.2f} ms, max {s.max * 1e3:.2f} ms"
    )


def figure_lines(
    outcome: str,
    detail: str,
    contact_speed: float | None,
    v_contact_plan: float | None,
    perch_time: float | None,
    plan_duration: float | None,
) -> list[str]:
    """The head every flight summary opens with, from a flight just flown (`perchd fly`) or
    read back from its log (`perchd log summary`): the outcome and what it means, then the
    contact speed and the perch time against the plan's."""
    meaning = EndReason[outcome].value if outcome in EndReason.__members__ else ""
    lines = [
        f"outcome: {outcome}"
        + (f" ({meaning})" if meaning else "")
        + (f": {detail}" if detail else "")
    ]
    if contact_speed is not None:
        plan = (
            ""
            if v_contact_plan is None
            else f" (plan {v_contact_plan:.3f} m/s, error {contact_speed - v_contact_plan:+.3f} m/s)"
        )
        lines.append(f"contact speed: {contact_speed:.3f} m/s{plan}")
    if perch_time is not None:
        plan = (
            ""
            if not plan_duration
            else f" (plan {plan_duration:.3f} s, error {100 * (perch_time / plan_duration - 1):+.1f} %)"
        )
        lines.append(f"perch time: {perch_time:.3f} s{plan}")
    return lines


def summary_text(s: LogSummary) -> str:
    lines = figure_lines(
        s.outcome, s.detail, s.contact_speed, s.v_contact_plan, s.perch_time, s.plan_duration
    )
    if s.tau_rms is not None:
        lines.append(
            f"tau tracking RMS: {s.tau_rms * 1e3:.1f} ms over {s.tau_rows} ticks "
            f"(stage 1 alone {s.tau_rms_stage1 * 1e3:.1f} ms)"
            if s.tau_rms_stage1 is not None
            else f"tau tracking RMS: {s.tau_rms * 1e3:.1f} ms over {s.tau_rows} ticks"
        )
    rate = f" at {s.rate_hz:g} Hz" if s.rate_hz else ""
    if s.sync == "mocap":  # no clock: the period below is the mocap's
        rate = " on each mocap frame"
    lines.append(f"loop: {s.ticks} ticks{rate} over {s.duration_s:.2f} s; period {_ms(s.period)}")
    lines.append(f"loop jitter: {_ms(s.jitter)}")
    return "\n".join(lines)
