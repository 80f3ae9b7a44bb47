"""The summary's words: no empty brackets, and the loop said as it ran."""

import dataclasses

from perchd.logs.summary import LogSummary, summary_text


def bare(**given) -> LogSummary:
    fields = {f.name: None for f in dataclasses.fields(LogSummary)}
    return LogSummary(**{**fields, "outcome": "OPERATOR_ABORT", "detail": "", "ticks": 0,
                         "duration_s": 0.0, **given})


def test_no_empty_brackets_after_the_outcome():
    first = summary_text(bare()).splitlines()[0]
    assert first == "outcome: OPERATOR_ABORT"


def test_a_mocap_synchronous_loop_is_not_called_a_fixed_rate():
    loop = [line for line in summary_text(bare(rate_hz=100.0, sync="mocap")).splitlines()
            if line.startswith("loop:")]
    assert len(loop) == 1 and "on each mocap frame" in loop[0] and "Hz" not in loop[0]
    fixed = summary_text(bare(rate_hz=100.0, sync="fixed"))
    assert "0 ticks at 100 Hz" in fixed
