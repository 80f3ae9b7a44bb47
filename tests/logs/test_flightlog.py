"""The flight log: written line by line as the flight goes, readable after a crash."""

from __future__ import annotations

import json
import math
import os

import pytest
from logseed import log_row

from perchd.core.errors import PerchdError
from perchd.flight.config import FlightConfig
from perchd.logs.flightlog import SCHEMA, FlightLogWriter, LogEvent, read_log


def row(k, end=None):
    return log_row(k, -1.0 + k * 0.01, end)


def test_every_row_is_on_disk_as_soon_as_it_is_written(tmp_path):
    w = FlightLogWriter(tmp_path / "f.jsonl", {"plan": {"x0": -3.0}, "config": FlightConfig()})
    for k in range(5):
        w.row(row(k))
    w.event(LogEvent(0.02, "trigger", "flown as made", {"x": -3.0}))
    log = read_log(tmp_path / "f.jsonl")  # read while the writer is still open
    assert [r.k for r in log.rows] == [0, 1, 2, 3, 4]
    assert log.events[0].values == {"x": -3.0}
    assert not log.complete
    assert log.header["schema"] == SCHEMA
    assert log.header["config"]["trigger"]["policy"] == "refuse"
    w.close()


def test_a_closed_log_carries_its_end(tmp_path):
    w = FlightLogWriter(tmp_path / "f.jsonl", {})
    w.row(row(0, "CONTACT"))
    w.close({"outcome": "CONTACT"})
    w.close({"outcome": "twice"})  # closing twice writes nothing more
    log = read_log(tmp_path / "f.jsonl")
    assert log.complete and log.end == {"outcome": "CONTACT"}
    assert log.rows[0] == row(0, "CONTACT")


def test_a_line_torn_by_a_killed_writer_is_dropped_and_the_rest_kept(tmp_path):
    path = tmp_path / "f.jsonl"
    w = FlightLogWriter(path, {})
    w.row(row(0))
    w.row(row(1))
    text = path.read_text()
    path.write_text(text + json.dumps({"row": {"t": 0.02}})[:17])
    log = read_log(path)
    assert len(log.rows) == 2 and not log.complete


def test_a_file_that_is_not_a_flight_log_is_one_clear_error(tmp_path):
    (tmp_path / "x.jsonl").write_text('{"schema": "other"}\n')
    with pytest.raises(PerchdError, match="not a perchd flight log"):
        read_log(tmp_path / "x.jsonl")


# --- a log that is not perchd's, or not whole: one PerchdError naming it, never another error --


def good_log(tmp_path):
    w = FlightLogWriter(tmp_path / "good.jsonl", {"plan": {"duration": 1.0}})
    for k in range(3):
        w.row(row(k))
    w.close({"outcome": "CONTACT"})
    return (tmp_path / "good.jsonl").read_bytes()


def edited(lines, i, edit):
    doc = json.loads(lines[i])
    edit(doc)
    return b"\n".join([*lines[:i], json.dumps(doc).encode(), *lines[i + 1 :]]) + b"\n"


BAD_LOGS = {
    "binary garbage": lambda lines: bytes(range(256)) * 4,
    "a torn line mid-file": lambda lines: b"\n".join([lines[0], lines[1][:20], *lines[2:]]),
    "another schema": lambda lines: b'{"schema": "perchd.flightlog/9"}\n' + b"\n".join(lines[1:]),
    "a header that is a list": lambda lines: b"[1, 2]\n" + b"\n".join(lines[1:]),
    "a row field that is text": lambda lines: edited(lines, 1, lambda d: d["row"].update(x="1")),
    "a row of 400 digits": lambda lines: edited(lines, 1, lambda d: d["row"].update(t=10**400)),
    "a row with NaN": lambda lines: edited(lines, 1, lambda d: d["row"].update(tau=math.nan)),
    "a row with a bool": lambda lines: edited(lines, 1, lambda d: d["row"].update(t=True)),
    "a row missing a field": lambda lines: edited(lines, 1, lambda d: d["row"].pop("phase")),
    "a row with an unknown field": lambda lines: edited(lines, 1, lambda d: d["row"].update(q=1)),
    "an end that is a number": lambda lines: edited(lines, -1, lambda d: d.update(end=1)),
    "a plan duration of text": lambda lines: edited(
        lines, 0, lambda d: d.update(plan={"duration": "1"})
    ),
    "1e999": lambda lines: lines[0] + b'\n{"row": {"t": 1e999}}\n',
    "a line that is a list": lambda lines: lines[0] + b"\n[1]\n" + lines[1] + b"\n",
}


@pytest.mark.parametrize("what", sorted(BAD_LOGS))
def test_a_log_that_is_not_perchds_is_one_perchd_error(tmp_path, what):
    lines = good_log(tmp_path).splitlines()
    path = tmp_path / "bad.jsonl"
    path.write_bytes(BAD_LOGS[what](lines))
    with pytest.raises(PerchdError, match=str(path)) as err:
        read_log(path)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("kind", ["fifo", "/dev/zero", "dir"])
def test_a_log_that_is_not_a_regular_file_is_refused_at_once(tmp_path, kind):
    path = {"fifo": tmp_path / "f", "/dev/zero": "/dev/zero", "dir": tmp_path}[kind]
    if kind == "fifo":
        os.mkfifo(path)
    with pytest.raises(PerchdError, match="not a regular file"):
        read_log(path)
