"""Issue 17 item 12: an end without detail prints no empty brackets."""

import dataclasses

from perchd.logs.summary import LogSummary, summary_text


def test_no_empty_brackets_after_the_outcome():
    fields = {f.name: None for f in dataclasses.fields(LogSummary)}
    s = LogSummary(**{**fields, "outcome": "OPERATOR_ABORT", "detail": "", "ticks": 0,
                      "duration_s": 0.0})
    first = summary_text(s).splitlines()[0]
    assert first == "outcome: OPERATOR_ABORT"
