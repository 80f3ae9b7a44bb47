"""The flight log: written line by line as the flight goes, readable after a crash."""

from __future__ import annotations

import json

import pytest

from perchd.core.errors import PerchdError
from perchd.flight.config import FlightConfig
from perchd.logs.flightlog import SCHEMA, FlightLogWriter, LogEvent, LogRow, read_log


def row(k, end=None):
    return LogRow(k * 0.01, k, "stage1", -1.0 + k * 0.01, 1.0, -1.0, -1.0, -1.0, 1.0, -0.5,
                  0.0, 1.0, 0.0, 0.1, 0.0, 0.3, -0.5, 0.0, 0.0, 0.01, 0.004, k, 0.0, 1e-4, end)


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
