"""The summary's words: no empty brackets, one head for a flight flown and a flight read back,
and the loop said as it ran."""

import dataclasses

from perchd.core.types import EndReason
from perchd.logs.summary import LogSummary, figure_lines, summary_text


def bare(**given) -> LogSummary:
    fields = {f.name: None for f in dataclasses.fields(LogSummary)}
    return LogSummary(
        **{
            **fields,
            "outcome": "OPERATOR_ABORT",
            "detail": "",
            "ticks": 0,
            "duration_s": 0.0,
            **given,
        }
    )


def test_no_empty_brackets_after_the_outcome():
    first = summary_text(bare()).splitlines()[0]
    assert first == f"outcome: OPERATOR_ABORT ({EndReason.OPERATOR_ABORT.value})"
    assert "()" not in summary_text(bare(outcome="NOT_A_REASON")).splitlines()[0]


def test_a_flight_read_back_opens_as_the_flight_did():
    """`perchd fly` and `perchd log summary` share one head: the same figures give the same
    lines whichever side formats them."""
    figures = dict(contact_speed=0.987, v_contact_plan=1.0, perch_time=2.03, plan_duration=2.0)
    read_back = summary_text(bare(outcome="CONTACT", detail="touched", **figures)).splitlines()
    flown = figure_lines("CONTACT", "touched", 0.987, 1.0, 2.03, 2.0)
    assert read_back[:3] == flown
    assert flown[1] == "contact speed: 0.987 m/s (plan 1.000 m/s, error -0.013 m/s)"
    assert flown[2] == "perch time: 2.030 s (plan 2.000 s, error +1.5 %)"


def test_a_mocap_synchronous_loop_is_not_called_a_fixed_rate():
    loop = [
        line
        for line in summary_text(bare(rate_hz=100.0, sync="mocap")).splitlines()
        if line.startswith("loop:")
    ]
    assert len(loop) == 1 and "on each mocap frame" in loop[0] and "Hz" not in loop[0]
    fixed = summary_text(bare(rate_hz=100.0, sync="fixed"))
    assert "0 ticks at 100 Hz" in fixed
